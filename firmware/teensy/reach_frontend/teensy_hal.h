// The HAL of the real board: Teensyduino API for a Teensy 3.5 (MK64FX512).
// Cannot be compiled on the host; kept small so it can be checked by reading.
#ifndef REACH_TEENSY_HAL_H
#define REACH_TEENSY_HAL_H

#include <Arduino.h>
#include <Wire.h>
#include <reach_core.h>

#ifndef RCM_SRS0_WDOG
#define RCM_SRS0_WDOG ((uint8_t)0x20)  // reset caused by the watchdog (K64 reference manual)
#endif

class TeensyHal : public reach::Hal {
 public:
  static const uint32_t kTecBaud = 19200;
  static const uint16_t kWatchdogMs = 1000;
  static const uint32_t kMinKickIntervalMs = 10;  // refreshes closer together can reset the K64

  // Before anything else in setup(): every output low, then made an output.
  void begin() {
    // RCM_SRS0 keeps the cause of the last reset until the next one.
    boot_ = (RCM_SRS0 & RCM_SRS0_WDOG) ? reach::BootReason::Watchdog : reach::BootReason::PowerOn;
    for (uint8_t i = 0; i < reach::pins::kOutputPinCount; ++i) {
      digitalWrite(reach::pins::kOutputPins[i], LOW);
      pinMode(reach::pins::kOutputPins[i], OUTPUT);
      digitalWrite(reach::pins::kOutputPins[i], LOW);
    }
    Serial1.begin(kTecBaud, SERIAL_8N1);
    Wire.begin();
  }

  // The WDOG runs from the 1 kHz LPO clock: timeout = kWatchdogMs ticks. Teensyduino's
  // start-up leaves WDOG_STCTRLH_ALLOWUPDATE set, so it can be configured here.
  void watchdog_start() {
    noInterrupts();
    WDOG_UNLOCK = WDOG_UNLOCK_SEQ1;
    WDOG_UNLOCK = WDOG_UNLOCK_SEQ2;
    delayMicroseconds(1);
    WDOG_TOVALH = 0;
    WDOG_TOVALL = kWatchdogMs;
    WDOG_PRESC = 0;
    WDOG_STCTRLH = WDOG_STCTRLH_ALLOWUPDATE | WDOG_STCTRLH_WDOGEN | WDOG_STCTRLH_WAITEN |
                   WDOG_STCTRLH_STOPEN;
    interrupts();
    last_kick_ = ::millis();
  }

  void pin_write(uint8_t pin, bool high) override { digitalWrite(pin, high ? HIGH : LOW); }

  reach::I2cStatus i2c_read16(uint8_t addr, uint8_t reg, uint16_t* value) override {
    Wire.beginTransmission(addr);
    Wire.write(reg);
    uint8_t status = Wire.endTransmission();
    if (status == 2) return reach::I2cStatus::Absent;  // address not acknowledged
    if (status != 0) return reach::I2cStatus::BusError;
    if (Wire.requestFrom(addr, static_cast<uint8_t>(2)) != 2) return reach::I2cStatus::BusError;
    uint16_t hi = static_cast<uint16_t>(Wire.read());
    uint16_t lo = static_cast<uint16_t>(Wire.read());
    *value = static_cast<uint16_t>((hi << 8) | lo);
    return reach::I2cStatus::Ok;
  }

  void host_write(const char* data, size_t n) override {
    Serial.write(reinterpret_cast<const uint8_t*>(data), n);
    Serial.send_now();
  }

  void uart1_write(const uint8_t* data, size_t n) override {
    Serial1.write(data, n);
    Serial1.flush();
  }

  int uart1_read(uint32_t timeout_ms) override {
    uint32_t start = ::millis();
    while (Serial1.available() <= 0) {
      if (::millis() - start >= timeout_ms) return -1;
    }
    return Serial1.read();
  }

  uint32_t millis() override { return ::millis(); }

  void watchdog_kick() override {
    uint32_t now = ::millis();
    if (now - last_kick_ < kMinKickIntervalMs) return;
    last_kick_ = now;
    noInterrupts();
    WDOG_REFRESH = 0xA602;
    WDOG_REFRESH = 0xB480;
    interrupts();
  }

  reach::BootReason boot_reason() override { return boot_; }

 private:
  reach::BootReason boot_ = reach::BootReason::PowerOn;
  uint32_t last_kick_ = 0;
};

#endif  // REACH_TEENSY_HAL_H
