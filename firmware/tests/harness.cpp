#include "harness.h"

#include <cstdio>
#include <vector>

namespace harness {
namespace {

struct Entry {
  const char* name;
  TestFn fn;
};

std::vector<Entry>& registry() {
  static std::vector<Entry> entries;
  return entries;
}

int g_failures_in_test = 0;
const char* g_current = "";

}  // namespace

Registrar::Registrar(const char* name, TestFn fn) { registry().push_back(Entry{name, fn}); }

void record_failure(const char* file, int line, const std::string& message) {
  ++g_failures_in_test;
  std::printf("  FAIL %s (%s:%d): %s\n", g_current, file, line, message.c_str());
}

}  // namespace harness

int main() {
  int passed = 0;
  int failed = 0;
  for (const auto& entry : harness::registry()) {
    harness::g_current = entry.name;
    harness::g_failures_in_test = 0;
    entry.fn();
    if (harness::g_failures_in_test == 0) {
      ++passed;
    } else {
      ++failed;
      std::printf("FAILED %s\n", entry.name);
    }
  }
  std::printf("firmware: %d passed, %d failed\n", passed, failed);
  return failed == 0 ? 0 : 1;
}
