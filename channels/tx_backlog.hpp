#pragma once

// The transmit backlog of a channel: frames the driver's queue had no room
// for, waiting in one queue per priority. Pure code (no clock, no I/O): the
// channel actor feeds it and hands its frames to the driver.
//
// Drop policy (docs/reliability.md, "Overload"): the backlog holds at most
// `max_bytes` (frame bytes plus a small per-frame overhead). A packet that
// does not fit evicts whole packets that have not started yet, of strictly
// lower priority (less urgent), bulk first and the newest first, until it
// fits; when that is not enough the new packet is dropped. So under
// overload the least urgent traffic goes first, and a control packet is
// only refused when the backlog is full of control packets. Every packet
// lost this way is counted by its priority.
//
// Order: a packet whose first frames already went to the driver finishes
// before anything else (fragments of one packet are never interleaved with
// another packet's by the backlog); otherwise the most urgent class goes
// first, FIFO within a class.

#include <array>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <vector>

#include "channels/link_driver.hpp"
#include "channels/messages.hpp"

namespace herm {

class tx_backlog {
public:
  /// Number of priority classes (prio_control .. prio_bulk).
  static constexpr size_t classes = 4;

  /// Bytes a queued frame costs beyond its own bytes (bookkeeping).
  static constexpr size_t frame_overhead = 2;

  struct frame {
    link_addr dst = 0;
    /// As given to open() (drivers may use more levels than the classes).
    uint8_t priority = 0;
    byte_buffer bytes;
  };

  struct counters {
    /// New packets refused because they did not fit, per priority.
    std::array<uint64_t, classes> refused{};
    /// Queued packets evicted for a more urgent one, per priority.
    std::array<uint64_t, classes> evicted{};
    /// Largest number of bytes held at once.
    size_t peak_bytes = 0;
  };

  explicit tx_backlog(size_t max_bytes);

  /// Nothing waits.
  bool empty() const noexcept {
    return bytes_ == 0 && packets_ == 0;
  }

  /// Bytes held (frames plus overhead).
  size_t bytes() const noexcept {
    return bytes_;
  }

  /// Packets held, the one in progress included.
  size_t packets() const noexcept {
    return packets_;
  }

  size_t max_bytes() const noexcept {
    return max_bytes_;
  }

  /// What a packet of `frames` frames and `size` payload bytes costs here
  /// at most (fragment headers included).
  /// (A fragmented stream adds a 4-byte CRC; a fragment header takes at
  /// most 4 bytes.)
  static size_t cost(size_t size, size_t frames) noexcept {
    return size + 4 + frames * (frame_overhead + 4);
  }

  /// Makes room for a new packet costing `cost` bytes at priority `prio`
  /// (clamped to bulk). Returns false, and counts the packet as refused,
  /// when even evicting every less urgent packet not yet started would not
  /// make room.
  bool admit(uint8_t prio, size_t cost);

  /// Starts a new packet at the back of its class. With `started`, frames
  /// of it already went to the driver: it goes out before anything else.
  /// A packet opened while another started one is still queued would
  /// interleave fragments: @pre !started || no started packet is queued.
  void open(uint8_t prio, bool started);

  /// Appends a frame to the packet opened last. Never refuses: admit()
  /// decided; a started packet's remainder is always taken.
  void append(link_addr dst, const uint8_t* data, size_t size);

  /// The next frame for the driver, or nullptr when empty.
  const frame* front() const noexcept;

  /// The driver took front().
  void pop();

  /// Writes the next frames for the driver, at most `max`, into `out` in
  /// the order front() and pop() would hand them out, and returns how many
  /// (0 when empty). The frames point into the backlog: valid until the
  /// next call of a non-const member. O(returned + classes + packets
  /// passed over), no allocation.
  size_t peek(tx_frame* out, size_t max) const noexcept;

  /// The driver took the first `n` frames peek() returned: pop() `n` times.
  void pop(size_t n);

  const counters& stats() const noexcept {
    return stats_;
  }

private:
  struct packet {
    std::vector<frame> frames;
    size_t next = 0;
    size_t bytes = 0;
  };

  /// The queue front() reads from, or nullptr.
  std::deque<packet>* current() noexcept;
  const std::deque<packet>* current() const noexcept;

  size_t max_bytes_;
  size_t bytes_ = 0;
  size_t packets_ = 0;
  std::array<std::deque<packet>, classes> queues_;
  /// Class whose front packet has started, or classes for none.
  size_t started_ = classes;
  /// Class of the packet opened last (append's target), and whether it
  /// sits at the front (started) or the back of that class.
  size_t open_ = classes;
  bool open_front_ = false;
  uint8_t open_priority_ = 0;
  counters stats_;
};

} // namespace herm
