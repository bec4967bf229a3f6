// PROTOCOL.md "Interlocks": each rule, tried from the side that must be refused; a
// refused command never writes a pin.
#include <string>

#include "bench.h"
#include "harness.h"

using bench::Bench;
using bench::RailId;
using bench::SwitchId;

namespace {
// A refused line: the expected reply, no pin written, state unchanged.
void refused(Bench& b, const std::string& line, const std::string& reply) {
  reach::FrontendState before = b.fw.state();
  b.hal.clear_writes();
  CHECK_EQ(b.cmd(line), reply + "\r\n");
  CHECK(b.hal.writes().empty());
  CHECK(b.fw.state() == before);
}
}  // namespace

TEST(switch_needs_its_drive_rail) {
  Bench b;
  refused(b, "select ms1 1", "ERR 20 ms1 needs rail 12v");
  refused(b, "select ms3 4", "ERR 20 ms3 needs rail 12v");
  refused(b, "select ms4 2", "ERR 20 ms4 needs rail 12v");
  refused(b, "select ms2 6", "ERR 20 ms2 needs rail 24v");
  refused(b, "select mts vna", "ERR 20 mts needs rail 24v");
  b.cmd("rail 24v on");  // the wrong rail does not help MS1
  refused(b, "select ms1 8", "ERR 20 ms1 needs rail 12v");
  b.cmd("rail 24v off");
  b.cmd("rail 12v on");
  refused(b, "select ms2 1", "ERR 20 ms2 needs rail 24v");
  CHECK_EQ(b.cmd("select ms1 8"), std::string("OK 00 ms1=8\r\n"));
}

TEST(position_zero_and_lna_are_always_allowed) {
  Bench b;
  CHECK_EQ(b.cmd("select ms1 0"), std::string("OK 00 ms1=0\r\n"));
  CHECK_EQ(b.cmd("select ms2 0"), std::string("OK 00 ms2=0\r\n"));
  CHECK_EQ(b.cmd("select mts lna"), std::string("OK 00 mts=lna\r\n"));
}

TEST(rail_off_refused_while_it_drives_a_switch) {
  Bench b;
  b.cmd("rail 12v on");
  b.cmd("rail 24v on");
  b.cmd("select ms1 1");
  refused(b, "rail 12v off", "ERR 22 rail 12v drives ms1");
  b.cmd("select ms1 0");
  b.cmd("select ms3 2");
  refused(b, "rail 12v off", "ERR 22 rail 12v drives ms3");
  b.cmd("select ms3 0");
  b.cmd("select ms4 3");
  refused(b, "rail 12v off", "ERR 22 rail 12v drives ms4");
  b.cmd("select ms4 0");
  CHECK_EQ(b.cmd("rail 12v off"), std::string("OK 00 12v=0\r\n"));

  b.cmd("select ms2 5");
  refused(b, "rail 24v off", "ERR 22 rail 24v drives ms2");
  b.cmd("select ms2 0");
  b.cmd("select mts vna");
  refused(b, "rail 24v off", "ERR 22 rail 24v drives mts");
  b.cmd("select mts lna");
  b.cmd("rail fan on");
  refused(b, "rail 24v off", "ERR 22 rail 24v drives fan");
  b.cmd("rail fan off");
  CHECK_EQ(b.cmd("rail 24v off"), std::string("OK 00 24v=0\r\n"));
}

TEST(unrelated_rails_go_off_while_switches_are_set) {
  Bench b;
  b.cmd("rail 12v on");
  b.cmd("rail 6v on");
  b.cmd("rail ns on");
  b.cmd("select ms1 3");
  CHECK_EQ(b.cmd("rail 6v off"), std::string("OK 00 6v=0\r\n"));
  CHECK_EQ(b.cmd("rail ns off"), std::string("OK 00 ns=0\r\n"));
}

TEST(rails_3v3_and_5v_are_never_switched) {
  Bench b;
  const char* lines[][2] = {{"rail 3v3 on", "3v3"}, {"rail 3v3 off", "3v3"}, {"rail 3v3", "3v3"},
                            {"rail 5v on", "5v"},   {"rail 5v off", "5v"},   {"rail 5v", "5v"},
                            {"rail 5v bogus", "5v"}};
  for (const auto& line : lines) {
    refused(b, line[0], std::string("ERR 21 rail ") + line[1] + " is not switchable");
  }
  CHECK(!b.hal.level(3) && !b.hal.level(4));
}

TEST(fan_needs_24v) {
  Bench b;
  refused(b, "rail fan on", "ERR 20 fan needs rail 24v");
  CHECK_EQ(b.cmd("rail fan off"), std::string("OK 00 fan=0\r\n"));
  b.cmd("rail 24v on");
  CHECK_EQ(b.cmd("rail fan on"), std::string("OK 00 fan=1\r\n"));
}

TEST(tec_needs_its_rail) {
  Bench b;
  refused(b, "tec send 0102", "ERR 30 tec rail is off");
  refused(b, "tec query 0102", "ERR 30 tec rail is off");
  CHECK(b.hal.uart_sent.empty());
  b.cmd("rail tec on");
  CHECK_EQ(b.cmd("tec send 0102"), std::string("OK 00 sent=2\r\n"));
}

TEST(argument_errors_come_before_interlocks) {
  Bench b;
  refused(b, "select ms1 9", "ERR 05 bad position");
  refused(b, "tec send 0", "ERR 05 bad hex");
  refused(b, "rail fan maybe", "ERR 05 expected on or off");
}

TEST(interlocks_hold_after_safe_from_anywhere) {
  Bench b;
  b.cmd("rail 24v on");
  b.cmd("rail fan on");
  b.cmd("rail 12v on");
  b.cmd("select ms2 4");
  b.cmd("select ms1 5");
  b.cmd("safe");
  CHECK(bench::interlocks_hold(b.fw.state()));
  CHECK_EQ(b.cmd("rail 12v off"), std::string("OK 00 12v=0\r\n"));  // nothing on 12v now
  refused(b, "rail 24v off", "ERR 22 rail 24v drives fan");  // safe keeps the fan
  CHECK_EQ(b.violations, 0);
}
