// Wire formats of the Network Adaptation Layer: exact layouts (the tables of
// docs/protocol.md, "Network packets"), round trips, and decoders that are
// total on any byte string.

#include <gtest/gtest.h>

#include <chrono>
#include <functional>
#include <iostream>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "actors/runtime/error.hpp"
#include "routing/wire.hpp"

using namespace herm;

namespace {

// -- helpers ---------------------------------------------------------------------

byte_buffer bytes(std::initializer_list<int> xs) {
  byte_buffer out;
  for (auto x : xs)
    out.push_back(static_cast<uint8_t>(x));
  return out;
}

template <class T>
byte_buffer enc(const T& x) {
  byte_buffer out;
  encode(x, out);
  return out;
}

/// The context string of a decoder's error ("hello: 3 trailing bytes").
template <class T>
std::string error_of(const caf::expected<T>& x) {
  if (x)
    return "(decoded)";
  EXPECT_TRUE(is(x.error(), ec::invalid_parameter)) << render(x.error());
  auto text = render(x.error());
  auto prefix = std::string{"herm.invalid_parameter: "};
  return text.compare(0, prefix.size(), prefix) == 0 ? text.substr(prefix.size())
                                                     : text;
}

void expect_same(const data_header& x, const data_header& y) {
  EXPECT_EQ(x.src, y.src);
  EXPECT_EQ(x.dst, y.dst);
  EXPECT_EQ(x.hop_limit, y.hop_limit);
  EXPECT_EQ(x.size_class, y.size_class);
  EXPECT_EQ(x.priority, y.priority);
  EXPECT_EQ(x.protocol, y.protocol);
}

void expect_same(const hello& x, const hello& y) {
  EXPECT_EQ(x.sender, y.sender);
  EXPECT_EQ(x.instance, y.instance);
  EXPECT_EQ(x.seqno, y.seqno);
  EXPECT_EQ(x.interval_ms, y.interval_ms);
}

void expect_same(const advertised& x, const advertised& y) {
  EXPECT_EQ(x.origin, y.origin);
  EXPECT_EQ(x.seqno, y.seqno);
  EXPECT_EQ(x.metrics, y.metrics);
  EXPECT_EQ(x.hops, y.hops);
  EXPECT_EQ(x.path, y.path);
}

void expect_same(const update& x, const update& y) {
  EXPECT_EQ(x.sender, y.sender);
  EXPECT_EQ(x.instance, y.instance);
  ASSERT_EQ(x.entries.size(), y.entries.size());
  for (size_t i = 0; i < x.entries.size(); ++i) {
    SCOPED_TRACE("entry " + std::to_string(i));
    expect_same(x.entries[i], y.entries[i]);
  }
}

void expect_same(const seqno_request& x, const seqno_request& y) {
  EXPECT_EQ(x.sender, y.sender);
  EXPECT_EQ(x.origin, y.origin);
  EXPECT_EQ(x.seqno, y.seqno);
  EXPECT_EQ(x.hop_count, y.hop_count);
}

void expect_same(const claim& x, const claim& y) {
  EXPECT_EQ(x.id, y.id);
  EXPECT_EQ(x.nonce, y.nonce);
  EXPECT_EQ(x.instance, y.instance);
  EXPECT_EQ(x.hop_limit, y.hop_limit);
}

void expect_same(const challenge_request& x, const challenge_request& y) {
  EXPECT_EQ(x.nonce, y.nonce);
}

void expect_same(const challenge_reply& x, const challenge_reply& y) {
  EXPECT_EQ(x.nonce, y.nonce);
}

void expect_same(const conflict& x, const conflict& y) {
  EXPECT_EQ(x.id, y.id);
  EXPECT_EQ(x.holder_instance, y.holder_instance);
  EXPECT_EQ(x.claim_nonce, y.claim_nonce);
  EXPECT_EQ(x.loser_instance, y.loser_instance);
  EXPECT_EQ(x.hop_limit, y.hop_limit);
}

/// A destination reachable in every class over `hops` links of `kind`.
advertised reachable(module_id origin, seqno_t seqno, uint8_t hops,
                     link_code kind = link_code::can20) {
  advertised a;
  a.origin = origin;
  a.seqno = seqno;
  for (size_t k = 0; k < size_classes; ++k) {
    a.metrics[k] = static_cast<metric>(10 * (k + 1) * (hops + 1));
    a.hops[k] = hops;
    a.path[k].assign(hops, kind);
  }
  return a;
}

/// The largest update: max_update_entries entries, 32-hop paths in every
/// class, every link code, extreme metrics.
update largest_update() {
  update u{0xFFFE, 0xFFFFFFFFFFFFFFFF, {}};
  for (size_t i = 0; i < max_update_entries; ++i) {
    advertised a;
    a.origin = static_cast<module_id>(0xFFFE - i);
    a.seqno = static_cast<seqno_t>(0xFFFF - i);
    for (size_t k = 0; k < size_classes; ++k) {
      a.metrics[k] = infinite_metric - 1 - static_cast<metric>(k);
      a.hops[k] = max_route_hops;
      for (size_t h = 0; h < max_route_hops; ++h)
        a.path[k].push_back(static_cast<link_code>((h + k + i) % 8));
    }
    u.entries.push_back(std::move(a));
  }
  return u;
}

/// One decoder seen through bytes: decodes, and on success re-encodes what
/// it decoded (for data packets: the header, followed by the payload).
struct codec {
  const char* name;
  packet_type type;
  std::function<bool(const byte_buffer&, byte_buffer&)> decode_encode;
};

template <class Decode>
codec make_codec(const char* name, packet_type type, Decode decode) {
  return {name, type, [decode](const byte_buffer& in, byte_buffer& out) {
            auto x = decode(in.data(), in.size());
            if (!x)
              return false;
            out.clear();
            encode(*x, out);
            return true;
          }};
}

const std::vector<codec>& codecs() {
  static const std::vector<codec> all{
    {"data", packet_type::data,
     [](const byte_buffer& in, byte_buffer& out) {
       auto h = decode_data_header(in.data(), in.size());
       if (!h)
         return false;
       out.clear();
       encode(*h, out);
       out.insert(out.end(), in.begin() + header_size(*h), in.end());
       return true;
     }},
    make_codec("hello", packet_type::hello, decode_hello),
    make_codec("update", packet_type::update, decode_update),
    make_codec("seqno_request", packet_type::seqno_request,
                              decode_seqno_request),
    make_codec("claim", packet_type::claim, decode_claim),
    make_codec("conflict", packet_type::conflict, decode_conflict),
    make_codec("challenge_request", packet_type::challenge_request,
               decode_challenge_request),
    make_codec("challenge_reply", packet_type::challenge_reply,
               decode_challenge_reply),
  };
  return all;
}

/// Valid packets of every type, small and large: the seeds of the
/// truncation, trailing-byte and mutation tests.
struct sample {
  std::string name;
  packet_type type;
  byte_buffer bytes;
};

std::vector<sample> samples() {
  std::vector<sample> out;
  auto add = [&](std::string name, packet_type t, byte_buffer b) {
    out.push_back({std::move(name), t, std::move(b)});
  };
  add("data header", packet_type::data,
      enc(data_header{0x4E, 0x42, 32, 2, 1, 1}));
  {
    auto b = enc(data_header{0x0100, 0xFFFF, 1, 3, 3, 255});
    for (int i = 0; i < 20; ++i)
      b.push_back(static_cast<uint8_t>(i));
    add("data with payload", packet_type::data, std::move(b));
  }
  add("hello", packet_type::hello, enc(hello{0x4E, 0x0123456789ABCDEF, 7, 1000}));
  add("empty update", packet_type::update, enc(update{0x42, 99, {}}));
  {
    update u{0x42, 99, {}};
    u.entries.push_back(reachable(0x4E, 3, 0));
    u.entries.push_back(reachable(0x50, 4, 2, link_code::ethernet));
    advertised gone;
    gone.origin = 0x51;
    gone.seqno = 9;
    u.entries.push_back(gone);
    add("update", packet_type::update, enc(u));
  }
  add("largest update", packet_type::update, enc(largest_update()));
  add("seqno_request", packet_type::seqno_request,
      enc(seqno_request{0x42, 0x4E, 0x8000, 5}));
  add("claim", packet_type::claim,
      enc(claim{0x1234, 0xDEADBEEFCAFEF00D, 0x1122334455667788, 32}));
  add("conflict", packet_type::conflict,
      enc(conflict{0x1234, 0xA, 0xB, 0xC, 31}));
  add("challenge_request", packet_type::challenge_request,
      enc(challenge_request{{9, 8, 7, 6, 5, 4, 3, 2}}));
  add("challenge_reply", packet_type::challenge_reply,
      enc(challenge_reply{{0xFF, 0, 0xFF, 0, 1, 2, 3, 4}}));
  return out;
}

} // namespace

// -- first byte ------------------------------------------------------------------

TEST(wire_type, peek_type_reads_version_1_and_the_eight_types) {
  struct row {
    int byte0;
    std::optional<packet_type> expected;
  };
  const row rows[] = {
    {0x10, packet_type::data},          {0x11, packet_type::hello},
    {0x12, packet_type::update},        {0x13, packet_type::seqno_request},
    {0x14, packet_type::claim},         {0x15, packet_type::conflict},
    {0x16, packet_type::challenge_request},
    {0x17, packet_type::challenge_reply},
    {0x18, std::nullopt},               {0x1F, std::nullopt},
    {0x00, std::nullopt},               {0x01, std::nullopt},
    {0x20, std::nullopt},               {0x21, std::nullopt},
    {0xF1, std::nullopt},               {0xFF, std::nullopt},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.byte0);
    auto b = bytes({r.byte0, 0, 0});
    auto t = peek_type(b.data(), b.size());
    if (r.expected) {
      ASSERT_TRUE(t) << render(t.error());
      EXPECT_EQ(*t, *r.expected);
    } else {
      EXPECT_FALSE(t);
    }
  }
  EXPECT_EQ(error_of(peek_type(nullptr, 0)), "packet: empty");
  auto v2 = bytes({0x21});
  EXPECT_EQ(error_of(peek_type(v2.data(), v2.size())),
            "packet: version 2, expected 1");
  auto t9 = bytes({0x19});
  EXPECT_EQ(error_of(peek_type(t9.data(), t9.size())), "packet: unknown type 9");
}

// -- exact layouts (the tables of the protocol document) ------------------------

TEST(wire_layout, data_header_is_eight_bytes_little_endian_with_packed_flags) {
  data_header h{0x004E, 0x1042, 17, 2, 3, 1};
  EXPECT_EQ(enc(h), bytes({0x10, 0x4E, 0x00, 0x42, 0x10, 17, 0x0E, 0x01}));
  EXPECT_EQ(data_header_size, 8u);
  // flags: size_class in bits 1..0, priority in bits 3..2.
  EXPECT_EQ(enc(data_header{1, 2, 3, 1, 0, 0})[6], 0x01);
  EXPECT_EQ(enc(data_header{1, 2, 3, 0, 1, 0})[6], 0x04);
  EXPECT_EQ(enc(data_header{1, 2, 3, 3, 3, 0})[6], 0x0F);
}

TEST(wire_layout, a_flooded_broadcast_carries_a_flood_id_after_flag_bit_4) {
  data_header h{0x004E, broadcast_module, 32, 0, 2, 1};
  h.flood_id = 0x01020304;
  EXPECT_EQ(enc(h), bytes({0x10, 0x4E, 0x00, 0xFF, 0xFF, 32, 0x18, 0x01,
                           0x04, 0x03, 0x02, 0x01}));
  EXPECT_EQ(header_size(h), 12u);
  auto b = enc(h);
  auto d = decode_data_header(b.data(), b.size());
  ASSERT_TRUE(d);
  EXPECT_EQ(d->flood_id, 0x01020304u);
  EXPECT_EQ(header_size(*d), 12u);
  // Without the flag a broadcast is link-local and has no flood id.
  auto local = enc(data_header{0x4E, broadcast_module, 1, 0, 2, 1});
  EXPECT_EQ(local.size(), 8u);
  EXPECT_EQ(decode_data_header(local.data(), local.size())->flood_id, 0u);
}

TEST(wire_malformed, flood_ids_are_checked) {
  data_header h{0x004E, broadcast_module, 32, 0, 2, 1};
  h.flood_id = 7;
  auto b = enc(h);
  for (size_t n = 8; n < 12; ++n)
    EXPECT_NE(error_of(decode_data_header(b.data(), n)).find("(flood id)"),
              std::string::npos) << n;
  auto unicast = b;
  unicast[3] = 0x42;
  unicast[4] = 0x00;
  EXPECT_EQ(error_of(decode_data_header(unicast.data(), unicast.size())),
            "data: flood id on a packet to 0x42");
  auto zero = b;
  zero[8] = 0;
  EXPECT_EQ(error_of(decode_data_header(zero.data(), zero.size())),
            "data: flood id 0");
}

TEST(wire_layout, encoders_append_to_what_the_buffer_holds) {
  byte_buffer out{0xAA};
  encode(hello{1, 2, 3, 4}, out);
  ASSERT_EQ(out.size(), 16u);
  EXPECT_EQ(out[0], 0xAA);
  EXPECT_EQ(out[1], 0x11);
}

TEST(wire_layout, hello_is_fifteen_bytes) {
  EXPECT_EQ(enc(hello{0x4E, 0x0807060504030201, 0xABCD, 1000}),
            bytes({0x11, 0x4E, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07,
                   0x08, 0xCD, 0xAB, 0xE8, 0x03}));
}

TEST(wire_layout, update_sends_hops_and_path_only_for_reachable_classes) {
  update u{0x0042, 0x0807060504030201, {}};
  advertised a;
  a.origin = 0x004E;
  a.seqno = 0x0102;
  a.metrics = {8, 30, infinite_metric, 0x01020304};
  a.hops = {1, 2, 0, 0};
  a.path[0] = {link_code::can20};
  a.path[1] = {link_code::ethernet, link_code::usb20};
  u.entries.push_back(a);
  EXPECT_EQ(enc(u), bytes({
                      0x12, 0x42, 0x00,                               // type, sender
                      0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, // instance
                      0x01,                                           // count
                      0x4E, 0x00, 0x02, 0x01,                         // origin, seqno
                      0x08, 0x00, 0x00, 0x00, 0x01, 0x05,             // class 0
                      0x1E, 0x00, 0x00, 0x00, 0x02, 0x06, 0x02,       // class 1
                      0xFF, 0xFF, 0xFF, 0xFF,                         // class 2
                      0x04, 0x03, 0x02, 0x01, 0x00,                   // class 3
                    }));
}

TEST(wire_layout, seqno_request_is_eight_bytes) {
  EXPECT_EQ(enc(seqno_request{0x0042, 0x004E, 0xFFFE, 7}),
            bytes({0x13, 0x42, 0x00, 0x4E, 0x00, 0xFE, 0xFF, 0x07}));
}

TEST(wire_layout, claim_is_twenty_bytes) {
  EXPECT_EQ(enc(claim{0x1234, 0x1111111111111111, 0x0807060504030201, 32}),
            bytes({0x14, 0x34, 0x12, 0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x11,
                   0x11, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x20}));
}

TEST(wire_layout, conflict_is_twenty_eight_bytes) {
  EXPECT_EQ(enc(conflict{0x1234, 0xA1, 0xB2, 0xC3, 9}),
            bytes({0x15, 0x34, 0x12,                                // type, id
                   0xA1, 0, 0, 0, 0, 0, 0, 0,                       // holder
                   0xB2, 0, 0, 0, 0, 0, 0, 0,                       // nonce
                   0xC3, 0, 0, 0, 0, 0, 0, 0,                       // loser
                   0x09}));
}

TEST(wire_layout, challenge_request_and_reply_are_nine_bytes) {
  // The examples of docs/protocol.md, "Authentication".
  challenge_nonce n{0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08};
  EXPECT_EQ(enc(challenge_request{n}),
            bytes({0x16, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08}));
  EXPECT_EQ(enc(challenge_reply{n}),
            bytes({0x17, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08}));
  EXPECT_EQ(challenge_nonce_size, 8u);
}

TEST(wire_layout, the_largest_update_with_32_hop_paths_takes_3660_bytes) {
  // 12 header bytes + 24 entries * (4 + 4 * (4 + 1 + 32)).
  EXPECT_EQ(enc(largest_update()).size(), 3660u);
  // With direct routes (hops 1) in every class an update fits a 1,024-byte
  // class-2 packet: 12 + 24 * (4 + 4 * 6) = 684.
  update u;
  for (size_t i = 0; i < max_update_entries; ++i)
    u.entries.push_back(reachable(static_cast<module_id>(0x100 + i), 1, 1));
  EXPECT_EQ(enc(u).size(), 684u);
}

// -- round trips -----------------------------------------------------------------

TEST(wire_round_trip, data_headers_survive_every_flag_value_and_extreme_ids) {
  for (uint8_t k = 0; k < size_classes; ++k)
    for (uint8_t p = 0; p < 4; ++p)
      for (auto h : {data_header{0, 0, 0, 0, 0, 0},
                     data_header{0xFFFF, 0xFFFF, 255, 0, 0, 255},
                     data_header{0x4E, 0x42, default_hop_limit, 0, 0, 1}}) {
        h.size_class = k;
        h.priority = p;
        auto b = enc(h);
        b.push_back(0x99); // a payload byte: allowed after the header
        auto d = decode_data_header(b.data(), b.size());
        ASSERT_TRUE(d) << render(d.error());
        expect_same(*d, h);
      }
}

TEST(wire_round_trip, hellos_survive_boundary_values) {
  for (auto x : {hello{0, 0, 0, 0}, hello{0xFFFF, ~uint64_t{0}, 0xFFFF, 0xFFFF},
                 hello{0x4E, 0x8000000000000000, 0x8000, 250}}) {
    auto b = enc(x);
    auto d = decode_hello(b.data(), b.size());
    ASSERT_TRUE(d) << render(d.error());
    expect_same(*d, x);
  }
}

TEST(wire_round_trip, the_largest_update_survives_with_every_link_code) {
  auto u = largest_update();
  auto b = enc(u);
  auto d = decode_update(b.data(), b.size());
  ASSERT_TRUE(d) << render(d.error());
  expect_same(*d, u);
}

TEST(wire_round_trip, updates_survive_retractions_self_routes_and_mixed_classes) {
  update u{0x0100, 1, {}};
  u.entries.push_back(reachable(0x0100, 0, 0)); // the sender itself, metric 10..40
  advertised zero = reachable(0x0101, 0xFFFF, 0);
  zero.metrics = {0, 0, 0, 0};
  u.entries.push_back(zero);
  advertised gone; // retracted in every class
  gone.origin = 0x0102;
  gone.seqno = 0x8000;
  u.entries.push_back(gone);
  advertised mixed = reachable(0x0103, 5, 3, link_code::rs232c);
  mixed.metrics[1] = infinite_metric;
  mixed.hops[1] = 0;
  mixed.path[1].clear();
  mixed.metrics[3] = infinite_metric - 1; // the largest finite metric
  u.entries.push_back(mixed);
  advertised far = reachable(0xFFFE, 1, max_route_hops, link_code::unknown);
  u.entries.push_back(far);
  auto b = enc(u);
  auto d = decode_update(b.data(), b.size());
  ASSERT_TRUE(d) << render(d.error());
  expect_same(*d, u);
  // And an update without entries.
  update none{0xFFFE, ~uint64_t{0}, {}};
  b = enc(none);
  EXPECT_EQ(b.size(), 12u);
  d = decode_update(b.data(), b.size());
  ASSERT_TRUE(d) << render(d.error());
  expect_same(*d, none);
}

TEST(wire_round_trip, seqno_requests_claims_and_conflicts_survive_boundary_values) {
  for (auto x : {seqno_request{0, 0, 0, 0},
                 seqno_request{0xFFFF, 0xFFFF, 0xFFFF, 0xFF}}) {
    auto b = enc(x);
    auto d = decode_seqno_request(b.data(), b.size());
    ASSERT_TRUE(d) << render(d.error());
    expect_same(*d, x);
  }
  for (auto x : {claim{0, 0, 0, 0}, claim{0xFFFF, ~uint64_t{0}, ~uint64_t{0}, 255},
                 claim{first_dynamic_module, 1, 2, default_hop_limit}}) {
    auto b = enc(x);
    auto d = decode_claim(b.data(), b.size());
    ASSERT_TRUE(d) << render(d.error());
    expect_same(*d, x);
  }
  for (auto x : {conflict{0, 0, 0, 0, 0},
                 conflict{0xFFFF, ~uint64_t{0}, ~uint64_t{0}, ~uint64_t{0}, 255},
                 conflict{last_dynamic_module, 1, 0, 2, default_hop_limit}}) {
    auto b = enc(x);
    auto d = decode_conflict(b.data(), b.size());
    ASSERT_TRUE(d) << render(d.error());
    expect_same(*d, x);
  }
}

TEST(wire_round_trip, challenges_survive_every_nonce_byte) {
  for (int v : {0x00, 0x01, 0x7F, 0x80, 0xFF}) {
    challenge_nonce n;
    n.fill(static_cast<uint8_t>(v));
    n[3] = static_cast<uint8_t>(~v);
    auto b = enc(challenge_request{n});
    auto d = decode_challenge_request(b.data(), b.size());
    ASSERT_TRUE(d) << render(d.error());
    expect_same(*d, challenge_request{n});
    b = enc(challenge_reply{n});
    auto r = decode_challenge_reply(b.data(), b.size());
    ASSERT_TRUE(r) << render(r.error());
    expect_same(*r, challenge_reply{n});
  }
}

// -- what the update encoder refuses to send --------------------------------------

TEST(wire_update_encoder, sends_a_class_it_cannot_describe_as_a_retraction) {
  // Retraction is always safe for loop freedom; a malformed route is not.
  struct row {
    const char* why;
    std::function<void(advertised&)> spoil;
  };
  const row rows[] = {
    {"infinite metric with hops and path",
     [](advertised& a) { a.metrics[2] = infinite_metric; }},
    {"path shorter than hops", [](advertised& a) { a.path[2].pop_back(); }},
    {"path longer than hops",
     [](advertised& a) { a.path[2].push_back(link_code::can20); }},
    {"more than max_route_hops",
     [](advertised& a) {
       a.hops[2] = max_route_hops + 1;
       a.path[2].assign(max_route_hops + 1, link_code::can20);
     }},
    {"unknown link code",
     [](advertised& a) { a.path[2][1] = static_cast<link_code>(8); }},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.why);
    auto good = reachable(0x4E, 1, 3);
    auto bad = good;
    r.spoil(bad);
    auto b = enc(update{1, 2, {bad}});
    auto d = decode_update(b.data(), b.size());
    ASSERT_TRUE(d) << render(d.error());
    auto expected = good;
    expected.metrics[2] = infinite_metric;
    expected.hops[2] = 0;
    expected.path[2].clear();
    expect_same(d->entries.at(0), expected);
  }
}

// -- malformed packets ------------------------------------------------------------

TEST(wire_malformed, every_truncation_of_every_packet_is_rejected) {
  for (auto& s : samples()) {
    SCOPED_TRACE(s.name);
    auto& c = codecs()[static_cast<size_t>(s.type)];
    byte_buffer out;
    ASSERT_TRUE(c.decode_encode(s.bytes, out));
    EXPECT_EQ(out, s.bytes);
    // A data packet is a header and any payload: shorter than the header is
    // truncated. Every other packet has one exact length.
    auto shortest = s.type == packet_type::data ? data_header_size
                                                : s.bytes.size();
    for (size_t n = 0; n < shortest; ++n) {
      SCOPED_TRACE(n);
      byte_buffer cut(s.bytes.begin(), s.bytes.begin() + static_cast<ptrdiff_t>(n));
      EXPECT_FALSE(c.decode_encode(cut, out));
    }
  }
}

TEST(wire_malformed, trailing_bytes_are_rejected) {
  for (auto& s : samples()) {
    if (s.type == packet_type::data)
      continue; // the payload follows the header
    SCOPED_TRACE(s.name);
    auto& c = codecs()[static_cast<size_t>(s.type)];
    for (size_t extra : {1, 3, 200}) {
      auto b = s.bytes;
      b.resize(b.size() + extra, 0);
      byte_buffer out;
      EXPECT_FALSE(c.decode_encode(b, out));
    }
  }
}

TEST(wire_malformed, a_bad_version_or_another_type_is_rejected_by_every_decoder) {
  for (auto& s : samples()) {
    SCOPED_TRACE(s.name);
    for (auto& c : codecs()) {
      SCOPED_TRACE(c.name);
      byte_buffer out;
      // Every other version.
      for (int v = 0; v < 16; ++v) {
        auto b = s.bytes;
        b[0] = static_cast<uint8_t>(v << 4 | (b[0] & 0x0F));
        EXPECT_EQ(c.decode_encode(b, out), v == 1 && c.type == s.type);
      }
      // Every other type, unknown ones included.
      for (int t = 0; t < 16; ++t) {
        auto b = s.bytes;
        b[0] = static_cast<uint8_t>(0x10 | t);
        if (t != static_cast<int>(c.type)) {
          EXPECT_FALSE(c.decode_encode(b, out));
        }
      }
    }
  }
}

TEST(wire_malformed, data_headers_with_reserved_flag_bits_are_rejected) {
  // Bit 5 is the authenticated flag (wire_layout.data_header_auth_flag_is_bit_5).
  auto good = enc(data_header{1, 2, 3, 3, 3, 0});
  for (int bit = 6; bit < 8; ++bit) {
    SCOPED_TRACE(bit);
    auto b = good;
    b[6] = static_cast<uint8_t>(b[6] | 1 << bit);
    EXPECT_EQ(error_of(decode_data_header(b.data(), b.size())),
              "data: reserved flag bits set (flags 0x"
                + std::string{"0123456789ABCDEF"[(b[6] >> 4) & 0xF]} + "F)");
  }
}

TEST(wire_malformed, errors_say_what_was_wrong) {
  struct row {
    const char* name;
    byte_buffer bytes;
    std::function<std::string(const byte_buffer&)> decode;
    std::string expected;
  };
  auto h = [](const byte_buffer& b) { return error_of(decode_hello(b.data(), b.size())); };
  auto u = [](const byte_buffer& b) { return error_of(decode_update(b.data(), b.size())); };
  auto c = [](const byte_buffer& b) { return error_of(decode_claim(b.data(), b.size())); };
  auto cq = [](const byte_buffer& b) {
    return error_of(decode_challenge_request(b.data(), b.size()));
  };
  auto cp = [](const byte_buffer& b) {
    return error_of(decode_challenge_reply(b.data(), b.size()));
  };
  auto request_bytes = enc(challenge_request{});
  auto reply_bytes = enc(challenge_reply{});
  auto d = [](const byte_buffer& b) {
    return error_of(decode_data_header(b.data(), b.size()));
  };
  auto hello_bytes = enc(hello{1, 2, 3, 4});
  auto plus = [](byte_buffer b, size_t n) {
    b.resize(b.size() + n);
    return b;
  };
  auto minus = [](byte_buffer b, size_t n) {
    b.resize(b.size() - n);
    return b;
  };
  // Two long entries (8 hops), then three short ones (2 hops), so that a
  // cut inside entry 3 still leaves the 5 * 20 bytes the count needs.
  update five{1, 2, {}};
  for (int i = 0; i < 5; ++i)
    five.entries.push_back(
      reachable(static_cast<module_id>(0x100 + i), 1, i < 2 ? 8 : 2));
  auto five_bytes = enc(five);
  // Entry 3 starts after the header and two entries of 4 + 4 * (5 + 8).
  auto entry3 = size_t{12} + 2 * 56;
  auto cut = [&](size_t n) {
    auto b = five_bytes;
    b.resize(n);
    return b;
  };
  auto hops_40 = five_bytes;
  hops_40[entry3 + 4 + 4] = 40; // entry 3, class 0, hops
  auto code_9 = five_bytes;
  code_9[entry3 + 4 + 7 + 4 + 1 + 1] = 9; // entry 3, class 1, second hop
  auto count_25 = enc(update{1, 2, {}});
  count_25[11] = 25;
  auto count_24_empty = count_25;
  count_24_empty[11] = 24;
  const row rows[] = {
    {"empty", {}, h, "hello: empty packet"},
    {"version", bytes({0x31}), h, "hello: version 3, expected 1"},
    {"type", bytes({0x12}), h, "hello: packet of type 2 (update)"},
    {"unknown type", bytes({0x1C}), h, "hello: packet of type 12 (unknown)"},
    {"truncated hello", minus(hello_bytes, 1), h, "hello: truncated: 14 of 15 bytes"},
    {"trailing", plus(hello_bytes, 3), h, "hello: 3 trailing bytes"},
    {"claim truncated", bytes({0x14, 1}), c, "claim: truncated: 2 of 20 bytes"},
    {"challenge request truncated", minus(request_bytes, 4), cq,
     "challenge_request: truncated: 5 of 9 bytes"},
    {"challenge request trailing", plus(request_bytes, 21), cq,
     "challenge_request: 21 trailing bytes"},
    {"challenge reply truncated", minus(reply_bytes, 1), cp,
     "challenge_reply: truncated: 8 of 9 bytes"},
    {"challenge reply trailing", plus(reply_bytes, 1), cp,
     "challenge_reply: 1 trailing bytes"},
    {"challenge reply for a request", request_bytes, cp,
     "challenge_reply: packet of type 6 (challenge_request)"},
    {"data header", bytes({0x10, 1, 2, 3}), d, "data: truncated header: 4 of 8 bytes"},
    {"update header", bytes({0x12, 1, 2, 3}), u, "update: truncated header: 4 of 12 bytes"},
    {"too many entries", count_25, u, "update: 25 entries, at most 24"},
    {"count beyond the bytes", count_24_empty, u,
     "update: 24 entries need at least 480 bytes, 0 left"},
    {"cut in an origin", cut(entry3 + 1), u, "update: entry 3 of 5 truncated"},
    {"cut in a metric", cut(entry3 + 4 + 7 + 2), u, "update: entry 3 of 5 truncated"},
    {"cut before hops", cut(entry3 + 4 + 4), u, "update: entry 3 of 5 truncated"},
    {"cut in a path", cut(entry3 + 10), u, "update: entry 3 of 5 truncated"},
    {"too many hops", hops_40, u, "update: entry 3 of 5, class 0: 40 hops, at most 32"},
    {"unknown link code", code_9, u,
     "update: entry 3 of 5, class 1: unknown link code 9 at hop 2"},
    {"update trailing", plus(five_bytes, 2), u, "update: 2 trailing bytes"},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.name);
    EXPECT_EQ(r.decode(r.bytes), r.expected);
  }
}

TEST(wire_malformed, an_update_is_refused_when_its_entries_cannot_fit_before_allocating) {
  // 24 announced entries need at least 24 * 20 bytes (every class
  // retracted); a packet that cannot hold them is refused at the header.
  for (size_t n = 0; n < 24 * 20; n += 7) {
    auto b = enc(update{1, 2, {}});
    b[11] = 24;
    b.resize(b.size() + n, 0xFF);
    auto d = decode_update(b.data(), b.size());
    ASSERT_FALSE(d);
    EXPECT_NE(error_of(d).find("24 entries need at least 480 bytes"),
              std::string::npos);
  }
}

// -- forwarding ------------------------------------------------------------------

TEST(wire_forwarding, set_hop_limit_rewrites_byte_5_and_nothing_else) {
  auto b = enc(data_header{0x4E, 0x42, 32, 1, 2, 1});
  b.push_back(0x77);
  auto before = b;
  set_hop_limit(b.data(), 31);
  EXPECT_EQ(b[5], 31);
  b[5] = before[5];
  EXPECT_EQ(b, before);
  set_hop_limit(b.data(), 0);
  auto d = decode_data_header(b.data(), b.size());
  ASSERT_TRUE(d);
  EXPECT_EQ(d->hop_limit, 0);
  EXPECT_EQ(d->src, 0x4E);
  EXPECT_EQ(d->dst, 0x42);
}

// -- robustness ------------------------------------------------------------------

namespace {

/// SplitMix64: a fast generator, so that the fuzz below spends its time in
/// the decoders rather than in std::mt19937_64.
struct fast_rng {
  using result_type = uint64_t;
  uint64_t state;

  static constexpr uint64_t min() {
    return 0;
  }
  static constexpr uint64_t max() {
    return ~uint64_t{0};
  }

  uint64_t operator()() {
    auto z = (state += 0x9E3779B97F4A7C15);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EB;
    return z ^ (z >> 31);
  }
};

/// Random plausible update bytes: a valid header, a count around the limit,
/// entries built from random choices (metric infinite or not, hops around the
/// limit, link codes around the limit), sometimes cut short. They reach the
/// decoder's deep paths far more often than uniform noise.
byte_buffer random_update(fast_rng& rng) {
  byte_buffer b{0x12};
  auto byte = [&] { return static_cast<uint8_t>(rng()); };
  for (int i = 0; i < 10; ++i)
    b.push_back(byte());
  auto count = static_cast<uint8_t>(rng() % 27);
  b.push_back(count);
  for (int i = 0; i < count; ++i) {
    for (int j = 0; j < 4; ++j)
      b.push_back(byte());
    for (size_t k = 0; k < size_classes; ++k) {
      bool infinite = rng() % 3 == 0;
      for (int j = 0; j < 4; ++j)
        b.push_back(infinite ? 0xFF : byte());
      if (infinite)
        continue;
      auto hops = static_cast<uint8_t>(rng() % 40 == 0 ? 33 + rng() % 3
                                                       : rng() % 5);
      b.push_back(hops);
      for (int h = 0; h < hops; ++h)
        b.push_back(static_cast<uint8_t>(rng() % 200 == 0 ? 8 + rng() % 248
                                                          : rng() % 8));
    }
  }
  if (rng() % 4 == 0)
    b.resize(rng() % (b.size() + 3));
  return b;
}

void mutate(byte_buffer& b, fast_rng& rng) {
  auto n = 1 + rng() % 4;
  for (size_t i = 0; i < n; ++i) {
    switch (rng() % 6) {
      case 0: // flip a bit
        if (!b.empty())
          b[rng() % b.size()] ^= static_cast<uint8_t>(1u << (rng() % 8));
        break;
      case 1: // overwrite a byte
        if (!b.empty())
          b[rng() % b.size()] = static_cast<uint8_t>(rng());
        break;
      case 2: // cut
        b.resize(b.empty() ? 0 : rng() % b.size());
        break;
      case 3: // insert a byte
        b.insert(b.begin() + static_cast<ptrdiff_t>(rng() % (b.size() + 1)),
                 static_cast<uint8_t>(rng()));
        break;
      case 4: // drop a byte
        if (!b.empty())
          b.erase(b.begin() + static_cast<ptrdiff_t>(rng() % b.size()));
        break;
      case 5: // append garbage
        for (auto k = rng() % 5; k > 0; --k)
          b.push_back(static_cast<uint8_t>(rng()));
        break;
    }
  }
}

} // namespace

TEST(wire_robustness, every_decoder_is_total_and_what_decodes_reencodes_to_the_same_bytes) {
  // Random and mutated byte strings through every decoder, for a bounded
  // time. Run under ASan/UBSan (HERM_SANITIZE) this is a small fuzz; the
  // bounds are checked there, and here that a decoded value is exactly what
  // its bytes said (re-encoding reproduces them) and that exactly the
  // decoder of the announced type can accept a packet.
  using clock = std::chrono::steady_clock;
  constexpr size_t max_inputs = 2'000'000;
  constexpr auto max_time = std::chrono::seconds(4);
  fast_rng rng{20240607};
  auto seeds = samples();
  std::vector<size_t> decoded(codecs().size(), 0);
  byte_buffer in;
  byte_buffer out;
  size_t inputs = 0;
  auto deadline = clock::now() + max_time;
  while (inputs < max_inputs && (inputs % 4096 != 0 || clock::now() < deadline)) {
    switch (rng() % 4) {
      case 0: { // noise, with a plausible first byte half the time
        in.resize(rng() % 8 == 0 ? rng() % 400 : rng() % 40);
        uint64_t bits = 0;
        for (size_t i = 0; i < in.size(); ++i) {
          if (i % 8 == 0)
            bits = rng();
          in[i] = static_cast<uint8_t>(bits >> (8 * (i % 8)));
        }
        if (!in.empty() && rng() % 2 == 0)
          in[0] = static_cast<uint8_t>(0x10 | rng() % 8);
        break;
      }
      case 1:
        in = random_update(rng);
        break;
      default:
        in = seeds[rng() % seeds.size()].bytes;
        mutate(in, rng);
        break;
    }
    ++inputs;
    auto type = peek_type(in.data(), in.size());
    for (size_t i = 0; i < codecs().size(); ++i) {
      auto& c = codecs()[i];
      if (!c.decode_encode(in, out))
        continue;
      ++decoded[i];
      ASSERT_TRUE(type) << c.name;
      ASSERT_EQ(*type, c.type) << c.name;
      ASSERT_EQ(out, in) << c.name;
    }
  }
  std::cout << "[          ] " << inputs << " inputs\n";
  // The loop is bounded by count and time; how many it gets through is
  // speed (sanitizer builds are ten times slower), so only require enough
  // inputs to mean something.
  EXPECT_GE(inputs, 10'000u);
  // The mix did reach a successful decode of every type.
  for (size_t i = 0; i < codecs().size(); ++i) {
    SCOPED_TRACE(codecs()[i].name);
    EXPECT_GT(decoded[i], 0u);
  }
}
