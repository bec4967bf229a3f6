// Microchip MCP9808 ambient-temperature decoding (datasheet DS25095A, register 0x05).
//
// The 16-bit register holds three alarm flags (bits 15-13) and the temperature as a
// 13-bit two's-complement number (bits 12-0, bit 12 the sign) at 0.0625 degC per LSB.
#ifndef REACH_MCP9808_H
#define REACH_MCP9808_H

#include <stdint.h>

namespace reach {
namespace mcp9808 {

constexpr uint8_t kFirstAddress = 0x18;  // A2..A0 select 0x18-0x1F
constexpr uint8_t kLastAddress = 0x1F;
constexpr uint8_t kAmbientRegister = 0x05;

// Temperature in sixteenths of a degree Celsius (flags dropped, sign extended).
int16_t sixteenths(uint16_t raw);

// Sixteenths of a degree to hundredths, rounded half away from zero.
int32_t sixteenths_to_centi(int16_t sixteenths);

}  // namespace mcp9808
}  // namespace reach

#endif  // REACH_MCP9808_H
