// The host implementation of the HAL, shared by the unit tests, the fuzzer and the
// simulator. It records every pin write, serves MCP9808 readings from a table, and
// either keeps its own manual clock and scripted UART (tests) or runs on the real
// monotonic clock with UART1 on a file descriptor (simulator).
#ifndef REACH_HOST_HAL_H
#define REACH_HOST_HAL_H

#include <cstdint>
#include <deque>
#include <functional>
#include <string>
#include <vector>

#include "../core/hal.h"

namespace reach {
namespace host {

struct PinWrite {
  uint8_t pin;
  bool high;
};

// The register word an MCP9808 shows for `celsius` (13-bit two's complement, 1/16 degC).
uint16_t mcp9808_raw(double celsius);

class HostHal : public Hal {
 public:
  static constexpr int kPinCount = 64;

  explicit HostHal(bool real_time = false);

  // --- Hal ---
  void pin_write(uint8_t pin, bool high) override;
  I2cStatus i2c_read16(uint8_t addr, uint8_t reg, uint16_t* value) override;
  void host_write(const char* data, size_t n) override;
  void uart1_write(const uint8_t* data, size_t n) override;
  int uart1_read(uint32_t timeout_ms) override;
  uint32_t millis() override;
  void watchdog_kick() override;
  BootReason boot_reason() override { return boot_; }

  // --- pins ---
  bool level(uint8_t pin) const { return levels_[pin]; }
  const std::vector<PinWrite>& writes() const { return writes_; }
  uint64_t write_count() const { return write_count_; }
  void clear_writes() { writes_.clear(); }
  // Called after every pin write with the levels already updated (invariant checks).
  std::function<void(const HostHal&, PinWrite)> on_pin_write;

  // --- I2C: each address is absent until set ---
  void set_sensor(uint8_t addr, double celsius);
  void set_sensor_fail(uint8_t addr);
  void set_sensor_absent(uint8_t addr);

  // --- host link: replies go to the sink when set, else are collected ---
  std::function<void(const char*, size_t)> host_sink;
  std::string take_output();

  // --- UART1: a file descriptor (simulator) or a script (tests) ---
  void set_uart_fd(int fd) { uart_fd_ = fd; }
  std::string uart_sent;          // bytes written, when no fd is set
  std::deque<uint8_t> uart_rx;    // bytes the fake controller "sends", when no fd is set
  // Called after a write when no fd is set: a fake controller answers into uart_rx.
  std::function<void(HostHal&, const uint8_t*, size_t)> on_uart_write;

  // --- time and watchdog ---
  void advance(uint32_t ms) { manual_ms_ += ms; }
  uint32_t last_kick_ms() const { return last_kick_ms_; }
  void set_boot_reason(BootReason reason) { boot_ = reason; }

 private:
  enum class Mode : uint8_t { Absent, Ok, Fail };
  struct Sensor {
    Mode mode = Mode::Absent;
    uint16_t raw = 0;
  };

  bool real_time_;
  bool levels_[kPinCount] = {};
  std::vector<PinWrite> writes_;
  uint64_t write_count_ = 0;
  Sensor sensors_[128];
  std::string output_;
  int uart_fd_ = -1;
  uint8_t uart_buf_[64] = {};
  size_t uart_len_ = 0;
  size_t uart_pos_ = 0;
  uint64_t manual_ms_ = 0;
  uint32_t last_kick_ms_ = 0;
  BootReason boot_ = BootReason::PowerOn;
};

}  // namespace host
}  // namespace reach

#endif  // REACH_HOST_HAL_H
