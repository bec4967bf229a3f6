#include "mcp9808.h"

namespace reach {
namespace mcp9808 {

int16_t sixteenths(uint16_t raw) {
  int32_t value = raw & 0x1FFF;
  if ((value & 0x1000) != 0) value -= 0x2000;  // sign bit 12
  return static_cast<int16_t>(value);
}

int32_t sixteenths_to_centi(int16_t sixteenths) {
  // centi = sixteenths * 100 / 16 = sixteenths * 25 / 4, rounded half away from zero.
  int32_t scaled = static_cast<int32_t>(sixteenths) * 25;
  if (scaled >= 0) return (scaled + 2) / 4;
  return -((-scaled + 2) / 4);
}

}  // namespace mcp9808
}  // namespace reach
