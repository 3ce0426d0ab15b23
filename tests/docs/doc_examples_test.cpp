// The examples of the docs that are not code: wire bytes and decoder errors
// in docs/protocol.md, marked `<!-- test: NAME -->` above their fenced block
// (tests/docs/check_quotes.py lists the markers). Each case NAME produces
// the block's content from the code and compares: a changed codec or error
// text fails here until the document says the same. Also the code the user
// guide quotes from here (run-module), compiled and run.

#include <gtest/gtest.h>
#include <gtest/gtest-spi.h>

#include <cctype>
#include <cstdio>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/make_message.hpp"

#include "actors/asl_wire.hpp"
#include "actors/marshal.hpp"
#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "channels/messages.hpp"
#include "routing/wire.hpp"

using namespace herm;

namespace {

// -- the documents -------------------------------------------------------------

using lines = std::vector<std::string>;

/// The fenced blocks of `doc` (relative to the source tree) marked
/// `<!-- test: NAME -->`, by NAME. A NAME marked twice fails the test.
std::map<std::string, lines> marked_blocks(const std::string& doc) {
  std::ifstream in{std::string{HERM_SOURCE_DIR} + "/" + doc};
  EXPECT_TRUE(in) << doc << " cannot be read";
  lines all;
  for (std::string line; std::getline(in, line);)
    all.push_back(line);
  std::map<std::string, lines> out;
  const std::string open = "<!-- test: ";
  for (size_t i = 0; i < all.size(); ++i) {
    if (all[i].rfind("```", 0) != 0)
      continue;
    auto end = i + 1;
    while (end < all.size() && all[end].rfind("```", 0) != 0)
      ++end;
    for (auto k = i; k > 0 && all[k - 1].rfind("<!-- ", 0) == 0; --k) {
      auto& marker = all[k - 1];
      if (marker.rfind(open, 0) != 0)
        continue;
      auto name = marker.substr(open.size(), marker.find(" -->") - open.size());
      EXPECT_EQ(out.count(name), 0u) << doc << ": " << name << " marked twice";
      out[name] = lines(all.begin() + i + 1, all.begin() + end);
    }
    i = end;
  }
  return out;
}

std::string hex(const byte_buffer& bytes) {
  std::string out;
  char buf[4];
  for (auto b : bytes) {
    std::snprintf(buf, sizeof(buf), out.empty() ? "%02X" : " %02X", b);
    out += buf;
  }
  return out;
}

/// The bytes of a hex dump whose lines are `HH HH ...`, then optionally two
/// or more spaces and a comment. A line that starts with anything but hex
/// bytes fails the test (nothing in the block goes unread).
byte_buffer bytes_of(const lines& block) {
  byte_buffer out;
  for (auto& line : block) {
    auto begin = line.find_first_not_of(' ');
    if (begin == std::string::npos)
      continue;
    auto end = line.find("  ", begin);
    std::istringstream words{line.substr(begin, end - begin)};
    for (std::string w; words >> w;) {
      auto ok = w.size() == 2 && std::isxdigit(static_cast<unsigned char>(w[0]))
                && std::isxdigit(static_cast<unsigned char>(w[1]));
      EXPECT_TRUE(ok) << "not a hex byte: '" << w << "' in: " << line;
      if (ok)
        out.push_back(static_cast<uint8_t>(std::stoul(w, nullptr, 16)));
    }
  }
  return out;
}

/// An error's context without the "category.code: " in front.
std::string context_of(const caf::error& err) {
  auto text = render(err);
  auto colon = text.find(": ");
  return colon == std::string::npos ? text : text.substr(colon + 2);
}

// -- an actor system that knows HERM's types, for APO payloads ----------------

/// Set while a doc_examples test runs (the fixture owns it).
caf::actor_system* the_system = nullptr;

class docs_examples : public ::testing::Test {
public:
  static void SetUpTestSuite() {
    cfg_ = std::make_unique<caf::actor_system_config>();
    configure(*cfg_);
    sys_ = std::make_unique<caf::actor_system>(*cfg_);
    the_system = sys_.get();
  }

  static void TearDownTestSuite() {
    the_system = nullptr;
    sys_.reset();
    cfg_.reset();
  }

private:
  static inline std::unique_ptr<caf::actor_system_config> cfg_;
  static inline std::unique_ptr<caf::actor_system> sys_;
};

byte_buffer marshal_or_fail(const caf::message& msg) {
  auto bytes = marshal(*the_system, msg);
  EXPECT_TRUE(bytes) << render(bytes.error());
  return bytes ? *bytes : byte_buffer{};
}

/// The golden payload of docs/protocol.md, "Worked example".
byte_buffer golden() {
  write_packet pkt;
  pkt.dst = 7;
  pkt.priority = prio_high;
  pkt.bytes = {0xDE, 0xAD};
  return marshal_or_fail(caf::make_message(uint16_t{0x0102}, pkt));
}

byte_buffer encode_asl(const asl_message& x) {
  byte_buffer out;
  encode(x, out);
  return out;
}

std::string unmarshal_error(const byte_buffer& bytes,
                            const unmarshal_limits& limits = {}) {
  auto msg = unmarshal(*the_system, bytes.data(), bytes.size(), limits);
  return msg ? std::string{"(decoded)"} : context_of(msg.error());
}

std::string asl_error(const byte_buffer& bytes) {
  auto msg = decode_asl(bytes.data(), bytes.size());
  return msg ? std::string{"(decoded)"} : context_of(msg.error());
}

byte_buffer operator+(byte_buffer x, const byte_buffer& y) {
  x.insert(x.end(), y.begin(), y.end());
  return x;
}

byte_buffer prefix(byte_buffer x, size_t n) {
  x.resize(n);
  return x;
}

constexpr uint64_t herm_category = 0x0FB6ADF2; // caf::atom("herm")

// -- the cases: each produces its block from the code ---------------------------

/// Hex dumps: the block's bytes equal what the encoder writes.
const std::map<std::string, std::function<byte_buffer()>> byte_cases = {
  {"routing-update",
   [] {
     // One entry for 0x4E: class 0 over CAN2.0, class 1 over Ethernet then
     // USB2.0, class 2 unreachable, class 3 with no path.
     advertised to_4e{0x004E, 0x0102, {8, 30, infinite_metric, 0x01020304},
                      {1, 2, 0, 0},
                      {{{link_code::can20},
                        {link_code::ethernet, link_code::usb20}, {}, {}}}};
     byte_buffer out;
     encode(update{0x0042, 0x0807060504030201, {to_4e}}, out);
     return out;
   }},
  {"marshal-golden", [] { return golden(); }},
  {"asl-answer",
   [] {
     return encode_asl(
       asl_answer{0x0A, {{0x11, "a", "t"}, {0x22, "", ""}}});
   }},
  {"asl-response-error",
   [] {
     return encode_asl(asl_response{
       0x0807060504030201, false, {}, {herm_category, 16, "gone"}});
   }},
};

/// Error lists: line k of the block is what the decoder says for input k.
const std::map<std::string, std::function<lines()>> error_cases = {
  {"marshal-errors",
   [] {
     auto g = golden();
     unmarshal_limits one_element;
     one_element.max_sequence = 1;
     auto str = marshal_or_fail(caf::make_message(std::string(70000, 'x')));
     auto flag = marshal_or_fail(caf::make_message(true));
     flag.back() = 2;
     byte_buffer unknown{1, 1, 8, 'f', 'o', 'o', ':', ':', 'b', 'a', 'r', 0};
     return lines{
       unmarshal_error(prefix(g, 30)),
       unmarshal_error(prefix(g, 39)),
       unmarshal_error(str),
       unmarshal_error(g, one_element),
       unmarshal_error(unknown),
       unmarshal_error(g + byte_buffer{0}),
       unmarshal_error(flag),
     };
   }},
  {"asl-errors",
   [] {
     return lines{
       asl_error({1, 15}),
       asl_error({1, 1, 0, 0, 0, 0, 2, 1, 'x'}),
       asl_error({1, 2, 0, 0, 0, 0, 2, 1, 0, 0, 0, 0, 0, 2, 0, 0,
                               0, 7, 'a', 'b', 'c'}),
       asl_error(byte_buffer{1, 2, 0, 0, 0, 0, 64}
                              + byte_buffer(10, 0)),
       asl_error(byte_buffer{1, 4, 1, 0, 0, 0, 0, 0, 0, 0, 2}),
       asl_error(byte_buffer{1, 5, 0x2A, 0, 0, 0, 0}),
     };
   }},
};

const char* const protocol_doc = "docs/protocol.md";

// -- the documents against the cases -------------------------------------------

TEST_F(docs_examples, every_marked_block_has_a_case_and_every_case_a_block) {
  auto blocks = marked_blocks(protocol_doc);
  std::set<std::string> cases;
  for (auto& [name, _] : byte_cases)
    cases.insert(name);
  for (auto& [name, _] : error_cases)
    cases.insert(name);
  for (auto& [name, _] : blocks)
    EXPECT_EQ(cases.count(name), 1u) << "no case for <!-- test: " << name << " -->";
  for (auto& name : cases)
    EXPECT_EQ(blocks.count(name), 1u) << "no block marked <!-- test: " << name << " -->";
}

TEST_F(docs_examples, hex_dumps_are_the_bytes_the_encoders_write) {
  auto blocks = marked_blocks(protocol_doc);
  for (auto& [name, produce] : byte_cases) {
    SCOPED_TRACE(name);
    ASSERT_EQ(blocks.count(name), 1u);
    EXPECT_EQ(hex(bytes_of(blocks[name])), hex(produce()));
  }
}

TEST_F(docs_examples, error_lists_are_what_the_decoders_say) {
  auto blocks = marked_blocks(protocol_doc);
  for (auto& [name, produce] : error_cases) {
    SCOPED_TRACE(name);
    ASSERT_EQ(blocks.count(name), 1u);
    EXPECT_EQ(blocks[name], produce());
  }
}

TEST(docs_hex_reader, reads_every_byte_and_refuses_what_is_not_hex) {
  EXPECT_EQ(bytes_of({"01 02   a comment: 03", "   FF 0a", ""}),
            (byte_buffer{0x01, 0x02, 0xFF, 0x0A}));
  // A planted mismatch: a dump one byte off must not equal the encoding.
  EXPECT_NE(hex(bytes_of({"12 42 00"})), hex(byte_buffer{0x12, 0x42, 0x01}));
  EXPECT_NONFATAL_FAILURE(bytes_of({"01 0x2"}), "not a hex byte: '0x2'");
}

// -- the user guide's running_module, compiled and run ------------------------

/// What the user guide's "Embedding a module" shows: returning from the
/// function that holds the running_module stops the module, then the actor
/// system ends (its destructor would otherwise wait for ever).
int embed(caf::actor_system_config& cfg, const module_config& mc,
          bool& had_apps) {
  // [run-module]
  caf::actor_system sys{cfg};
  auto m = herm::run_module(sys, mc);
  if (!m)
    return 1;
  // ... use (*m)->apps; returning stops the module, then sys ends
  // [run-module-end]
  had_apps = static_cast<bool>((*m)->apps);
  return 0;
}

TEST(docs_embedding, a_running_module_stops_when_its_scope_ends) {
  caf::actor_system_config cfg;
  configure(cfg);
  module_config mc;
  mc.routing.id = 7;
  mc.devices.push_back({"lo0", "inproc", "doc-examples", {}});
  bool had_apps = false;
  EXPECT_EQ(embed(cfg, mc, had_apps), 0); // returns: nothing waits for ever
  EXPECT_TRUE(had_apps);
}

} // namespace
