// The front-end's switches and rails: state, interlocks and the pin writes that apply it
// (PROTOCOL.md, "Switches and positions", "Rails", "Interlocks", "safe").
//
// Every change is split into a check (const, touches nothing) and an apply (writes pins).
// The command layer calls apply only after every check of the line has passed, so a
// refused command never moves a pin.
#ifndef REACH_FRONTEND_H
#define REACH_FRONTEND_H

#include <stddef.h>
#include <stdint.h>

#include "hal.h"
#include "text.h"

namespace reach {

enum class SwitchId : uint8_t { Ms1, Ms2, Ms3, Ms4, Mts };
constexpr size_t kSwitchCount = 5;

// In the order of the `state` reply.
enum class RailId : uint8_t { V6, V12, V24, Ns, Fan, Tec };
constexpr size_t kRailCount = 6;

struct SwitchDef {
  const char* name;
  uint8_t lines;        // control lines = highest position (MTS: 1, high = "vna")
  RailId drive;         // rail that powers the switch's actuators
  const uint8_t* pins;  // pins[k] drives position k + 1
};

struct RailDef {
  const char* name;
  uint8_t pin;
  bool has_need;  // the rail may only be on while `need` is on (fan needs 24v)
  RailId need;
};

// The complete output state; position 0 = every line of the switch low (MTS: "lna").
struct FrontendState {
  uint8_t position[kSwitchCount];
  bool rail_on[kRailCount];
};
bool operator==(const FrontendState& a, const FrontendState& b);
inline bool operator!=(const FrontendState& a, const FrontendState& b) { return !(a == b); }

// Why a change was refused: the ERR code and its reason text.
struct Refusal {
  uint8_t code = 0;
  TextBuf<48> reason;
};

enum class RailLookup : uint8_t { Found, NotSwitchable, Unknown };

const SwitchDef& switch_def(SwitchId id);
const RailDef& rail_def(RailId id);
bool find_switch(const Token& name, SwitchId* id);
RailLookup find_rail(const Token& name, RailId* id);
// "0".."8" for a multi-throw switch (up to its line count), "lna"/"vna" for the MTS.
bool parse_position(SwitchId id, const Token& word, uint8_t* position);
const char* position_name(SwitchId id, uint8_t position);

class Frontend {
 public:
  explicit Frontend(Hal& hal) : hal_(hal) {}

  // Power-on state: every output pin low, every switch at 0, every rail off.
  void power_on();

  bool check_select(SwitchId id, uint8_t position, Refusal* why) const;
  void select(SwitchId id, uint8_t position);
  bool check_rail(RailId id, bool on, Refusal* why) const;
  void set_rail(RailId id, bool on);
  // Noise source off, every switch to 0, MTS to lna, 6v off, 12v off; always allowed.
  void safe();

  const FrontendState& state() const { return state_; }
  // Output changes since power_on(): one per switch or rail that actually moved.
  uint32_t changes() const { return changes_; }

 private:
  Hal& hal_;
  FrontendState state_{};
  uint32_t changes_ = 0;
};

}  // namespace reach

#endif  // REACH_FRONTEND_H
