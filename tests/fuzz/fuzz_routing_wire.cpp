// Fuzz target: every decoder of routing/wire.hpp (docs/protocol.md,
// "Network packets").
//
// Properties checked for every input:
// - each decoder is total: it returns a value or ec::invalid_parameter;
// - a packet decodes with at most one decoder, the one of the type that
//   peek_type reads from its first byte;
// - what decodes re-encodes to exactly the input bytes (every format is
//   canonical; a data packet is its header followed by the payload);
// - decoded values respect the documented bounds (priority, size class,
//   update entries, hop counts, path lengths, link codes);
// - set_hop_limit changes the hop limit of a data packet and nothing else;
//   set_authenticated changes flag bit 5 and nothing else;
// - a keyed receiver never finds the input's tag right (it was not signed
//   with the key), whatever its trailer says: not accepted, not even
//   challenged; and it never crashes.

#include <cstddef>
#include <cstdint>

#include "actors/runtime/error.hpp"
#include "routing/auth.hpp"
#include "routing/wire.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace herm;

namespace {

byte_buffer out;

template <class T>
bool refused_properly(const caf::expected<T>& x) {
  return x || is(x.error(), ec::invalid_parameter);
}

/// Decodes with `decode`; on success checks the type and the round trip.
template <class Decode, class Check>
int try_decoder(const uint8_t* data, size_t size, packet_type type,
                const caf::expected<packet_type>& peeked, Decode decode,
                Check check) {
  auto x = decode(data, size);
  HERM_FUZZ_CHECK(refused_properly(x));
  if (!x)
    return 0;
  HERM_FUZZ_CHECK(peeked && *peeked == type);
  check(*x);
  out.clear();
  encode(*x, out);
  HERM_FUZZ_CHECK(out.size() == size);
  HERM_FUZZ_CHECK(std::equal(out.begin(), out.end(), data));
  return 1;
}

void check_data(const uint8_t* data, size_t size,
                const caf::expected<packet_type>& peeked, int& decoded) {
  auto h = decode_data_header(data, size);
  HERM_FUZZ_CHECK(refused_properly(h));
  if (!h)
    return;
  ++decoded;
  HERM_FUZZ_CHECK(peeked && *peeked == packet_type::data);
  HERM_FUZZ_CHECK(h->size_class < size_classes);
  HERM_FUZZ_CHECK(h->priority <= 3);
  HERM_FUZZ_CHECK(h->flood_id == 0 || h->dst == broadcast_module);
  auto hs = header_size(*h);
  HERM_FUZZ_CHECK(hs <= size);
  out.clear();
  encode(*h, out);
  HERM_FUZZ_CHECK(out.size() == hs);
  HERM_FUZZ_CHECK(std::equal(out.begin(), out.end(), data));
  // Forwarding rewrites the hop limit in place and nothing else.
  byte_buffer copy(data, data + size);
  auto limit = static_cast<uint8_t>(h->hop_limit ^ 0x5A);
  set_hop_limit(copy.data(), limit);
  auto again = decode_data_header(copy.data(), copy.size());
  HERM_FUZZ_CHECK(again);
  HERM_FUZZ_CHECK(again->hop_limit == limit);
  HERM_FUZZ_CHECK(again->src == h->src && again->dst == h->dst
                  && again->size_class == h->size_class
                  && again->priority == h->priority
                  && again->protocol == h->protocol
                  && again->flood_id == h->flood_id);
  for (size_t i = 0; i < size; ++i)
    HERM_FUZZ_CHECK(i == 5 || copy[i] == data[i]);
  // The authenticated flag is bit 5 of the flags and nothing else.
  set_authenticated(copy.data(), !h->authenticated);
  auto flipped = decode_data_header(copy.data(), copy.size());
  HERM_FUZZ_CHECK(flipped);
  HERM_FUZZ_CHECK(flipped->authenticated != h->authenticated);
  HERM_FUZZ_CHECK((copy[6] ^ data[6]) == 0x20);
  set_authenticated(copy.data(), h->authenticated);
  HERM_FUZZ_CHECK(copy[6] == data[6]);
}

/// A keyed network's receiver: nothing unsigned passes.
void check_auth(const uint8_t* data, size_t size) {
  static auth_config cfg = [] {
    auth_config c;
    c.key.assign(32, 0x3C);
    return c;
  }();
  authenticator rx{cfg, 1};
  auth_trailer t;
  auto res = rx.verify(data, size, 4, authenticator::time_point{}, t);
  HERM_FUZZ_CHECK(res != auth_result::ok && res != auth_result::unknown_index
                  && res != auth_result::replayed);
  HERM_FUZZ_CHECK(t.body_size == 0);
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto peeked = peek_type(data, size);
  HERM_FUZZ_CHECK(refused_properly(peeked));
  int decoded = 0;
  check_auth(data, size);
  check_data(data, size, peeked, decoded);
  decoded += try_decoder(data, size, packet_type::hello, peeked, decode_hello,
                         [](const hello&) {});
  decoded += try_decoder(
    data, size, packet_type::update, peeked, decode_update,
    [](const update& u) {
      HERM_FUZZ_CHECK(u.entries.size() <= max_update_entries);
      for (auto& e : u.entries) {
        for (size_t k = 0; k < size_classes; ++k) {
          if (e.metrics[k] == infinite_metric) {
            HERM_FUZZ_CHECK(e.hops[k] == 0 && e.path[k].empty());
            continue;
          }
          HERM_FUZZ_CHECK(e.hops[k] <= max_route_hops);
          HERM_FUZZ_CHECK(e.path[k].size() == e.hops[k]);
          for (auto c : e.path[k])
            HERM_FUZZ_CHECK(static_cast<uint8_t>(c) <= 7);
        }
      }
    });
  decoded += try_decoder(data, size, packet_type::seqno_request, peeked,
                         decode_seqno_request, [](const seqno_request&) {});
  decoded += try_decoder(data, size, packet_type::claim, peeked, decode_claim,
                         [](const claim&) {});
  decoded += try_decoder(data, size, packet_type::conflict, peeked,
                         decode_conflict, [](const conflict&) {});
  decoded += try_decoder(data, size, packet_type::challenge_request, peeked,
                         decode_challenge_request,
                         [](const challenge_request&) {});
  decoded += try_decoder(data, size, packet_type::challenge_reply, peeked,
                         decode_challenge_reply, [](const challenge_reply&) {});
  HERM_FUZZ_CHECK(decoded <= 1);
  return 0;
}
