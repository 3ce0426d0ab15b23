// Table 1 of the HERM paper, the static link cost and the size-aware cost,
// and device option parsing.

#include <gtest/gtest.h>

#include "actors/runtime/error.hpp"
#include "channels/link_profile.hpp"
#include "channels/options.hpp"

using namespace herm;

namespace {

struct table1_row {
  const char* profile;
  uint64_t bandwidth;
  uint32_t mtu;
  uint32_t cost;
};

// The paper's Table 1, row by row.
const table1_row table1[] = {
  {"usb1.1", 12'000'000, 1023, 19},   {"usb2.0", 480'000'000, 1024, 3},
  {"ieee1394a", 400'000'000, 4096, 4}, {"ieee1394b", 800'000'000, 8192, 1},
  {"can2.0", 1'000'000, 8, 30},        {"ethernet", 100'000'000, 1500, 10},
  {"rs232c", 19'200, 32, 47},
};

} // namespace

TEST(link_profile, builtin_profiles_reproduce_table_1) {
  ASSERT_EQ(builtin_profiles().size(), std::size(table1));
  for (auto& row : table1) {
    SCOPED_TRACE(row.profile);
    auto* p = find_profile(row.profile);
    ASSERT_NE(p, nullptr);
    EXPECT_EQ(p->bandwidth_bps, row.bandwidth);
    EXPECT_EQ(p->mtu, row.mtu);
    EXPECT_EQ(link_cost(*p), row.cost);
    EXPECT_EQ(link_cost(row.bandwidth), row.cost);
  }
}

TEST(link_profile, cost_scales_with_the_delay_coefficient) {
  EXPECT_EQ(link_cost(100'000'000, 2.0), 20u);
  EXPECT_EQ(link_cost(1'000'000, 0.5), 15u);
}

TEST(link_profile, cost_is_at_least_one_and_refuses_zero_bandwidth) {
  EXPECT_EQ(link_cost(10'000'000'000ull), 1u); // faster than 1 Gbit/s
  EXPECT_EQ(link_cost(0), UINT32_MAX);
  EXPECT_EQ(link_cost(1000, 0.0), UINT32_MAX);
}

TEST(link_profile, message_cost_counts_frames_of_the_mtu) {
  auto can = *find_profile("can2.0");
  auto eth = *find_profile("ethernet");
  EXPECT_EQ(message_cost(can, 0), 30u);
  EXPECT_EQ(message_cost(can, 8), 30u);
  EXPECT_EQ(message_cost(can, 9), 60u);
  EXPECT_EQ(message_cost(can, 1000), 30u * 125);
  EXPECT_EQ(message_cost(eth, 1000), 10u);
  EXPECT_EQ(message_cost(eth, 1501), 20u);
}

TEST(link_profile, unknown_profile_is_not_found) {
  EXPECT_EQ(find_profile("token-ring"), nullptr);
}

// -- option_reader ---------------------------------------------------------------

namespace {

device_config dev(option_map opts) {
  return device_config{"fw0", "emu", "/tmp/x", std::move(opts)};
}

} // namespace

TEST(option_reader, resolves_a_profile_with_overrides) {
  auto cfg = dev({{"profile", "can2.0"}, {"bandwidth", "500000"}});
  option_reader r{cfg};
  auto p = r.profile("ethernet");
  ASSERT_TRUE(p) << render(p.error());
  EXPECT_EQ(p->name, "can2.0");
  EXPECT_EQ(p->bandwidth_bps, 500'000u);
  EXPECT_EQ(p->mtu, 8u);
  EXPECT_FALSE(r.finish());
}

TEST(option_reader, names_device_option_and_value_on_bad_numbers) {
  auto cfg = dev({{"loss", "lots"}});
  option_reader r{cfg};
  auto x = r.real("loss", 0, 0, 1);
  ASSERT_FALSE(x);
  EXPECT_TRUE(is(x.error(), ec::invalid_parameter));
  auto text = render(x.error());
  EXPECT_NE(text.find("device 'fw0'"), std::string::npos) << text;
  EXPECT_NE(text.find("'loss'"), std::string::npos) << text;
  EXPECT_NE(text.find("'lots'"), std::string::npos) << text;
}

TEST(option_reader, refuses_out_of_range_and_negative_integers) {
  auto cfg = dev({{"station", "300"}, {"queue", "-1"}});
  option_reader r{cfg};
  EXPECT_FALSE(r.u64("station", 0, 1, 254));
  EXPECT_FALSE(r.u64("queue", 0, 0, 100));
}

TEST(option_reader, refuses_unknown_profiles_listing_the_known_ones) {
  auto cfg = dev({{"profile", "firewire"}});
  option_reader r{cfg};
  auto p = r.profile("ethernet");
  ASSERT_FALSE(p);
  auto text = render(p.error());
  EXPECT_NE(text.find("firewire"), std::string::npos) << text;
  EXPECT_NE(text.find("ieee1394a"), std::string::npos) << text;
}

TEST(option_reader, finish_names_every_unread_option) {
  auto cfg = dev({{"station", "1"}, {"lsos", "0.1"}});
  option_reader r{cfg};
  ASSERT_TRUE(r.u64("station", 0, 1, 254));
  auto err = r.finish();
  ASSERT_TRUE(err);
  EXPECT_NE(render(err).find("'lsos'"), std::string::npos) << render(err);
}

TEST(option_reader, parses_flags) {
  auto cfg = dev({{"a", "yes"}, {"b", "off"}, {"c", "maybe"}});
  option_reader r{cfg};
  EXPECT_EQ(*r.flag("a", false), true);
  EXPECT_EQ(*r.flag("b", true), false);
  EXPECT_FALSE(r.flag("c", true));
  EXPECT_EQ(*r.flag("d", true), true);
}
