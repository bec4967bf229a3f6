// Umbrella header of the portable front-end core (also the Arduino library's entry).
#ifndef REACH_CORE_H
#define REACH_CORE_H

#include "firmware.h"
#include "frontend.h"
#include "hal.h"
#include "line_assembler.h"
#include "mcp9808.h"
#include "pins.h"
#include "text.h"

#endif  // REACH_CORE_H
