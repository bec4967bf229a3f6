#include "host_hal.h"

#include <errno.h>
#include <poll.h>
#include <time.h>
#include <unistd.h>

#include <cmath>

namespace reach {
namespace host {

uint16_t mcp9808_raw(double celsius) {
  long sixteenths = std::lround(celsius * 16.0);
  if (sixteenths > 4095) sixteenths = 4095;
  if (sixteenths < -4096) sixteenths = -4096;
  return static_cast<uint16_t>(sixteenths & 0x1FFF);
}

HostHal::HostHal(bool real_time) : real_time_(real_time) {}

void HostHal::pin_write(uint8_t pin, bool high) {
  if (pin >= kPinCount) return;
  levels_[pin] = high;
  writes_.push_back(PinWrite{pin, high});
  ++write_count_;
  if (on_pin_write) on_pin_write(*this, PinWrite{pin, high});
}

I2cStatus HostHal::i2c_read16(uint8_t addr, uint8_t reg, uint16_t* value) {
  const Sensor& sensor = sensors_[addr & 0x7F];
  if (sensor.mode == Mode::Absent) return I2cStatus::Absent;
  if (sensor.mode == Mode::Fail || reg != 0x05) return I2cStatus::BusError;
  *value = sensor.raw;
  return I2cStatus::Ok;
}

void HostHal::set_sensor(uint8_t addr, double celsius) {
  sensors_[addr & 0x7F] = Sensor{Mode::Ok, mcp9808_raw(celsius)};
}
void HostHal::set_sensor_fail(uint8_t addr) { sensors_[addr & 0x7F] = Sensor{Mode::Fail, 0}; }
void HostHal::set_sensor_absent(uint8_t addr) { sensors_[addr & 0x7F] = Sensor{}; }

void HostHal::host_write(const char* data, size_t n) {
  if (host_sink) {
    host_sink(data, n);
  } else {
    output_.append(data, n);
  }
}

std::string HostHal::take_output() {
  std::string out;
  out.swap(output_);
  return out;
}

void HostHal::uart1_write(const uint8_t* data, size_t n) {
  if (uart_fd_ < 0) {
    uart_sent.append(reinterpret_cast<const char*>(data), n);
    if (on_uart_write) on_uart_write(*this, data, n);
    return;
  }
  size_t done = 0;
  while (done < n) {
    ssize_t w = ::write(uart_fd_, data + done, n - done);
    if (w > 0) {
      done += static_cast<size_t>(w);
    } else if (w < 0 && errno == EINTR) {
      continue;
    } else {
      return;  // a full or dead line drops bytes, as a real UART would
    }
  }
}

int HostHal::uart1_read(uint32_t timeout_ms) {
  if (uart_fd_ < 0) {
    if (!uart_rx.empty()) {
      uint8_t b = uart_rx.front();
      uart_rx.pop_front();
      return b;
    }
    if (real_time_) {
      ::poll(nullptr, 0, static_cast<int>(timeout_ms));
    } else {
      manual_ms_ += timeout_ms;
    }
    return -1;
  }
  if (uart_pos_ < uart_len_) return uart_buf_[uart_pos_++];
  struct pollfd pfd = {uart_fd_, POLLIN, 0};
  int ready = ::poll(&pfd, 1, static_cast<int>(timeout_ms));
  if (ready <= 0 || (pfd.revents & POLLIN) == 0) {
    if (ready > 0) ::poll(nullptr, 0, static_cast<int>(timeout_ms));  // hung-up line: wait
    return -1;
  }
  ssize_t got = ::read(uart_fd_, uart_buf_, sizeof(uart_buf_));
  if (got <= 0) return -1;
  uart_len_ = static_cast<size_t>(got);
  uart_pos_ = 1;
  return uart_buf_[0];
}

uint32_t HostHal::millis() {
  if (!real_time_) return static_cast<uint32_t>(manual_ms_);
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  uint64_t ms = static_cast<uint64_t>(ts.tv_sec) * 1000u + static_cast<uint64_t>(ts.tv_nsec) / 1000000u;
  return static_cast<uint32_t>(ms);
}

void HostHal::watchdog_kick() { last_kick_ms_ = millis(); }

}  // namespace host
}  // namespace reach
