// teensy-sim: the firmware core on the host HAL, serving PROTOCOL.md on a pseudo-terminal.
//
//   teensy-sim [--uart1 PATH] [--watchdog-ms N]
//
// stdout: "PTY <slave path>" once, then "PINS <state payload>" at start and after every
//         line that changed an output (and after a watchdog reset or a dead-man trip);
//         "TXDROP <n>" when a reply was dropped because nobody read the terminal.
// The dead-man switch runs on the host's monotonic clock, checked at least every 20 ms.
// stdin:  "I2C <addr> <celsius>|fail|absent" sets a simulated MCP9808;
//         "HANG" stops the main loop, so the simulated watchdog resets the core after
//         N ms (default 1000): power-on state, boot=wdog. EOF on stdin ends the program.
// --uart1 PATH: the TEC controller's serial device (raw, 19200 8N1); without it
//         `tec query` times out.
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <string>

#include "../core/firmware.h"
#include "../host/host_hal.h"

namespace {

volatile sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

bool make_raw(int fd, bool set_speed) {
  struct termios tio;
  if (tcgetattr(fd, &tio) != 0) return false;
  cfmakeraw(&tio);
  if (set_speed) {
    cfsetispeed(&tio, B19200);
    cfsetospeed(&tio, B19200);
  }
  return tcsetattr(fd, TCSANOW, &tio) == 0;
}

// Replies leave through a transmit queue of whole lines. When it has no room the
// firmware waits up to 70 ms for the client to take bytes, then drops the reply, and
// after such a timeout drops at once until bytes leave again, as the board's USB serial
// does (Teensyduino's usb_serial.c, TX_TIMEOUT_MSEC), so a client that stopped reading
// cannot stall the loop. The queue's 64 KiB stand for the buffering a USB serial port
// has in the host's kernel, which a pseudo-terminal lacks (it refuses writes after some
// 20 kB of short replies). A client that reads keeps every reply (the firmware waits and
// reads no request meanwhile, so the writer waits too); one that leaves queue and
// terminal full for 70 ms loses whole replies, never part of one, each reported on
// stdout as "TXDROP <replies dropped so far>" (PROTOCOL.md, "Flow control").
constexpr int64_t kTxTimeoutMs = 70;
constexpr size_t kTxQueueBytes = 64 * 1024;

int64_t monotonic_ms() {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000 + ts.tv_nsec / 1000000;
}

class Transmit {
 public:
  explicit Transmit(int fd) : fd_(fd) {}

  bool pending() const { return !queue_.empty(); }

  // A reset loses what the USB buffers held.
  void discard() {
    queue_.clear();
    timed_out_ = false;
  }

  // Move queued bytes to the terminal as far as it takes them (a line may be split
  // between writes: its rest stays queued, it is never dropped).
  void flush() {
    while (!queue_.empty()) {
      ssize_t w = write(fd_, queue_.data(), queue_.size());
      if (w > 0) {
        queue_.erase(0, static_cast<size_t>(w));
        timed_out_ = false;
      } else if (!(w < 0 && errno == EINTR)) {
        return;  // full (EAGAIN), or no terminal: wait for POLLOUT
      }
    }
  }

  // Queue one reply, waiting up to kTxTimeoutMs for room; false when it was dropped.
  bool send(const char* data, size_t n) {
    flush();
    const int64_t deadline = monotonic_ms() + kTxTimeoutMs;
    while (queue_.size() + n > kTxQueueBytes) {
      const int64_t left = deadline - monotonic_ms();
      if (timed_out_ || left <= 0) {
        timed_out_ = true;
        ++dropped_;
        printf("TXDROP %llu\n", static_cast<unsigned long long>(dropped_));
        fflush(stdout);
        return false;
      }
      struct pollfd out = {fd_, POLLOUT, 0};
      poll(&out, 1, static_cast<int>(left));
      flush();
    }
    queue_.append(data, n);
    flush();
    return true;
  }

 private:
  int fd_;
  std::string queue_;
  bool timed_out_ = false;  // the last reply was dropped and nothing left since
  uint64_t dropped_ = 0;
};

void print_pins(reach::Firmware& fw) {
  reach::Payload payload;
  fw.state_payload(&payload);
  printf("PINS %.*s\n", static_cast<int>(payload.size()), payload.data());
  fflush(stdout);
}

// One stdin command; returns true for HANG.
bool stdin_command(const std::string& line, reach::host::HostHal& hal) {
  char addr_text[32] = {0}, value[64] = {0};
  if (line == "HANG") return true;
  if (sscanf(line.c_str(), "I2C %31s %63s", addr_text, value) == 2) {
    char* end = nullptr;
    long addr = strtol(addr_text, &end, 0);
    if (*end == '\0' && addr >= 0 && addr < 128) {
      uint8_t a = static_cast<uint8_t>(addr);
      if (strcmp(value, "fail") == 0) {
        hal.set_sensor_fail(a);
        return false;
      }
      if (strcmp(value, "absent") == 0) {
        hal.set_sensor_absent(a);
        return false;
      }
      double celsius = strtod(value, &end);
      if (*end == '\0') {
        hal.set_sensor(a, celsius);
        return false;
      }
    }
  }
  fprintf(stderr, "teensy-sim: ignored stdin line: %s\n", line.c_str());
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  const char* uart1_path = nullptr;
  long watchdog_ms = 1000;
  for (int i = 1; i < argc; ++i) {
    if (strcmp(argv[i], "--uart1") == 0 && i + 1 < argc) {
      uart1_path = argv[++i];
    } else if (strcmp(argv[i], "--watchdog-ms") == 0 && i + 1 < argc) {
      watchdog_ms = strtol(argv[++i], nullptr, 10);
    } else {
      fprintf(stderr, "usage: teensy-sim [--uart1 PATH] [--watchdog-ms N]\n");
      return 2;
    }
  }

  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_signal;
  sigaction(SIGTERM, &sa, nullptr);
  sigaction(SIGINT, &sa, nullptr);
  signal(SIGPIPE, SIG_IGN);

  int master = posix_openpt(O_RDWR | O_NOCTTY);
  if (master < 0 || grantpt(master) != 0 || unlockpt(master) != 0) {
    perror("teensy-sim: pseudo-terminal");
    return 1;
  }
  const char* slave_path = ptsname(master);
  // Holding the slave open keeps the master readable (no EIO) between clients.
  int slave_keep = slave_path ? open(slave_path, O_RDWR | O_NOCTTY) : -1;
  if (slave_keep < 0 || !make_raw(slave_keep, false)) {
    perror("teensy-sim: slave");
    return 1;
  }
  fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);

  int uart1 = -1;
  if (uart1_path != nullptr) {
    uart1 = open(uart1_path, O_RDWR | O_NOCTTY | O_NONBLOCK);
    if (uart1 < 0 || !make_raw(uart1, true)) {
      fprintf(stderr, "teensy-sim: cannot open uart1 %s: %s\n", uart1_path, strerror(errno));
      return 1;
    }
  }

  reach::host::HostHal hal(/*real_time=*/true);
  hal.set_uart_fd(uart1);
  // A reply leaves only after the pin changes it caused have been reported on stdout, so
  // whoever has read the reply can trust the simulator's view of the switches.
  uint64_t pins_reported = 0;
  Transmit transmit(master);
  reach::Firmware* reporting = nullptr;
  hal.host_sink = [&](const char* data, size_t n) {
    if (reporting != nullptr && hal.write_count() != pins_reported) {
      print_pins(*reporting);
      pins_reported = hal.write_count();
    }
    transmit.send(data, n);
  };
  reach::Firmware fw(hal);
  reporting = &fw;
  fw.begin();
  hal.watchdog_kick();

  printf("PTY %s\n", slave_path);
  print_pins(fw);
  pins_reported = hal.write_count();

  bool hung = false;
  bool uart1_alive = uart1 >= 0;
  std::string stdin_buf;
  char buf[512];
  while (!g_stop) {
    // Queued replies leave as the terminal takes them (POLLOUT).
    const short master_events = static_cast<short>(transmit.pending() ? POLLIN | POLLOUT : POLLIN);
    struct pollfd fds[3] = {{STDIN_FILENO, POLLIN, 0},
                            {hung ? -1 : master, master_events, 0},
                            {uart1_alive && !hung ? uart1 : -1, POLLIN, 0}};
    int ready = poll(fds, 3, 20);
    if (ready < 0 && errno != EINTR) break;
    if (g_stop) break;

    // stdin first: a sensor value or HANG sent before a request applies to it.
    if (fds[0].revents & (POLLIN | POLLHUP)) {
      ssize_t got = read(STDIN_FILENO, buf, sizeof buf);
      if (got <= 0) break;  // EOF: the launcher is gone
      stdin_buf.append(buf, static_cast<size_t>(got));
      size_t lf;
      while ((lf = stdin_buf.find('\n')) != std::string::npos) {
        std::string line = stdin_buf.substr(0, lf);
        stdin_buf.erase(0, lf + 1);
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (stdin_command(line, hal)) hung = true;
      }
      if (stdin_buf.size() > 1024) {
        fprintf(stderr, "teensy-sim: stdin line too long, dropped\n");
        stdin_buf.clear();
      }
    }

    // A hung loop reads nothing: bytes wait in the terminal until the reset drops them.
    if (!hung) {
      if (fds[1].revents & POLLIN) {
        ssize_t got = read(master, buf, sizeof buf);
        for (ssize_t i = 0; i < got; ++i) {
          fw.feed(static_cast<uint8_t>(buf[i]));
          if (hal.write_count() != pins_reported) {
            print_pins(fw);
            pins_reported = hal.write_count();
          }
        }
      } else if (fds[1].revents & (POLLHUP | POLLERR) && !(fds[1].revents & POLLOUT)) {
        poll(nullptr, 0, 10);  // no slave open at all: wait instead of spinning
      }
      if (fds[2].revents & POLLIN) {
        // Bytes the controller sent unasked are dropped, as the firmware would.
        if (read(uart1, buf, sizeof buf) <= 0) uart1_alive = false;
      } else if (fds[2].revents & (POLLHUP | POLLERR)) {
        uart1_alive = false;
      }
      if (fds[1].revents & POLLOUT) transmit.flush();
      fw.poll();  // the dead-man switch, as the board's loop() does
      if (hal.write_count() != pins_reported) {
        print_pins(fw);
        pins_reported = hal.write_count();
      }
      hal.watchdog_kick();
    }

    // Only a loop that HANG stopped starves the WDOG: this process being descheduled by a
    // busy host for a second is not a hung core, and must not reset the board.
    if (hung && hal.millis() - hal.last_kick_ms() >= static_cast<uint32_t>(watchdog_ms)) {
      // The WDOG fires: what the host sent meanwhile is lost, the board starts afresh.
      while (read(master, buf, sizeof buf) > 0) {
      }
      transmit.discard();
      hal.set_boot_reason(reach::BootReason::Watchdog);
      fw.begin();
      hal.watchdog_kick();
      hung = false;
      print_pins(fw);
      pins_reported = hal.write_count();
    }
  }
  if (uart1 >= 0) close(uart1);
  close(slave_keep);
  close(master);
  return 0;
}
