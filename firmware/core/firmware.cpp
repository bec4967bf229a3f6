#include "firmware.h"

#include "mcp9808.h"

namespace reach {
namespace {

bool is_alnum(char c) {
  return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z');
}

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// Even number of hex digits, at most `capacity` bytes.
bool parse_hex(const Token& word, uint8_t* out, size_t capacity, size_t* size) {
  if (word.size % 2 != 0 || word.size / 2 > capacity) return false;
  for (size_t i = 0; i < word.size; i += 2) {
    int hi = hex_value(word.text[i]);
    int lo = hex_value(word.text[i + 1]);
    if (hi < 0 || lo < 0) return false;
    out[i / 2] = static_cast<uint8_t>(hi * 16 + lo);
  }
  *size = word.size / 2;
  return true;
}

// A decimal count of milliseconds: 1-7 digits, no leading zero (one spelling per value).
bool parse_ms(const Token& word, uint32_t* ms) {
  if (word.size < 1 || word.size > 7 || (word.size > 1 && word.text[0] == '0')) return false;
  uint32_t value = 0;
  for (size_t i = 0; i < word.size; ++i) {
    if (word.text[i] < '0' || word.text[i] > '9') return false;
    value = value * 10 + static_cast<uint32_t>(word.text[i] - '0');
  }
  *ms = value;
  return true;
}

enum class TagKind : uint8_t { None, Good, Bad };

// A line may open with `#<tag> `: 1-8 letters or digits. `rest` is where the command
// starts. In a truncated (overlong) line a tag running into the cut is not trusted.
TagKind read_tag(const char* line, size_t size, bool truncated, Token* tag, size_t* rest) {
  size_t i = 0;
  while (i < size && line[i] == ' ') ++i;
  *rest = 0;
  if (i == size || line[i] != '#') return TagKind::None;
  size_t end = i + 1;
  while (end < size && line[end] != ' ') ++end;
  *rest = end;
  if (truncated && end == size) return TagKind::Bad;
  size_t length = end - i - 1;
  if (length < 1 || length > 8) return TagKind::Bad;
  for (size_t k = i + 1; k < end; ++k) {
    if (!is_alnum(line[k])) return TagKind::Bad;
  }
  tag->text = line + i + 1;
  tag->size = length;
  return TagKind::Good;
}

// Splits on one or more spaces; counts every word, keeps the first `capacity`.
size_t split_words(const char* text, size_t size, Token* words, size_t capacity) {
  size_t count = 0;
  size_t i = 0;
  while (i < size) {
    while (i < size && text[i] == ' ') ++i;
    if (i == size) break;
    size_t start = i;
    while (i < size && text[i] != ' ') ++i;
    if (count < capacity) words[count] = Token{text + start, i - start};
    ++count;
  }
  return count;
}

void append_celsius(Payload* out, int32_t centi) {
  if (centi < 0) {
    out->append('-');
    centi = -centi;
  }
  out->append_uint(static_cast<uint32_t>(centi / 100));
  out->append('.');
  out->append(static_cast<char>('0' + (centi / 10) % 10));
  out->append(static_cast<char>('0' + centi % 10));
}

}  // namespace

const Firmware::Command Firmware::kCommands[] = {
    {"help", 0, 0, &Firmware::cmd_help},     {"id", 0, 0, &Firmware::cmd_id},
    {"version", 0, 0, &Firmware::cmd_version}, {"ping", 0, 0, &Firmware::cmd_ping},
    {"state", 0, 0, &Firmware::cmd_state},   {"select", 2, 2, &Firmware::cmd_select},
    {"rail", 1, 2, &Firmware::cmd_rail},     {"temps", 0, 0, &Firmware::cmd_temps},
    {"tec", 2, 2, &Firmware::cmd_tec},       {"safe", 0, 0, &Firmware::cmd_safe},
    {"deadman", 0, 1, &Firmware::cmd_deadman},
};
const size_t Firmware::kCommandCount = sizeof(kCommands) / sizeof(kCommands[0]);

void Firmware::begin() {
  line_.clear();
  frontend_.power_on();
  boot_ = hal_.boot_reason();
  boot_ms_ = hal_.millis();
  deadman_ms_ = 0;
  deadman_renewed_ms_ = boot_ms_;
  tripped_after_ms_ = 0;
}

void Firmware::feed(uint8_t byte) {
  if (line_.push(byte)) answer_line();
}

void Firmware::poll() {
  if (deadman_ms_ == 0 || hal_.millis() - deadman_renewed_ms_ < deadman_ms_) return;
  frontend_.safe();
  tripped_after_ms_ = deadman_ms_;
  deadman_ms_ = 0;
}

void Firmware::answer_line() {
  // A request that arrives after the timeout ran out (before the main loop noticed) finds
  // the front-end already safe, exactly as one that arrives later.
  poll();
  Reply reply;
  Token tag{nullptr, 0};
  size_t rest = 0;
  TagKind kind = read_tag(line_.data(), line_.size(), line_.overlong(), &tag, &rest);
  if (line_.overlong()) {
    reply.fail(1, "line too long");
  } else if (line_.has_bad_byte()) {
    reply.fail(2, "byte outside printable ascii");
  } else if (kind == TagKind::Bad) {
    reply.fail(7, "bad tag");
  } else {
    Token words[kMaxWords];
    size_t count = split_words(line_.data() + rest, line_.size() - rest, words, kMaxWords);
    if (count == 0) {
      reply.fail(6, "empty line");
    } else if (tripped_after_ms_ != 0) {
      // Told once, to the first request after the trip, which is not run: the host
      // must learn that the front-end moved on its own before it moves anything.
      reply.fail(kTrippedCode, "dead-man tripped after ");
      reply.text.append_uint(tripped_after_ms_);
      reply.text.append(" ms without the host; front-end safe");
      tripped_after_ms_ = 0;
    } else {
      run(words, count, &reply);
      deadman_renewed_ms_ = hal_.millis();
    }
  }
  send(reply, kind == TagKind::Good ? &tag : nullptr);
}

void Firmware::run(const Token* words, size_t count, Reply* reply) {
  for (size_t i = 0; i < kCommandCount; ++i) {
    const Command& command = kCommands[i];
    if (!words[0].equals(command.name)) continue;
    size_t args = count - 1;
    if (args < command.min_args || args > command.max_args) {
      reply->fail(4, "wrong number of arguments");
      return;
    }
    (this->*command.handler)(words + 1, args, reply);
    return;
  }
  reply->fail(3, "unknown command");
}

void Firmware::send(const Reply& reply, const Token* tag) {
  TextBuf<256> line;
  if (reply.code == 0) {
    line.append("OK 00");
  } else {
    line.append("ERR ");
    line.append(static_cast<char>('0' + reply.code / 10));
    line.append(static_cast<char>('0' + reply.code % 10));
  }
  if (tag != nullptr) {
    line.append(" #");
    line.append(*tag);
  }
  if (reply.text.size() > 0) {
    line.append(' ');
    line.append(reply.text.data(), reply.text.size());
  }
  line.append("\r\n");
  hal_.host_write(line.data(), line.size());
  ++lines_answered_;
}

void Firmware::state_payload(Payload* out) {
  for (size_t i = 0; i < kSwitchCount; ++i) {
    SwitchId id = static_cast<SwitchId>(i);
    out->append(switch_def(id).name);
    out->append('=');
    out->append(position_name(id, state().position[i]));
    out->append(' ');
  }
  for (size_t i = 0; i < kRailCount; ++i) {
    out->append(rail_def(static_cast<RailId>(i)).name);
    out->append(state().rail_on[i] ? "=1 " : "=0 ");
  }
  out->append(boot_ == BootReason::Watchdog ? "boot=wdog" : "boot=por");
  out->append(" uptime_ms=");
  out->append_uint(hal_.millis() - boot_ms_);
  out->append(" changes=");
  out->append_uint(frontend_.changes());
  out->append(" deadman=");
  out->append_uint(deadman_ms_);
}

void Firmware::cmd_help(const Token*, size_t, Reply* reply) {
  for (size_t i = 0; i < kCommandCount; ++i) {
    if (i > 0) reply->text.append(' ');
    reply->text.append(kCommands[i].name);
  }
}

void Firmware::cmd_id(const Token*, size_t, Reply* reply) {
  reply->text.append("REACH front-end teensy35");
}

void Firmware::cmd_version(const Token*, size_t, Reply* reply) {
  reply->text.append("firmware=");
  reply->text.append(kFirmwareVersion);
  reply->text.append(" protocol=");
  reply->text.append(kProtocolVersion);
}

void Firmware::cmd_ping(const Token*, size_t, Reply* reply) { reply->text.append("pong"); }

void Firmware::cmd_state(const Token*, size_t, Reply* reply) { state_payload(&reply->text); }

void Firmware::cmd_select(const Token* args, size_t, Reply* reply) {
  SwitchId id = SwitchId::Ms1;
  uint8_t position = 0;
  if (!find_switch(args[0], &id)) return reply->fail(5, "unknown switch");
  if (!parse_position(id, args[1], &position)) {
    return reply->fail(5, "bad position");
  }
  Refusal why;
  if (!frontend_.check_select(id, position, &why)) return reply->refuse(why);
  frontend_.select(id, position);
  reply->text.append(switch_def(id).name);
  reply->text.append('=');
  reply->text.append(position_name(id, position));
}

void Firmware::cmd_rail(const Token* args, size_t count, Reply* reply) {
  RailId id = RailId::V6;
  RailLookup found = find_rail(args[0], &id);
  if (found == RailLookup::NotSwitchable) {
    reply->fail(21, "rail ");
    reply->text.append(args[0]);
    reply->text.append(" is not switchable");
    return;
  }
  if (found == RailLookup::Unknown) return reply->fail(5, "unknown rail");
  if (count == 2) {
    bool on = args[1].equals("on");
    if (!on && !args[1].equals("off")) {
      return reply->fail(5, "expected on or off");
    }
    Refusal why;
    if (!frontend_.check_rail(id, on, &why)) return reply->refuse(why);
    frontend_.set_rail(id, on);
  }
  reply->text.append(rail_def(id).name);
  reply->text.append(state().rail_on[static_cast<size_t>(id)] ? "=1" : "=0");
}

void Firmware::cmd_temps(const Token*, size_t, Reply* reply) {
  for (uint8_t addr = mcp9808::kFirstAddress; addr <= mcp9808::kLastAddress; ++addr) {
    uint16_t raw = 0;
    I2cStatus status = hal_.i2c_read16(addr, mcp9808::kAmbientRegister, &raw);
    if (status == I2cStatus::Absent) continue;
    if (status == I2cStatus::BusError) {
      reply->fail(40, "i2c bus error at ");
      reply->text.append_i2c_addr(addr);
      return;
    }
    if (reply->text.size() > 0) reply->text.append(' ');
    reply->text.append_i2c_addr(addr);
    reply->text.append('=');
    append_celsius(&reply->text, mcp9808::sixteenths_to_centi(mcp9808::sixteenths(raw)));
  }
}

void Firmware::cmd_tec(const Token* args, size_t, Reply* reply) {
  bool query = args[0].equals("query");
  if (!query && !args[0].equals("send")) {
    return reply->fail(5, "expected send or query");
  }
  uint8_t request[kTecFrameMax];
  size_t size = 0;
  if (!parse_hex(args[1], request, kTecFrameMax, &size)) {
    return reply->fail(5, "bad hex");
  }
  if (!state().rail_on[static_cast<size_t>(RailId::Tec)]) {
    return reply->fail(30, "tec rail is off");
  }
  if (query) return tec_query(request, size, reply);
  hal_.uart1_write(request, size);
  reply->text.append("sent=");
  reply->text.append_uint(static_cast<uint32_t>(size));
}

void Firmware::tec_query(const uint8_t* request, size_t size, Reply* reply) {
  // Drop whatever the controller sent unasked, so the reply read is this request's.
  for (int i = 0; i < 256 && hal_.uart1_read(0) >= 0; ++i) {
  }
  hal_.uart1_write(request, size);
  uint8_t answer[kTecFrameMax];
  size_t got = 0;
  uint32_t start = hal_.millis();
  for (;;) {
    uint32_t elapsed = hal_.millis() - start;
    int byte = elapsed < kTecTimeoutMs ? hal_.uart1_read(kTecTimeoutMs - elapsed) : -1;
    if (byte < 0) return reply->fail(31, "tec no reply within 300 ms");
    if (got == kTecFrameMax) {
      return reply->fail(32, "tec reply longer than 96 bytes");
    }
    answer[got++] = static_cast<uint8_t>(byte);
    if (got >= 2 && answer[got - 2] == '\r' && answer[got - 1] == '\n') break;
  }
  for (size_t i = 0; i < got; ++i) reply->text.append_hex_byte(answer[i]);
}

void Firmware::cmd_safe(const Token*, size_t, Reply* reply) {
  frontend_.safe();
  state_payload(&reply->text);
}

void Firmware::cmd_deadman(const Token* args, size_t count, Reply* reply) {
  if (count == 1) {
    uint32_t ms = 0;
    bool valid = parse_ms(args[0], &ms);
    if (!valid || (ms != 0 && (ms < kDeadmanMinMs || ms > kDeadmanMaxMs))) {
      return reply->fail(5, "timeout must be 0 (off) or 100-3600000 ms");
    }
    deadman_ms_ = ms;  // answer_line renews the timer after this
  }
  reply->text.append("deadman=");
  reply->text.append_uint(deadman_ms_);
}

}  // namespace reach
