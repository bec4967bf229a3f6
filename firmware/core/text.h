// Fixed-size text helpers: a bounded string builder and a view of one word of a line.
#ifndef REACH_TEXT_H
#define REACH_TEXT_H

#include <stddef.h>
#include <stdint.h>

namespace reach {

// A word of a request line: a pointer into the line buffer and a length (no NUL).
struct Token {
  const char* text;
  size_t size;

  bool equals(const char* word) const {
    size_t i = 0;
    for (; i < size; ++i) {
      if (word[i] == '\0' || word[i] != text[i]) return false;
    }
    return word[i] == '\0';
  }
};

// A string builder over a fixed array. Appending past the end truncates silently; every
// caller sizes its buffer for the longest text it can produce, and the tests check that.
template <size_t N>
class TextBuf {
 public:
  void clear() { size_ = 0; }
  const char* data() const { return buf_; }
  size_t size() const { return size_; }
  bool truncated() const { return truncated_; }

  void append(char c) {
    if (size_ < N) {
      buf_[size_++] = c;
    } else {
      truncated_ = true;
    }
  }
  void append(const char* s) {
    while (*s != '\0') append(*s++);
  }
  void append(const char* s, size_t n) {
    for (size_t i = 0; i < n; ++i) append(s[i]);
  }
  void append(const Token& t) { append(t.text, t.size); }
  void append_uint(uint32_t v) {
    char digits[10];
    size_t n = 0;
    do {
      digits[n++] = static_cast<char>('0' + v % 10);
      v /= 10;
    } while (v != 0);
    while (n > 0) append(digits[--n]);
  }
  // Two upper-case hex digits.
  void append_hex_byte(uint8_t b) {
    static const char kHex[] = "0123456789ABCDEF";
    append(kHex[b >> 4]);
    append(kHex[b & 0x0F]);
  }
  // "0x" and two lower-case hex digits, the address style of PROTOCOL.md's `temps`.
  void append_i2c_addr(uint8_t addr) {
    static const char kHex[] = "0123456789abcdef";
    append("0x");
    append(kHex[addr >> 4]);
    append(kHex[addr & 0x0F]);
  }

 private:
  char buf_[N];
  size_t size_ = 0;
  bool truncated_ = false;
};

}  // namespace reach

#endif  // REACH_TEXT_H
