// Helpers shared by the C client's specifications: byte strings written as
// hex text ("10 4E 00"), so the golden strings of docs/protocol.md read the
// same here.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace mcu_test {

using bytes = std::vector<uint8_t>;

/// "10 4E 00" -> {0x10, 0x4E, 0x00}; spaces and newlines are ignored.
inline bytes hex(const std::string& text) {
  bytes out;
  int nibble = -1;
  for (char c : text) {
    int v = c >= '0' && c <= '9'   ? c - '0'
            : c >= 'a' && c <= 'f' ? c - 'a' + 10
            : c >= 'A' && c <= 'F' ? c - 'A' + 10
                                   : -1;
    if (v < 0)
      continue;
    if (nibble < 0) {
      nibble = v;
    } else {
      out.push_back(static_cast<uint8_t>(nibble * 16 + v));
      nibble = -1;
    }
  }
  return out;
}

/// Collects the packets a receiver delivers, with their source: its
/// on_packet is the link layer's callback (hermc_link.h), `this` its ctx.
struct packet_sink {
  std::vector<bytes> packets;
  std::vector<uint8_t> sources;

  static void on_packet(void* ctx, uint8_t src, const uint8_t* pkt, size_t len) {
    auto* self = static_cast<packet_sink*>(ctx);
    self->packets.emplace_back(pkt, pkt + len);
    self->sources.push_back(src);
  }
};

/// The first `n` bytes of `p` as a vector.
inline bytes take(const uint8_t* p, size_t n) {
  return bytes(p, p + n);
}

/// For failure messages: "10 4E 00".
inline std::string to_hex(const bytes& b) {
  std::string s;
  char buf[4];
  for (auto x : b) {
    std::snprintf(buf, sizeof buf, "%02X ", x);
    s += buf;
  }
  return s;
}

} // namespace mcu_test
