// The shared little-endian reader and writer (channels/le_codec.hpp): exact
// byte layout, round trips, and that a short input is refused at every
// length without reading past it.

#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <functional>
#include <cstddef>
#include <string>
#include <vector>

#include "channels/le_codec.hpp"

using namespace herm;

namespace {

using bytes = std::vector<uint8_t>;

/// A heap copy of the first n bytes, exactly n long: a read past it shows
/// under ASan.
bytes prefix(const bytes& x, size_t n) {
  return bytes(x.begin(), x.begin() + static_cast<std::ptrdiff_t>(n));
}

/// One integer field: how to write it, how to read it back, its bytes.
struct int_case {
  const char* name;
  std::function<void(le_writer&)> write;
  std::function<uint64_t(le_reader&)> read;
  uint64_t value;
  bytes layout;
};

std::vector<int_case> int_cases() {
  return {
    {"u8", [](le_writer& w) { w.u8(0xAB); },
     [](le_reader& r) { return r.u8(); }, 0xAB, {0xAB}},
    {"u16", [](le_writer& w) { w.u16(0x1234); },
     [](le_reader& r) { return r.u16(); }, 0x1234, {0x34, 0x12}},
    {"u16 max", [](le_writer& w) { w.u16(0xFFFF); },
     [](le_reader& r) { return r.u16(); }, 0xFFFF, {0xFF, 0xFF}},
    {"u32", [](le_writer& w) { w.u32(0xDEADBEEF); },
     [](le_reader& r) { return r.u32(); }, 0xDEADBEEF,
     {0xEF, 0xBE, 0xAD, 0xDE}},
    {"u64", [](le_writer& w) { w.u64(0x0102030405060708); },
     [](le_reader& r) { return r.u64(); }, 0x0102030405060708,
     {0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02, 0x01}},
    {"u64 max", [](le_writer& w) { w.u64(UINT64_MAX); },
     [](le_reader& r) { return r.u64(); }, UINT64_MAX, bytes(8, 0xFF)},
    {"le<uint32_t>", [](le_writer& w) { w.le(uint32_t{7}); },
     [](le_reader& r) { return r.le<uint32_t>(); }, 7, {7, 0, 0, 0}},
  };
}

} // namespace

// -- integers ---------------------------------------------------------------------

TEST(le_codec, writes_integers_least_significant_byte_first) {
  for (auto& c : int_cases()) {
    bytes out;
    le_writer w{out};
    c.write(w);
    EXPECT_EQ(out, c.layout) << c.name;
  }
}

TEST(le_codec, reads_back_what_it_wrote) {
  for (auto& c : int_cases()) {
    le_reader r{c.layout.data(), c.layout.size()};
    EXPECT_EQ(c.read(r), c.value) << c.name;
    EXPECT_TRUE(r.ok()) << c.name;
    EXPECT_EQ(r.left(), 0u) << c.name;
  }
}

TEST(le_codec, refuses_an_integer_at_every_short_length) {
  for (auto& c : int_cases()) {
    for (size_t n = 0; n < c.layout.size(); ++n) {
      auto in = prefix(c.layout, n);
      le_reader r{in.data(), n};
      EXPECT_EQ(c.read(r), 0u) << c.name << " with " << n << " bytes";
      EXPECT_FALSE(r.ok()) << c.name << " with " << n << " bytes";
      EXPECT_EQ(r.pos(), 0u) << c.name << " with " << n << " bytes";
    }
  }
}

TEST(le_codec, store_and_load_match_the_writer) {
  std::array<uint8_t, 4> buf{};
  store_le(uint32_t{0xA1B2C3D4}, buf.data());
  EXPECT_EQ(buf, (std::array<uint8_t, 4>{0xD4, 0xC3, 0xB2, 0xA1}));
  EXPECT_EQ(load_le<uint32_t>(buf.data()), 0xA1B2C3D4u);
  EXPECT_EQ(load_le<uint16_t>(buf.data()), 0xC3D4u);
}

// -- a composite layout -----------------------------------------------------------

namespace {

/// u8, u16, u32, u64, a 3-byte array, a 2-byte string: 20 bytes.
bytes composite() {
  bytes out;
  le_writer w{out};
  w.u8(1).u16(0x0302).u32(0x07060504).u64(0x0F0E0D0C0B0A0908);
  w.bytes(std::array<uint8_t, 3>{0x10, 0x11, 0x12});
  w.bytes("hi", 2);
  return out;
}

struct parsed {
  uint8_t a = 0;
  uint16_t b = 0;
  uint32_t c = 0;
  uint64_t d = 0;
  std::array<uint8_t, 3> e{};
  std::string f;
};

/// Reads the whole layout without checking between fields.
parsed read_composite(le_reader& r) {
  parsed p;
  p.a = r.u8();
  p.b = r.u16();
  p.c = r.u32();
  p.d = r.u64();
  r.bytes(p.e);
  r.str(2, p.f);
  return p;
}

} // namespace

TEST(le_codec, composite_layout_is_the_fields_back_to_back) {
  bytes want{1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15,
             0x10, 0x11, 0x12, 'h', 'i'};
  EXPECT_EQ(composite(), want);
  le_reader r{want.data(), want.size()};
  auto p = read_composite(r);
  EXPECT_TRUE(r.ok());
  EXPECT_EQ(r.left(), 0u);
  EXPECT_EQ(p.a, 1);
  EXPECT_EQ(p.b, 0x0302);
  EXPECT_EQ(p.c, 0x07060504u);
  EXPECT_EQ(p.d, 0x0F0E0D0C0B0A0908u);
  EXPECT_EQ(p.e, (std::array<uint8_t, 3>{0x10, 0x11, 0x12}));
  EXPECT_EQ(p.f, "hi");
}

TEST(le_codec, a_counted_list_is_its_count_byte_then_each_element_in_order) {
  bytes out;
  le_writer w{out};
  std::vector<uint16_t> xs{0x0201, 0x0403, 0x0605};
  w.u8(0xAA).u8_counted(xs, 3, [&w](uint16_t x) { w.u16(x); }).u8(0xBB);
  EXPECT_EQ(out, (bytes{0xAA, 3, 1, 2, 3, 4, 5, 6, 0xBB}));
}

TEST(le_codec, an_empty_counted_list_is_a_zero_byte) {
  bytes out;
  le_writer w{out};
  size_t calls = 0;
  w.u8_counted(std::vector<int>{}, 255, [&calls](int) { ++calls; });
  EXPECT_EQ(out, bytes{0});
  EXPECT_EQ(calls, 0u);
}

TEST(le_codec, a_counted_list_that_cannot_follow_says_why) {
  struct {
    size_t count, max, min_entry, left;
    const char* why;
  } cases[] = {
    {0, 0, 6, 0, ""},
    {3, 3, 6, 18, ""},
    {3, 3, 6, 100, ""},
    {4, 3, 6, 100, "4 entries, at most 3"},
    {3, 3, 6, 17, "3 entries need at least 18 bytes, 17 left"},
    {255, 255, 20, 0, "255 entries need at least 5100 bytes, 0 left"},
  };
  for (auto& c : cases)
    EXPECT_EQ(counted_list_problem(c.count, c.max, c.min_entry, c.left), c.why)
      << c.count << " entries of " << c.min_entry << " bytes, " << c.left
      << " left, at most " << c.max;
}

TEST(le_codec, truncation_at_every_length_fails_and_stays_failed) {
  auto full = composite();
  for (size_t n = 0; n < full.size(); ++n) {
    auto in = prefix(full, n);
    le_reader r{in.data(), n};
    auto p = read_composite(r);
    EXPECT_FALSE(r.ok()) << n << " bytes";
    EXPECT_LE(r.pos(), n) << n << " bytes";
    // The field that did not fit, and every one after it, reads as empty.
    EXPECT_TRUE(p.f.empty()) << n << " bytes";
    EXPECT_EQ(r.u8(), 0) << "sticky after " << n << " bytes";
    EXPECT_EQ(r.bytes(0), nullptr) << "sticky after " << n << " bytes";
    bytes rest{1};
    r.rest(rest);
    EXPECT_TRUE(rest.empty()) << "sticky after " << n << " bytes";
  }
}

TEST(le_codec, reader_starts_at_the_given_offset) {
  bytes in{0xFF, 0x34, 0x12};
  le_reader r{in.data(), in.size(), 1};
  EXPECT_EQ(r.left(), 2u);
  EXPECT_EQ(r.u16(), 0x1234);
  EXPECT_TRUE(r.ok());
  le_reader past{in.data(), in.size(), 4};
  EXPECT_FALSE(past.ok());
  EXPECT_EQ(past.left(), 0u);
}

TEST(le_codec, null_input_is_empty) {
  le_reader r{nullptr, 5};
  EXPECT_EQ(r.left(), 0u);
  EXPECT_EQ(r.u8(), 0);
  EXPECT_FALSE(r.ok());
}

TEST(le_codec, rest_takes_everything_left) {
  bytes in{1, 2, 3, 4};
  le_reader r{in.data(), in.size(), 1};
  bytes out;
  r.rest(out);
  EXPECT_EQ(out, (bytes{2, 3, 4}));
  EXPECT_EQ(r.left(), 0u);
  EXPECT_TRUE(r.ok());
}

TEST(le_codec, a_string_that_does_not_fit_leaves_the_target_alone) {
  bytes in{'a', 'b'};
  le_reader r{in.data(), in.size()};
  std::string s = "kept";
  EXPECT_FALSE(r.str(3, s));
  EXPECT_EQ(s, "kept");
  EXPECT_EQ(r.pos(), 0u);
}

// -- LEB128 -----------------------------------------------------------------------

namespace {

struct leb_case {
  uint64_t value;
  bytes layout;
};

const std::vector<leb_case> leb_cases = {
  {0, {0x00}},
  {1, {0x01}},
  {127, {0x7F}},
  {128, {0x80, 0x01}},
  {300, {0xAC, 0x02}},
  {16383, {0xFF, 0x7F}},
  {16384, {0x80, 0x80, 0x01}},
  {UINT32_MAX, {0xFF, 0xFF, 0xFF, 0xFF, 0x0F}},
  {UINT64_MAX, {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x01}},
};

} // namespace

TEST(le_codec, leb128_writes_the_minimal_form_and_reads_it_back) {
  for (auto& c : leb_cases) {
    bytes out;
    le_writer{out}.leb128(c.value);
    EXPECT_EQ(out, c.layout) << c.value;
    EXPECT_EQ(leb128_size(c.value), c.layout.size()) << c.value;
    le_reader r{out.data(), out.size()};
    uint64_t x = 0;
    EXPECT_EQ(r.leb128(x), leb128_status::ok) << c.value;
    EXPECT_EQ(x, c.value);
    EXPECT_EQ(r.left(), 0u) << c.value;
  }
}

TEST(le_codec, leb128_refuses_every_short_prefix) {
  for (auto& c : leb_cases) {
    for (size_t n = 0; n < c.layout.size(); ++n) {
      auto in = prefix(c.layout, n);
      le_reader r{in.data(), n};
      uint64_t x = 42;
      EXPECT_EQ(r.leb128(x), leb128_status::truncated) << c.value << "/" << n;
      EXPECT_EQ(x, 42u);
      EXPECT_EQ(r.pos(), 0u);
      EXPECT_FALSE(r.ok());
    }
  }
}

TEST(le_codec, leb128_refuses_malformed_numbers) {
  struct bad_case {
    const char* name;
    bytes layout;
    size_t max_bytes;
    bool minimal;
    leb128_status want;
  };
  std::vector<bad_case> cases = {
    {"trailing zero byte", {0x80, 0x00}, 10, true, leb128_status::not_minimal},
    {"trailing zero allowed", {0x80, 0x00}, 10, false, leb128_status::ok},
    {"above 64 bits",
     {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x02}, 10, true,
     leb128_status::too_long},
    {"longer than allowed", {0x80, 0x80, 0x01}, 2, true,
     leb128_status::too_long},
    {"eleven bytes", bytes(11, 0x80), 10, true, leb128_status::too_long},
  };
  for (auto& c : cases) {
    le_reader r{c.layout.data(), c.layout.size()};
    uint64_t x = 0;
    EXPECT_EQ(r.leb128(x, c.max_bytes, c.minimal), c.want) << c.name;
    EXPECT_EQ(r.ok(), c.want == leb128_status::ok) << c.name;
  }
}
