// hermctl watch's pure core (apps/hermctl/watch.hpp): replies parsed into
// snapshots, links that disappeared kept as "down", and frames drawn from
// two snapshots: rates from counter deltas, route changes, plain text off a
// terminal and a fitted, highlighted screen on one.

#include <gtest/gtest.h>

#include <sstream>

#include "apps/hermctl/watch.hpp"

using namespace hermctl;

namespace {

watch_channel up(uint64_t id, const std::string& device, uint64_t tx_bytes,
                 uint64_t rx_bytes, uint64_t tx_frames, uint64_t rx_frames,
                 uint64_t drops = 0) {
  watch_channel c;
  c.id = id;
  c.device = device;
  c.kind = "udp";
  c.state = "up";
  c.has_stats = true;
  c.tx_bytes = tx_bytes;
  c.rx_bytes = rx_bytes;
  c.tx_frames = tx_frames;
  c.rx_frames = rx_frames;
  c.drops = drops;
  return c;
}

watch_snapshot alpha(uint64_t at_ms) {
  watch_snapshot s;
  s.at_ms = at_ms;
  s.self = 0x30;
  s.name = "alpha";
  s.names = {{0x30, "alpha"}, {0x31, "beta"}, {0x32, "gamma"}};
  s.topics_note = "(not available from this module: unknown command 'topics' "
                  "[unknown_command])";
  return s;
}

size_t count(const std::string& s, const std::string& part) {
  size_t n = 0;
  for (auto pos = s.find(part); pos != std::string::npos; pos = s.find(part, pos + 1))
    ++n;
  return n;
}

} // namespace

TEST(hermctl_watch, byte_rates_read_like_a_person_would_write_them) {
  std::vector<std::pair<double, std::string>> cases{
    {0, "0 B/s"},          {950, "950 B/s"},       {999.4, "999 B/s"},
    {999.6, "1.0 kB/s"},   {1234, "1.2 kB/s"},     {12345, "12 kB/s"},
    {2.5e6, "2.5 MB/s"},   {120e6, "120 MB/s"},    {3e12, "3000 GB/s"},
  };
  for (auto& [in, out] : cases)
    EXPECT_EQ(byte_rate_text(in), out) << in;
}

TEST(hermctl_watch, routes_keep_the_selected_class_0_row_per_destination) {
  auto routes = json::parse(R"([
    {"destination": "0x32", "size_class": 0, "selected": true, "cost": 40,
     "hops": 2, "neighbour_module": "0x31"},
    {"destination": "0x32", "size_class": 1, "selected": true, "cost": 250,
     "hops": 2, "neighbour_module": "0x31"},
    {"destination": "0x33", "size_class": 0, "selected": false, "cost": 90,
     "hops": 3, "neighbour_module": "0x31"},
    {"destination": "0x31", "size_class": 0, "selected": true, "cost": null,
     "hops": 1, "neighbour_module": null},
    {"destination": "zz", "size_class": 0, "selected": true},
    "not a row"])");
  auto got = parse_routes(routes);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0], (watch_route{0x31, std::nullopt, 1, "-"}));
  EXPECT_EQ(got[1], (watch_route{0x32, 40, 2, "0x31"}));
  EXPECT_TRUE(parse_routes(json::object()).empty());
}

TEST(hermctl_watch, channels_sum_their_drop_counters_and_know_when_they_have_none) {
  auto channels = json::parse(R"([
    {"id": 3, "device": "can0", "kind": "can", "state": "retrying", "stats": null},
    {"id": 1, "device": "eth0", "kind": "udp", "state": "up",
     "stats": {"tx_bytes": 100, "rx_bytes": 200, "tx_frames": 3, "rx_frames": 4,
               "tx_dropped": 1, "rx_malformed": 2, "rx_reassembly_dropped": 3,
               "rx_kernel_dropped": 4, "rx_queue_dropped": 5, "rx_orphans": 100}}])");
  auto got = parse_channels(channels);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].device, "eth0");
  EXPECT_TRUE(got[0].has_stats);
  EXPECT_EQ(got[0].tx_bytes, 100u);
  EXPECT_EQ(got[0].rx_frames, 4u);
  EXPECT_EQ(got[0].drops, 15u);
  EXPECT_EQ(got[1].device, "can0");
  EXPECT_EQ(got[1].state, "retrying");
  EXPECT_FALSE(got[1].has_stats);
}

TEST(hermctl_watch, a_link_that_disappears_stays_as_down) {
  auto before = alpha(0);
  before.channels = {up(1, "eth0", 0, 0, 0, 0), up(2, "eth1", 0, 0, 0, 0)};
  auto now = alpha(1000);
  now.channels = {up(1, "eth0", 10, 10, 1, 1)};
  carry_gone(before, now);
  ASSERT_EQ(now.channels.size(), 2u);
  EXPECT_EQ(now.channels[1].device, "eth1");
  EXPECT_EQ(now.channels[1].state, "down");
  EXPECT_FALSE(now.channels[1].has_stats);
  // Still there a frame later, and gone as "down" once the device is back.
  auto later = alpha(2000);
  later.channels = {up(1, "eth0", 20, 20, 2, 2)};
  carry_gone(now, later);
  ASSERT_EQ(later.channels.size(), 2u);
  EXPECT_EQ(later.channels[1].state, "down");
  auto back = alpha(3000);
  back.channels = {up(1, "eth0", 30, 30, 3, 3), up(5, "eth1", 0, 0, 0, 0)};
  carry_gone(later, back);
  ASSERT_EQ(back.channels.size(), 2u);
  EXPECT_EQ(back.channels[1].id, 5u);
  EXPECT_EQ(back.channels[1].state, "up");
}

TEST(hermctl_watch, the_first_frame_has_no_rates_and_no_changes) {
  auto s = alpha(5000);
  s.routes = {{0x31, 10, 1, "0x31"}};
  s.channels = {up(1, "eth0", 1000, 2000, 10, 20)};
  frame_style style;
  style.clock = "12:00:00";
  EXPECT_EQ(render_frame(nullptr, s, style),
            "alpha (0x30)  frame 1, every 1s, 12:00:00\n"
            "\n"
            "modules (2)\n"
            "MODULE  NAME   COST  HOPS  VIA\n"
            "0x30    alpha  0     0     -\n"
            "0x31    beta   10    1     0x31\n"
            "\n"
            "links (1)\n"
            "DEVICE  ID  KIND  STATE  TX B/S  RX B/S  TX FR/S  RX FR/S  DROPS\n"
            "eth0    1   udp   up     -       -       -        -        0\n"
            "\n"
            "route changes (0)\n"
            "(first frame)\n"
            "\n"
            "topics\n"
            "(not available from this module: unknown command 'topics' "
            "[unknown_command])\n"
            "\n");
}

TEST(hermctl_watch, the_next_frame_shows_rates_drops_down_links_and_route_changes) {
  auto before = alpha(1000);
  before.routes = {{0x31, 10, 1, "0x31"}, {0x32, 40, 2, "0x31"}, {0x33, 50, 2, "0x31"}};
  before.channels = {up(1, "eth0", 1000, 2000, 10, 20, 1), up(2, "can0", 0, 0, 0, 0)};
  auto now = alpha(3000);
  now.routes = {{0x31, 10, 1, "0x31"}, {0x32, std::nullopt, 2, "0x31"},
                {0x34, 20, 1, "0x34"}};
  now.channels = {up(1, "eth0", 5000, 3000, 50, 25, 4)};
  carry_gone(before, now);
  frame_style style;
  style.number = 2;
  style.interval_ms = 2000;
  auto frame = render_frame(&before, now, style);
  EXPECT_EQ(frame,
            "alpha (0x30)  frame 2, every 2s\n"
            "\n"
            "modules (4)\n"
            "MODULE  NAME   COST  HOPS  VIA\n"
            "0x30    alpha  0     0     -\n"
            "0x31    beta   10    1     0x31\n"
            "0x32    gamma  inf   2     0x31\n"
            "0x34    -      20    1     0x34\n"
            "\n"
            "links (2)\n"
            "DEVICE  ID  KIND  STATE  TX B/S    RX B/S   TX FR/S  RX FR/S  DROPS\n"
            "eth0    1   udp   up     2.0 kB/s  500 B/s  20.0     2.5      4 (+3)\n"
            "can0    2   udp   down   -         -        -        -        -\n"
            "\n"
            "route changes (3)\n"
            "0x32  cost 40 -> inf\n"
            "0x33  gone (was cost 50 via 0x31)\n"
            "0x34  new: cost 20 via 0x34, 1 hop\n"
            "\n"
            "topics\n"
            "(not available from this module: unknown command 'topics' "
            "[unknown_command])\n"
            "\n");
  EXPECT_EQ(frame.find('\x1b'), std::string::npos);
}

TEST(hermctl_watch, errors_of_a_poll_head_the_frame) {
  auto s = alpha(0);
  s.errors = {"routes: no reply from /r/a.sock within 300 ms"};
  auto frame = render_frame(nullptr, s, frame_style{});
  EXPECT_NE(frame.find("alpha (0x30)  frame 1, every 1s\n"
                       "error: routes: no reply from /r/a.sock within 300 ms\n"),
            std::string::npos)
    << frame;
}

TEST(hermctl_watch, sub_second_intervals_show_in_ms) {
  frame_style style;
  style.interval_ms = 500;
  auto frame = render_frame(nullptr, alpha(0), style);
  EXPECT_EQ(frame.rfind("alpha (0x30)  frame 1, every 500 ms\n", 0), 0u) << frame;
}

TEST(hermctl_watch, on_a_terminal_it_redraws_in_place_fits_the_width_and_highlights) {
  auto before = alpha(0);
  before.routes = {{0x31, 10, 1, "0x31"}, {0x32, 40, 2, "0x31"}};
  before.channels = {up(1, "eth0", 0, 0, 0, 0)};
  auto now = alpha(1000);
  now.routes = {{0x31, 10, 1, "0x31"}, {0x32, 60, 3, "0x31"}};
  now.channels = {up(1, "eth0", 100, 100, 1, 1)};
  frame_style style;
  style.ansi = true;
  style.width = 20;
  auto frame = render_frame(&before, now, style);
  EXPECT_EQ(frame.rfind("\x1b[H", 0), 0u) << "starts at home";
  EXPECT_EQ(frame.substr(frame.size() - 3), "\x1b[J") << "clears the rest";
  // Every line: at most 20 visible columns, then clear-to-end-of-line.
  std::istringstream lines{frame};
  std::string l;
  size_t n = 0;
  while (std::getline(lines, l)) {
    if (l.rfind("\x1b[H", 0) == 0)
      l = l.substr(3);
    if (l == "\x1b[J")
      break;
    ++n;
    ASSERT_GE(l.size(), 3u);
    EXPECT_EQ(l.substr(l.size() - 3), "\x1b[K") << l;
    auto text = l.substr(0, l.size() - 3);
    for (auto esc : {std::string{"\x1b[7m"}, std::string{"\x1b[0m"}})
      for (auto p = text.find(esc); p != std::string::npos; p = text.find(esc))
        text.erase(p, esc.size());
    EXPECT_LE(text.size(), 20u) << text;
  }
  EXPECT_GT(n, 10u);
  // The changed route, in the modules table and in the changes, reversed.
  EXPECT_NE(frame.find("\x1b[7m0x32    gamma  60  "), std::string::npos) << frame;
  EXPECT_NE(frame.find("\x1b[7m0x32  cost 40 -> 60,"), std::string::npos) << frame;
  EXPECT_EQ(count(frame, "\x1b[7m"), 2u) << frame;
}

TEST(hermctl_watch, clipping_counts_characters_not_bytes) {
  auto s = alpha(0);
  s.name = "\xc3\xa9t\xc3\xa9";  // "été": 3 columns, 5 bytes
  frame_style style;
  style.ansi = true;
  style.width = 7;
  auto frame = render_frame(nullptr, s, style);
  EXPECT_EQ(frame.rfind("\x1b[H\xc3\xa9t\xc3\xa9 (0x\x1b[K\n", 0), 0u) << frame;
}

TEST(hermctl_watch, sections_are_bounded) {
  auto s = alpha(0);
  for (uint32_t i = 0; i < max_watch_rows + 10; ++i)
    s.routes.push_back({static_cast<herm::module_id>(0x100 + i), 10, 1, "0x31"});
  auto frame = render_frame(nullptr, s, frame_style{});
  EXPECT_NE(frame.find("modules (" + std::to_string(max_watch_rows + 11) + ")"),
            std::string::npos);
  EXPECT_NE(frame.find("... 11 more\n"), std::string::npos) << frame.substr(0, 200);
}

TEST(hermctl_watch, topics_show_the_networks_topics_and_their_publish_rates) {
  // The merged "topics" rows of "all": sonar published by two modules,
  // one of whose counters wraps; odom by five, none of which answered.
  auto rows = [](uint32_t a, uint32_t b) {
    return json::array(
      {{{"topic", "sonar"}, {"type", "herm::hermd::srf04_reading"},
        {"publishers", {"0x30", "0x31"}}, {"subscribers", {"0x31", "0x32"}},
        {"seqs", {{"0x30", a}, {"0x31", b}}}},
       {{"topic", "odom"}, {"type", ""},
        {"publishers", {"0x31", "0x32", "0x33", "0x34", "0x35"}},
        {"subscribers", json::array()}, {"seqs", json::object()}},
       "not a row",
       {{"topic", "bad"}, {"publishers", "0x31"}, {"seqs", {{"0x31", -4}}}}});
  };
  auto before = alpha(1000);
  before.topics = parse_topics(rows(4294967290u, 100));
  auto now = alpha(3000);
  // 20 messages from 0x30 (wrapped) and 10 from 0x31 in 2 s: 15 per second.
  now.topics = parse_topics(rows(14, 110));
  now.topic_modules = 2;
  now.topics_unanswered = {"0x33"};
  ASSERT_TRUE(now.topics);
  ASSERT_EQ(now.topics->size(), 3u);
  EXPECT_EQ((*now.topics)[1].topic, "odom");
  EXPECT_EQ((*now.topics)[1].publisher_count, 5u);
  EXPECT_TRUE((*now.topics)[0].seqs.empty());  // "bad": no list, no seqs
  auto frame = render_frame(&before, now, frame_style{});
  auto at = frame.find("topics (3, from 2 modules)\n");
  ASSERT_NE(at, std::string::npos) << frame;
  EXPECT_EQ(frame.substr(at),
            "topics (3, from 2 modules)\n"
            "(no answer from 0x33)\n"
            "TOPIC  TYPE                        PUB/S  PUBLISHERS              "
            "SUBSCRIBERS\n"
            "bad    -                           -      -                       -\n"
            "odom   -                           -      0x31,0x32,0x33,0x34 +1  -\n"
            "sonar  herm::hermd::srf04_reading  15.0   0x30,0x31               "
            "0x31,0x32\n"
            "\n");
  // The first frame has no rates.
  auto first = render_frame(nullptr, now, frame_style{});
  EXPECT_NE(first.find("sonar  herm::hermd::srf04_reading  -      0x30,0x31"),
            std::string::npos)
    << first;
  EXPECT_FALSE(parse_topics(json::object()));
  EXPECT_NE(render_frame(nullptr, alpha(0), frame_style{}).find("topics\n(not available from"),
            std::string::npos);
}

TEST(hermctl_watch, a_frame_taller_than_the_terminal_ends_with_what_was_left_out) {
  auto s = alpha(0);
  for (uint32_t i = 0; i < 30; ++i)
    s.routes.push_back({static_cast<herm::module_id>(0x100 + i), 10, 1, "0x31"});
  frame_style style;
  style.ansi = true;
  style.height = 10;
  auto frame = render_frame(nullptr, s, style);
  EXPECT_EQ(count(frame, "\n"), 9u) << frame;
  EXPECT_NE(frame.find("\x1b[7m... 36 more lines: a taller terminal shows them\x1b[0m"),
            std::string::npos)
    << frame;
  // Off a terminal nothing is cut.
  style.ansi = false;
  EXPECT_NE(render_frame(nullptr, s, style).find("0x11D "), std::string::npos);
}
