#include "channels/reassembler.hpp"

#include <algorithm>
#include <array>
#include <cassert>
#include <cstring>
#include <map>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "channels/fragment_wire.hpp"
#include "channels/le_codec.hpp"

namespace herm {

using namespace fragment_wire;

namespace {

// -- reassembler state -----------------------------------------------------------

using time_point = reassembler::time_point;

/// One packet being reassembled. Its only heap block is `buf`: the stream
/// (payload || CRC-32) followed by a bitmap of the frames that arrived, so a
/// packet costs exactly one allocation.
struct packet {
  byte_buffer buf;
  time_point deadline;
  size_t charge = 0;        // bytes counted against the limits
  uint32_t length = 0;      // payload bytes
  uint32_t first_data = 0;  // stream bytes in frame 0
  uint32_t chunk = 0;       // stream bytes in frames 1 .. frames - 2
  uint32_t frames = 0;
  uint32_t received = 0;
  uint32_t lowest_missing = 0;
  /// Highest frame index received so far.
  uint32_t highest = 0;
  bool wide = false;

  uint32_t stream_size() const noexcept {
    return length + crc_size;
  }

  bool has(uint32_t i) const noexcept {
    return (buf[stream_size() + i / 8] >> (i % 8)) & 1;
  }

  void mark(uint32_t i) noexcept {
    buf[stream_size() + i / 8] |= static_cast<uint8_t>(1u << (i % 8));
  }

  size_t offset_of(uint32_t i) const noexcept {
    return i == 0 ? 0 : first_data + size_t{i - 1} * chunk;
  }

  size_t size_of(uint32_t i) const noexcept {
    return i == 0 ? first_data
                  : std::min<size_t>(chunk, stream_size() - offset_of(i));
  }
};

/// A consecutive fragment that matched no packet (yet): usually one that
/// overtook its first fragment.
struct stash_entry {
  byte_buffer bytes; // stream bytes, header stripped
  time_point deadline;
  size_t charge;
  uint64_t order; // arrival order over all senders, for evicting the oldest
  uint16_t seq;
  uint8_t tag;
  bool wide;
};

/// One sender's lane (link_driver.hpp): packets in different lanes of one
/// sender may interleave on the link, so each lane reassembles on its own.
/// Ordered by sender first, so a sender's lanes are neighbours in a map.
struct lane_key {
  link_addr src;
  uint8_t lane;

  friend bool operator<(const lane_key& x, const lane_key& y) noexcept {
    return x.src != y.src ? x.src < y.src : x.lane < y.lane;
  }

  friend bool operator==(const lane_key& x, const lane_key& y) noexcept {
    return x.src == y.src && x.lane == y.lane;
  }
};

struct lane_key_hash {
  size_t operator()(const lane_key& k) const noexcept {
    return std::hash<uint64_t>{}(k.src ^ uint64_t{k.lane} << 56);
  }
};

/// What one lane of one sender holds.
struct lane_state {
  std::array<std::optional<packet>, 4> packets; // by tag
  std::vector<stash_entry> stash;               // in arrival order
  size_t packet_bytes = 0;
  size_t stash_bytes = 0;
  size_t packet_count = 0;

  bool empty() const noexcept {
    return packet_count == 0 && stash.empty();
  }
};

/// Saturating `start + timeout + 1 tick`: the first instant at which a
/// packet started at `start` is older than the timeout.
time_point deadline_after(time_point start, std::chrono::milliseconds timeout) {
  using duration = time_point::duration;
  constexpr auto longest = std::chrono::duration_cast<std::chrono::milliseconds>(
    duration::max() - duration{1});
  duration wait = timeout <= timeout.zero() ? duration::zero()
                  : timeout >= longest
                    ? duration::max() - duration{1}
                    : std::chrono::duration_cast<duration>(timeout);
  wait += duration{1};
  if (start > time_point::max() - wait)
    return time_point::max();
  return start + wait;
}

enum class placement { placed, duplicate, misfit };

/// Puts a consecutive fragment into the unique frame index congruent to `seq`
/// in [lowest_missing, lowest_missing + modulus). A fragment that lands past
/// the last frame or whose size differs from that frame's is a misfit: it
/// belongs to some other packet.
placement place(packet& p, uint32_t seq, const uint8_t* bytes, size_t size) {
  auto modulus = p.wide ? wide_modulus : narrow_modulus;
  auto low = p.lowest_missing;
  auto index = low + (seq + modulus - low % modulus) % modulus;
  // A copy of a frame that arrived moments ago maps one modulus ahead of the
  // original (the window has moved past it). Recognise it by its bytes so
  // that a repeated frame costs nothing instead of the whole packet.
  // Only a frame that would land beyond the next expected one can be such
  // a copy: an in-order frame equal to the one a modulus back (a payload
  // repeating every 16 frames, e.g. zeros) is not.
  if (index >= modulus && index > p.highest + 1) {
    auto prev = index - modulus;
    if (prev < p.frames && p.has(prev) && size == p.size_of(prev)
        && (index >= p.frames || !p.has(index))
        && std::memcmp(p.buf.data() + p.offset_of(prev), bytes, size) == 0)
      return placement::duplicate;
  }
  if (index >= p.frames || size != p.size_of(index))
    return placement::misfit;
  if (p.has(index))
    return placement::duplicate;
  std::memcpy(p.buf.data() + p.offset_of(index), bytes, size);
  p.mark(index);
  ++p.received;
  p.highest = std::max(p.highest, index);
  while (p.lowest_missing < p.frames && p.has(p.lowest_missing))
    ++p.lowest_missing;
  return placement::placed;
}

} // namespace

// -- reassembler -----------------------------------------------------------------

struct reassembler::impl {
  using lane_map = std::map<lane_key, lane_state>;
  using lane_iter = lane_map::iterator;

  /// Charged for every lane holding something: its map node.
  static constexpr size_t lane_overhead
    = sizeof(lane_map::value_type) + 4 * sizeof(void*);

  reassembly_limits limits;
  reassembly_stats stats;
  lane_map lanes;
  /// One map node kept after its lane emptied, so that a lone sender does
  /// not cost a node allocation per packet.
  lane_map::node_type spare;
  /// Early fragments being moved from the stash into a new packet; reused.
  std::vector<stash_entry> early;
  size_t bytes = 0;       // everything charged, overhead included
  size_t stash_bytes = 0; // the stashed part of `bytes`
  size_t pending = 0;
  uint64_t next_order = 0;

  explicit impl(reassembly_limits lim) : limits(lim) {
  }

  // -- lanes and senders ---------------------------------------------------------

  lane_iter lane_for(lane_key key) {
    auto i = lanes.lower_bound(key);
    if (i != lanes.end() && i->first == key)
      return i;
    bytes += lane_overhead;
    if (!spare.empty()) {
      spare.key() = key;
      return lanes.insert(i, std::move(spare));
    }
    return lanes.emplace_hint(i, key, lane_state{});
  }

  void release_if_empty(lane_iter i) {
    if (!i->second.empty())
      return;
    bytes -= lane_overhead;
    if (spare.empty())
      spare = lanes.extract(i);
    else
      lanes.erase(i);
  }

  /// The lanes of sender `src`: [first, second).
  std::pair<lane_iter, lane_iter> lanes_of(link_addr src) {
    return {lanes.lower_bound(lane_key{src, 0}),
            lanes.upper_bound(lane_key{src, UINT8_MAX})};
  }

  /// What sender `src` holds, over all its lanes.
  struct usage {
    size_t overhead = 0;
    size_t packets = 0;
    size_t stash = 0;

    size_t total() const noexcept {
      return overhead + packets + stash;
    }
  };

  usage usage_of(link_addr src) const {
    usage u;
    for (auto i = lanes.lower_bound(lane_key{src, 0});
         i != lanes.end() && i->first.src == src; ++i) {
      u.overhead += lane_overhead;
      u.packets += i->second.packet_bytes;
      u.stash += i->second.stash_bytes;
    }
    return u;
  }

  // -- packets -------------------------------------------------------------------

  void drop_packet(lane_state& s, uint8_t tag) {
    auto& p = *s.packets[tag];
    s.packet_bytes -= p.charge;
    bytes -= p.charge;
    --s.packet_count;
    --pending;
    s.packets[tag].reset();
  }

  /// Evicts the oldest incomplete packet of `self`'s sender, in any of its
  /// lanes. A lane other than `self` left empty is released.
  /// @pre the sender holds a packet
  void evict_oldest_packet(lane_iter self) {
    auto [first, last] = lanes_of(self->first.src);
    auto victim = last;
    uint8_t tag = 0;
    for (auto i = first; i != last; ++i)
      for (uint8_t t = 0; t < 4; ++t)
        if (auto& p = i->second.packets[t];
            p
            && (victim == last
                || p->deadline < victim->second.packets[tag]->deadline)) {
          victim = i;
          tag = t;
        }
    assert(victim != last);
    drop_packet(victim->second, tag);
    ++stats.over_limit;
    if (victim != self)
      release_if_empty(victim);
  }

  /// Checks the CRC of a packet whose frames all arrived, delivers or drops
  /// it, and forgets it.
  result finish(lane_iter i, uint8_t tag, byte_buffer& out) {
    auto& p = *i->second.packets[tag];
    auto r = result::dropped;
    if (crc_of(p.buf.data(), p.length) == load_le<uint32_t>(p.buf.data() + p.length)) {
      p.buf.resize(p.length);
      out.swap(p.buf);
      ++stats.packets;
      r = result::complete;
    } else {
      ++stats.bad_checksum;
    }
    drop_packet(i->second, tag);
    release_if_empty(i);
    return r;
  }

  // -- stash ---------------------------------------------------------------------

  void erase_stash(lane_state& s, size_t index) {
    auto charge = s.stash[index].charge;
    s.stash.erase(s.stash.begin() + static_cast<ptrdiff_t>(index));
    s.stash_bytes -= charge;
    stash_bytes -= charge;
    bytes -= charge;
  }

  /// Moves the stashed fragments of `tag` into `early`, keeping their order.
  void take_early(lane_state& s, uint8_t tag) {
    size_t kept = 0;
    for (size_t k = 0; k < s.stash.size(); ++k) {
      auto& e = s.stash[k];
      if (e.tag == tag) {
        s.stash_bytes -= e.charge;
        stash_bytes -= e.charge;
        bytes -= e.charge;
        early.push_back(std::move(e));
      } else {
        if (kept != k) // no self-move: it would empty the entry's buffer
          s.stash[kept] = std::move(e);
        ++kept;
      }
    }
    s.stash.erase(s.stash.begin() + static_cast<ptrdiff_t>(kept), s.stash.end());
  }

  /// Evicts the stashed fragment that arrived first in [first, last). A
  /// lane other than `self` left empty is released.
  /// @pre a lane in [first, last) holds a stashed fragment
  void evict_oldest_stash(lane_iter first, lane_iter last, lane_iter self) {
    auto victim = last;
    for (auto i = first; i != last; ++i)
      if (!i->second.stash.empty()
          && (victim == last
              || i->second.stash.front().order
                   < victim->second.stash.front().order))
        victim = i;
    assert(victim != last);
    erase_stash(victim->second, 0);
    ++stats.orphans;
    if (victim != self)
      release_if_empty(victim);
  }

  // -- memory bounds -------------------------------------------------------------

  /// Whether `need` more bytes for lane `key` of its sender (`exists`: the
  /// lane holds something already) can fit once stashed fragments, and for
  /// a packet the sender's own older packets in any of its lanes, are
  /// evicted. Other senders' packets are never evicted. Decided before
  /// anything is allocated or evicted.
  bool can_make_room(lane_key key, bool exists, size_t need,
                     bool for_packet) const {
    auto own = usage_of(key.src);
    auto own_charged = own.overhead + own.packets;
    auto own_fixed = own.overhead + (exists ? 0 : lane_overhead)
                     + (for_packet ? 0 : own.packets);
    auto others_fixed = bytes - stash_bytes - own_charged;
    return need <= limits.per_sender
           && own_fixed <= limits.per_sender - need && need <= limits.total
           && others_fixed + own_fixed <= limits.total - need;
  }

  /// Makes room for `need` more bytes held by `self` (already charged for its
  /// overhead). Stashed fragments are guesses and go first, oldest first.
  /// @pre can_make_room(self->first, ..., need, for_packet) held before
  ///      `self` was created or anything was taken out of its stash
  void make_room(lane_iter self, size_t need) {
    auto src = self->first.src;
    for (;;) {
      auto own = usage_of(src);
      if (own.total() + need <= limits.per_sender)
        break;
      if (own.stash > 0) {
        auto [first, last] = lanes_of(src);
        evict_oldest_stash(first, last, self);
      } else {
        evict_oldest_packet(self);
      }
    }
    while (bytes + need > limits.total) {
      if (stash_bytes > 0)
        evict_oldest_stash(lanes.begin(), lanes.end(), self);
      else
        evict_oldest_packet(self);
    }
  }

  // -- frames --------------------------------------------------------------------

  result malformed() {
    ++stats.malformed;
    return result::dropped;
  }

  result on_single(const uint8_t* data, size_t size, byte_buffer& out) {
    if ((data[0] & 0x0f) != 0 || size - 1 > limits.max_packet)
      return malformed();
    out.assign(data + 1, data + size);
    ++stats.packets;
    return result::complete;
  }

  result on_first(lane_key key, const uint8_t* data, size_t size,
                  time_point now, byte_buffer& out) {
    if ((data[0] & 0x07) != 0)
      return malformed();
    auto tag = tag_of(data[0]);
    bool wide = (data[0] & first_wide_flag) != 0;
    auto len = decode_length(data + 1, size - 1);
    if (!len || len->value > limits.max_packet)
      return malformed();
    auto hdr = 1 + len->size;
    if (size <= hdr)
      return malformed();
    auto* body = data + hdr;
    auto first_data = size - hdr;
    auto stream = len->value + crc_size;
    if (first_data > stream)
      return malformed();
    auto i = lanes.find(key);
    if (i != lanes.end() && i->second.packets[tag]) {
      auto& old = *i->second.packets[tag];
      if (old.wide == wide && old.length == len->value
          && old.first_data == first_data
          && std::equal(body, body + first_data, old.buf.data())) {
        ++stats.duplicates;
        return result::dropped;
      }
      drop_packet(i->second, tag);
      ++stats.superseded;
    }
    if (first_data == stream) {
      // The whole stream fits the first frame: nothing to hold.
      if (i != lanes.end())
        release_if_empty(i);
      if (crc_of(body, len->value) != load_le<uint32_t>(body + len->value)) {
        ++stats.bad_checksum;
        return result::dropped;
      }
      out.assign(body, body + len->value);
      ++stats.packets;
      return result::complete;
    }
    // Every frame but the last fills the MTU, so the first frame's size is
    // the sender's MTU and fixes where each later frame goes.
    auto chunk = size - (wide ? 2 : 1);
    auto frames = 1 + (stream - first_data + chunk - 1) / chunk;
    auto need = stream + (frames + 7) / 8;
    auto* known = i != lanes.end() ? &i->second : nullptr;
    if (!can_make_room(key, known != nullptr, need, true)) {
      ++stats.over_limit;
      if (known != nullptr) {
        // Early fragments of a refused packet will never be placed.
        take_early(*known, tag);
        stats.orphans += early.size();
        early.clear();
        release_if_empty(i);
      }
      return result::dropped;
    }
    if (i == lanes.end())
      i = lane_for(key);
    auto& s = i->second;
    take_early(s, tag);
    make_room(i, need);
    auto& p = s.packets[tag].emplace();
    p.buf.resize(need); // the packet's one allocation, bitmap zeroed
    p.deadline = deadline_after(now, limits.timeout);
    p.charge = need;
    p.length = static_cast<uint32_t>(len->value);
    p.first_data = static_cast<uint32_t>(first_data);
    p.chunk = static_cast<uint32_t>(chunk);
    p.frames = static_cast<uint32_t>(frames);
    p.wide = wide;
    std::memcpy(p.buf.data(), body, first_data);
    p.mark(0);
    p.received = 1;
    p.lowest_missing = 1;
    s.packet_bytes += need;
    bytes += need;
    ++s.packet_count;
    ++pending;
    auto* hist = find_history(key);
    for (auto& e : early) {
      if (e.wide != wide) {
        ++stats.malformed;
        continue;
      }
      // A stashed fragment identical to a frame of this tag's previous
      // packet is a late copy of it, not an early fragment of this one.
      if (hist != nullptr && hist->tags[tag].contains(frame_hash(tag, e))) {
        ++stats.duplicates;
        continue;
      }
      switch (place(p, e.seq, e.bytes.data(), e.bytes.size())) {
        case placement::placed:
          break;
        case placement::duplicate:
          ++stats.duplicates;
          break;
        case placement::misfit:
          ++stats.orphans;
          break;
      }
    }
    early.clear();
    if (p.received == p.frames)
      return finish(i, tag, out);
    return result::pending;
  }

  result on_consecutive(lane_key key, const uint8_t* data, size_t size,
                        time_point now, byte_buffer& out) {
    auto h = decode_consecutive(data, size);
    if (!h)
      return malformed();
    auto [tag, wide, seq, hdr] = *h;
    auto* body = data + hdr;
    auto n = size - hdr;
    auto i = lanes.find(key);
    if (i != lanes.end() && i->second.packets[tag]) {
      auto& p = *i->second.packets[tag];
      if (p.wide != wide)
        return malformed();
      switch (place(p, seq, body, n)) {
        case placement::placed:
          if (p.received == p.frames)
            return finish(i, tag, out);
          return result::pending;
        case placement::duplicate:
          ++stats.duplicates;
          return result::dropped;
        case placement::misfit:
          break; // maybe early for the tag's next packet: stash it
      }
    }
    return stash(key, i, tag, wide, seq, body, n, now);
  }

  /// Holds a consecutive fragment that found no packet. `i` is the lane or
  /// lanes.end().
  result stash(lane_key key, lane_iter i, uint8_t tag, bool wide,
               uint16_t seq, const uint8_t* body, size_t n, time_point now) {
    if (i != lanes.end()) {
      // One entry per (tag, width, seq): the same fragment again is a
      // duplicate, a different one replaces the older (and staler) guess.
      auto& st = i->second.stash;
      for (size_t k = 0; k < st.size(); ++k) {
        auto& e = st[k];
        if (e.tag == tag && e.wide == wide && e.seq == seq) {
          if (e.bytes.size() == n
              && std::equal(body, body + n, e.bytes.data())) {
            ++stats.duplicates;
            return result::dropped;
          }
          erase_stash(i->second, k);
          ++stats.orphans;
          break;
        }
      }
    }
    auto need = sizeof(stash_entry) + n;
    if (!can_make_room(key, i != lanes.end(), need, false)) {
      ++stats.orphans;
      if (i != lanes.end())
        release_if_empty(i);
      return result::dropped;
    }
    if (i == lanes.end())
      i = lane_for(key);
    make_room(i, need);
    auto& s = i->second;
    s.stash.push_back(stash_entry{byte_buffer(body, body + n),
                                  deadline_after(now, limits.timeout), need,
                                  next_order++, seq, tag, wide});
    s.stash_bytes += need;
    stash_bytes += need;
    bytes += need;
    return result::pending;
  }

  result push(lane_key key, const uint8_t* data, size_t size, time_point now,
              byte_buffer& out) {
    if (size == 0 || data == nullptr)
      return malformed();
    auto tag = tag_of(data[0]);
    if (type_of(data[0]) == type_single) {
      if (auto* hist = find_history(key))
        hist->started(tag);
      return on_single(data, size, out);
    }
    // A copy of a frame of the tag's last completed packet, arriving when no
    // packet with that tag is in progress, is a late duplicate: taken for an
    // early fragment it would spoil the tag's next packet. A legitimately
    // repeated packet (same bytes, same tag) comes only after the sender
    // started packets with each of the three other tags, so a match counts
    // as a duplicate only until then.
    auto hash = std::hash<std::string_view>{}(
      std::string_view{reinterpret_cast<const char*>(data), size});
    auto si = lanes.find(key);
    bool in_progress = si != lanes.end() && si->second.packets[tag];
    if (auto* hist = find_history(key); hist != nullptr) {
      auto& h = hist->tags[tag];
      if (h.completed && !in_progress && !hist->moved_on(tag)
          && h.contains(hash)) {
        ++stats.duplicates;
        return result::dropped;
      }
    }
    bool first = type_of(data[0]) == type_first;
    auto res = first ? on_first(key, data, size, now, out)
                     : on_consecutive(key, data, size, now, out);
    // Remember only frames that were taken: refusing allocates nothing.
    if (res != result::dropped) {
      auto& hist = history(key);
      auto& h = hist.tags[tag];
      if (first) {
        hist.started(tag);
        h = tag_history{};
        h.first = hash;
        h.completed = res == result::complete;
      } else if (in_progress) {
        // Only frames placed into a packet belong to its history; a stashed
        // early fragment does not (yet).
        h.add(hash);
        h.completed = res == result::complete;
      }
    }
    return res;
  }

  /// The hash push() computes for the frame a stash entry came from.
  static size_t frame_hash(uint8_t tag, const stash_entry& e) {
    uint8_t hdr[2];
    auto n = encode_consecutive(tag, e.wide, e.seq, hdr);
    std::string frame(reinterpret_cast<const char*>(hdr), n);
    frame.append(reinterpret_cast<const char*>(e.bytes.data()), e.bytes.size());
    return std::hash<std::string_view>{}(frame);
  }

  /// Hashes of the frames of one tag's current or last packet: its first
  /// frame and its last 16 consecutive frames.
  struct tag_history {
    static constexpr size_t capacity = 16;
    size_t first = 0;
    std::array<size_t, capacity> tail{};
    uint8_t next = 0;
    uint8_t count = 0;
    bool completed = false;

    bool contains(size_t h) const noexcept {
      if (h == first)
        return true;
      for (size_t i = 0; i < count; ++i)
        if (tail[i] == h)
          return true;
      return false;
    }

    void add(size_t h) noexcept {
      tail[next] = h;
      next = static_cast<uint8_t>((next + 1) % capacity);
      if (count < capacity)
        ++count;
    }
  };

  struct lane_history {
    std::array<tag_history, 4> tags;
    /// Per tag: the other tags whose packets started since its last one.
    std::array<uint8_t, 4> seen_since{};

    void started(uint8_t tag) noexcept {
      for (uint8_t t = 0; t < 4; ++t)
        seen_since[t] |= static_cast<uint8_t>(1u << tag);
      seen_since[tag] = 0;
    }

    /// True once packets with every other tag started after `tag`'s last.
    bool moved_on(uint8_t tag) const noexcept {
      return (seen_since[tag] | (1u << tag)) == 0x0F;
    }
  };

  /// Bounded: forgetting every lane's history costs at most a missed
  /// duplicate, which the window and the CRC still catch.
  static constexpr size_t max_recent_lanes = 4096;

  lane_history* find_history(lane_key key) {
    if (last_hist != nullptr && last_key == key)
      return last_hist;
    auto i = recent.find(key);
    if (i == recent.end())
      return nullptr;
    last_key = key;
    return last_hist = &i->second;
  }

  lane_history& history(lane_key key) {
    if (auto* h = find_history(key))
      return *h;
    if (recent.size() >= max_recent_lanes) {
      recent.clear();
      last_hist = nullptr;
    }
    last_key = key;
    // References into an unordered_map survive rehashing.
    return *(last_hist = &recent[key]);
  }

  std::unordered_map<lane_key, lane_history, lane_key_hash> recent;
  lane_key last_key{0, 0};
  lane_history* last_hist = nullptr;

  // -- time ----------------------------------------------------------------------

  size_t expire(time_point now) {
    size_t dropped = 0;
    for (auto i = lanes.begin(); i != lanes.end();) {
      auto& s = i->second;
      for (uint8_t t = 0; t < 4; ++t) {
        if (s.packets[t] && s.packets[t]->deadline <= now) {
          drop_packet(s, t);
          ++stats.timed_out;
          ++dropped;
        }
      }
      for (size_t k = s.stash.size(); k-- > 0;) {
        if (s.stash[k].deadline <= now) {
          erase_stash(s, k);
          ++stats.orphans;
        }
      }
      auto next = std::next(i);
      release_if_empty(i);
      i = next;
    }
    return dropped;
  }

  std::optional<time_point> next_deadline() const {
    std::optional<time_point> first;
    auto consider = [&](time_point t) {
      if (!first || t < *first)
        first = t;
    };
    for (auto& [key, s] : lanes) {
      for (auto& p : s.packets)
        if (p)
          consider(p->deadline);
      for (auto& e : s.stash)
        consider(e.deadline);
    }
    return first;
  }
};

reassembler::reassembler(reassembly_limits limits)
  : impl_(std::make_unique<impl>(limits)) {
}

reassembler::~reassembler() = default;

reassembler::reassembler(reassembler&&) noexcept = default;

reassembler& reassembler::operator=(reassembler&&) noexcept = default;

reassembler::result reassembler::push(link_addr src, uint8_t lane,
                                      const uint8_t* data, size_t size,
                                      time_point now, byte_buffer& out) {
  return impl_->push(lane_key{src, lane}, data, size, now, out);
}

reassembler::result reassembler::push(link_addr src, const uint8_t* data,
                                      size_t size, time_point now,
                                      byte_buffer& out) {
  return impl_->push(lane_key{src, 0}, data, size, now, out);
}

size_t reassembler::expire(time_point now) {
  return impl_->expire(now);
}

std::optional<reassembler::time_point> reassembler::next_deadline() const {
  return impl_->next_deadline();
}

size_t reassembler::memory_in_use() const noexcept {
  return impl_->bytes;
}

size_t reassembler::pending() const noexcept {
  return impl_->pending;
}

const reassembly_stats& reassembler::stats() const noexcept {
  return impl_->stats;
}

const reassembly_limits& reassembler::limits() const noexcept {
  return impl_->limits;
}

} // namespace herm
