#include "routing/wire.hpp"

#include <algorithm>
#include <cassert>
#include <cstdio>
#include <iterator>
#include <string>
#include <tuple>
#include <type_traits>
#include <utility>

#include "channels/le_codec.hpp"
#include "routing/error.hpp"

namespace herm {

namespace {

// -- layout ----------------------------------------------------------------------

// Sizes of the fixed parts (docs/protocol.md, "Network packets").
constexpr size_t hello_size = 15;          // byte0, sender, instance, seqno, interval
constexpr size_t seqno_request_size = 8;   // byte0, sender, origin, seqno, hop_count
constexpr size_t claim_size = 20;          // byte0, id, nonce, instance, hop_limit
constexpr size_t conflict_size = 28;       // byte0, id, holder, nonce, loser, hop_limit
constexpr size_t challenge_size = 1 + challenge_nonce_size; // byte0, nonce
constexpr size_t update_head_size = 12;    // byte0, sender, instance, count
constexpr size_t entry_head_size = 4;      // origin, seqno
constexpr size_t class_metric_size = 4;    // metric
constexpr size_t min_entry_size = entry_head_size + size_classes * class_metric_size;

/// Offset of the hop limit in a data header, and the flags' reserved bits.
constexpr size_t data_hop_limit_offset = 5;
constexpr size_t data_flags_offset = 6;
constexpr uint8_t data_reserved_flags = 0xC0;
constexpr uint8_t data_auth_flag = 0x20;
constexpr uint8_t data_flood_flag = 0x10;

/// Largest link_code value on the wire.
constexpr uint8_t max_link_code = static_cast<uint8_t>(link_code::rs232c);

constexpr uint8_t first_byte(packet_type t) {
  return static_cast<uint8_t>(wire_version << 4 | static_cast<uint8_t>(t));
}

/// Type names for errors, by type value.
constexpr const char* type_names[] = {
  "data",  "hello",    "update",            "seqno_request",
  "claim", "conflict", "challenge_request", "challenge_reply",
};

const char* name_of(packet_type t) {
  auto i = static_cast<size_t>(t);
  return i < std::size(type_names) ? type_names[i] : "?";
}

constexpr bool known_type(uint8_t t) {
  return t < std::size(type_names);
}
static_assert(!known_type(static_cast<uint8_t>(packet_type::challenge_reply)
                          + 1)
              && known_type(static_cast<uint8_t>(packet_type::challenge_reply)));

std::string num(size_t x) {
  return std::to_string(x);
}

std::string hex(uint8_t x) {
  char buf[8];
  std::snprintf(buf, sizeof(buf), "0x%02X", x);
  return buf;
}

caf::error bad(packet_type t, const std::string& what) {
  return make_error(ec::invalid_parameter, std::string{name_of(t)} + ": " + what);
}

/// Checks the first byte of a packet that must be of type `t`.
caf::error check_head(packet_type t, const uint8_t* data, size_t size) {
  if (size == 0 || data == nullptr)
    return bad(t, "empty packet");
  auto version = data[0] >> 4;
  if (version != wire_version)
    return bad(t, "version " + num(version) + ", expected "
                    + num(wire_version));
  auto type = static_cast<uint8_t>(data[0] & 0x0F);
  if (type != static_cast<uint8_t>(t))
    return bad(t, "packet of type " + num(type)
                    + (known_type(type)
                         ? std::string{" ("} + name_of(packet_type{type}) + ")"
                         : std::string{" (unknown)"}));
  return caf::none;
}

/// check_head, then that a variable-size packet holds its `head_size`-byte
/// header.
caf::error check_header(packet_type t, const uint8_t* data, size_t size,
                        size_t head_size) {
  if (auto err = check_head(t, data, size))
    return err;
  if (size < head_size)
    return bad(t, "truncated header: " + num(size) + " of " + num(head_size)
                    + " bytes");
  return caf::none;
}

/// Checks that a fixed-size packet has exactly `expected` bytes.
caf::error check_exact(packet_type t, size_t size, size_t expected) {
  if (size < expected)
    return bad(t, "truncated: " + num(size) + " of " + num(expected)
                    + " bytes");
  if (size > expected)
    return bad(t, num(size - expected) + " trailing bytes");
  return caf::none;
}

// -- fixed-size packets -----------------------------------------------------------

// One field of a fixed-size packet: an unsigned integer or a nonce.

template <class T>
void put(le_writer& w, T x) {
  w.le(x);
}

void put(le_writer& w, const challenge_nonce& x) {
  w.bytes(x);
}

template <class T>
void get(le_reader& r, T& x) {
  x = r.le<T>();
}

void get(le_reader& r, challenge_nonce& x) {
  r.bytes(x);
}

template <class T>
constexpr size_t wire_size = sizeof(T);
template <>
constexpr size_t wire_size<challenge_nonce> = challenge_nonce_size;

/// The layout of each fixed-size packet: its type, then its fields in wire
/// order after the first byte. One table serves encode, decode and size.
template <class T>
constexpr auto layout = nullptr;
template <>
constexpr auto layout<hello>
  = std::make_tuple(packet_type::hello, &hello::sender, &hello::instance,
                    &hello::seqno, &hello::interval_ms);
template <>
constexpr auto layout<seqno_request>
  = std::make_tuple(packet_type::seqno_request, &seqno_request::sender,
                    &seqno_request::origin, &seqno_request::seqno,
                    &seqno_request::hop_count);
template <>
constexpr auto layout<claim>
  = std::make_tuple(packet_type::claim, &claim::id, &claim::nonce,
                    &claim::instance, &claim::hop_limit);
template <>
constexpr auto layout<conflict>
  = std::make_tuple(packet_type::conflict, &conflict::id,
                    &conflict::holder_instance, &conflict::claim_nonce,
                    &conflict::loser_instance, &conflict::hop_limit);
template <>
constexpr auto layout<challenge_request>
  = std::make_tuple(packet_type::challenge_request, &challenge_request::nonce);
template <>
constexpr auto layout<challenge_reply>
  = std::make_tuple(packet_type::challenge_reply, &challenge_reply::nonce);

/// Bytes of a fixed-size packet, first byte included.
template <class T>
constexpr size_t fixed_size() {
  return std::apply(
    [](packet_type, auto... field) {
      return (size_t{1} + ... + wire_size<std::remove_reference_t<
                                  decltype(std::declval<T&>().*field)>>);
    },
    layout<T>);
}

static_assert(fixed_size<hello>() == hello_size);
static_assert(fixed_size<seqno_request>() == seqno_request_size);
static_assert(fixed_size<claim>() == claim_size);
static_assert(fixed_size<conflict>() == conflict_size);
static_assert(fixed_size<challenge_request>() == challenge_size);
static_assert(fixed_size<challenge_reply>() == challenge_size);

template <class T>
void encode_fixed(const T& x, byte_buffer& out) {
  le_writer w{out};
  std::apply(
    [&](packet_type t, auto... field) {
      w.u8(first_byte(t));
      (put(w, x.*field), ...);
    },
    layout<T>);
}

template <class T>
caf::expected<T> decode_fixed(const uint8_t* data, size_t size) {
  constexpr auto t = std::get<0>(layout<T>);
  if (auto err = check_head(t, data, size))
    return err;
  if (auto err = check_exact(t, size, fixed_size<T>()))
    return err;
  le_reader r{data, size, 1};
  T x;
  std::apply([&](packet_type, auto... field) { (get(r, x.*field), ...); },
             layout<T>);
  return x;
}

/// Whether class `k` of `x` can be sent as it is. A class that cannot is
/// sent as a retraction, which is always safe for loop freedom.
bool class_encodable(const advertised& x, size_t k) {
  if (x.metrics[k] == infinite_metric)
    return false;
  if (x.hops[k] > max_route_hops || x.path[k].size() != x.hops[k])
    return false;
  for (auto c : x.path[k])
    if (static_cast<uint8_t>(c) > max_link_code)
      return false;
  return true;
}

} // namespace

// -- type ------------------------------------------------------------------------

caf::expected<packet_type> peek_type(const uint8_t* data, size_t size) {
  if (size == 0 || data == nullptr)
    return make_error(ec::invalid_parameter, "packet: empty");
  auto version = data[0] >> 4;
  if (version != wire_version)
    return make_error(ec::invalid_parameter,
                      "packet: version " + num(version) + ", expected "
                        + num(wire_version));
  auto type = static_cast<uint8_t>(data[0] & 0x0F);
  if (!known_type(type))
    return make_error(ec::invalid_parameter,
                      "packet: unknown type " + num(type));
  return packet_type{type};
}

// -- data ------------------------------------------------------------------------

void encode(const data_header& h, byte_buffer& out) {
  assert(h.size_class < size_classes && h.priority <= 3);
  assert(h.flood_id == 0 || h.dst == broadcast_module);
  le_writer w{out};
  w.u8(first_byte(packet_type::data));
  w.u16(h.src);
  w.u16(h.dst);
  w.u8(h.hop_limit);
  w.u8(static_cast<uint8_t>((h.size_class & 0x03) | (h.priority & 0x03) << 2
                            | (h.flood_id != 0 ? data_flood_flag : 0)
                            | (h.authenticated ? data_auth_flag : 0)));
  w.u8(h.protocol);
  if (h.flood_id != 0)
    w.u32(h.flood_id);
}

caf::expected<data_header> decode_data_header(const uint8_t* data,
                                              size_t size) {
  constexpr auto t = packet_type::data;
  if (auto err = check_header(t, data, size, data_header_size))
    return err;
  le_reader r{data, size, 1};
  data_header h;
  h.src = r.u16();
  h.dst = r.u16();
  h.hop_limit = r.u8();
  auto flags = r.u8();
  if ((flags & data_reserved_flags) != 0)
    return bad(t, "reserved flag bits set (flags " + hex(flags) + ")");
  h.size_class = static_cast<uint8_t>(flags & 0x03);
  h.priority = static_cast<uint8_t>(flags >> 2 & 0x03);
  h.protocol = r.u8();
  h.authenticated = (flags & data_auth_flag) != 0;
  if ((flags & data_flood_flag) != 0) {
    if (size < flood_header_size)
      return bad(t, "truncated header: " + num(size) + " of "
                      + num(flood_header_size) + " bytes (flood id)");
    if (h.dst != broadcast_module)
      return bad(t, "flood id on a packet to " + to_hex(h.dst));
    h.flood_id = r.u32();
    if (h.flood_id == 0)
      return bad(t, "flood id 0");
  }
  return h;
}

void set_hop_limit(uint8_t* packet, uint8_t hop_limit) {
  packet[data_hop_limit_offset] = hop_limit;
}

void set_authenticated(uint8_t* packet, bool on) {
  if (on)
    packet[data_flags_offset] |= data_auth_flag;
  else
    packet[data_flags_offset] &= static_cast<uint8_t>(~data_auth_flag);
}

// -- fixed-size packets ------------------------------------------------------------

// Each fixed-size packet's encode() and decode_<packet>(), as wire.hpp
// declares them: one definition per packet, through the templates above.
#define HERM_FIXED_PACKET(T)                                                   \
  void encode(const T& x, byte_buffer& out) {                                  \
    encode_fixed(x, out);                                                      \
  }                                                                            \
  caf::expected<T> decode_##T(const uint8_t* data, size_t size) {              \
    return decode_fixed<T>(data, size);                                        \
  }

HERM_FIXED_PACKET(hello)
HERM_FIXED_PACKET(seqno_request)
HERM_FIXED_PACKET(claim)
HERM_FIXED_PACKET(conflict)
HERM_FIXED_PACKET(challenge_request)
HERM_FIXED_PACKET(challenge_reply)

#undef HERM_FIXED_PACKET

// -- update ----------------------------------------------------------------------

void encode(const update& x, byte_buffer& out) {
  le_writer w{out};
  w.u8(first_byte(packet_type::update));
  w.u16(x.sender);
  w.u64(x.instance);
  w.u8_counted(x.entries, max_update_entries, [&w](const advertised& e) {
    w.u16(e.origin);
    w.u16(e.seqno);
    for (size_t k = 0; k < size_classes; ++k) {
      if (!class_encodable(e, k)) {
        w.u32(infinite_metric);
        continue;
      }
      w.u32(e.metrics[k]);
      w.u8(e.hops[k]);
      for (auto c : e.path[k])
        w.u8(static_cast<uint8_t>(c));
    }
  });
}

caf::expected<update> decode_update(const uint8_t* data, size_t size) {
  constexpr auto t = packet_type::update;
  if (auto err = check_header(t, data, size, update_head_size))
    return err;
  le_reader r{data, size, 1};
  update x;
  x.sender = r.u16();
  x.instance = r.u64();
  size_t count = r.u8();
  if (auto why = counted_list_problem(count, max_update_entries,
                                      min_entry_size, r.left());
      !why.empty())
    return bad(t, why);
  x.entries.resize(count);
  for (size_t i = 0; i < count; ++i) {
    auto where = [&] { return "entry " + num(i + 1) + " of " + num(count); };
    auto& e = x.entries[i];
    if (r.left() < entry_head_size)
      return bad(t, where() + " truncated");
    e.origin = r.u16();
    e.seqno = r.u16();
    for (size_t k = 0; k < size_classes; ++k) {
      auto in_class = [&] { return where() + ", class " + num(k); };
      if (r.left() < class_metric_size)
        return bad(t, where() + " truncated");
      e.metrics[k] = r.u32();
      e.hops[k] = 0;
      if (e.metrics[k] == infinite_metric)
        continue;
      if (r.left() < 1)
        return bad(t, where() + " truncated");
      auto hops = r.u8();
      if (hops > max_route_hops)
        return bad(t, in_class() + ": " + num(hops) + " hops, at most "
                        + num(max_route_hops));
      if (r.left() < hops)
        return bad(t, where() + " truncated");
      e.hops[k] = hops;
      e.path[k].reserve(hops);
      for (size_t h = 0; h < hops; ++h) {
        auto c = r.u8();
        if (c > max_link_code)
          return bad(t, in_class() + ": unknown link code " + num(c)
                          + " at hop " + num(h + 1));
        e.path[k].push_back(static_cast<link_code>(c));
      }
    }
  }
  if (r.left() != 0)
    return bad(t, num(r.left()) + " trailing bytes");
  return x;
}

} // namespace herm
