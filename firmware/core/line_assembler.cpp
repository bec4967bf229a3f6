#include "line_assembler.h"

namespace reach {

void LineAssembler::clear() {
  size_ = 0;
  overlong_ = false;
  bad_byte_ = false;
  cr_pending_ = false;
  complete_ = false;
}

bool LineAssembler::push(uint8_t byte) {
  if (complete_) clear();
  if (byte == '\n') {
    cr_pending_ = false;  // the CR before the LF is not part of the line
    complete_ = true;
    return true;
  }
  if (cr_pending_) {
    cr_pending_ = false;
    store('\r');  // a CR not followed by LF is an ordinary (bad) byte
  }
  if (byte == '\r') {
    cr_pending_ = true;
    return false;
  }
  store(byte);
  return false;
}

void LineAssembler::store(uint8_t byte) {
  if (size_ >= kMaxLine) {
    overlong_ = true;
    return;
  }
  if (byte < 0x20 || byte > 0x7E) bad_byte_ = true;
  buf_[size_++] = static_cast<char>(byte);
}

}  // namespace reach
