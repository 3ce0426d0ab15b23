// Fuzz target: fragmentation and reassembly (channels/fragmentation.hpp,
// docs/protocol.md "Fragment header"). The input is a script that plays one
// link: arbitrary frames from up to eight senders, interleaved with the
// frames of one honest sender (a fragmenter) in two lanes, and the passing
// of time.
//
// Script (bytes are read front to back; missing bytes read as 0):
//   MTU of the honest sender (2 bytes: 8 + x % 1493), then operations:
//   0  frame:    src/action (1 byte: bits 0..2 the sender, bits 3..6 an
//                action for the honest sender, bit 7 the frame's lane, 0 or
//                1), length (1 byte; 255: 2 more bytes), the frame's bytes;
//                then one honest step
//   1  packet:   the honest sender starts a packet in a lane: size (2 bytes,
//                % (max_packet + 1)), content (1 byte: bit 0 set = bytes
//                from the script, repeated, else pseudo-random bytes; bit 7
//                the lane, 0 or 1). The lane's previous packet is sent out
//                first; the other lane's may still be under way.
//   2  time:     milliseconds (2 bytes); expire()
//   3  steps:    count (1 byte), action (1 byte): that many honest steps
// An honest step sends the next frame of one lane (action bit 3; the other
// lane when that one has nothing to send); the action may swap it with the
// lane's one after (reordering within the window) and may repeat a frame
// at once (duplication). Steps on the two lanes interleave their packets
// frame by frame, as a CAN controller does when a control frame overtakes
// bulk frames: the honest sender keeps one tag sequence per lane, so the
// two packets under way often share a tag. Reordering is used only with
// pseudo-random content: a payload repeating every 16 frames makes a
// swapped frame look like a late copy, which the receiver rules (window,
// late duplicates) drop by design.
//
// Properties checked:
// - push() is total and its result agrees with the counters: complete adds
//   exactly one to `packets`, dropped adds to some drop counter, pending
//   adds no packet; no counter ever goes down;
// - a single frame is delivered at once with its payload, or is malformed;
// - memory_in_use() never exceeds limits.total; a delivered packet never
//   exceeds max_packet;
// - the honest sender's packets (MTU 8..1500, narrow and wide sequence
//   numbers) are all delivered, exactly, in order within their lane,
//   whatever the other senders send in between, however the two lanes
//   interleave, and whatever swaps and repeats the actions ask for; each
//   frame but the last of its packet is pending, a repeat is a duplicate (a
//   repeated single frame is delivered again, as documented);
// - the fragmenter emits frames_for() frames, each full but the last;
// - after expire(now), next_deadline() lies after now; once every timeout
//   passed, nothing is pending and no memory is in use.
// When a script frame claims the honest sender's own address (in any
// lane), its packets are no longer checked (anything may happen to them
// then).

#include <algorithm>
#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <vector>

#include "channels/fragmenter.hpp"
#include "channels/reassembler.hpp"
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
    auto lane = static_cast<uint8_t>(b >> 7);
    size_t len = in.u8();
    if (len == 255)
      len = in.u16();
    auto* p = in.take(len);
    // Its own heap block, so that ASan sees reads past the frame.
    std::vector<uint8_t> frame(p, p + len);
    if (src == honest)
      tainted_ = true;
    push(src, lane, frame.data(), frame.size());
    honest_step(static_cast<uint8_t>(b >> 3 & 0x0F));
  }

  void start_packet(fuzz::reader& in) {
    auto size = size_t{in.u16()} % (r_.limits().max_packet + 1);
    auto mode = in.u8();
    auto lane = static_cast<uint8_t>(mode >> 7);
    auto& st = lanes_[lane];
    drain(lane);
    byte_buffer payload(size);
    st.random = (mode & 1) == 0;
    if (!st.random) {
      size_t n = std::min<size_t>(size, 64);
      auto* p = in.take(n);
      for (size_t i = 0; i < size; ++i)
        payload[i] = n == 0 ? 0 : p[i % n];
    } else {
      for (auto& x : payload)
        x = static_cast<uint8_t>(next_random() >> 56);
    }
    st.queue.clear();
    frag_.split(0, lane, payload.data(), payload.size(),
                [&st](const uint8_t* f, size_t n) {
                  st.queue.emplace_back(f, f + n);
                });
    // The fragmenter's own contract.
    HERM_FUZZ_CHECK(st.queue.size() == frag_.frames_for(size));
    for (size_t i = 0; i < st.queue.size(); ++i) {
      HERM_FUZZ_CHECK(st.queue[i].size() <= frag_.mtu());
      if (st.queue.size() > 1 && i + 1 < st.queue.size())
        HERM_FUZZ_CHECK(st.queue[i].size() == frag_.mtu());
    }
    st.single = st.queue.size() == 1;
    st.expected = std::move(payload);
  }

  void advance(fuzz::reader& in) {
    drain_all();
    now_ += std::chrono::milliseconds{in.u16()};
    expire();
  }

  void steps(fuzz::reader& in) {
    auto n = size_t{in.u8()};
    auto action = in.u8();
    for (size_t i = 0; i < n && !(lanes_[0].queue.empty() && lanes_[1].queue.empty());
         ++i)
      honest_step(action);
  }

  void finish() {
    drain_all();
    now_ += r_.limits().timeout + std::chrono::seconds{1};
    expire();
    HERM_FUZZ_CHECK(r_.pending() == 0);
    HERM_FUZZ_CHECK(r_.memory_in_use() == 0);
    HERM_FUZZ_CHECK(!r_.next_deadline());
  }

private:
  // -- the honest sender -----------------------------------------------------

  /// One lane of the honest sender: the frames of its packet under way.
  struct lane_state {
    std::deque<byte_buffer> queue;
    byte_buffer expected;
    bool random = true;
    bool single = false;
  };

  /// Sends the next frame of lane `action` bit 3 (of the other lane when
  /// that one is idle); action bit 0: swap it with the one after (random
  /// content only), bit 1: repeat the first frame sent, bit 2: repeat the
  /// second.
  void honest_step(uint8_t action) {
    auto lane = static_cast<uint8_t>(action >> 3 & 1);
    if (lanes_[lane].queue.empty())
      lane ^= 1;
    auto& st = lanes_[lane];
    if (st.queue.empty())
      return;
    if ((action & 1) != 0 && st.random && st.queue.size() >= 2) {
      std::swap(st.queue[0], st.queue[1]);
      send_next(lane, result::pending, (action & 2) != 0);
      send_next(lane, st.queue.size() == 1 ? result::complete : result::pending,
                (action & 4) != 0);
      return;
    }
    send_next(lane, st.queue.size() == 1 ? result::complete : result::pending,
              (action & 2) != 0);
  }

  void send_next(uint8_t lane, result want, bool repeat) {
    auto& st = lanes_[lane];
    auto frame = std::move(st.queue.front());
    st.queue.pop_front();
    auto got = push(honest, lane, frame.data(), frame.size());
    if (!tainted_) {
      HERM_FUZZ_CHECK(got == want);
      if (want == result::complete)
        HERM_FUZZ_CHECK(out_ == st.expected);
    }
    if (!repeat)
      return;
    auto before = r_.stats();
    got = push(honest, lane, frame.data(), frame.size());
    if (tainted_)
      return;
    if (st.single) {
      // Single frames carry no sequence number: delivered again.
      HERM_FUZZ_CHECK(got == result::complete && out_ == st.expected);
      return;
    }
    HERM_FUZZ_CHECK(got == result::dropped);
    auto after = r_.stats();
    HERM_FUZZ_CHECK(after.duplicates == before.duplicates + 1);
    HERM_FUZZ_CHECK(drops(after) == drops(before) + 1);
  }

  void drain(uint8_t lane) {
    auto& st = lanes_[lane];
    while (!st.queue.empty())
      send_next(lane, st.queue.size() == 1 ? result::complete : result::pending,
                false);
  }

  void drain_all() {
    drain(0);
    drain(1);
  }

  uint64_t next_random() {
    // splitmix64: payloads that never repeat within a run.
    auto z = (rng_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }

  // -- the receiver ----------------------------------------------------------

  result push(link_addr src, uint8_t lane, const uint8_t* data, size_t size) {
    auto before = r_.stats();
    out_.assign(3, 0xEE);
    auto got = r_.push(src, lane, data, size, now_, out_);
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
  std::array<lane_state, 2> lanes_;
  byte_buffer out_;
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
