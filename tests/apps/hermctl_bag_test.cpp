// hermctl's recordings (apps/hermctl/bag.hpp) and the one function that
// turns a raw topic stream's lines into them (record_line,
// apps/hermctl/topics.hpp): pure, no module. The live record and play are
// in hermctl_topics_test.

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "apps/hermctl/bag.hpp"
#include "apps/hermctl/topics.hpp"
#include "tests/support/temp_dir.hpp"

using namespace hermctl;

namespace {

const std::string good_line
  = R"({"topic": "sonar", "publisher": "0x22", "seq": 7,)"
    R"( "time_ns": 1795587266435114751, "types": ["range"], "value": 1.5,)"
    R"( "payload": "0000c03f", "descriptions": [{"name": "range", "kind": "float32"}]})";

std::vector<bag_message> messages(bag& b) {
  std::vector<bag_message> out;
  b.read({}, [&](const bag_message& m) {
    out.push_back(m);
    return true;
  });
  return out;
}

/// good_line with `key`'s value replaced by `value` (JSON text).
std::string with(const std::string& key, const std::string& value) {
  auto at = good_line.find("\"" + key + "\": ");
  EXPECT_NE(at, std::string::npos) << key;
  auto from = at + key.size() + 4;
  auto depth = 0;
  auto to = from;
  for (; to < good_line.size(); ++to) {
    auto ch = good_line[to];
    if (ch == '[' || ch == '{')
      ++depth;
    else if (ch == ']' || ch == '}')
      --depth;
    if (depth < 0 || (depth == 0 && ch == ','))
      break;
  }
  return good_line.substr(0, from) + value + good_line.substr(to);
}

} // namespace

TEST(hermctl_bag, a_recording_reads_back_what_was_written) {
  herm::test::temp_dir dir{"herm-bag"};
  auto path = dir.path() + "/run.db3";
  {
    auto b = bag::create(path);
    b.describe("range", R"({"name":"range"})");
    b.set_metadata("module", "0x30");
    for (uint32_t i = 0; i < 3; ++i)
      b.add({"sonar", "range", 1000 + i, 0x22, i, {uint8_t(i), 0xFF}});
    b.add({"cmd", "twist", 999, 0x23, 5, {}});
    b.flush();
  }
  auto b = bag::open(path);
  auto info = b.info();
  EXPECT_EQ(info.messages, 4u);
  EXPECT_EQ(info.start_ns, 999);
  EXPECT_EQ(info.end_ns, 1002);
  ASSERT_EQ(info.topics.size(), 2u);
  EXPECT_EQ(info.descriptions.at("range"), R"({"name":"range"})");
  EXPECT_EQ(info.metadata.at("module"), "0x30");
  auto all = messages(b);
  ASSERT_EQ(all.size(), 4u);
  EXPECT_EQ(all[0].topic, "cmd"); // time order
  EXPECT_TRUE(all[0].payload.empty());
  EXPECT_EQ(all[3].payload, (std::vector<uint8_t>{2, 0xFF}));
  EXPECT_EQ(all[3].publisher, 0x22u);
  EXPECT_EQ(all[3].seq, 2u);
  std::vector<bag_message> sonar;
  b.read({"sonar"}, [&](const bag_message& m) {
    sonar.push_back(m);
    return sonar.size() < 2; // stops after two
  });
  EXPECT_EQ(sonar.size(), 2u);
}

TEST(hermctl_bag, an_existing_file_is_not_overwritten) {
  herm::test::temp_dir dir{"herm-bag"};
  auto path = dir.path() + "/run.db3";
  bag::create(path).flush();
  EXPECT_THROW(bag::create(path), bag_error);
  EXPECT_THROW(bag::open(dir.path() + "/missing.db3"), bag_error);
}

TEST(hermctl_bag, a_stream_line_becomes_one_message_with_its_descriptions) {
  herm::test::temp_dir dir{"herm-bag"};
  auto path = dir.path() + "/run.db3";
  {
    auto b = bag::create(path);
    EXPECT_TRUE(record_line(b, good_line));
    b.flush();
  }
  auto b = bag::open(path);
  auto all = messages(b);
  ASSERT_EQ(all.size(), 1u);
  EXPECT_EQ(all[0].topic, "sonar");
  EXPECT_EQ(all[0].type, "range");
  EXPECT_EQ(all[0].publisher, 0x22u);
  EXPECT_EQ(all[0].seq, 7u);
  EXPECT_EQ(all[0].time_ns, 1795587266435114751);
  EXPECT_EQ(all[0].payload, (std::vector<uint8_t>{0, 0, 0xC0, 0x3F}));
  EXPECT_EQ(b.info().descriptions.count("range"), 1u);
}

TEST(hermctl_bag, a_malformed_stream_line_is_skipped_and_the_recording_goes_on) {
  herm::test::temp_dir dir{"herm-bag"};
  auto path = dir.path() + "/run.db3";
  const std::vector<std::string> bad{
    "",
    "not json",
    "[1, 2]",
    R"({"dropped": 3})", // a note, not a value
    with("publisher", R"("0xZZ")"),
    with("publisher", R"("0x123456")"),
    with("publisher", "34"),
    with("seq", R"("7")"),
    with("time_ns", "1.5"),
    with("topic", "null"),
    with("payload", R"("0g")"),
    with("payload", "[0, 0]"),
    with("types", "[1]"),
  };
  {
    auto b = bag::create(path);
    for (auto& l : bad)
      EXPECT_FALSE(record_line(b, l)) << l;
    EXPECT_TRUE(record_line(b, good_line));
    b.flush();
  }
  auto b = bag::open(path);
  EXPECT_EQ(b.info().messages, 1u);
}
