#include "frontend.h"

#include "pins.h"

namespace reach {
namespace {

constexpr size_t ix(SwitchId id) { return static_cast<size_t>(id); }
constexpr size_t ix(RailId id) { return static_cast<size_t>(id); }

const uint8_t kMtsPins[1] = {pins::kMts};

// Drive rails: PROTOCOL.md "Switches and positions" (MS3/MS4 assumed 12 V like MS1).
const SwitchDef kSwitches[kSwitchCount] = {
    {"ms1", 8, RailId::V12, pins::kMs1},
    {"ms2", 6, RailId::V24, pins::kMs2},
    {"ms3", 4, RailId::V12, pins::kMs3},
    {"ms4", 4, RailId::V12, pins::kMs4},
    {"mts", 1, RailId::V24, kMtsPins},
};

const RailDef kRails[kRailCount] = {
    {"6v", pins::kRail6v, false, RailId::V6},
    {"12v", pins::kRail12v, false, RailId::V12},
    {"24v", pins::kRail24v, false, RailId::V24},
    {"ns", pins::kRailNs, false, RailId::Ns},
    {"fan", pins::kRailFan, true, RailId::V24},
    {"tec", pins::kRailTec, false, RailId::Tec},
};

const char* const kDigits[9] = {"0", "1", "2", "3", "4", "5", "6", "7", "8"};

}  // namespace

bool operator==(const FrontendState& a, const FrontendState& b) {
  for (size_t i = 0; i < kSwitchCount; ++i) {
    if (a.position[i] != b.position[i]) return false;
  }
  for (size_t i = 0; i < kRailCount; ++i) {
    if (a.rail_on[i] != b.rail_on[i]) return false;
  }
  return true;
}

const SwitchDef& switch_def(SwitchId id) { return kSwitches[ix(id)]; }
const RailDef& rail_def(RailId id) { return kRails[ix(id)]; }

bool find_switch(const Token& name, SwitchId* id) {
  for (size_t i = 0; i < kSwitchCount; ++i) {
    if (name.equals(kSwitches[i].name)) {
      *id = static_cast<SwitchId>(i);
      return true;
    }
  }
  return false;
}

RailLookup find_rail(const Token& name, RailId* id) {
  // 3v3 feeds the Teensy, 5v the USB-to-fibre link (thesis table A.3): no pin behind them.
  if (name.equals("3v3") || name.equals("5v")) return RailLookup::NotSwitchable;
  for (size_t i = 0; i < kRailCount; ++i) {
    if (name.equals(kRails[i].name)) {
      *id = static_cast<RailId>(i);
      return RailLookup::Found;
    }
  }
  return RailLookup::Unknown;
}

bool parse_position(SwitchId id, const Token& word, uint8_t* position) {
  if (id == SwitchId::Mts) {
    if (word.equals("lna")) {
      *position = 0;
      return true;
    }
    if (word.equals("vna")) {
      *position = 1;
      return true;
    }
    return false;
  }
  if (word.size != 1 || word.text[0] < '0' || word.text[0] > '9') return false;
  uint8_t p = static_cast<uint8_t>(word.text[0] - '0');
  if (p > switch_def(id).lines) return false;
  *position = p;
  return true;
}

const char* position_name(SwitchId id, uint8_t position) {
  if (id == SwitchId::Mts) return position == 0 ? "lna" : "vna";
  return kDigits[position < 9 ? position : 0];
}

void Frontend::power_on() {
  for (uint8_t i = 0; i < pins::kOutputPinCount; ++i) hal_.pin_write(pins::kOutputPins[i], false);
  state_ = FrontendState{};
  changes_ = 0;
}

bool Frontend::check_select(SwitchId id, uint8_t position, Refusal* why) const {
  const SwitchDef& sw = switch_def(id);
  if (position == 0 || state_.rail_on[ix(sw.drive)]) return true;
  why->code = 20;
  why->reason.append(sw.name);
  why->reason.append(" needs rail ");
  why->reason.append(rail_def(sw.drive).name);
  return false;
}

void Frontend::select(SwitchId id, uint8_t position) {
  const SwitchDef& sw = switch_def(id);
  uint8_t old = state_.position[ix(id)];
  if (old == position) return;
  // Break before make: the old line is released before the new one is driven, so two
  // lines of one switch are never high together.
  if (old != 0) hal_.pin_write(sw.pins[old - 1], false);
  state_.position[ix(id)] = 0;
  if (position != 0) hal_.pin_write(sw.pins[position - 1], true);
  state_.position[ix(id)] = position;
  ++changes_;
}

bool Frontend::check_rail(RailId id, bool on, Refusal* why) const {
  const RailDef& rail = rail_def(id);
  if (on) {
    if (!rail.has_need || state_.rail_on[ix(rail.need)]) return true;
    why->code = 20;
    why->reason.append(rail.name);
    why->reason.append(" needs rail ");
    why->reason.append(rail_def(rail.need).name);
    return false;
  }
  const char* user = nullptr;
  for (size_t i = 0; i < kSwitchCount && user == nullptr; ++i) {
    if (kSwitches[i].drive == id && state_.position[i] != 0) user = kSwitches[i].name;
  }
  for (size_t i = 0; i < kRailCount && user == nullptr; ++i) {
    if (kRails[i].has_need && kRails[i].need == id && state_.rail_on[i]) user = kRails[i].name;
  }
  if (user == nullptr) return true;
  why->code = 22;
  why->reason.append("rail ");
  why->reason.append(rail.name);
  why->reason.append(" drives ");
  why->reason.append(user);
  return false;
}

void Frontend::set_rail(RailId id, bool on) {
  if (state_.rail_on[ix(id)] == on) return;
  hal_.pin_write(rail_def(id).pin, on);
  state_.rail_on[ix(id)] = on;
  ++changes_;
}

void Frontend::safe() {
  set_rail(RailId::Ns, false);
  select(SwitchId::Ms1, 0);
  select(SwitchId::Ms2, 0);
  select(SwitchId::Ms3, 0);
  select(SwitchId::Ms4, 0);
  select(SwitchId::Mts, 0);
  set_rail(RailId::V6, false);
  set_rail(RailId::V12, false);
}

}  // namespace reach
