#pragma once

// UART `n` of a simulated AVR, bridged to a pseudo-terminal at the line rate
// (or to a serial line the caller names: attach()).
//
// Board -> host: every byte the firmware writes to UDRn is queued and written
// to the pty master by pump(). simavr 1.6 already paces the transmitter: UDRE
// comes back one frame time after each byte (avr_uart.c's TX pump).
// Host -> board: bytes read from the pty are fed into the UART one per frame
// time (a cycle timer), and only while the board's receive buffer has room
// (the ATmega's two-byte FIFO): the next byte waits, and `held` counts it,
// instead of overrunning a board that has not read its data register. Bytes
// that arrive while the board's receiver is off are lost, as on a real
// board, and counted in `lost_rx_off`.
//
// simavr 1.6 quirk, corrected here: avr_uart_baud_write counts a parity bit
// in every frame (word_size = 1 + data + 1 + stop), so 8N1 frames last 11
// bit times instead of 10 and a 19,200 baud line moves 1,745 bytes/s instead
// of 1,920. After every pump() the frame time is recomputed from UBRRn, U2Xn,
// UCSZn, UPMn and USBSn and written back into the UART model.
//
// Bounds: at most to_board_limit bytes wait for the board (the pty is not
// read while the queue is full, so the writer is held back, not dropped);
// at most to_host_limit bytes wait for the host (more are dropped and counted
// in dropped_to_host: nobody is reading the pty).
// Single-threaded: pump() and the simavr callbacks run on the harness thread.

#include <cstdint>
#include <deque>
#include <memory>
#include <string>

#include "apps/mcu/sim/simavr.hpp"

namespace herm::avr_sim {

struct uart_counters {
  uint64_t to_board = 0;        ///< bytes given to the board's receiver
  uint64_t to_host = 0;         ///< bytes the board sent, written to the pty
  uint64_t held = 0;            ///< frame times a byte waited: receive buffer full
  uint64_t lost_rx_off = 0;     ///< bytes that came while the receiver was off
  uint64_t dropped_to_host = 0; ///< board bytes dropped: the pty was not read
};

class uart_bridge {
public:
  static constexpr size_t to_board_limit = 4096;
  static constexpr size_t to_host_limit = 65536;

  /// Opens a pty in raw mode and connects it to UART `uart` ('0', '1') of
  /// `avr`. With a non-empty `link`, a symlink of that name points at the
  /// pty's slave (replacing an existing symlink, never a regular file) and
  /// is removed again by the destructor. On failure returns null and says
  /// why in `error`.
  static std::unique_ptr<uart_bridge> open(avr_t* avr, char uart,
                                           const std::string& link,
                                           std::string& error);

  /// Connects UART `uart` of `avr` to an existing serial line `device`
  /// instead (e.g. one end of a paced pty cable, or a real tty), opened
  /// raw (8N1, no echo, no flow control) and non-blocking. The line's own
  /// rate is left as it is: the bridge paces bytes at the UART's rate. On
  /// failure returns null and says why (with the path) in `error`.
  static std::unique_ptr<uart_bridge> attach(avr_t* avr, char uart,
                                             const std::string& device,
                                             std::string& error);

  ~uart_bridge();
  uart_bridge(const uart_bridge&) = delete;
  uart_bridge& operator=(const uart_bridge&) = delete;

  /// The slave side's path, e.g. /dev/pts/7 (attach: the device's path).
  const std::string& pty_path() const {
    return pty_path_;
  }

  /// Moves bytes between the pty and the queues (non-blocking) and keeps
  /// the UART's frame time right. Call between simulation slices.
  void pump();

  /// One frame on the line, in CPU cycles (10 bit times at 8N1).
  avr_cycle_count_t frame_cycles() const;

  const uart_counters& counters() const {
    return counters_;
  }

private:
  uart_bridge(avr_t* avr, avr_uart_t* uart);

  /// The bridge of `avr`'s UART `uart`, not yet connected; null (and
  /// `error` set) when the core has no such UART.
  static std::unique_ptr<uart_bridge> make(avr_t* avr, char uart,
                                           std::string& error);
  void connect_irqs(char uart);

  static void on_output(avr_irq_t* irq, uint32_t value, void* param);
  static avr_cycle_count_t feed(avr_t* avr, avr_cycle_count_t when, void* param);
  void correct_frame_time();
  void arm_feed();

  avr_t* avr_;
  avr_uart_t* uart_;
  avr_irq_t* input_ = nullptr;
  int master_ = -1; ///< the pty's master, or the attached device
  std::string pty_path_;
  std::string link_;
  std::deque<uint8_t> to_board_;
  std::deque<uint8_t> to_host_;
  bool feed_armed_ = false;
  uart_counters counters_;
};

} // namespace herm::avr_sim
