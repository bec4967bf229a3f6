// REACH front-end controller, Teensy 3.5: PROTOCOL.md version 2 over USB serial.
// The logic lives in the reach_core library (firmware/core); this sketch only wires it
// to the board. Build: see firmware/README.md.
#include "teensy_hal.h"

static TeensyHal hal;
static reach::Firmware firmware(hal);

void setup() {
  hal.begin();       // every output low before anything else
  firmware.begin();  // power-on state, boot reason (por or wdog)
  Serial.begin(9600);  // USB CDC: the baud rate is ignored
  hal.watchdog_start();
}

void loop() {
  int available = Serial.available();
  while (available-- > 0) {
    int byte = Serial.read();
    if (byte >= 0) firmware.feed(static_cast<uint8_t>(byte));
  }
  firmware.poll();      // the dead-man switch: safe state once the host has gone quiet
  hal.watchdog_kick();  // from the main loop only: a hang anywhere resets the board
}
