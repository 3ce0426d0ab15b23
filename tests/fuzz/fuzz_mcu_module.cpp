// Fuzz target: the C client's module (apps/mcu/client/hermc.h) fed what a
// neighbour could send: network packets handed over whole
// (hermc_handle_packet) and line bytes (hermc_feed), with clock ticks in
// between, on a module with an APO, a remote APO and a topic.
//
// Input: a script of steps; each starts with one byte:
//   0..127   a packet of (byte & 0x7F) bytes follows (handle_packet);
//   128..191 line bytes: (byte & 0x3F) bytes follow (feed);
//   192..255 the clock advances by (byte & 0x3F) * 50 ms (tick), and a
//            request to the remote APO is tried.
//
// Properties checked for every input:
// 1. No undefined behaviour (ASan, UBSan): bad input is only counted.
// 2. Everything the module sends decodes with the C codecs as a hello, an
//    update of our own id alone, or a data packet of protocol 1 from our id
//    holding a valid APO message: a leaf never forwards or relays.
// 3. Bounded tables stay within their bounds (APOs, remotes, pending
//    requests, subscribers, the flood ring), and every response callback
//    runs at most once per request sent.

#include <cstddef>
#include <cstdint>

#include "hermc.h"
#include "tests/fuzz/fuzz_support.hpp"

namespace {

constexpr uint16_t self_id = 0x0042;

uint8_t handler(void*, const uint8_t* req, size_t n, uint8_t* resp,
                size_t cap, size_t* len) {
  if (n == 0)
    return HERMC_EC_INVALID_PARAMETER;
  size_t k = n < cap ? n : cap;
  for (size_t i = 0; i < k; ++i)
    resp[i] = req[i];
  *len = k;
  return 0;
}

uint32_t requests_sent, callbacks_run;

void on_response(void*, hermc_status, const uint8_t*, size_t, uint64_t,
                 uint8_t) {
  ++callbacks_run;
}

void check_sent(const uint8_t* p, size_t n) {
  hermc_packet_type t;
  HERM_FUZZ_CHECK(hermc_peek_type(p, n, &t) == HERMC_NET_OK);
  if (t == HERMC_PT_HELLO) {
    hermc_hello h;
    HERM_FUZZ_CHECK(hermc_hello_decode(p, n, &h) == HERMC_NET_OK);
    HERM_FUZZ_CHECK(h.sender == self_id);
  } else if (t == HERMC_PT_UPDATE) {
    hermc_update_header h;
    hermc_update_entry e[1];
    HERM_FUZZ_CHECK(hermc_update_decode(p, n, &h, e, 1) == HERMC_NET_OK);
    HERM_FUZZ_CHECK(h.sender == self_id && h.count == 1
                    && e[0].origin == self_id);
  } else {
    HERM_FUZZ_CHECK(t == HERMC_PT_DATA);
    hermc_data_header h;
    size_t at;
    HERM_FUZZ_CHECK(hermc_data_header_decode(p, n, &h, &at) == HERMC_NET_OK);
    HERM_FUZZ_CHECK(h.src == self_id && h.protocol == HERMC_PROTOCOL_ASL);
    hermc_asl_msg m;
    HERM_FUZZ_CHECK(hermc_asl_decode(p + at, n - at, &m) == HERMC_ASL_OK);
  }
}

void on_sent(void*, uint8_t, const uint8_t* p, size_t n) {
  check_sent(p, n);
}

hermc_module m;
hermc_link_rx out_rx;

void drain() {
  uint8_t buf[64];
  size_t n;
  while ((n = hermc_poll_tx(&m, buf, sizeof buf)) > 0)
    hermc_link_rx_feed(&out_rx, buf, n, on_sent, nullptr);
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  hermc_config cfg;
  hermc_config_default(&cfg, self_id, 0x1122334455667788ull);
  HERM_FUZZ_CHECK(hermc_init(&m, &cfg) == HERMC_OK);
  hermc_link_rx_init(&out_rx, false);
  HERM_FUZZ_CHECK(hermc_register_apo(&m, "sonar", "t", handler, nullptr) == 1);
  int r = hermc_remote(&m, "sonar");
  int t = hermc_topic(&m, "range");
  requests_sent = callbacks_run = 0;
  uint32_t now = 0;
  hermc_tick(&m, now);
  herm::fuzz::reader in{data, size};
  while (!in.empty()) {
    uint8_t op = in.u8();
    if (op < 128) {
      size_t n = op & 0x7Fu;
      if (n > in.size)
        n = in.size;
      hermc_handle_packet(&m, in.data, n);
      in.data += n;
      in.size -= n;
    } else if (op < 192) {
      size_t n = op & 0x3Fu;
      if (n > in.size)
        n = in.size;
      hermc_feed(&m, in.data, n);
      in.data += n;
      in.size -= n;
    } else {
      now += 50u * (op & 0x3Fu);
      hermc_tick(&m, now);
      const uint8_t v[] = {1, 2};
      if (hermc_request(&m, r, v, 2, on_response, nullptr, 300) == HERMC_OK)
        ++requests_sent;
      (void)hermc_publish(&m, t, v, 2);
    }
    drain();
  }
  now += 60000;
  hermc_tick(&m, now); // every pending request ends here at the latest
  drain();
  HERM_FUZZ_CHECK(callbacks_run == requests_sent);
  HERM_FUZZ_CHECK(m.napos <= HERMC_MAX_APOS && m.nremotes <= HERMC_MAX_REMOTES
                  && m.ntopics <= HERMC_MAX_TOPICS
                  && m.flood_next < HERMC_FLOOD_CACHE);
  return 0;
}
