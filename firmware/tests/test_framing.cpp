// PROTOCOL.md "Framing": line length, printable bytes, CR handling, tags, one reply each.
#include <string>

#include "bench.h"
#include "harness.h"

using bench::Bench;
using bench::RailId;
using harness::visible;

TEST(ping_answers_pong) {
  Bench b;
  CHECK_EQ(b.cmd("ping"), std::string("OK 00 pong\r\n"));
}

TEST(cr_before_lf_is_ignored) {
  Bench b;
  CHECK_EQ(b.feed("ping\r\n"), std::string("OK 00 pong\r\n"));
}

TEST(cr_elsewhere_is_a_bad_byte) {
  Bench b;
  CHECK_EQ(b.feed("pi\rng\n"), std::string("ERR 02 byte outside printable ascii\r\n"));
  CHECK_EQ(b.feed("ping\r\r\n"), std::string("ERR 02 byte outside printable ascii\r\n"));
  CHECK_EQ(b.feed("rail 6v on\r\r\n").substr(0, 6), std::string("ERR 02"));
  CHECK(!b.rail(RailId::V6));
}

TEST(line_of_200_bytes_is_accepted) {
  Bench b;
  std::string line = "ping" + std::string(196, ' ');
  CHECK_EQ(line.size(), size_t(200));
  CHECK_EQ(b.cmd(line), std::string("OK 00 pong\r\n"));
  CHECK_EQ(b.feed(line + "\r\n"), std::string("OK 00 pong\r\n"));  // the ignored CR is not counted
}

TEST(line_of_201_bytes_is_refused_once) {
  Bench b;
  std::string line = "ping" + std::string(197, ' ');
  CHECK_EQ(b.cmd(line), std::string("ERR 01 line too long\r\n"));
}

TEST(very_long_line_gets_one_reply_and_the_next_line_works) {
  Bench b;
  std::string line = "rail 6v on" + std::string(5000, 'x');
  CHECK_EQ(b.cmd(line), std::string("ERR 01 line too long\r\n"));
  CHECK(!b.rail(RailId::V6));
  CHECK(b.hal.writes().empty());
  CHECK_EQ(b.cmd("ping"), std::string("OK 00 pong\r\n"));
}

TEST(overlong_line_with_a_valid_command_in_front_changes_nothing) {
  Bench b;
  std::string line = "rail 6v on" + std::string(195, ' ');
  CHECK_EQ(b.cmd(line), std::string("ERR 01 line too long\r\n"));
  CHECK(!b.rail(RailId::V6));
  CHECK(b.hal.writes().empty());
}

TEST(non_printable_bytes_are_refused) {
  const char bad[] = {'\0', '\t', '\x1b', '\x7f', '\x80', '\xff'};
  for (char c : bad) {
    Bench b;
    std::string line = std::string("rail 6v on") + c;
    CHECK_EQ(b.cmd(line), std::string("ERR 02 byte outside printable ascii\r\n"));
    CHECK(!b.rail(RailId::V6));
    CHECK(b.hal.writes().empty());
  }
}

TEST(nul_in_the_middle_of_a_line_is_refused) {
  Bench b;
  CHECK_EQ(b.feed(std::string("rail 6v\0on\n", 11)),
           std::string("ERR 02 byte outside printable ascii\r\n"));
  CHECK(!b.rail(RailId::V6));
}

TEST(empty_and_blank_lines_are_refused) {
  Bench b;
  CHECK_EQ(b.cmd(""), std::string("ERR 06 empty line\r\n"));
  CHECK_EQ(b.cmd("    "), std::string("ERR 06 empty line\r\n"));
  CHECK_EQ(b.feed("\r\n"), std::string("ERR 06 empty line\r\n"));
}

TEST(lone_lf_ends_a_partial_line_with_one_error) {
  Bench b;
  CHECK_EQ(b.feed("rail 6"), std::string());
  CHECK_EQ(b.feed("\n"), std::string("ERR 05 unknown rail\r\n"));
  CHECK_EQ(b.cmd("#r1 ping"), std::string("OK 00 #r1 pong\r\n"));
}

TEST(every_line_gets_exactly_one_reply) {
  Bench b;
  std::string out = b.feed("ping\n\nbogus\nid\n");
  CHECK_EQ(visible(out), visible("OK 00 pong\r\nERR 06 empty line\r\nERR 03 unknown command\r\n"
                                 "OK 00 REACH front-end teensy35\r\n"));
}

TEST(words_may_be_separated_by_several_spaces) {
  Bench b;
  CHECK_EQ(b.cmd("  rail   12v    on  "), std::string("OK 00 12v=1\r\n"));
  CHECK_EQ(b.cmd("select  ms1   3"), std::string("OK 00 ms1=3\r\n"));
}

TEST(tag_is_echoed_on_ok_and_err) {
  Bench b;
  CHECK_EQ(b.cmd("#a1 ping"), std::string("OK 00 #a1 pong\r\n"));
  CHECK_EQ(b.cmd("#ABCdef78 ping"), std::string("OK 00 #ABCdef78 pong\r\n"));
  CHECK_EQ(b.cmd("#t9 bogus"), std::string("ERR 03 #t9 unknown command\r\n"));
  CHECK_EQ(b.cmd("#x select ms1 1"), std::string("ERR 20 #x ms1 needs rail 12v\r\n"));
  CHECK_EQ(b.cmd("#e"), std::string("ERR 06 #e empty line\r\n"));
  CHECK_EQ(b.cmd("#q2   ping"), std::string("OK 00 #q2 pong\r\n"));
}

TEST(tag_is_echoed_on_framing_errors_when_readable) {
  Bench b;
  CHECK_EQ(b.cmd("#t2 ping\x01"), std::string("ERR 02 #t2 byte outside printable ascii\r\n"));
  CHECK_EQ(b.cmd("#t3 " + std::string(300, 'p')), std::string("ERR 01 #t3 line too long\r\n"));
  CHECK_EQ(b.cmd("#t\x01 ping"), std::string("ERR 02 byte outside printable ascii\r\n"));
  CHECK_EQ(b.cmd("#" + std::string(300, 'a')), std::string("ERR 01 line too long\r\n"));
}

TEST(bad_tags_are_refused_without_echo_and_change_nothing) {
  const char* bad[] = {"# ping", "#abcdefghi ping", "#a-b ping", "#a_b ping", "## ping",
                       "#ab! rail 6v on", "#\xe9 ping"};
  for (const char* line : bad) {
    Bench b;
    std::string reply = b.cmd(line);
    if (std::string(line).find('\xe9') != std::string::npos) {
      CHECK_EQ(reply, std::string("ERR 02 byte outside printable ascii\r\n"));
    } else {
      CHECK_EQ(reply, std::string("ERR 07 bad tag\r\n"));
    }
    CHECK(b.hal.writes().empty());
  }
}

TEST(commands_are_lower_case) {
  Bench b;
  CHECK_EQ(b.cmd("PING"), std::string("ERR 03 unknown command\r\n"));
  CHECK_EQ(b.cmd("Rail 6v on"), std::string("ERR 03 unknown command\r\n"));
  CHECK_EQ(b.cmd("rail 6V on"), std::string("ERR 05 unknown rail\r\n"));
}

TEST(wrong_argument_counts_are_refused) {
  const char* lines[] = {"ping x",        "help me",         "state now",      "safe please",
                         "select ms1",    "select ms1 1 2",  "rail",           "rail 6v on now",
                         "tec send",      "tec",             "temps 0x18",     "id x",
                         "version 1",     "select",          "tec send 00 01", "select a b c d e f g h i",
                         "deadman 100 ms"};
  for (const char* line : lines) {
    Bench b;
    CHECK_EQ(b.cmd(line), std::string("ERR 04 wrong number of arguments\r\n"));
    CHECK(b.hal.writes().empty());
  }
}

TEST(longest_reply_is_not_truncated) {
  Bench b;
  b.cmd("rail tec on");
  std::string frame(94, 'A');
  frame += "\r\n";
  b.hal.on_uart_write = [&](bench::HostHal& h, const uint8_t*, size_t) {
    for (char c : frame) h.uart_rx.push_back(static_cast<uint8_t>(c));
  };
  std::string reply = b.cmd("#abcdefgh tec query " + std::string(170, '0'));
  std::string hex;
  for (size_t i = 0; i < 94; ++i) hex += "41";
  CHECK_EQ(reply, "OK 00 #abcdefgh " + hex + "0D0A\r\n");
}
