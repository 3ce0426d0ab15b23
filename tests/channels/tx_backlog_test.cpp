// The transmit backlog's order and drop policy (channels/tx_backlog.hpp).

#include "channels/tx_backlog.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

using namespace herm;

namespace {

/// Queues a packet of `frames` frames of `size` bytes each, the first byte
/// of each frame being `tag`. Returns admit()'s verdict.
bool queue(tx_backlog& b, uint8_t prio, uint8_t tag, size_t frames,
           size_t size = 8, bool started = false) {
  if (!started && !b.admit(prio, tx_backlog::cost(frames * size, frames)))
    return false;
  b.open(prio, started);
  for (size_t i = 0; i < frames; ++i) {
    std::vector<uint8_t> f(size, static_cast<uint8_t>(i));
    f[0] = tag;
    b.append(0x10 + tag, f.data(), f.size());
  }
  return true;
}

/// Takes up to `n` frames; returns their tags as a string.
std::string drain(tx_backlog& b, size_t n = SIZE_MAX) {
  std::string out;
  while (n-- > 0) {
    auto* f = b.front();
    if (f == nullptr)
      break;
    out += static_cast<char>(f->bytes[0]);
    b.pop();
  }
  return out;
}

} // namespace

TEST(tx_backlog, starts_empty_and_bounded) {
  tx_backlog b{1000};
  EXPECT_TRUE(b.empty());
  EXPECT_EQ(b.front(), nullptr);
  EXPECT_EQ(b.max_bytes(), 1000u);
}

TEST(tx_backlog, most_urgent_class_first_fifo_within_a_class) {
  tx_backlog b{1 << 20};
  queue(b, prio_bulk, 'a', 2);
  queue(b, prio_normal, 'b', 1);
  queue(b, prio_bulk, 'c', 1);
  queue(b, prio_control, 'd', 2);
  queue(b, prio_normal, 'e', 1);
  EXPECT_EQ(drain(b), "ddbeaac");
  EXPECT_TRUE(b.empty());
  EXPECT_EQ(b.bytes(), 0u);
  EXPECT_EQ(b.packets(), 0u);
}

TEST(tx_backlog, a_started_packet_finishes_before_a_more_urgent_one) {
  tx_backlog b{1 << 20};
  queue(b, prio_bulk, 'a', 3);
  EXPECT_EQ(drain(b, 1), "a"); // the driver took a's first frame
  queue(b, prio_control, 'c', 2);
  EXPECT_EQ(drain(b), "aacc");
}

TEST(tx_backlog, a_packet_started_on_the_driver_goes_first) {
  tx_backlog b{1 << 20};
  queue(b, prio_control, 'c', 1);
  // The channel sent part of 'b' straight to the driver before its queue
  // filled up: its remainder must not be overtaken.
  queue(b, prio_bulk, 'b', 2, 8, true);
  EXPECT_EQ(drain(b), "bbc");
}

TEST(tx_backlog, frames_keep_destination_and_priority) {
  tx_backlog b{1 << 20};
  queue(b, 7, 'x', 1); // above bulk: queued as bulk, priority kept
  auto* f = b.front();
  ASSERT_NE(f, nullptr);
  EXPECT_EQ(f->dst, 0x10u + 'x');
  EXPECT_EQ(f->priority, 7u);
  EXPECT_EQ(f->bytes.size(), 8u);
}

TEST(tx_backlog, a_full_backlog_evicts_less_urgent_packets_newest_first) {
  auto one = tx_backlog::cost(8, 1); // one 1-frame packet
  tx_backlog b{4 * one};
  ASSERT_TRUE(queue(b, prio_normal, 'n', 1));
  ASSERT_TRUE(queue(b, prio_bulk, 'a', 1));
  ASSERT_TRUE(queue(b, prio_bulk, 'b', 1));
  ASSERT_TRUE(queue(b, prio_high, 'h', 1));
  // Control packets keep coming: once full, the newest bulk packet goes
  // first, then the older one, then normal, then high.
  for (char t : std::string{"0123456"})
    queue(b, prio_control, static_cast<uint8_t>(t), 1);
  EXPECT_LE(b.bytes(), b.max_bytes());
  auto& s = b.stats();
  EXPECT_EQ(s.evicted[prio_bulk], 2u);
  EXPECT_EQ(s.evicted[prio_normal], 1u);
  EXPECT_EQ(s.evicted[prio_high], 1u);
  EXPECT_EQ(s.evicted[prio_control], 0u);
  EXPECT_GT(s.refused[prio_control], 0u); // only control packets left
  auto out = drain(b);
  EXPECT_EQ(out.find_first_of("abnh"), std::string::npos) << out;
  EXPECT_EQ(out, "012345") << "control packets in order, the last refused";
}

TEST(tx_backlog, a_less_urgent_packet_never_evicts_a_more_urgent_one) {
  auto one = tx_backlog::cost(8, 1);
  tx_backlog b{2 * one};
  ASSERT_TRUE(queue(b, prio_control, 'c', 1));
  ASSERT_TRUE(queue(b, prio_high, 'h', 1));
  EXPECT_FALSE(queue(b, prio_bulk, 'b', 1));
  EXPECT_FALSE(queue(b, prio_high, 'i', 1)); // same class: no eviction
  EXPECT_EQ(b.stats().refused[prio_bulk], 1u);
  EXPECT_EQ(b.stats().refused[prio_high], 1u);
  EXPECT_EQ(drain(b), "ch");
}

TEST(tx_backlog, never_evicts_the_packet_in_progress) {
  auto three = tx_backlog::cost(24, 3);
  tx_backlog b{three + 8};
  ASSERT_TRUE(queue(b, prio_bulk, 'a', 3));
  EXPECT_EQ(drain(b, 1), "a");
  // No room without evicting 'a', which has started: refused.
  EXPECT_FALSE(queue(b, prio_control, 'c', 3));
  EXPECT_EQ(b.stats().evicted[prio_bulk], 0u);
  EXPECT_EQ(drain(b), "aa");
}

TEST(tx_backlog, a_packet_larger_than_the_bound_is_refused) {
  tx_backlog b{100};
  ASSERT_TRUE(queue(b, prio_bulk, 'a', 1));
  EXPECT_FALSE(queue(b, prio_control, 'c', 20));
  EXPECT_EQ(b.stats().refused[prio_control], 1u);
  EXPECT_EQ(b.stats().evicted[prio_bulk], 0u); // nothing evicted in vain
}

TEST(tx_backlog, accounts_bytes_and_peak) {
  tx_backlog b{1 << 20};
  queue(b, prio_normal, 'a', 2, 10);
  queue(b, prio_normal, 'b', 1, 5);
  auto full = 2 * (10 + tx_backlog::frame_overhead) + 5 + tx_backlog::frame_overhead;
  EXPECT_EQ(b.bytes(), full);
  EXPECT_EQ(b.packets(), 2u);
  drain(b, 1);
  EXPECT_EQ(b.bytes(), full - 10 - tx_backlog::frame_overhead);
  drain(b);
  EXPECT_EQ(b.bytes(), 0u);
  EXPECT_EQ(b.stats().peak_bytes, full);
}

// -- peek: the batch the channel hands to link_driver::send_batch -------------

namespace {

/// The tags of what peek() returns with room for `max` frames.
std::string peek_tags(const tx_backlog& b, size_t max) {
  std::vector<tx_frame> out(max);
  auto n = b.peek(out.data(), out.size());
  EXPECT_LE(n, max);
  std::string tags;
  for (size_t i = 0; i < n; ++i)
    tags += static_cast<char>(out[i].data[0]);
  return tags;
}

} // namespace

TEST(tx_backlog, peek_lists_frames_in_the_order_front_and_pop_hand_them_out) {
  tx_backlog b{1 << 20};
  queue(b, prio_bulk, 'a', 3);
  EXPECT_EQ(drain(b, 1), "a"); // 'a' has started
  queue(b, prio_normal, 'n', 2);
  queue(b, prio_control, 'c', 1);
  queue(b, prio_bulk, 'b', 1);
  queue(b, prio_control, 'd', 2);
  queue(b, prio_high, 'h', 1);
  auto copy = b;
  auto want = drain(copy);
  EXPECT_EQ(want, "aacddhnnb");
  EXPECT_EQ(peek_tags(b, 64), want);
  // peek changes nothing.
  EXPECT_EQ(drain(b), want);
}

TEST(tx_backlog, peek_keeps_each_frames_destination_size_and_priority) {
  tx_backlog b{1 << 20};
  queue(b, 7, 'x', 2, 5);
  std::vector<tx_frame> out(4);
  ASSERT_EQ(b.peek(out.data(), out.size()), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(out[i].dst, 0x10u + 'x');
    EXPECT_EQ(out[i].size, 5u);
    EXPECT_EQ(out[i].priority, 7u);
    EXPECT_EQ(out[i].data[1], i);
  }
}

TEST(tx_backlog, peek_is_bounded_and_pop_n_takes_what_it_listed) {
  tx_backlog b{1 << 20};
  EXPECT_EQ(peek_tags(b, 8), "");
  queue(b, prio_normal, 'a', 2);
  queue(b, prio_normal, 'b', 2);
  queue(b, prio_control, 'c', 1);
  EXPECT_EQ(peek_tags(b, 3), "caa");
  b.pop(3);
  EXPECT_EQ(peek_tags(b, 3), "bb");
  b.pop(2);
  EXPECT_TRUE(b.empty());
  EXPECT_EQ(b.bytes(), 0u);
  EXPECT_EQ(peek_tags(b, 3), "");
}

TEST(tx_backlog, peek_stops_at_an_opened_packet_whose_frames_are_still_coming) {
  tx_backlog b{1 << 20};
  b.open(prio_control, false); // no frame appended yet
  queue(b, prio_normal, 'n', 1);
  EXPECT_EQ(b.front(), nullptr);
  EXPECT_EQ(peek_tags(b, 8), "");
}
