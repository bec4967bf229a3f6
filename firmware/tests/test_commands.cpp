// PROTOCOL.md "Commands", "State", "Power-on state and safe state", MCP9808 decoding.
#include <string>

#include "bench.h"
#include "harness.h"

using bench::Bench;
using bench::RailId;
using bench::SwitchId;
using reach::BootReason;

namespace {
const std::string kPowerOnState =
    "ms1=0 ms2=0 ms3=0 ms4=0 mts=lna 6v=0 12v=0 24v=0 ns=0 fan=0 tec=0 boot=por";
}

TEST(help_id_version) {
  Bench b;
  CHECK_EQ(b.cmd("help"), std::string("OK 00 help id version ping state select rail temps tec safe deadman\r\n"));
  CHECK_EQ(b.cmd("id"), std::string("OK 00 REACH front-end teensy35\r\n"));
  CHECK_EQ(b.cmd("version"), std::string("OK 00 firmware=2.0.0 protocol=2\r\n"));
}

TEST(power_on_drives_every_output_pin_low_once) {
  reach::host::HostHal hal;
  reach::Firmware fw(hal);
  fw.begin();
  CHECK_EQ(hal.writes().size(), size_t(reach::pins::kOutputPinCount));
  for (uint8_t i = 0; i < reach::pins::kOutputPinCount; ++i) {
    CHECK_EQ(int(hal.writes()[i].pin), int(reach::pins::kOutputPins[i]));
    CHECK(!hal.writes()[i].high);
  }
}

TEST(power_on_state_and_uptime) {
  Bench b;
  b.hal.advance(1234);
  CHECK_EQ(b.cmd("state"), "OK 00 " + kPowerOnState + " uptime_ms=1234 changes=0 deadman=0\r\n");
}

TEST(pin_table_is_consistent) {
  // Every rail and switch line appears once in kOutputPins, and no pin collides with
  // UART1 (0/1), GPIO3/4, the LED (13) or I2C0 (18/19).
  int seen[64] = {};
  for (uint8_t i = 0; i < reach::pins::kOutputPinCount; ++i) {
    uint8_t p = reach::pins::kOutputPins[i];
    CHECK(p < 58);
    CHECK(p != 0 && p != 1 && p != 3 && p != 4 && p != 13 && p != 18 && p != 19);
    ++seen[p];
  }
  int expected = 0;
  for (size_t i = 0; i < reach::kSwitchCount; ++i) {
    const reach::SwitchDef& sw = reach::switch_def(static_cast<SwitchId>(i));
    for (uint8_t k = 0; k < sw.lines; ++k) CHECK_EQ(seen[sw.pins[k]], 1);
    expected += sw.lines;
  }
  for (size_t i = 0; i < reach::kRailCount; ++i) {
    CHECK_EQ(seen[reach::rail_def(static_cast<RailId>(i)).pin], 1);
    ++expected;
  }
  CHECK_EQ(expected, int(reach::pins::kOutputPinCount));
  // Fig. 2.42 pins.
  CHECK_EQ(int(reach::rail_def(RailId::V6).pin), 5);
  CHECK_EQ(int(reach::rail_def(RailId::V12).pin), 22);
  CHECK_EQ(int(reach::rail_def(RailId::V24).pin), 24);
  CHECK_EQ(int(reach::rail_def(RailId::Fan).pin), 20);
  CHECK_EQ(int(reach::rail_def(RailId::Ns).pin), 6);
  CHECK_EQ(int(reach::rail_def(RailId::Tec).pin), 2);
  for (uint8_t k = 0; k < 4; ++k) CHECK_EQ(int(reach::switch_def(SwitchId::Ms4).pins[k]), 9 + k);
}

TEST(rail_set_and_query) {
  Bench b;
  CHECK_EQ(b.cmd("rail 6v"), std::string("OK 00 6v=0\r\n"));
  CHECK_EQ(b.cmd("rail 6v on"), std::string("OK 00 6v=1\r\n"));
  CHECK(b.hal.level(5));
  CHECK_EQ(b.cmd("rail 6v"), std::string("OK 00 6v=1\r\n"));
  CHECK_EQ(b.cmd("rail 6v off"), std::string("OK 00 6v=0\r\n"));
  CHECK(!b.hal.level(5));
  CHECK_EQ(b.cmd("rail 6v toggle"), std::string("ERR 05 expected on or off\r\n"));
  CHECK_EQ(b.cmd("rail 7v on"), std::string("ERR 05 unknown rail\r\n"));
}

TEST(commands_are_idempotent) {
  Bench b;
  CHECK_EQ(b.cmd("rail 12v on"), std::string("OK 00 12v=1\r\n"));
  CHECK_EQ(b.cmd("select ms1 4"), std::string("OK 00 ms1=4\r\n"));
  b.hal.clear_writes();
  CHECK_EQ(b.cmd("rail 12v on"), std::string("OK 00 12v=1\r\n"));
  CHECK_EQ(b.cmd("select ms1 4"), std::string("OK 00 ms1=4\r\n"));
  CHECK(b.hal.writes().empty());
  CHECK_EQ(b.cmd("select ms1 0"), std::string("OK 00 ms1=0\r\n"));
  CHECK_EQ(b.cmd("select ms1 0"), std::string("OK 00 ms1=0\r\n"));
  CHECK_EQ(b.hal.writes().size(), size_t(1));
}

TEST(bad_positions_are_refused) {
  Bench b;
  b.cmd("rail 12v on");
  b.cmd("rail 24v on");
  const char* lines[] = {"select ms1 9", "select ms2 7", "select ms3 5", "select ms4 5",
                         "select ms1 -1", "select ms1 01", "select ms1 x", "select mts 1",
                         "select mts 0", "select mts LNA", "select ms5 1", "select lna mts"};
  for (const char* line : lines) {
    CHECK_EQ(b.cmd(line).substr(0, 7), std::string("ERR 05 "));
  }
  CHECK_EQ(b.hal.writes().size(), size_t(2));
}

TEST(every_position_of_every_switch) {
  Bench b;
  b.cmd("rail 12v on");
  b.cmd("rail 24v on");
  const struct {
    const char* name;
    int lines;
  } switches[] = {{"ms1", 8}, {"ms2", 6}, {"ms3", 4}, {"ms4", 4}};
  for (const auto& sw : switches) {
    for (int p = 0; p <= sw.lines; ++p) {
      std::string pos = std::to_string(p);
      CHECK_EQ(b.cmd(std::string("select ") + sw.name + " " + pos),
               std::string("OK 00 ") + sw.name + "=" + pos + "\r\n");
      CHECK(bench::pins_match_state(b.hal, b.fw.state()));
    }
  }
  CHECK_EQ(b.cmd("select mts vna"), std::string("OK 00 mts=vna\r\n"));
  CHECK(b.hal.level(reach::pins::kMts));
  CHECK_EQ(b.cmd("select mts lna"), std::string("OK 00 mts=lna\r\n"));
  CHECK(!b.hal.level(reach::pins::kMts));
  CHECK_EQ(b.violations, 0);
}

TEST(positions_are_exclusive_through_every_change) {
  // Every ordered pair of positions: the old line is released before the new one is
  // driven (checked on each single pin write by the bench's hook, and by the order).
  const struct {
    const char* name;
    SwitchId id;
    int lines;
  } switches[] = {{"ms1", SwitchId::Ms1, 8}, {"ms2", SwitchId::Ms2, 6},
                  {"ms3", SwitchId::Ms3, 4}, {"ms4", SwitchId::Ms4, 4}};
  for (const auto& sw : switches) {
    for (int from = 1; from <= sw.lines; ++from) {
      for (int to = 1; to <= sw.lines; ++to) {
        if (from == to) continue;
        Bench b;
        b.cmd("rail 12v on");
        b.cmd("rail 24v on");
        b.cmd(std::string("select ") + sw.name + " " + std::to_string(from));
        b.hal.clear_writes();
        b.cmd(std::string("select ") + sw.name + " " + std::to_string(to));
        const uint8_t* pins = reach::switch_def(sw.id).pins;
        CHECK_EQ(b.hal.writes().size(), size_t(2));
        if (b.hal.writes().size() == 2) {
          CHECK_EQ(int(b.hal.writes()[0].pin), int(pins[from - 1]));
          CHECK(!b.hal.writes()[0].high);
          CHECK_EQ(int(b.hal.writes()[1].pin), int(pins[to - 1]));
          CHECK(b.hal.writes()[1].high);
        }
        CHECK_EQ(bench::high_lines(b.hal, sw.id), 1);
        CHECK_EQ(b.violations, 0);
      }
    }
  }
}

TEST(state_reports_everything) {
  Bench b;
  b.cmd("rail 12v on");
  b.cmd("rail 24v on");
  b.cmd("rail fan on");
  b.cmd("select ms1 7");
  b.cmd("select ms2 5");
  b.cmd("select ms3 2");
  b.cmd("select ms4 4");
  b.cmd("select mts vna");
  b.hal.advance(42);
  CHECK_EQ(b.cmd("state"),
           std::string("OK 00 ms1=7 ms2=5 ms3=2 ms4=4 mts=vna 6v=0 12v=1 24v=1 ns=0 fan=1 "
                       "tec=0 boot=por uptime_ms=42 changes=8 deadman=0\r\n"));
}

TEST(safe_order_and_result) {
  Bench b;
  const char* setup[] = {"rail 6v on",   "rail 12v on",  "rail 24v on",  "rail ns on",
                         "rail fan on",  "rail tec on",  "select ms1 2", "select ms2 3",
                         "select ms3 4", "select ms4 1", "select mts vna"};
  for (const char* line : setup) CHECK_EQ(b.cmd(line).substr(0, 5), std::string("OK 00"));
  b.hal.clear_writes();
  CHECK_EQ(b.cmd("#s safe"),
           std::string("OK 00 #s ms1=0 ms2=0 ms3=0 ms4=0 mts=lna 6v=0 12v=0 24v=1 ns=0 fan=1 "
                       "tec=1 boot=por uptime_ms=0 changes=19 deadman=0\r\n"));
  // Noise source first, then the switches in order, the MTS, the LNA rail, then 12v.
  const uint8_t order[] = {reach::pins::kRailNs, reach::pins::kMs1[1], reach::pins::kMs2[2],
                           reach::pins::kMs3[3], reach::pins::kMs4[0], reach::pins::kMts,
                           reach::pins::kRail6v, reach::pins::kRail12v};
  CHECK_EQ(b.hal.writes().size(), sizeof(order));
  for (size_t i = 0; i < sizeof(order) && i < b.hal.writes().size(); ++i) {
    CHECK_EQ(int(b.hal.writes()[i].pin), int(order[i]));
    CHECK(!b.hal.writes()[i].high);
  }
  b.hal.clear_writes();
  CHECK_EQ(b.cmd("safe").substr(0, 5), std::string("OK 00"));  // idempotent
  CHECK(b.hal.writes().empty());
  CHECK(bench::pins_match_state(b.hal, b.fw.state()));
}

TEST(safe_from_power_on_changes_nothing) {
  Bench b;
  CHECK_EQ(b.cmd("safe"), "OK 00 " + kPowerOnState + " uptime_ms=0 changes=0 deadman=0\r\n");
  CHECK(b.hal.writes().empty());
}

TEST(watchdog_reset_gives_power_on_state_with_boot_wdog) {
  Bench b;
  b.cmd("rail 12v on");
  b.cmd("rail 24v on");
  b.cmd("rail fan on");
  b.cmd("select ms1 3");
  b.cmd("select mts vna");
  b.feed("rail 6v");  // a partial line is lost with the reset
  b.hal.advance(5000);
  b.hal.set_boot_reason(BootReason::Watchdog);
  b.hal.clear_writes();
  b.fw.begin();  // what setup() does after the WDOG reset
  CHECK_EQ(b.hal.writes().size(), size_t(reach::pins::kOutputPinCount));
  for (uint8_t i = 0; i < reach::pins::kOutputPinCount; ++i) CHECK(!b.hal.level(reach::pins::kOutputPins[i]));
  CHECK_EQ(b.cmd(" on"), std::string("ERR 03 unknown command\r\n"));
  b.hal.advance(7);
  CHECK_EQ(b.cmd("state"),
           std::string("OK 00 ms1=0 ms2=0 ms3=0 ms4=0 mts=lna 6v=0 12v=0 24v=0 ns=0 fan=0 "
                       "tec=0 boot=wdog uptime_ms=7 changes=0 deadman=0\r\n"));
}

TEST(temps_reads_every_sensor_present) {
  Bench b;
  CHECK_EQ(b.cmd("temps"), std::string("OK 00\r\n"));
  b.hal.set_sensor(0x18, 24.94);
  b.hal.set_sensor(0x1F, -10.5);
  b.hal.set_sensor(0x19, 25.06);
  CHECK_EQ(b.cmd("#t temps"), std::string("OK 00 #t 0x18=24.94 0x19=25.06 0x1f=-10.50\r\n"));
  b.hal.set_sensor(0x20, 30.0);  // outside the MCP9808 address range: not read
  b.hal.set_sensor_absent(0x19);
  CHECK_EQ(b.cmd("temps"), std::string("OK 00 0x18=24.94 0x1f=-10.50\r\n"));
  b.hal.set_sensor_fail(0x1a);
  CHECK_EQ(b.cmd("temps"), std::string("ERR 40 i2c bus error at 0x1a\r\n"));
}

TEST(mcp9808_decoding) {
  using reach::mcp9808::sixteenths;
  using reach::mcp9808::sixteenths_to_centi;
  CHECK_EQ(sixteenths(0x0190), 400);      // +25.0000 C
  CHECK_EQ(sixteenths(0xE190), 400);      // alarm flags (bits 15-13) ignored
  CHECK_EQ(sixteenths(0x1FF0), -16);      // -1.0000 C
  CHECK_EQ(sixteenths(0x1E70), -400);     // -25.0000 C
  CHECK_EQ(sixteenths(0x1D80), -640);     // -40.0000 C
  CHECK_EQ(sixteenths(0x07D0), 2000);     // +125.0000 C
  CHECK_EQ(sixteenths(0x0FFF), 4095);     // largest positive code
  CHECK_EQ(sixteenths(0x1000), -4096);    // most negative code
  CHECK_EQ(sixteenths_to_centi(1), 6);    // 0.0625 -> 0.06
  CHECK_EQ(sixteenths_to_centi(2), 13);   // 0.125 -> 0.13 (half away from zero)
  CHECK_EQ(sixteenths_to_centi(-1), -6);
  CHECK_EQ(sixteenths_to_centi(-2), -13);
  CHECK_EQ(sixteenths_to_centi(399), 2494);
  for (int s = -4096; s <= 4095; ++s) {
    double exact = s * 6.25;
    int32_t c = sixteenths_to_centi(static_cast<int16_t>(s));
    CHECK(c - exact <= 0.5 && exact - c <= 0.5);
    CHECK_EQ(int(sixteenths(reach::host::mcp9808_raw(s / 16.0))), s);
  }
}

TEST(temperature_format_near_zero) {
  Bench b;
  b.hal.set_sensor(0x18, -0.0625);
  b.hal.set_sensor(0x19, 0.0);
  b.hal.set_sensor(0x1a, 0.125);
  CHECK_EQ(b.cmd("temps"), std::string("OK 00 0x18=-0.06 0x19=0.00 0x1a=0.13\r\n"));
}

TEST(tec_send_writes_the_bytes) {
  Bench b;
  b.cmd("rail tec on");
  CHECK_EQ(b.cmd("tec send 016A30303031"), std::string("OK 00 sent=6\r\n"));
  CHECK_EQ(b.hal.uart_sent, std::string("\x01j00" "01"));
  CHECK_EQ(b.cmd("tec send 0a0B"), std::string("OK 00 sent=2\r\n"));
}

TEST(tec_bad_hex_is_refused) {
  Bench b;
  b.cmd("rail tec on");
  const char* lines[] = {"tec send 0", "tec send zz", "tec send 0x01", "tec query 123",
                         "tec push 00"};
  for (const char* line : lines) CHECK_EQ(b.cmd(line).substr(0, 7), std::string("ERR 05 "));
  CHECK(b.hal.uart_sent.empty());
}

TEST(tec_query_returns_the_reply_with_its_crlf) {
  Bench b;
  b.cmd("rail tec on");
  b.hal.uart_rx.push_back('z');  // stale byte from before the request: dropped
  b.hal.on_uart_write = [](bench::HostHal& h, const uint8_t*, size_t) {
    for (char c : std::string("\x01j02OK5D\r\n")) h.uart_rx.push_back(static_cast<uint8_t>(c));
  };
  CHECK_EQ(b.cmd("#q tec query 016A303043"),
           std::string("OK 00 #q 016A30324F4B35440D0A\r\n"));
  CHECK_EQ(b.hal.uart_sent, std::string("\x01j00C"));
}

TEST(tec_query_times_out) {
  Bench b;
  b.cmd("rail tec on");
  uint32_t before = b.hal.millis();
  CHECK_EQ(b.cmd("tec query 01"), std::string("ERR 31 tec no reply within 300 ms\r\n"));
  CHECK(b.hal.millis() - before >= 300);
  b.hal.on_uart_write = [](bench::HostHal& h, const uint8_t*, size_t) {
    for (char c : std::string("\x01j02OK5D")) h.uart_rx.push_back(static_cast<uint8_t>(c));
  };
  CHECK_EQ(b.cmd("tec query 01"), std::string("ERR 31 tec no reply within 300 ms\r\n"));
}

TEST(tec_query_reply_too_long) {
  Bench b;
  b.cmd("rail tec on");
  b.hal.on_uart_write = [](bench::HostHal& h, const uint8_t*, size_t) {
    for (int i = 0; i < 200; ++i) h.uart_rx.push_back('x');
  };
  CHECK_EQ(b.cmd("tec query 01"), std::string("ERR 32 tec reply longer than 96 bytes\r\n"));
}
