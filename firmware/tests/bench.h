// A firmware on the recording host HAL, plus the properties every state must have.
// Shared by the unit tests and the fuzzer.
#ifndef REACH_TEST_BENCH_H
#define REACH_TEST_BENCH_H

#include <string>

#include "../core/reach_core.h"
#include "../host/host_hal.h"

namespace bench {

using reach::FrontendState;
using reach::RailId;
using reach::SwitchId;
using reach::host::HostHal;

inline int high_lines(const HostHal& hal, SwitchId id) {
  const reach::SwitchDef& sw = reach::switch_def(id);
  int high = 0;
  for (uint8_t k = 0; k < sw.lines; ++k) high += hal.level(sw.pins[k]) ? 1 : 0;
  return high;
}

// Never two control lines of one switch high at once.
inline bool exclusive(const HostHal& hal) {
  for (size_t i = 0; i < reach::kSwitchCount; ++i) {
    if (high_lines(hal, static_cast<SwitchId>(i)) > 1) return false;
  }
  return true;
}

// The recorded pin levels are exactly what the state says.
inline bool pins_match_state(const HostHal& hal, const FrontendState& state) {
  for (size_t i = 0; i < reach::kSwitchCount; ++i) {
    const reach::SwitchDef& sw = reach::switch_def(static_cast<SwitchId>(i));
    for (uint8_t k = 0; k < sw.lines; ++k) {
      if (hal.level(sw.pins[k]) != (state.position[i] == k + 1)) return false;
    }
  }
  for (size_t i = 0; i < reach::kRailCount; ++i) {
    if (hal.level(reach::rail_def(static_cast<RailId>(i)).pin) != state.rail_on[i]) return false;
  }
  return true;
}

// What the interlocks guarantee: a switch away from 0 has its drive rail; fan has 24v.
inline bool interlocks_hold(const FrontendState& state) {
  for (size_t i = 0; i < reach::kSwitchCount; ++i) {
    const reach::SwitchDef& sw = reach::switch_def(static_cast<SwitchId>(i));
    if (state.position[i] != 0 && !state.rail_on[static_cast<size_t>(sw.drive)]) return false;
  }
  return !state.rail_on[static_cast<size_t>(RailId::Fan)] ||
         state.rail_on[static_cast<size_t>(RailId::V24)];
}

// Outputs (switch positions and rails) that differ between two states.
inline uint32_t outputs_differing(const FrontendState& a, const FrontendState& b) {
  uint32_t n = 0;
  for (size_t i = 0; i < reach::kSwitchCount; ++i) n += a.position[i] != b.position[i] ? 1 : 0;
  for (size_t i = 0; i < reach::kRailCount; ++i) n += a.rail_on[i] != b.rail_on[i] ? 1 : 0;
  return n;
}

// `after` is what `safe` makes of `before`: every switch at 0 (MTS lna), ns, 6v and 12v
// off, 24v, fan and tec as they were.
inline bool safe_from(const FrontendState& before, const FrontendState& after) {
  for (size_t i = 0; i < reach::kSwitchCount; ++i) {
    if (after.position[i] != 0) return false;
  }
  for (RailId off : {RailId::Ns, RailId::V6, RailId::V12}) {
    if (after.rail_on[static_cast<size_t>(off)]) return false;
  }
  for (RailId kept : {RailId::V24, RailId::Fan, RailId::Tec}) {
    size_t i = static_cast<size_t>(kept);
    if (after.rail_on[i] != before.rail_on[i]) return false;
  }
  return true;
}

inline bool is_output_pin(uint8_t pin) {
  for (uint8_t i = 0; i < reach::pins::kOutputPinCount; ++i) {
    if (reach::pins::kOutputPins[i] == pin) return true;
  }
  return false;
}

// A started firmware whose HAL counts every pin write that breaks exclusivity (the
// transient inside a change included) or touches a pin outside the pin table.
struct Bench {
  HostHal hal;
  reach::Firmware fw{hal};
  int violations = 0;

  Bench() {
    hal.on_pin_write = [this](const HostHal& h, reach::host::PinWrite w) {
      if (!exclusive(h) || !is_output_pin(w.pin)) ++violations;
    };
    fw.begin();
    hal.clear_writes();
  }

  // Send one line (LF appended) and return everything the firmware answered.
  std::string cmd(const std::string& line) { return feed(line + "\n"); }

  std::string feed(const std::string& bytes) {
    for (char c : bytes) fw.feed(static_cast<uint8_t>(c));
    return hal.take_output();
  }

  bool rail(RailId id) const { return fw.state().rail_on[static_cast<size_t>(id)]; }
  uint8_t pos(SwitchId id) const { return fw.state().position[static_cast<size_t>(id)]; }
};

}  // namespace bench

#endif  // REACH_TEST_BENCH_H
