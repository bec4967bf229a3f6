// The ONE pin table of the front-end board (thesis fig. 2.42, Teensy 3.5 numbering).
//
// Known from fig. 2.42: 6V_EN 5 (both +6V_A and +6V_B), +12V 22, +24V 24, INT_FAN 20,
// NS_PWR 6, TEC_EN 2, MS4-1..4 on 9..12, TEC UART on RX1/TX1 (pins 0/1), MCP9808s on
// SCL0/SDA0 (pins 19/18). Pins 3/4 (GPIO3/GPIO4) and 13 (LED) are left alone.
//
// ASSUMPTION, TO BE CHECKED AGAINST THE BOARD: the thesis text lost the Teensy pins of
// MS1-1..8, MS2-1..6, MS3-1..4 and MTS. The values marked "assumed" below are free
// Teensy 3.5 pins chosen for this firmware, not read from the board. Measure the
// breakout board (J4 connector) before flashing a real front-end.
#ifndef REACH_PINS_H
#define REACH_PINS_H

#include <stdint.h>

namespace reach {
namespace pins {

// Power rails (fig. 2.42).
constexpr uint8_t kRail6v = 5;    // 6V_EN: the LNA's +6V_A and +6V_B
constexpr uint8_t kRail12v = 22;  // +12V: VNA, MS1, MS3, MS4
constexpr uint8_t kRail24v = 24;  // +24V: internal fan supply, MS2, MTS
constexpr uint8_t kRailNs = 6;    // NS_PWR: 28 V noise-diode supply
constexpr uint8_t kRailFan = 20;  // INT_FAN: enclosure fan
constexpr uint8_t kRailTec = 2;   // TEC_EN: Peltier controller

// Switch control lines; index k drives position k + 1.
constexpr uint8_t kMs1[8] = {25, 26, 27, 28, 29, 30, 31, 32};  // assumed
constexpr uint8_t kMs2[6] = {33, 34, 35, 36, 37, 38};          // assumed
constexpr uint8_t kMs3[4] = {14, 15, 16, 17};                  // assumed
constexpr uint8_t kMs4[4] = {9, 10, 11, 12};                   // fig. 2.42
constexpr uint8_t kMts = 39;  // assumed; high = "vna", low = "lna" (rest position)

// Every output pin, for the HAL's start-up (drive low, then make it an output).
constexpr uint8_t kOutputPins[] = {
    kRail6v, kRail12v, kRail24v, kRailNs, kRailFan, kRailTec,
    25, 26, 27, 28, 29, 30, 31, 32,  // MS1
    33, 34, 35, 36, 37, 38,          // MS2
    14, 15, 16, 17,                  // MS3
    9, 10, 11, 12,                   // MS4
    kMts,
};
constexpr uint8_t kOutputPinCount = sizeof(kOutputPins) / sizeof(kOutputPins[0]);

}  // namespace pins
}  // namespace reach

#endif  // REACH_PINS_H
