// A do-nothing HAL and main() so the core can be linked for Cortex-M4 and sized.
// Not firmware: the Teensy sketch (teensy/) is the real program.
#include "../core/reach_core.h"

namespace {

class NullHal : public reach::Hal {
 public:
  void pin_write(uint8_t, bool) override {}
  reach::I2cStatus i2c_read16(uint8_t, uint8_t, uint16_t*) override {
    return reach::I2cStatus::Absent;
  }
  void host_write(const char*, size_t) override {}
  void uart1_write(const uint8_t*, size_t) override {}
  int uart1_read(uint32_t) override { return -1; }
  uint32_t millis() override { return ticks_++; }
  void watchdog_kick() override {}
  reach::BootReason boot_reason() override { return reach::BootReason::PowerOn; }

 private:
  uint32_t ticks_ = 0;
};

NullHal hal;
reach::Firmware firmware(hal);

}  // namespace

int main() {
  firmware.begin();
  const char line[] = "#1 state\n";
  for (;;) {
    for (char c : line) firmware.feed(static_cast<uint8_t>(c));
    firmware.poll();
    hal.watchdog_kick();
  }
}
