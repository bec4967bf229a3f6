// Property test: random and mutated input lines against the firmware on the host HAL.
//
// For every LF-ended line: exactly one reply, well formed; an ERR reply leaves the state
// and every pin untouched; after every line the pins match the state, the interlocks
// hold, and (checked on each single pin write) no switch ever has two lines high. The
// `changes` counter grows by exactly the outputs that moved (so it never decreases
// between resets). The main loop's poll() runs before every byte, with time jumping now
// and then past the dead-man's timeout: a trip happens only while armed, gives the safe
// state and disarms, and ERR 50 answers exactly the first request after it.
// Usage: fuzz [inputs] [seed]
#include <cctype>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <set>
#include <string>
#include <vector>

#include "bench.h"
#include "harness.h"

namespace {

struct Rng {  // xorshift64*, seeded: every run is reproducible
  uint64_t s;
  uint64_t next() {
    s ^= s >> 12;
    s ^= s << 25;
    s ^= s >> 27;
    return s * 0x2545F4914F6CDD1Dull;
  }
  uint32_t below(uint32_t n) { return static_cast<uint32_t>(next() % n); }
  bool chance(uint32_t percent) { return below(100) < percent; }
};

const char* const kValid[] = {
    "help", "id", "version", "ping", "state", "temps", "safe",
    "select ms1 0", "select ms1 1", "select ms1 5", "select ms1 8", "select ms2 0", "select ms2 3",
    "select ms2 6", "select ms3 0", "select ms3 2", "select ms3 4", "select ms4 0", "select ms4 1",
    "select ms4 4", "select mts lna", "select mts vna",
    "rail 6v on", "rail 6v off", "rail 12v on", "rail 12v off", "rail 24v on", "rail 24v off",
    "rail ns on", "rail ns off", "rail fan on", "rail fan off", "rail tec on", "rail tec off",
    "rail 12v", "rail 3v3 on", "rail 5v off",
    "tec send 016A3030", "tec query 016A303043", "tec send 00",
    "deadman", "deadman 0", "deadman 100", "deadman 250", "deadman 3600000", "deadman 99",
};
constexpr size_t kValidCount = sizeof(kValid) / sizeof(kValid[0]);

std::string random_tag(Rng& rng) {
  static const char kAlnum[] = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789";
  std::string tag = "#";
  uint32_t n = rng.below(10);  // 0 and 9 are bad lengths
  for (uint32_t i = 0; i < n; ++i) tag += kAlnum[rng.below(sizeof(kAlnum) - 1)];
  return tag + " ";
}

uint8_t special_byte(Rng& rng) {
  static const uint8_t kSpecial[] = {0x00, '\r', '\n', ' ', '#', 0x7F, 0x80, 0xFF, '\t', 'x'};
  return kSpecial[rng.below(sizeof(kSpecial))];
}

void mutate(Rng& rng, std::string& s) {
  uint32_t edits = 1 + rng.below(4);
  for (uint32_t e = 0; e < edits; ++e) {
    size_t at = s.empty() ? 0 : rng.below(static_cast<uint32_t>(s.size()));
    switch (rng.below(7)) {
      case 0: if (!s.empty()) s[at] = static_cast<char>(rng.below(256)); break;
      case 1: s.insert(s.begin() + static_cast<long>(at), static_cast<char>(special_byte(rng))); break;
      case 2: if (!s.empty()) s.erase(at, 1 + rng.below(3)); break;
      case 3: s.insert(at, std::string(1 + rng.below(4), ' ')); break;
      case 4: if (!s.empty()) s[at] = static_cast<char>(s[at] ^ 0x20); break;  // case flip
      case 5: s.insert(at, kValid[rng.below(kValidCount)]); break;
      default: s.insert(at, std::to_string(rng.below(20))); break;
    }
  }
}

// One generated input; always ends with LF, may hold further LFs inside.
std::string generate(Rng& rng) {
  std::string s;
  switch (rng.below(6)) {
    case 0: {  // random bytes
      uint32_t n = rng.below(260);
      for (uint32_t i = 0; i < n; ++i) s += static_cast<char>(rng.below(256));
      break;
    }
    case 1: {  // random printable
      uint32_t n = rng.below(220);
      for (uint32_t i = 0; i < n; ++i) s += static_cast<char>(0x20 + rng.below(95));
      break;
    }
    case 2:  // overlong around the 200-byte limit
    {
      s = kValid[rng.below(kValidCount)];
      size_t target = 185 + rng.below(35);
      s += std::string(target - s.size(), rng.chance(50) ? ' ' : 'a');
      break;
    }
    case 3:  // mutated valid command
      s = kValid[rng.below(kValidCount)];
      mutate(rng, s);
      break;
    default:  // valid command, to walk the state machine through many states
      s = kValid[rng.below(kValidCount)];
      break;
  }
  if (rng.chance(30)) s = random_tag(rng) + s;
  if (rng.chance(10)) s += '\r';
  return s + '\n';
}

bool well_formed(const std::string& reply) {
  if (reply.size() < 7 || reply.compare(reply.size() - 2, 2, "\r\n") != 0) return false;
  for (size_t i = 0; i + 2 < reply.size(); ++i) {
    unsigned char c = static_cast<unsigned char>(reply[i]);
    if (c < 0x20 || c > 0x7E) return false;
  }
  if (reply.compare(0, 6, "OK 00\r") == 0 || reply.compare(0, 6, "OK 00 ") == 0) return true;
  return reply.compare(0, 4, "ERR ") == 0 && isdigit(static_cast<unsigned char>(reply[4])) &&
         isdigit(static_cast<unsigned char>(reply[5])) && (reply[6] == ' ' || reply[6] == '\r') &&
         reply.compare(4, 2, "00") != 0;
}

}  // namespace

int main(int argc, char** argv) {
  long inputs = argc > 1 ? std::atol(argv[1]) : 100000;
  uint64_t seed = argc > 2 ? std::strtoull(argv[2], nullptr, 0) : 0x5EACC0DEull;
  Rng rng{seed};
  bench::Bench b;
  b.hal.set_sensor(0x18, 24.5);
  b.hal.set_sensor(0x1c, -3.25);
  b.hal.on_uart_write = [&rng](bench::HostHal& h, const uint8_t*, size_t) {
    uint32_t kind = rng.below(3);  // answer, stay silent, or flood
    size_t n = kind == 0 ? 8 : kind == 1 ? 0 : 150;
    for (size_t i = 0; i < n; ++i) h.uart_rx.push_back('A');
    if (kind == 0) {
      h.uart_rx.push_back('\r');
      h.uart_rx.push_back('\n');
    }
  };

  long lines = 0, errors = 0, failures = 0, trips = 0, told = 0, resets = 0;
  std::set<std::string> states;  // distinct output states reached, a coverage figure
  auto fail = [&](const char* what, const std::string& input, const std::string& reply) {
    if (++failures <= 10) {
      std::printf("FAIL %s\n  input: %s\n  reply: %s\n", what, harness::visible(input).c_str(),
                  harness::visible(reply).c_str());
    }
  };
  // The main loop between two bytes: poll() may trip the dead-man, and nothing else.
  auto poll = [&](const std::string& line) {
    reach::FrontendState before = b.fw.state();
    uint32_t changes = b.fw.changes();
    bool armed = b.fw.deadman_ms() != 0;
    bool pending = b.fw.deadman_tripped();
    b.fw.poll();
    if (b.fw.deadman_tripped() == pending) {
      if (b.fw.state() != before || b.fw.changes() != changes) fail("poll moved outputs", line, "");
      return;
    }
    ++trips;
    if (!armed || b.fw.deadman_ms() != 0) fail("trip while disarmed, or stayed armed", line, "");
    if (!bench::safe_from(before, b.fw.state())) fail("trip did not give the safe state", line, "");
    if (b.fw.changes() - changes != bench::outputs_differing(before, b.fw.state())) {
      fail("changes miscounted by the trip", line, "");
    }
    if (!bench::pins_match_state(b.hal, b.fw.state())) fail("pins differ after trip", line, "");
  };

  for (long n = 0; n < inputs; ++n) {
    if (rng.chance(1)) b.hal.set_sensor_fail(0x1a);
    if (rng.chance(1)) b.hal.set_sensor_absent(0x1a);
    b.hal.advance(rng.below(200) == 0 ? 100 + rng.below(400) : rng.below(50));
    if (rng.below(1000) == 0) {  // a watchdog reset between two inputs
      ++resets;
      b.hal.set_boot_reason(reach::BootReason::Watchdog);
      b.fw.begin();
      if (b.fw.changes() != 0 || b.fw.deadman_ms() != 0 || b.fw.deadman_tripped()) {
        fail("reset left changes, dead-man or trip report", "", "");
      }
    }
    std::string input = generate(rng);
    std::string line;
    for (char c : input) {
      line += c;
      poll(line);
      reach::FrontendState before = b.fw.state();
      uint64_t writes_before = b.hal.write_count();
      uint32_t changes_before = b.fw.changes();
      bool pending = b.fw.deadman_tripped();
      b.fw.feed(static_cast<uint8_t>(c));
      if (c != '\n') continue;
      ++lines;
      std::string reply = b.hal.take_output();
      size_t crlf = reply.find("\r\n");
      if (crlf == std::string::npos || crlf + 2 != reply.size()) fail("not one reply", line, reply);
      if (!well_formed(reply)) fail("malformed reply", line, reply);
      if (reply.compare(0, 3, "ERR") == 0) {
        ++errors;
        if (b.fw.state() != before || b.hal.write_count() != writes_before) {
          fail("rejected line changed the state", line, reply);
        }
      }
      bool told_now = reply.compare(0, 6, "ERR 50") == 0;
      told += told_now ? 1 : 0;
      if (told_now != (pending && !b.fw.deadman_tripped())) {
        fail("ERR 50 not exactly the first request after a trip", line, reply);
      }
      if (b.fw.changes() - changes_before != bench::outputs_differing(before, b.fw.state())) {
        fail("changes miscounted", line, reply);
      }
      if (!bench::pins_match_state(b.hal, b.fw.state())) fail("pins differ from state", line, reply);
      if (!bench::interlocks_hold(b.fw.state())) fail("interlock broken", line, reply);
      reach::FrontendState after = b.fw.state();
      states.insert(std::string(reinterpret_cast<const char*>(&after), sizeof after));
      line.clear();
    }
    if (b.hal.writes().size() > 4096) b.hal.clear_writes();
  }
  if (b.violations != 0) {
    ++failures;
    std::printf("FAIL %d pin writes broke exclusivity or left the pin table\n", b.violations);
  }
  if (b.hal.take_output().size() != 0) ++failures;
  std::printf("fuzz: %ld inputs, %ld lines (%ld refused), %zu distinct states, %ld dead-man "
              "trips (%ld told), %ld resets, seed 0x%llx, %ld failures\n",
              inputs, lines, errors, states.size(), trips, told, resets,
              static_cast<unsigned long long>(seed), failures);
  return failures == 0 && lines >= inputs ? 0 : 1;
}
