// Fuzz target: the serial link's byte-stream framing
// (channels/drivers/serial_framing.hpp, docs/protocol.md "Serial framing"):
// the incremental COBS + CRC-16 decoder a serial driver feeds with whatever
// comes off the line, and the COBS codec itself.
//
// Input: MTU (1 byte, 1..255), options (1 byte: bit 0 escaped mode (XON/XOFF),
// bits 1..7 a chunk size), then the line bytes.
//
// Properties checked for every input:
// 1. Decoding is independent of how the bytes are cut into reads: the whole
//    stream at once and in chunks give the same frames, errors and stats.
// 2. Every frame handed up has 1..MTU bytes; each callback is counted once
//    in the stats; every delimiter ends exactly one run (frame, idle or one
//    error), plus at most one error reported early for the unfinished run.
// 3. Every frame handed up re-encodes (encode_frame) to a run that a fresh
//    decoder turns back into that frame alone.
// 4. Resynchronisation: after arbitrary garbage, frames sent with a leading
//    delimiter all arrive, exactly and in order (the last frames decoded).
// 5. COBS: encoding any bytes gives no 0x00, at most cobs_max_size bytes and
//    decodes back; decoding any bytes either fails or gives bytes that
//    re-encode to the input (or to the input without the redundant 0x01
//    that may follow a final full block).

#include <cstddef>
#include <cstdint>
#include <vector>

#include "channels/drivers/serial_framing.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace herm;

namespace {

/// One decoder callback: a frame, or an error (frame empty, error set).
struct event {
  std::vector<uint8_t> frame;
  int error = -1;

  bool operator==(const event& y) const {
    return frame == y.frame && error == y.error;
  }
};

struct run_result {
  std::vector<event> events;
  serial::decoder_stats stats;
};

run_result decode(uint32_t mtu, bool escaped, const uint8_t* data,
                  size_t size, size_t chunk) {
  serial::decoder d{mtu, escaped};
  run_result r;
  auto on_frame = [&](const uint8_t* p, size_t n) {
    r.events.push_back(event{std::vector<uint8_t>(p, p + n), -1});
  };
  auto on_bad = [&](serial::rx_error e) {
    r.events.push_back(event{{}, static_cast<int>(e)});
  };
  for (size_t pos = 0; pos < size; pos += chunk)
    d.feed(data + pos, std::min(chunk, size - pos), on_frame, on_bad);
  r.stats = d.stats();
  return r;
}

bool same_stats(const serial::decoder_stats& a,
                const serial::decoder_stats& b) {
  return a.frames == b.frames && a.idle == b.idle && a.errors == b.errors;
}

void check_stream(uint32_t mtu, bool escaped, size_t chunk,
                  const uint8_t* data, size_t size) {
  auto whole = decode(mtu, escaped, data, size, size == 0 ? 1 : size);
  auto cut = decode(mtu, escaped, data, size, chunk);
  HERM_FUZZ_CHECK(whole.events == cut.events);
  HERM_FUZZ_CHECK(same_stats(whole.stats, cut.stats));
  size_t frames = 0;
  size_t errors = 0;
  for (auto& e : whole.events) {
    if (e.error >= 0) {
      HERM_FUZZ_CHECK(e.error < static_cast<int>(serial::rx_error_count));
      ++errors;
      continue;
    }
    ++frames;
    HERM_FUZZ_CHECK(!e.frame.empty() && e.frame.size() <= mtu);
    // Property 3: the frame's own encoding decodes to it alone.
    std::vector<uint8_t> wire;
    serial::append_frame(wire, e.frame.data(), e.frame.size(), false,
                         escaped);
    HERM_FUZZ_CHECK(wire.size() <= serial::max_wire_size(e.frame.size(),
                                                          escaped));
    auto back = decode(mtu, escaped, wire.data(), wire.size(), wire.size());
    HERM_FUZZ_CHECK(back.events.size() == 1);
    HERM_FUZZ_CHECK(back.events[0].error < 0
                    && back.events[0].frame == e.frame);
  }
  auto& st = whole.stats;
  HERM_FUZZ_CHECK(st.frames == frames && st.malformed() == errors);
  size_t delimiters = 0;
  for (size_t i = 0; i < size; ++i)
    delimiters += data[i] == serial::delimiter;
  auto runs = st.frames + st.idle + st.malformed();
  HERM_FUZZ_CHECK(runs >= delimiters && runs <= delimiters + 1);
}

void check_resync(uint32_t mtu, bool escaped, size_t chunk,
                  const uint8_t* data, size_t size) {
  // Frames cut from the input itself, at most 16, each 1..mtu bytes.
  std::vector<std::vector<uint8_t>> frames;
  for (size_t pos = 0; pos < size && frames.size() < 16;) {
    auto n = std::min<size_t>(1 + data[pos] % mtu, size - pos);
    frames.emplace_back(data + pos, data + pos + n);
    pos += n;
  }
  // The input as garbage, then the frames; only the first needs its
  // leading delimiter, the others share delimiters or not (from the data).
  std::vector<uint8_t> wire(data, data + size);
  for (size_t i = 0; i < frames.size(); ++i) {
    bool leading = i == 0 || (frames[i][0] & 1) != 0;
    serial::append_frame(wire, frames[i].data(), frames[i].size(), leading,
                         escaped);
  }
  auto got = decode(mtu, escaped, wire.data(), wire.size(), chunk);
  std::vector<const event*> received;
  for (auto& e : got.events)
    if (e.error < 0)
      received.push_back(&e);
  HERM_FUZZ_CHECK(received.size() >= frames.size());
  auto offset = received.size() - frames.size();
  for (size_t i = 0; i < frames.size(); ++i)
    HERM_FUZZ_CHECK(received[offset + i]->frame == frames[i]);
  // Nothing after the frames: the last event is the last frame.
  if (!frames.empty())
    HERM_FUZZ_CHECK(got.events.back().error < 0);
}

void check_cobs(const uint8_t* data, size_t size) {
  std::vector<uint8_t> enc(serial::cobs_max_size(size));
  auto n = serial::cobs_encode(data, size, enc.data());
  HERM_FUZZ_CHECK(n >= 1 && n <= enc.size());
  for (size_t i = 0; i < n; ++i)
    HERM_FUZZ_CHECK(enc[i] != 0);
  std::vector<uint8_t> dec(n);
  auto m = serial::cobs_decode(enc.data(), n, dec.data());
  HERM_FUZZ_CHECK(m == size);
  HERM_FUZZ_CHECK(std::equal(dec.begin(), dec.begin() + m, data));
  // Decoding arbitrary bytes (exactly sized output: ASan sees overruns).
  std::vector<uint8_t> raw(size);
  auto k = serial::cobs_decode(data, size, raw.data());
  if (k == SIZE_MAX)
    return;
  HERM_FUZZ_CHECK(k <= size);
  std::vector<uint8_t> re(serial::cobs_max_size(k));
  auto r = serial::cobs_encode(raw.data(), k, re.data());
  bool same = r == size && std::equal(re.begin(), re.begin() + r, data);
  bool redundant_tail = size >= 2 && r == size - 1 && data[size - 1] == 0x01
                        && std::equal(re.begin(), re.begin() + r, data);
  HERM_FUZZ_CHECK(same || redundant_tail || size == 0);
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::reader in{data, size};
  auto mtu = static_cast<uint32_t>(1 + in.u8() % serial::max_mtu);
  auto opts = in.u8();
  bool escaped = (opts & 1) != 0;
  size_t chunk = 1 + (opts >> 1);
  // The line bytes in their own heap block, so that ASan sees overruns.
  std::vector<uint8_t> line(in.data, in.data + in.size);
  check_stream(mtu, escaped, chunk, line.data(), line.size());
  check_resync(mtu, escaped, chunk, line.data(), line.size());
  check_cobs(line.data(), line.size());
  return 0;
}
