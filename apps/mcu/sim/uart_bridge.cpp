#include "apps/mcu/sim/uart_bridge.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

namespace herm::avr_sim {

namespace {

/// simavr 1.6 has no accessor for a UART's state: walk the io modules.
avr_uart_t* find_uart(avr_t* avr, char name) {
  for (auto* io = avr->io_port; io != nullptr; io = io->next)
    if (io->kind != nullptr && std::strcmp(io->kind, "uart") == 0) {
      auto* uart = reinterpret_cast<avr_uart_t*>(io); // io is its first member
      if (uart->name == name)
        return uart;
    }
  return nullptr;
}

std::string errno_text(const char* what) {
  return std::string{what} + ": " + std::strerror(errno);
}

/// The AVR's receive FIFO holds two bytes (plus the one in the shift
/// register, which is the one being fed).
constexpr unsigned board_rx_fifo = 2;

/// Bytes waiting in simavr's receive FIFO (its accessors are defined in
/// avr_uart.c only, so the count is taken from the ring's cursors).
unsigned waiting(const uart_fifo_t& f) {
  return (static_cast<unsigned>(f.write) + uart_fifo_fifo_size - f.read)
         & (uart_fifo_fifo_size - 1u);
}

} // namespace

std::unique_ptr<uart_bridge> uart_bridge::make(avr_t* avr, char uart,
                                               std::string& error) {
  auto* port = find_uart(avr, uart);
  if (port == nullptr) {
    error = std::string{"the core has no UART"} + uart;
    return nullptr;
  }
  return std::unique_ptr<uart_bridge>{new uart_bridge(avr, port)};
}

std::unique_ptr<uart_bridge> uart_bridge::open(avr_t* avr, char uart,
                                               const std::string& link,
                                               std::string& error) {
  auto self = make(avr, uart, error);
  if (self == nullptr)
    return nullptr;
  self->master_ = ::posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (self->master_ < 0) {
    error = errno_text("posix_openpt");
    return nullptr;
  }
  char name[128];
  if (::grantpt(self->master_) != 0 || ::unlockpt(self->master_) != 0
      || ::ptsname_r(self->master_, name, sizeof(name)) != 0) {
    error = errno_text("pty set-up");
    return nullptr;
  }
  self->pty_path_ = name;
  termios tio{};
  if (::tcgetattr(self->master_, &tio) == 0) {
    ::cfmakeraw(&tio);
    ::tcsetattr(self->master_, TCSANOW, &tio);
  }
  if (!link.empty()) {
    struct stat st {};
    if (::lstat(link.c_str(), &st) == 0) {
      if (!S_ISLNK(st.st_mode)) {
        error = "--pty-link " + link + " exists and is not a symlink";
        return nullptr;
      }
      ::unlink(link.c_str());
    }
    if (::symlink(name, link.c_str()) != 0) {
      error = errno_text(("symlink " + link).c_str());
      return nullptr;
    }
    self->link_ = link;
  }
  self->connect_irqs(uart);
  return self;
}

std::unique_ptr<uart_bridge> uart_bridge::attach(avr_t* avr, char uart,
                                                 const std::string& device,
                                                 std::string& error) {
  auto self = make(avr, uart, error);
  if (self == nullptr)
    return nullptr;
  self->master_ = ::open(device.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (self->master_ < 0) {
    error = errno_text(("cannot open --device " + device).c_str());
    return nullptr;
  }
  termios tio{};
  if (::tcgetattr(self->master_, &tio) != 0) {
    error = errno_text(("--device " + device + " is not a serial line").c_str());
    return nullptr;
  }
  ::cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag &= static_cast<tcflag_t>(~CRTSCTS);
  if (::tcsetattr(self->master_, TCSANOW, &tio) != 0) {
    error = errno_text(("cannot set --device " + device + " raw").c_str());
    return nullptr;
  }
  self->pty_path_ = device;
  self->connect_irqs(uart);
  return self;
}

void uart_bridge::connect_irqs(char uart) {
  // Binary on the line: no console echo of what the board prints, and no
  // usleep inside status-register reads (the harness paces time itself).
  uint32_t flags = 0;
  avr_ioctl(avr_, AVR_IOCTL_UART_SET_FLAGS(uart), &flags);
  avr_irq_register_notify(
    avr_io_getirq(avr_, AVR_IOCTL_UART_GETIRQ(uart), UART_IRQ_OUTPUT),
    &uart_bridge::on_output, this);
  input_ = avr_io_getirq(avr_, AVR_IOCTL_UART_GETIRQ(uart), UART_IRQ_INPUT);
}

uart_bridge::uart_bridge(avr_t* avr, avr_uart_t* uart) : avr_(avr), uart_(uart) {
}

uart_bridge::~uart_bridge() {
  if (feed_armed_)
    avr_cycle_timer_cancel(avr_, &uart_bridge::feed, this);
  avr_irq_unregister_notify(
    avr_io_getirq(avr_, AVR_IOCTL_UART_GETIRQ(uart_->name), UART_IRQ_OUTPUT),
    &uart_bridge::on_output, this);
  if (!link_.empty())
    ::unlink(link_.c_str());
  if (master_ >= 0)
    ::close(master_);
}

void uart_bridge::on_output(avr_irq_t*, uint32_t value, void* param) {
  auto* self = static_cast<uart_bridge*>(param);
  if (self->to_host_.size() >= to_host_limit) {
    ++self->counters_.dropped_to_host;
    return;
  }
  self->to_host_.push_back(static_cast<uint8_t>(value));
}

avr_cycle_count_t uart_bridge::frame_cycles() const {
  return uart_->cycles_per_byte;
}

void uart_bridge::correct_frame_time() {
  auto* avr = avr_;
  uint32_t ubrr = avr_regbit_get(avr, uart_->ubrrl)
                  | (static_cast<uint32_t>(avr_regbit_get(avr, uart_->ubrrh)) << 8);
  static constexpr uint32_t data_bits[] = {5, 6, 7, 8, 8, 8, 8, 9};
  uint32_t db = data_bits[avr_regbit_get(avr, uart_->ucsz)
                          | (avr_regbit_get(avr, uart_->ucsz2) << 2)];
  uint32_t sb = 1u + avr_regbit_get(avr, uart_->usbs);
  uint32_t parity = ((avr->data[uart_->r_ucsrc] >> 4) & 3u) != 0 ? 1u : 0u; // UPMn1:0
  uint32_t cycles_per_bit = (ubrr + 1u) * (avr_regbit_get(avr, uart_->u2x) ? 8u : 16u);
  avr_cycle_count_t frame = cycles_per_bit * (1u + db + parity + sb);
  // Only replace simavr's own figure (which always counts a parity bit),
  // i.e. after the firmware configured the baud rate.
  avr_cycle_count_t simavr_frame = cycles_per_bit * (1u + db + 1u + sb);
  if (uart_->cycles_per_byte == simavr_frame)
    uart_->cycles_per_byte = frame;
}

void uart_bridge::arm_feed() {
  if (feed_armed_ || to_board_.empty())
    return;
  feed_armed_ = true;
  avr_cycle_timer_register(avr_, uart_->cycles_per_byte, &uart_bridge::feed, this);
}

avr_cycle_count_t uart_bridge::feed(avr_t* avr, avr_cycle_count_t when,
                                    void* param) {
  auto* self = static_cast<uart_bridge*>(param);
  auto* uart = self->uart_;
  if (self->to_board_.empty()) {
    self->feed_armed_ = false;
    return 0;
  }
  if (!avr_regbit_get(avr, uart->rxen)) {
    self->to_board_.pop_front();
    ++self->counters_.lost_rx_off;
  } else if (waiting(uart->input) >= board_rx_fifo) {
    ++self->counters_.held;
  } else {
    avr_raise_irq(self->input_, self->to_board_.front());
    self->to_board_.pop_front();
    ++self->counters_.to_board;
  }
  if (self->to_board_.empty()) {
    self->feed_armed_ = false;
    return 0;
  }
  return when + uart->cycles_per_byte;
}

void uart_bridge::pump() {
  correct_frame_time();
  uint8_t buf[512];
  while (to_board_.size() < to_board_limit) {
    auto room = std::min(sizeof(buf), to_board_limit - to_board_.size());
    auto n = ::read(master_, buf, room);
    if (n <= 0) // EAGAIN: nothing; EIO: no one has the slave open
      break;
    to_board_.insert(to_board_.end(), buf, buf + n);
  }
  arm_feed();
  while (!to_host_.empty()) {
    size_t len = std::min(sizeof(buf), to_host_.size());
    std::copy(to_host_.begin(), to_host_.begin() + static_cast<long>(len), buf);
    auto n = ::write(master_, buf, len);
    if (n <= 0)
      break; // EAGAIN: the pty's buffer is full; try again next pump
    to_host_.erase(to_host_.begin(), to_host_.begin() + n);
    counters_.to_host += static_cast<uint64_t>(n);
  }
}

} // namespace herm::avr_sim
