// The per-thread caches of blocks and buffers (channels/thread_cache.hpp):
// what they keep, their bounds, and the mailbox elements and messages made
// from them.

#include "channels/thread_cache.hpp"

#include <gtest/gtest.h>

#include <string>
#include <thread>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/scoped_actor.hpp"

using namespace herm;

namespace {

using limits = block_cache_limits;

TEST(block_cache, a_freed_block_serves_the_next_request_of_its_size_class) {
  auto before = this_thread_block_cache();
  void* a = cached_allocate(100);
  cached_release(a, 100);
  // 100 and 120 bytes share the 128-byte class.
  void* b = cached_allocate(120);
  EXPECT_EQ(a, b);
  auto after = this_thread_block_cache();
  EXPECT_EQ(after.reused - before.reused, 1u);
  EXPECT_EQ(after.cached - before.cached, 1u);
  // Another class does not take it.
  cached_release(b, 120);
  void* c = cached_allocate(200);
  EXPECT_NE(b, c);
  cached_release(c, 200);
}

TEST(block_cache, keeps_at_most_its_bound_per_class_and_counts_the_rest) {
  auto before = this_thread_block_cache();
  std::vector<void*> blocks;
  for (size_t i = 0; i < limits::per_class + 5; ++i)
    blocks.push_back(cached_allocate(limits::step * 3));
  for (auto* b : blocks)
    cached_release(b, limits::step * 3);
  auto after = this_thread_block_cache();
  // Whatever the class held before counts against the bound too.
  EXPECT_EQ(after.cached - before.cached + after.returned - before.returned,
            limits::per_class + 5);
  EXPECT_GE(after.returned - before.returned, 5u);
  EXPECT_LE(after.held, limits::per_class * limits::classes);
}

TEST(block_cache, larger_blocks_go_to_the_allocator_both_ways) {
  auto before = this_thread_block_cache();
  auto size = limits::step * limits::classes + 1;
  void* a = cached_allocate(size);
  cached_release(a, size);
  auto after = this_thread_block_cache();
  EXPECT_EQ(after.allocated - before.allocated, 1u);
  EXPECT_EQ(after.returned - before.returned, 1u);
  EXPECT_EQ(after.held, before.held);
}

TEST(block_cache, a_block_freed_on_another_thread_joins_that_threads_cache) {
  void* a = cached_allocate(64);
  cache_stats there;
  std::thread t{[&] {
    cached_release(a, 64);
    void* b = cached_allocate(64);
    EXPECT_EQ(a, b);
    cached_release(b, 64);
    there = this_thread_block_cache();
  }};
  t.join();
  EXPECT_EQ(there.reused, 1u);
  EXPECT_EQ(there.held, 1u);
  // The thread's exit gave it back to the allocator (LeakSanitizer would
  // report it otherwise).
}

TEST(buffer_cache, a_recycled_buffer_comes_back_with_its_storage_and_empty) {
  auto before = this_thread_buffer_cache();
  auto buf = take_buffer(300);
  buf.assign(300, 7);
  auto* storage = buf.data();
  recycle_buffer(std::move(buf));
  EXPECT_EQ(buf.capacity(), 0u);
  auto again = take_buffer(200);
  EXPECT_EQ(again.data(), storage);
  EXPECT_TRUE(again.empty());
  EXPECT_GE(again.capacity(), 300u);
  // Too small for what is asked: a new one.
  recycle_buffer(std::move(again));
  auto bigger = take_buffer(1000);
  EXPECT_NE(bigger.data(), storage);
  auto after = this_thread_buffer_cache();
  EXPECT_EQ(after.reused - before.reused, 1u);
  EXPECT_EQ(after.allocated - before.allocated, 2u);
  EXPECT_EQ(after.held, before.held + 1);
  // Leave the cache as found.
  auto rest = take_buffer(300);
  EXPECT_EQ(rest.data(), storage);
}

TEST(buffer_cache, hands_out_the_smallest_fit_and_no_much_larger_one) {
  auto with_capacity = [](size_t n) {
    byte_buffer x;
    x.reserve(n);
    return x;
  };
  recycle_buffer(with_capacity(1000));
  recycle_buffer(with_capacity(500));
  recycle_buffer(with_capacity(8000));
  EXPECT_EQ(take_buffer(400).capacity(), 500u);
  EXPECT_EQ(take_buffer(400).capacity(), 1000u);
  // 8000 bytes for 100 asked would be kept alive with a small payload.
  auto before = this_thread_buffer_cache();
  EXPECT_EQ(take_buffer(100).capacity(), 100u);
  EXPECT_EQ(this_thread_buffer_cache().allocated - before.allocated, 1u);
  EXPECT_EQ(take_buffer(4000).capacity(), 8000u);
}

TEST(buffer_cache, a_buffer_kept_long_comes_from_a_tighter_bound) {
  // An empty cache, whatever ran before on this thread.
  while (this_thread_buffer_cache().held > 0)
    (void) take_buffer(1, buffer_cache_limits::max_capacity);
  byte_buffer kept;
  kept.reserve(1024);
  recycle_buffer(std::move(kept));
  // Within the default bound of take_buffer(128), not within 512.
  auto before = this_thread_buffer_cache();
  EXPECT_EQ(take_buffer(128, 512).capacity(), 128u);
  EXPECT_EQ(this_thread_buffer_cache().allocated - before.allocated, 1u);
  EXPECT_EQ(take_buffer(128).capacity(), 1024u);
}

TEST(buffer_cache, keeps_at_most_its_bound_and_no_large_buffers) {
  auto before = this_thread_buffer_cache();
  for (size_t i = 0; i < buffer_cache_limits::count + 3; ++i)
    recycle_buffer(byte_buffer(64));
  recycle_buffer(byte_buffer(buffer_cache_limits::max_capacity + 1));
  // Nothing to keep.
  recycle_buffer(byte_buffer{});
  auto after = this_thread_buffer_cache();
  EXPECT_EQ(after.held, buffer_cache_limits::count);
  EXPECT_EQ(after.returned - before.returned,
            4u + before.held); // what was held before counts too
  for (size_t i = 0; i < buffer_cache_limits::count; ++i)
    (void) take_buffer(1);
  EXPECT_EQ(this_thread_buffer_cache().held, 0u);
}

class pooled_elements : public testing::Test {
protected:
  caf::actor_system_config cfg;
  caf::actor_system sys{cfg};
  caf::scoped_actor self{sys};
};

TEST_F(pooled_elements, carry_their_values_sender_and_id_and_reuse_their_block) {
  auto send = [&](int x) {
    self->ctrl()->enqueue(make_pooled_element(self->ctrl(),
                                              caf::make_message_id(), x,
                                              std::string{"x"}),
                          nullptr);
  };
  auto receive = [&] {
    int got = 0;
    self->receive([&](int x, const std::string& s) {
      EXPECT_EQ(s, "x");
      EXPECT_EQ(self->current_sender(), self->ctrl());
      got = x;
    });
    return got;
  };
  send(1);
  EXPECT_EQ(receive(), 1);
  auto before = this_thread_block_cache();
  send(2);
  EXPECT_EQ(receive(), 2);
  EXPECT_EQ(this_thread_block_cache().reused - before.reused, 1u);
}

TEST_F(pooled_elements, wrap_a_message_as_cafs_own_wrapper_does) {
  auto mid = caf::make_message_id().response_id();
  auto what = make_pooled_message_element(nullptr, mid,
                                          caf::make_message(3, 4.5));
  EXPECT_EQ(what->mid, mid);
  EXPECT_TRUE((what->content().match_elements<int, double>()));
  auto empty = make_pooled_message_element(nullptr, mid, caf::message{});
  EXPECT_EQ(empty->content().size(), 0u);
}

TEST_F(pooled_elements, take_content_keeps_the_values_in_their_element) {
  auto what = caf::make_mailbox_element(nullptr, caf::make_message_id(), {},
                                        1, std::string{"two"});
  auto* in_element = what->content().get(1);
  auto msg = take_content(what);
  // Not copied: the message shows the values where the element holds them.
  EXPECT_EQ(msg.cvals()->get(1), in_element);
  EXPECT_EQ(what, nullptr);
  ASSERT_TRUE((msg.match_elements<int, std::string>()));
  EXPECT_EQ(msg.get_as<int>(0), 1);
  EXPECT_EQ(msg.get_as<std::string>(1), "two");
  EXPECT_EQ(to_string(msg), "(1, \"two\")");
  // Copy on write: changing a copy leaves the original alone.
  auto copy = msg;
  copy.get_mutable_as<int>(0) = 3;
  EXPECT_EQ(msg.get_as<int>(0), 1);
  EXPECT_EQ(copy.get_as<int>(0), 3);
  EXPECT_EQ(copy.get_as<std::string>(1), "two");
  // A handler matches it as any message.
  self->send(self, std::move(msg));
  self->receive([](int x, const std::string& s) {
    EXPECT_EQ(x, 1);
    EXPECT_EQ(s, "two");
  });
}

TEST_F(pooled_elements, take_content_of_a_wrapped_message_moves_that_message) {
  auto inner = caf::make_message(7);
  auto* data = inner.cvals().get();
  auto what = caf::make_mailbox_element(nullptr, caf::make_message_id(), {},
                                        std::move(inner));
  auto msg = take_content(what);
  EXPECT_EQ(msg.cvals().get(), data);
  EXPECT_EQ(msg.get_as<int>(0), 7);
}

} // namespace
