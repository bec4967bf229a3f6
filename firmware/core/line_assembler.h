// Assembles request lines from the byte stream (PROTOCOL.md, "Framing").
//
// A line ends at LF. A CR directly before the LF is dropped; any other CR stays in the
// line as a non-printable byte. At most kMaxLine bytes are kept: the rest of an overlong
// line is discarded up to its LF and the line is flagged. A line with a byte outside
// 0x20-0x7E is flagged too (it is still stored, so a tag in front can be echoed).
#ifndef REACH_LINE_ASSEMBLER_H
#define REACH_LINE_ASSEMBLER_H

#include <stddef.h>
#include <stdint.h>

namespace reach {

class LineAssembler {
 public:
  static constexpr size_t kMaxLine = 200;

  // Feed one byte; true when it was the LF that ended a line. The line then stays
  // readable until the next push().
  bool push(uint8_t byte);

  const char* data() const { return buf_; }
  size_t size() const { return size_; }
  bool overlong() const { return overlong_; }
  bool has_bad_byte() const { return bad_byte_; }
  void clear();

 private:
  void store(uint8_t byte);

  char buf_[kMaxLine];
  size_t size_ = 0;
  bool overlong_ = false;
  bool bad_byte_ = false;
  bool cr_pending_ = false;
  bool complete_ = false;
};

}  // namespace reach

#endif  // REACH_LINE_ASSEMBLER_H
