// Fuzz target: fragmentation and reassembly (channels/fragmentation.hpp,
// docs/protocol.md "Fragment header"). The input is a script that plays one
// link: arbitrary frames from up to eight senders, interleaved with the
// frames of one honest sender (a fragmenter), and the passing of time.
//
// Script (bytes are read front to back; missing bytes read as 0):
//   MTU of the honest sender (2 bytes: 8 + x % 1493), then operations:
//   0  frame:    src/action (1 byte: bits 0..2 the sender, bits 3..7 an
//                action for the honest sender), length (1 byte; 255: 2 more
//                bytes), the frame's bytes; then one honest step
//   1  packet:   the honest sender starts a packet: size (2 bytes,
//                % (max_packet + 1)), content (1 byte: bit 0 set = bytes
//                from the script, repeated, else pseudo-random bytes)
//   2  time:     milliseconds (2 bytes); expire()
//   3  steps:    count (1 byte), action (1 byte): that many honest steps
// An honest step sends the honest sender's next frame; the action may swap
// it with the one after (reordering within the window) and may repeat a
// frame at once (duplication). Reordering is used only with pseudo-random
// content: a payload repeating every 16 frames makes a swapped frame look
// like a late copy, which the receiver rules (window, late duplicates) drop
// by design.
//
// Properties checked:
// - push() is total and its result agrees with the counters: complete adds
//   exactly one to `packets`, dropped adds to some drop counter, pending
//   adds no packet; no counter ever goes down;
// - a single frame is delivered at once with its payload, or is malformed;
// - memory_in_use() never exceeds limits.total; a delivered packet never
//   exceeds max_packet;
// - the honest sender's packets (MTU 8..1500, narrow and wide sequence
//   numbers) are all delivered, exactly, in order, whatever the other
//   senders send in between, and whatever swaps and repeats the actions
//   ask for; each frame but the last is pending, a repeat is a duplicate
//   (a repeated single frame is delivered again, as documented);
// - the fragmenter emits frames_for() frames, each full but the last;
// - after expire(now), next_deadline() lies after now; once every timeout
//   passed, nothing is pending and no memory is in use.
// When a script frame claims the honest sender's own address, its packets
// are no longer checked (anything may happen to them then).

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <vector>

#include "channels/fragmentation.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace herm;

namespace {

using clock_type = std::chrono::steady_clock;
using result = reassembler::result;

/// The honest sender's link address; script frames use 0..7.
constexpr link_addr honest = 7;

/// Small enough to keep runs fast, large enough for every frame type:
/// eight senders at most hold 8 * per_sender < total, so the total bound
/// never makes one sender evict another's stashed frames.
reassembly_limits make_limits() {
  reassembly_limits l;
  l.max_packet = 16 * 1024;
  l.per_sender = 64 * 1024;
  l.total = 16 * l.per_sender;
  l.timeout = std::chrono::milliseconds{2000};
  return l;
}

uint64_t drops(const reassembly_stats& s) {
  return s.malformed + s.duplicates + s.orphans + s.timed_out + s.over_limit
         + s.bad_checksum + s.superseded;
}

bool monotonic(const reassembly_stats& a, const reassembly_stats& b) {
  return b.packets >= a.packets && b.malformed >= a.malformed
         && b.duplicates >= a.duplicates && b.orphans >= a.orphans
         && b.timed_out >= a.timed_out && b.over_limit >= a.over_limit
         && b.bad_checksum >= a.bad_checksum && b.superseded >= a.superseded;
}

class harness {
public:
  harness(uint32_t mtu) : frag_(mtu), r_(make_limits()) {
  }

  // -- operations ------------------------------------------------------------

  void script_frame(fuzz::reader& in) {
    auto b = in.u8();
    auto src = static_cast<link_addr>(b & 0x07);
    size_t len = in.u8();
    if (len == 255)
      len = in.u16();
    auto* p = in.take(len);
    // Its own heap block, so that ASan sees reads past the frame.
    std::vector<uint8_t> frame(p, p + len);
    if (src == honest)
      tainted_ = true;
    push(src, frame.data(), frame.size());
    honest_step(static_cast<uint8_t>(b >> 3));
  }

  void start_packet(fuzz::reader& in) {
    drain();
    auto size = size_t{in.u16()} % (r_.limits().max_packet + 1);
    auto mode = in.u8();
    byte_buffer payload(size);
    random_ = (mode & 1) == 0;
    if (!random_) {
      size_t n = std::min<size_t>(size, 64);
      auto* p = in.take(n);
      for (size_t i = 0; i < size; ++i)
        payload[i] = n == 0 ? 0 : p[i % n];
    } else {
      for (auto& x : payload)
        x = static_cast<uint8_t>(next_random() >> 56);
    }
    queue_.clear();
    frag_.split(payload.data(), payload.size(),
                [this](const uint8_t* f, size_t n) {
                  queue_.emplace_back(f, f + n);
                });
    // The fragmenter's own contract.
    HERM_FUZZ_CHECK(queue_.size() == frag_.frames_for(size));
    for (size_t i = 0; i < queue_.size(); ++i) {
      HERM_FUZZ_CHECK(queue_[i].size() <= frag_.mtu());
      if (queue_.size() > 1 && i + 1 < queue_.size())
        HERM_FUZZ_CHECK(queue_[i].size() == frag_.mtu());
    }
    single_ = queue_.size() == 1;
    expected_ = std::move(payload);
  }

  void advance(fuzz::reader& in) {
    drain();
    now_ += std::chrono::milliseconds{in.u16()};
    expire();
  }

  void steps(fuzz::reader& in) {
    auto n = size_t{in.u8()};
    auto action = in.u8();
    for (size_t i = 0; i < n && !queue_.empty(); ++i)
      honest_step(action);
  }

  void finish() {
    drain();
    now_ += r_.limits().timeout + std::chrono::seconds{1};
    expire();
    HERM_FUZZ_CHECK(r_.pending() == 0);
    HERM_FUZZ_CHECK(r_.memory_in_use() == 0);
    HERM_FUZZ_CHECK(!r_.next_deadline());
  }

private:
  // -- the honest sender -----------------------------------------------------

  /// Sends the next frame; action bit 0: swap it with the one after (random
  /// content only), bit 1: repeat the first frame sent, bit 2: repeat the
  /// second.
  void honest_step(uint8_t action) {
    if (queue_.empty())
      return;
    if ((action & 1) != 0 && random_ && queue_.size() >= 2) {
      std::swap(queue_[0], queue_[1]);
      send_next(result::pending, (action & 2) != 0);
      send_next(queue_.size() == 1 ? result::complete : result::pending,
                (action & 4) != 0);
      return;
    }
    send_next(queue_.size() == 1 ? result::complete : result::pending,
              (action & 2) != 0);
  }

  void send_next(result want, bool repeat) {
    auto frame = std::move(queue_.front());
    queue_.pop_front();
    auto got = push(honest, frame.data(), frame.size());
    if (!tainted_) {
      HERM_FUZZ_CHECK(got == want);
      if (want == result::complete)
        HERM_FUZZ_CHECK(out_ == expected_);
    }
    if (!repeat)
      return;
    auto before = r_.stats();
    got = push(honest, frame.data(), frame.size());
    if (tainted_)
      return;
    if (single_) {
      // Single frames carry no sequence number: delivered again.
      HERM_FUZZ_CHECK(got == result::complete && out_ == expected_);
      return;
    }
    HERM_FUZZ_CHECK(got == result::dropped);
    auto after = r_.stats();
    HERM_FUZZ_CHECK(after.duplicates == before.duplicates + 1);
    HERM_FUZZ_CHECK(drops(after) == drops(before) + 1);
  }

  void drain() {
    while (!queue_.empty())
      send_next(queue_.size() == 1 ? result::complete : result::pending,
                false);
  }

  uint64_t next_random() {
    // splitmix64: payloads that never repeat within a run.
    auto z = (rng_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }

  // -- the receiver ----------------------------------------------------------

  result push(link_addr src, const uint8_t* data, size_t size) {
    auto before = r_.stats();
    out_.assign(3, 0xEE);
    auto got = r_.push(src, data, size, now_, out_);
    auto& after = r_.stats();
    HERM_FUZZ_CHECK(monotonic(before, after));
    HERM_FUZZ_CHECK(r_.memory_in_use() <= r_.limits().total);
    switch (got) {
      case result::complete:
        HERM_FUZZ_CHECK(after.packets == before.packets + 1);
        HERM_FUZZ_CHECK(out_.size() <= r_.limits().max_packet);
        break;
      case result::dropped:
        HERM_FUZZ_CHECK(after.packets == before.packets);
        HERM_FUZZ_CHECK(drops(after) > drops(before));
        break;
      case result::pending:
        HERM_FUZZ_CHECK(after.packets == before.packets);
        break;
      default:
        HERM_FUZZ_CHECK(false);
    }
    if (size == 0) {
      HERM_FUZZ_CHECK(got == result::dropped);
      HERM_FUZZ_CHECK(after.malformed == before.malformed + 1);
    } else if (data[0] >> 6 == 0) {
      // A single frame: delivered at once, or malformed.
      if ((data[0] & 0x0F) == 0 && size - 1 <= r_.limits().max_packet) {
        HERM_FUZZ_CHECK(got == result::complete);
        HERM_FUZZ_CHECK(out_.size() == size - 1
                        && std::equal(out_.begin(), out_.end(), data + 1));
      } else {
        HERM_FUZZ_CHECK(got == result::dropped);
        HERM_FUZZ_CHECK(after.malformed == before.malformed + 1);
      }
    }
    return got;
  }

  void expire() {
    r_.expire(now_);
    auto next = r_.next_deadline();
    HERM_FUZZ_CHECK(!next || *next > now_);
    HERM_FUZZ_CHECK(r_.memory_in_use() <= r_.limits().total);
    if (r_.pending() == 0 && !next)
      HERM_FUZZ_CHECK(r_.memory_in_use() == 0);
  }

  fragmenter frag_;
  reassembler r_;
  // Far from the clock's epoch: deadlines are computed as now + timeout.
  clock_type::time_point now_ = clock_type::time_point{} + std::chrono::hours{1};
  std::deque<byte_buffer> queue_;
  byte_buffer expected_;
  byte_buffer out_;
  bool random_ = true;
  bool single_ = false;
  bool tainted_ = false;
  uint64_t rng_ = 0;
};

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::reader in{data, size};
  auto mtu = static_cast<uint32_t>(min_fragment_mtu + in.u16() % 1493);
  harness h{mtu};
  while (!in.empty()) {
    switch (in.u8() % 4) {
      case 0:
        h.script_frame(in);
        break;
      case 1:
        h.start_packet(in);
        break;
      case 2:
        h.advance(in);
        break;
      default:
        h.steps(in);
        break;
    }
  }
  h.finish();
  return 0;
}
