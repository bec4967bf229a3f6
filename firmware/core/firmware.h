// The command interpreter of the front-end Teensy (PROTOCOL.md, protocol version 2).
//
// Bytes from the back-end go in through feed(); each LF-ended line gets exactly one
// reply through Hal::host_write. A line is parsed and checked completely (framing, tag,
// command, arguments, interlocks) before the first pin is written.
//
// The dead-man switch (PROTOCOL.md, "Dead-man switch") runs on Hal::millis: poll(), from
// the main loop, puts the front-end in its safe state once the host has been silent for
// the armed timeout; the next request is then answered ERR 50 instead of being run.
#ifndef REACH_FIRMWARE_H
#define REACH_FIRMWARE_H

#include <stddef.h>
#include <stdint.h>

#include "frontend.h"
#include "hal.h"
#include "line_assembler.h"
#include "text.h"

namespace reach {

constexpr const char* kFirmwareVersion = "2.0.0";
constexpr const char* kProtocolVersion = "2";

using Payload = TextBuf<224>;

// The answer to one line: code 0 with a payload, or an error code with its reason.
struct Reply {
  uint8_t code = 0;
  Payload text;

  void fail(uint8_t error, const char* reason) {
    code = error;
    text.clear();
    text.append(reason);
  }
  void refuse(const Refusal& why) {
    fail(why.code, "");
    text.append(why.reason.data(), why.reason.size());
  }
};

class Firmware {
 public:
  static constexpr uint32_t kTecTimeoutMs = 300;
  static constexpr size_t kTecFrameMax = 96;  // request and reply bytes of `tec`
  static constexpr size_t kMaxWords = 8;      // words kept per line (more are counted)
  static constexpr uint32_t kDeadmanMinMs = 100;
  static constexpr uint32_t kDeadmanMaxMs = 3600000;  // one hour
  static constexpr uint8_t kTrippedCode = 50;

  explicit Firmware(Hal& hal) : hal_(hal), frontend_(hal) {}

  // Start (or restart after a reset): power-on state, boot reason, uptime origin.
  void begin();
  // One received byte; answers the line when the byte is its LF.
  void feed(uint8_t byte);
  // From the main loop: trips the dead-man switch once its timeout has run out.
  void poll();

  const FrontendState& state() const { return frontend_.state(); }
  BootReason boot() const { return boot_; }
  // The payload of `state` (also the simulator's PINS line).
  void state_payload(Payload* out);
  uint32_t lines_answered() const { return lines_answered_; }
  // Output changes since begin() (the `changes` field of `state`).
  uint32_t changes() const { return frontend_.changes(); }
  // The armed dead-man timeout in ms, 0 when off.
  uint32_t deadman_ms() const { return deadman_ms_; }
  // The dead-man tripped and the next request has not been told yet.
  bool deadman_tripped() const { return tripped_after_ms_ != 0; }

 private:
  using Handler = void (Firmware::*)(const Token* args, size_t count, Reply* reply);
  struct Command {
    const char* name;
    uint8_t min_args;
    uint8_t max_args;
    Handler handler;
  };
  static const Command kCommands[];
  static const size_t kCommandCount;

  void answer_line();
  void run(const Token* words, size_t count, Reply* reply);
  void send(const Reply& reply, const Token* tag);

  void cmd_help(const Token* args, size_t count, Reply* reply);
  void cmd_id(const Token* args, size_t count, Reply* reply);
  void cmd_version(const Token* args, size_t count, Reply* reply);
  void cmd_ping(const Token* args, size_t count, Reply* reply);
  void cmd_state(const Token* args, size_t count, Reply* reply);
  void cmd_select(const Token* args, size_t count, Reply* reply);
  void cmd_rail(const Token* args, size_t count, Reply* reply);
  void cmd_temps(const Token* args, size_t count, Reply* reply);
  void cmd_tec(const Token* args, size_t count, Reply* reply);
  void cmd_safe(const Token* args, size_t count, Reply* reply);
  void cmd_deadman(const Token* args, size_t count, Reply* reply);
  void tec_query(const uint8_t* request, size_t size, Reply* reply);

  Hal& hal_;
  Frontend frontend_;
  LineAssembler line_;
  BootReason boot_ = BootReason::PowerOn;
  uint32_t boot_ms_ = 0;
  uint32_t lines_answered_ = 0;
  uint32_t deadman_ms_ = 0;        // armed timeout, 0 = off
  uint32_t deadman_renewed_ms_ = 0;
  uint32_t tripped_after_ms_ = 0;  // timeout that tripped, until a request is told; 0 = none
};

}  // namespace reach

#endif  // REACH_FIRMWARE_H
