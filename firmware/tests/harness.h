// A tiny test harness: TEST(name) registers a function, CHECK/CHECK_EQ record failures
// with file and line and carry on, the runner ends with "N passed, N failed".
#ifndef REACH_TEST_HARNESS_H
#define REACH_TEST_HARNESS_H

#include <sstream>
#include <string>

namespace harness {

using TestFn = void (*)();

struct Registrar {
  Registrar(const char* name, TestFn fn);
};

void record_failure(const char* file, int line, const std::string& message);

template <typename A, typename B>
void check_eq(const A& a, const B& b, const char* ea, const char* eb, const char* file, int line) {
  if (a == b) return;
  std::ostringstream out;
  out << ea << " == " << eb << "\n      left:  [" << a << "]\n      right: [" << b << "]";
  record_failure(file, line, out.str());
}

// Shows control characters so a failed comparison of replies is readable.
inline std::string visible(const std::string& text) {
  static const char kHex[] = "0123456789abcdef";
  std::string out;
  for (unsigned char c : text) {
    if (c == '\r') {
      out += "\\r";
    } else if (c == '\n') {
      out += "\\n";
    } else if (c < 0x20 || c > 0x7E) {
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 0x0F];
    } else {
      out += static_cast<char>(c);
    }
  }
  return out;
}

}  // namespace harness

#define TEST(name)                                              \
  static void name();                                           \
  static const harness::Registrar name##_registrar(#name, name); \
  static void name()

#define CHECK(cond)                                                        \
  do {                                                                     \
    if (!(cond)) harness::record_failure(__FILE__, __LINE__, "CHECK(" #cond ")"); \
  } while (0)

#define CHECK_EQ(a, b) harness::check_eq((a), (b), #a, #b, __FILE__, __LINE__)

#endif  // REACH_TEST_HARNESS_H
