// The only door from the portable core to the hardware.
//
// The core never includes an Arduino or POSIX header: the Teensy build implements this
// interface with pinMode/digitalWrite, Wire, Serial/Serial1 and the WDOG registers
// (teensy/), the host build with a recording fake (host/). No method may allocate.
#ifndef REACH_HAL_H
#define REACH_HAL_H

#include <stddef.h>
#include <stdint.h>

namespace reach {

// Why the board last started (PROTOCOL.md, "State": boot=por or boot=wdog).
enum class BootReason : uint8_t { PowerOn, Watchdog };

// Outcome of one I2C register read.
enum class I2cStatus : uint8_t {
  Ok,        // the device answered; the value is valid
  Absent,    // no device acknowledged the address
  BusError,  // the device was addressed but the transfer failed
};

class Hal {
 public:
  // Drive one output pin (already configured as an output by the HAL).
  virtual void pin_write(uint8_t pin, bool high) = 0;
  // Read a 16-bit big-endian register of the I2C device at `addr` on bus 0.
  virtual I2cStatus i2c_read16(uint8_t addr, uint8_t reg, uint16_t* value) = 0;
  // Send bytes to the back-end over the USB serial link.
  virtual void host_write(const char* data, size_t n) = 0;
  // Send bytes to the TEC controller on UART1 (19200 8N1).
  virtual void uart1_write(const uint8_t* data, size_t n) = 0;
  // One byte from UART1 within `timeout_ms`, or -1 when none arrived in time.
  virtual int uart1_read(uint32_t timeout_ms) = 0;
  // Milliseconds since an arbitrary origin; wraps after 49 days.
  virtual uint32_t millis() = 0;
  // Restart the 1 s watchdog; called from the main loop only.
  virtual void watchdog_kick() = 0;
  virtual BootReason boot_reason() = 0;

 protected:
  // Never deleted through the interface: no virtual destructor, so the bare-metal build
  // needs no operator delete.
  ~Hal() = default;
};

}  // namespace reach

#endif  // REACH_HAL_H
