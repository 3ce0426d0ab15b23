#include "channels/thread_cache.hpp"

#include <algorithm>
#include <array>
#include <new>

#include "caf/detail/dynamic_message_data.hpp"
#include "caf/downstream_msg.hpp"
#include "caf/message_builder.hpp"
#include "caf/upstream_msg.hpp"

#if defined(__SANITIZE_ADDRESS__)
#  include <sanitizer/asan_interface.h>
#  define HERM_POISON(ptr, size) ASAN_POISON_MEMORY_REGION(ptr, size)
#  define HERM_UNPOISON(ptr, size) ASAN_UNPOISON_MEMORY_REGION(ptr, size)
#else
#  define HERM_POISON(ptr, size) ((void) (ptr), (void) (size))
#  define HERM_UNPOISON(ptr, size) ((void) (ptr), (void) (size))
#endif

namespace herm {

namespace {

using limits = block_cache_limits;

constexpr size_t largest = limits::step * limits::classes;

/// A free block's first bytes link it to the next one.
struct free_block {
  free_block* next;
};

/// One thread's free lists. Trivially destructible, so that a block freed
/// while the thread's other thread-locals are being destroyed still finds
/// valid lists (then `closed` sends it to the allocator).
struct free_lists {
  free_block* heads[limits::classes];
  uint16_t counts[limits::classes];
  bool closed;
  cache_stats stats;
};

thread_local free_lists lists;

/// Empties the lists when the thread ends.
struct drain_at_exit {
  bool armed = false;

  ~drain_at_exit() {
    lists.closed = true;
    for (size_t k = 0; k < limits::classes; ++k) {
      while (auto* b = lists.heads[k]) {
        HERM_UNPOISON(b, (k + 1) * limits::step);
        lists.heads[k] = b->next;
        ::operator delete(b);
        ++lists.stats.returned;
      }
      lists.counts[k] = 0;
    }
    lists.stats.held = 0;
  }
};

/// Touched before a thread caches its first block, so that it exists (and
/// empties the lists) when the thread ends.
thread_local drain_at_exit drain;

/// The class of a block of `size` bytes (its size rounded up to a step).
size_t class_of(size_t size) noexcept {
  return (size + limits::step - 1) / limits::step - 1;
}

// -- buffers ---------------------------------------------------------------

/// Trivially destructible, like free_lists.
struct buffer_state {
  size_t count;
  bool closed;
  cache_stats stats;
};

thread_local buffer_state buffers;

struct buffer_shelf {
  std::array<byte_buffer, buffer_cache_limits::count> slots;

  ~buffer_shelf() {
    buffers.closed = true;
    buffers.stats.returned += buffers.count;
    buffers.count = 0;
    buffers.stats.held = 0;
  }
};

thread_local buffer_shelf shelf;

} // namespace

cache_stats this_thread_buffer_cache() {
  return buffers.stats;
}

byte_buffer take_buffer(size_t capacity) {
  // Not much larger than asked: a buffer may be kept for a while (a
  // reliable request waiting for its ack), and should not hold a large
  // frame's storage meanwhile.
  return take_buffer(capacity,
                     std::max(capacity * 4, buffer_cache_limits::small));
}

byte_buffer take_buffer(size_t capacity, size_t most) {
  if (!buffers.closed && buffers.count > 0) {
    // The smallest that fits.
    size_t best = buffers.count;
    for (size_t i = 0; i < buffers.count; ++i) {
      auto have = shelf.slots[i].capacity();
      if (have >= capacity && have <= most
          && (best == buffers.count
              || have < shelf.slots[best].capacity()))
        best = i;
    }
    if (best != buffers.count) {
      auto& slot = shelf.slots[best];
      byte_buffer result = std::move(slot);
      if (best + 1 != buffers.count)
        slot = std::move(shelf.slots[buffers.count - 1]);
      --buffers.count;
      --buffers.stats.held;
      ++buffers.stats.reused;
      return result;
    }
  }
  ++buffers.stats.allocated;
  byte_buffer result;
  result.reserve(capacity);
  return result;
}

void recycle_buffer(byte_buffer&& buf) noexcept {
  if (buf.capacity() == 0)
    return;
  if (buffers.closed || buf.capacity() > buffer_cache_limits::max_capacity
      || buffers.count == buffer_cache_limits::count) {
    ++buffers.stats.returned;
    byte_buffer{}.swap(buf);
    return;
  }
  buf.clear();
  shelf.slots[buffers.count++] = std::move(buf);
  buf = byte_buffer{};
  ++buffers.stats.held;
  ++buffers.stats.cached;
}

cache_stats this_thread_block_cache() {
  return lists.stats;
}

void* cached_allocate(size_t size) {
  if (size == 0 || size > largest) {
    ++lists.stats.allocated;
    return ::operator new(size);
  }
  auto k = class_of(size);
  if (auto* b = lists.heads[k]) {
    HERM_UNPOISON(b, (k + 1) * limits::step);
    lists.heads[k] = b->next;
    --lists.counts[k];
    --lists.stats.held;
    ++lists.stats.reused;
    return b;
  }
  ++lists.stats.allocated;
  // Every block of a class has the class's full size, so any of them can
  // serve any size in the class.
  return ::operator new((k + 1) * limits::step);
}

void cached_release(void* ptr, size_t size) noexcept {
  if (ptr == nullptr)
    return;
  if (size == 0 || size > largest) {
    ++lists.stats.returned;
    ::operator delete(ptr);
    return;
  }
  auto k = class_of(size);
  if (lists.closed || lists.counts[k] >= limits::per_class) {
    ++lists.stats.returned;
    ::operator delete(ptr);
    return;
  }
  // As in cached_allocate: a thread may only ever free blocks.
  drain.armed = true;
  auto* b = static_cast<free_block*>(ptr);
  b->next = lists.heads[k];
  lists.heads[k] = b;
  ++lists.counts[k];
  ++lists.stats.held;
  ++lists.stats.cached;
  HERM_POISON(b, (k + 1) * limits::step);
}

namespace {

/// caf's mailbox_element_wrapper (mailbox_element.cpp), with its block from
/// the cache.
class pooled_message_element final : public caf::mailbox_element,
                                     public block_cached {
public:
  pooled_message_element(caf::strong_actor_ptr&& from, caf::message_id id,
                         caf::message&& msg)
    : caf::mailbox_element(std::move(from), corrected(msg, id),
                           forwarding_stack{}),
      msg_(std::move(msg)) {
    // content() must be able to reach the data.
    if (msg_.vals() == nullptr)
      msg_ = caf::message_builder{}.to_message();
  }

  using block_cached::operator new;
  using block_cached::operator delete;

  caf::type_erased_tuple& content() override {
    return msg_;
  }

  const caf::type_erased_tuple& content() const override {
    return msg_.content();
  }

  caf::message move_content_to_message() override {
    return std::move(msg_);
  }

  caf::message copy_content_to_message() const override {
    return msg_;
  }

private:
  static caf::message_id corrected(const caf::message& msg,
                                   caf::message_id mid) {
    auto tt = msg.type_token();
    if (tt == caf::make_type_token<caf::downstream_msg>())
      return caf::mailbox_category_corrector<caf::downstream_msg>::apply(mid);
    if (tt == caf::make_type_token<caf::upstream_msg>())
      return caf::mailbox_category_corrector<caf::upstream_msg>::apply(mid);
    return mid;
  }

  caf::message msg_;
};

/// A message's data that owns a mailbox element and shows its content.
class element_data final : public caf::detail::message_data,
                           public block_cached {
public:
  explicit element_data(caf::mailbox_element_ptr what)
    : what_(std::move(what)) {
    // nop
  }

  using block_cached::operator new;
  using block_cached::operator delete;

  caf::detail::message_data* copy() const override {
    caf::detail::dynamic_message_data::elements xs;
    xs.reserve(size());
    for (size_t i = 0; i < size(); ++i)
      xs.emplace_back(content().copy(i));
    return new caf::detail::dynamic_message_data(std::move(xs));
  }

  void* get_mutable(size_t pos) override {
    return what_->content().get_mutable(pos);
  }

  caf::error load(size_t pos, caf::deserializer& source) override {
    return what_->content().load(pos, source);
  }

  size_t size() const noexcept override {
    return content().size();
  }

  uint32_t type_token() const noexcept override {
    return content().type_token();
  }

  caf::rtti_pair type(size_t pos) const noexcept override {
    return content().type(pos);
  }

  const void* get(size_t pos) const noexcept override {
    return content().get(pos);
  }

  std::string stringify(size_t pos) const override {
    return content().stringify(pos);
  }

  using caf::detail::message_data::copy;

  caf::type_erased_value_ptr copy(size_t pos) const override {
    return content().copy(pos);
  }

  caf::error save(size_t pos, caf::serializer& sink) const override {
    return content().save(pos, sink);
  }

private:
  const caf::type_erased_tuple& content() const noexcept {
    return static_cast<const caf::mailbox_element&>(*what_).content();
  }

  caf::mailbox_element_ptr what_;
};

} // namespace

caf::message take_content(caf::mailbox_element_ptr& what) {
  if (!what)
    return {};
  auto& xs = what->content();
  if (dynamic_cast<caf::message*>(&xs) != nullptr || xs.empty())
    return what->move_content_to_message();
  // Only the values live on; the forwarding chain is not the message's.
  what->stages.clear();
  return caf::message{
    caf::message::data_ptr{new element_data(std::move(what)), false}};
}

caf::mailbox_element_ptr make_pooled_message_element(caf::strong_actor_ptr sender,
                                                     caf::message_id mid,
                                                     caf::message msg) {
  return caf::mailbox_element_ptr{
    new pooled_message_element(std::move(sender), mid, std::move(msg))};
}

} // namespace herm
