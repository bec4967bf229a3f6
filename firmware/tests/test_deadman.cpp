// PROTOCOL.md "Dead-man switch" and the `changes` counter of `state`.
#include <string>

#include "bench.h"
#include "harness.h"

using bench::Bench;
using bench::RailId;
using bench::SwitchId;
using reach::BootReason;

namespace {

const std::string kTripped = "dead-man tripped after 300 ms without the host; front-end safe";

// Rails and switches on, the fan and the TEC included.
void busy(Bench& b) {
  const char* setup[] = {"rail 24v on", "rail fan on",  "rail tec on",   "rail 12v on",
                         "rail 6v on",  "rail ns on",   "select ms1 3",  "select ms2 5",
                         "select ms4 2", "select mts vna"};
  for (const char* line : setup) CHECK_EQ(b.cmd(line).substr(0, 5), std::string("OK 00"));
}

}  // namespace

TEST(deadman_query_arm_and_disarm) {
  Bench b;
  CHECK_EQ(b.cmd("deadman"), std::string("OK 00 deadman=0\r\n"));
  CHECK_EQ(b.cmd("#d1 deadman 300"), std::string("OK 00 #d1 deadman=300\r\n"));
  CHECK_EQ(b.cmd("deadman"), std::string("OK 00 deadman=300\r\n"));
  CHECK_EQ(b.fw.deadman_ms(), 300u);
  CHECK(b.cmd("state").find(" changes=0 deadman=300\r\n") != std::string::npos);
  CHECK_EQ(b.cmd("deadman 3600000"), std::string("OK 00 deadman=3600000\r\n"));
  CHECK_EQ(b.cmd("deadman 100"), std::string("OK 00 deadman=100\r\n"));
  CHECK_EQ(b.cmd("deadman 0"), std::string("OK 00 deadman=0\r\n"));
  CHECK_EQ(b.fw.deadman_ms(), 0u);
  CHECK(b.hal.writes().empty());
}

TEST(deadman_bad_timeouts_are_refused_and_change_nothing) {
  Bench b;
  b.cmd("deadman 500");
  const char* lines[] = {"deadman 99",  "deadman 3600001", "deadman 0100", "deadman -1",
                         "deadman 1e3", "deadman 12345678", "deadman x",   "deadman 00"};
  for (const char* line : lines) {
    CHECK_EQ(b.cmd(line), std::string("ERR 05 timeout must be 0 (off) or 100-3600000 ms\r\n"));
  }
  CHECK_EQ(b.cmd("deadman 1 2"), std::string("ERR 04 wrong number of arguments\r\n"));
  CHECK_EQ(b.fw.deadman_ms(), 500u);
}

TEST(deadman_trips_into_the_safe_state_on_its_own) {
  Bench b;
  busy(b);
  reach::FrontendState before = b.fw.state();
  uint32_t changes = b.fw.changes();
  CHECK_EQ(b.cmd("deadman 300"), std::string("OK 00 deadman=300\r\n"));
  b.hal.clear_writes();
  b.hal.advance(299);
  b.fw.poll();
  CHECK(b.hal.writes().empty());
  CHECK(!b.fw.deadman_tripped());
  b.hal.advance(1);
  b.fw.poll();  // the main loop, with no request in sight
  CHECK(b.fw.deadman_tripped());
  CHECK_EQ(b.fw.deadman_ms(), 0u);
  CHECK(bench::safe_from(before, b.fw.state()));
  CHECK(bench::pins_match_state(b.hal, b.fw.state()));
  CHECK(b.rail(RailId::Fan) && b.rail(RailId::V24) && b.rail(RailId::Tec));
  // The same pin writes, in the same order, as `safe`.
  const uint8_t order[] = {reach::pins::kRailNs, reach::pins::kMs1[2], reach::pins::kMs2[4],
                           reach::pins::kMs4[1], reach::pins::kMts,    reach::pins::kRail6v,
                           reach::pins::kRail12v};
  CHECK_EQ(b.hal.writes().size(), sizeof(order));
  for (size_t i = 0; i < sizeof(order) && i < b.hal.writes().size(); ++i) {
    CHECK_EQ(int(b.hal.writes()[i].pin), int(order[i]));
    CHECK(!b.hal.writes()[i].high);
  }
  CHECK_EQ(b.fw.changes(), changes + 7);
  b.hal.clear_writes();
  b.hal.advance(10000);
  b.fw.poll();  // disarmed by the trip: nothing more happens
  CHECK(b.hal.writes().empty());
  CHECK_EQ(b.violations, 0);
}

TEST(the_next_request_is_told_once_and_not_run) {
  Bench b;
  b.cmd("rail 12v on");
  b.cmd("deadman 300");
  b.hal.advance(300);
  b.fw.poll();
  b.hal.clear_writes();
  CHECK_EQ(b.cmd("#k7 rail 6v on"), "ERR 50 #k7 " + kTripped + "\r\n");
  CHECK(!b.rail(RailId::V6));
  CHECK(b.hal.writes().empty());
  CHECK(!b.fw.deadman_tripped());
  CHECK_EQ(b.cmd("#k8 rail 6v on"), std::string("OK 00 #k8 6v=1\r\n"));
  std::string state = b.cmd("state");
  CHECK(state.find(" 12v=0 ") != std::string::npos);
  CHECK(state.find(" deadman=0\r\n") != std::string::npos);
}

TEST(any_request_renews_the_timer) {
  Bench b;
  b.cmd("rail 12v on");
  b.cmd("deadman 300");
  // OK replies and refusals alike: the host is there.
  const char* lines[] = {"ping", "#t state", "select ms1 9", "bogus", "select ms2 1",
                         "rail 5v off", "deadman", "temps", "ping x"};
  for (int round = 0; round < 3; ++round) {
    for (const char* line : lines) {
      b.hal.advance(250);
      b.fw.poll();
      CHECK(b.cmd(line).find("ERR 50") == std::string::npos);
    }
  }
  CHECK(!b.fw.deadman_tripped());
  CHECK(b.rail(RailId::V12));
  CHECK_EQ(b.fw.deadman_ms(), 300u);
}

TEST(framing_errors_neither_renew_nor_take_the_report) {
  Bench b;
  b.cmd("rail 12v on");
  b.cmd("deadman 300");
  b.hal.advance(200);
  CHECK_EQ(b.cmd(""), std::string("ERR 06 empty line\r\n"));  // the driver's resync LF
  CHECK_EQ(b.feed("ping\x01\n"), std::string("ERR 02 byte outside printable ascii\r\n"));
  b.hal.advance(100);
  b.fw.poll();
  CHECK(b.fw.deadman_tripped());
  CHECK_EQ(b.cmd(""), std::string("ERR 06 empty line\r\n"));
  CHECK_EQ(b.cmd("#bad-tag ping"), std::string("ERR 07 bad tag\r\n"));
  CHECK_EQ(b.cmd("#r1"), std::string("ERR 06 #r1 empty line\r\n"));
  CHECK_EQ(b.cmd("#r2 ping"), "ERR 50 #r2 " + kTripped + "\r\n");
  CHECK_EQ(b.cmd("#r3 ping"), std::string("OK 00 #r3 pong\r\n"));
}

TEST(a_late_request_finds_the_front_end_already_safe) {
  // The request arrives after the timeout but before the main loop polled: it is told,
  // not run, exactly as if the loop had been quicker.
  Bench b;
  b.cmd("rail 12v on");
  b.cmd("deadman 300");
  b.hal.advance(301);
  CHECK_EQ(b.cmd("#a select ms1 2"), "ERR 50 #a " + kTripped + "\r\n");
  CHECK_EQ(b.pos(SwitchId::Ms1), 0);
  CHECK(!b.rail(RailId::V12));
}

TEST(unknown_commands_are_told_too) {
  Bench b;
  b.cmd("deadman 300");
  b.hal.advance(300);
  b.fw.poll();
  CHECK_EQ(b.cmd("launch"), "ERR 50 " + kTripped + "\r\n");
  CHECK_EQ(b.cmd("launch"), std::string("ERR 03 unknown command\r\n"));
}

TEST(deadman_zero_never_trips) {
  Bench b;
  busy(b);
  b.cmd("deadman 300");
  CHECK_EQ(b.cmd("deadman 0"), std::string("OK 00 deadman=0\r\n"));
  b.hal.clear_writes();
  for (int i = 0; i < 100; ++i) {
    b.hal.advance(3600000);
    b.fw.poll();
  }
  CHECK(b.hal.writes().empty());
  CHECK_EQ(b.cmd("#z ping"), std::string("OK 00 #z pong\r\n"));
  CHECK(b.rail(RailId::V12));
}

TEST(rearming_after_a_trip_starts_afresh) {
  Bench b;
  b.cmd("deadman 300");
  b.hal.advance(300);
  b.fw.poll();
  CHECK_EQ(b.cmd("deadman 400"), "ERR 50 " + kTripped + "\r\n");  // not run either
  CHECK_EQ(b.fw.deadman_ms(), 0u);
  CHECK_EQ(b.cmd("deadman 400"), std::string("OK 00 deadman=400\r\n"));
  b.hal.advance(399);
  b.fw.poll();
  CHECK(!b.fw.deadman_tripped());
  b.hal.advance(1);
  b.fw.poll();
  CHECK(b.fw.deadman_tripped());
  CHECK_EQ(b.cmd("ping"),
           std::string("ERR 50 dead-man tripped after 400 ms without the host; front-end safe\r\n"));
}

TEST(deadman_survives_the_millis_wrap) {
  Bench b;
  b.hal.advance(0xFFFFFFFFull - 100);
  b.cmd("deadman 300");
  b.hal.advance(250);  // millis() wrapped past zero
  b.fw.poll();
  CHECK(!b.fw.deadman_tripped());
  b.hal.advance(50);
  b.fw.poll();
  CHECK(b.fw.deadman_tripped());
}

TEST(changes_count_every_output_that_moves) {
  Bench b;
  CHECK_EQ(b.fw.changes(), 0u);
  b.cmd("rail 12v on");
  CHECK_EQ(b.fw.changes(), 1u);
  b.cmd("select ms1 3");
  b.cmd("select ms1 5");  // two pin writes, one output change
  CHECK_EQ(b.fw.changes(), 3u);
  b.cmd("select ms1 5");  // idempotent: nothing moves
  b.cmd("rail 12v on");
  b.cmd("select ms2 1");  // refused
  b.cmd("rail 12v off");  // refused
  b.cmd("rail 12v");      // a query
  CHECK_EQ(b.fw.changes(), 3u);
  CHECK(b.cmd("state").find(" changes=3 deadman=0\r\n") != std::string::npos);
  b.cmd("safe");  // ms1 to 0, 12v off
  CHECK_EQ(b.fw.changes(), 5u);
  b.cmd("safe");
  CHECK_EQ(b.fw.changes(), 5u);
}

TEST(a_reset_zeroes_changes_disarms_and_forgets_the_trip) {
  Bench b;
  b.cmd("rail 12v on");
  b.cmd("deadman 300");
  b.hal.advance(300);
  b.fw.poll();
  CHECK(b.fw.deadman_tripped());
  CHECK_EQ(b.fw.changes(), 2u);
  b.hal.set_boot_reason(BootReason::Watchdog);
  b.fw.begin();
  CHECK(!b.fw.deadman_tripped());
  CHECK_EQ(b.fw.changes(), 0u);
  CHECK_EQ(b.fw.deadman_ms(), 0u);
  CHECK_EQ(b.cmd("state"),
           std::string("OK 00 ms1=0 ms2=0 ms3=0 ms4=0 mts=lna 6v=0 12v=0 24v=0 ns=0 fan=0 "
                       "tec=0 boot=wdog uptime_ms=0 changes=0 deadman=0\r\n"));
}
