#pragma once

// Per-thread caches of what the data path allocates and frees over and
// over (docs/architecture.md, "Threads"). On the loop scheduler one thread
// makes a packet's buffers and messages and frees them again a moment
// later, many times a second; these caches hand the same memory back
// instead of going to the allocator each time, as CAF's per-thread memory
// cache did before 0.16 and as Cyclone DDS's receive buffer pool does.
//
// - **Blocks** for mailbox elements and message data. Every message CAF
//   0.17 sends costs a heap block for its mailbox element. HERM makes its
//   own hot messages (a received frame, a delivered packet, a packet to
//   write, a request handed to application support, what application
//   support posts to an actor) as `pooled_element`s, and unmarshalled
//   messages from `block_cached` data: their blocks come from the cache.
// - **Byte buffers** for frames, packets and payloads: the device takes
//   one per received frame, application support gives it back once the
//   message in it is decoded; a packet to send is taken the same way and
//   given back by the channel that wrote it.
//
// Bounds: a thread keeps at most `block_cache_limits::per_class` free
// blocks in each of `block_cache_limits::classes` size classes (64-byte
// steps up to 512 bytes; larger blocks are never cached), 72 KiB at most,
// and at most `buffer_cache_limits::count` buffers of at most
// `buffer_cache_limits::max_capacity` bytes, 128 KiB at most. What comes
// back beyond that goes to the allocator (counted in `returned`). Memory
// may be freed on another thread than the one that took it; it then joins
// that thread's cache. Under AddressSanitizer a cached block is poisoned
// until reused.
//
// Time: blocks O(1); buffers O(count). Lock-free, never blocking.

#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <utility>

#include "caf/actor_cast.hpp"
#include "channels/messages.hpp"
#include "caf/mailbox_element.hpp"
#include "caf/message.hpp"

namespace herm {

struct block_cache_limits {
  /// Size classes: 64, 128, ... bytes.
  static constexpr size_t step = 64;
  static constexpr size_t classes = 8;
  /// Free blocks kept per class and thread.
  static constexpr size_t per_class = 32;
};

/// What one of the calling thread's caches did since the thread started.
struct cache_stats {
  /// Blocks or buffers handed out from the cache.
  uint64_t reused = 0;
  /// Handed out from the allocator (cache empty, or a block too large).
  uint64_t allocated = 0;
  /// Given back and kept.
  uint64_t cached = 0;
  /// Given back to the allocator (cache full, too large, or the thread
  /// exiting).
  uint64_t returned = 0;
  /// What the cache holds now.
  size_t held = 0;
};

cache_stats this_thread_block_cache();

struct buffer_cache_limits {
  /// Buffers kept per thread.
  static constexpr size_t count = 16;
  /// Larger buffers are not kept (a UDP datagram fits; a reassembled
  /// packet of tens of kilobytes is rare and goes back).
  static constexpr size_t max_capacity = 8192;
  /// take_buffer(n) hands out a kept buffer of at most max(4 n, small)
  /// bytes, the smallest that fits.
  static constexpr size_t small = 2048;
};

/// What the calling thread's buffer cache did since the thread started.
cache_stats this_thread_buffer_cache();

/// An empty buffer with room for at least `capacity` bytes: the smallest
/// the thread kept that fits and is not much larger (buffer_cache_limits),
/// else a new one.
byte_buffer take_buffer(size_t capacity);

/// Likewise, with a kept buffer of at most `most` bytes: for a buffer that
/// may be kept a long time (a marshalled payload a parked reliable request
/// or a topic's last value holds).
byte_buffer take_buffer(size_t capacity, size_t most);

/// Keeps the storage of `buf` for a later take_buffer on this thread
/// (`buf` is left empty). Buffers without storage are ignored.
void recycle_buffer(byte_buffer&& buf) noexcept;

/// A block of at least `size` bytes, aligned for any object.
void* cached_allocate(size_t size);

/// Gives back a block `cached_allocate(size)` returned, on any thread.
void cached_release(void* ptr, size_t size) noexcept;

/// Gives every class that derives from it the cache's allocation. Its
/// blocks have __STDCPP_DEFAULT_NEW_ALIGNMENT__: a class that derives from
/// it must need no more (those that hold values of any type assert it).
struct block_cached {
  static void* operator new(size_t size) {
    return cached_allocate(size);
  }

  static void operator delete(void* ptr, size_t size) noexcept {
    cached_release(ptr, size);
  }
};

/// caf::mailbox_element_vals with its block from the cache.
template <class... Ts>
class pooled_element final
  : public caf::mailbox_element,
    public caf::detail::tuple_vals_impl<caf::type_erased_tuple, Ts...>,
    public block_cached {
public:
  template <class... Us>
  pooled_element(caf::strong_actor_ptr&& from, caf::message_id id, Us&&... xs)
    : caf::mailbox_element(std::move(from),
                           caf::mailbox_category_corrector<Ts...>::apply(id),
                           forwarding_stack{}),
      caf::detail::tuple_vals_impl<caf::type_erased_tuple, Ts...>(
        std::forward<Us>(xs)...) {
    // nop
  }

  using block_cached::operator new;
  using block_cached::operator delete;

  caf::type_erased_tuple& content() override {
    return *this;
  }

  const caf::type_erased_tuple& content() const override {
    return *this;
  }

  caf::message move_content_to_message() override {
    caf::message_factory f;
    auto& xs = this->data();
    return caf::detail::apply_moved_args(f, caf::detail::get_indices(xs), xs);
  }

  caf::message copy_content_to_message() const override {
    caf::message_factory f;
    auto& xs = this->data();
    return caf::detail::apply_args(f, caf::detail::get_indices(xs), xs);
  }
};

/// A mailbox element holding `xs` from `sender` with id `mid`, its block
/// from the cache.
template <class... Ts>
caf::mailbox_element_ptr make_pooled_element(caf::strong_actor_ptr sender,
                                             caf::message_id mid, Ts&&... xs) {
  static_assert(!(sizeof...(Ts) == 1
                  && (std::is_same_v<std::decay_t<Ts>, caf::message> && ...)),
                "a message goes in make_pooled_message_element");
  using element = pooled_element<typename caf::unbox_message_element<
    typename caf::detail::strip_and_convert<Ts>::type>::type...>;
  static_assert(alignof(element) <= __STDCPP_DEFAULT_NEW_ALIGNMENT__,
                "cached blocks have the default new alignment");
  return caf::mailbox_element_ptr{
    new element(std::move(sender), mid, std::forward<Ts>(xs)...)};
}

/// A mailbox element holding the content of `msg`, its block from the
/// cache (CAF's own wrapper of a message takes a fresh one).
caf::mailbox_element_ptr make_pooled_message_element(caf::strong_actor_ptr sender,
                                                     caf::message_id mid,
                                                     caf::message msg);

/// The content of `what` as a message, without copying or moving its
/// values: a message data block from the cache takes over the element
/// (CAF's move_content_to_message allocates a fresh tuple). An element
/// that already wraps a message gives that up instead. Leaves `what` null
/// or empty.
caf::message take_content(caf::mailbox_element_ptr& what);

/// Enqueues `xs` at `dst` as an anonymous asynchronous message in a pooled
/// element (caf::anon_send without the allocation). Null `dst`: nothing.
template <class Handle, class... Ts>
void pooled_anon_send(const Handle& dst, Ts&&... xs) {
  if (!dst)
    return;
  caf::actor_cast<caf::abstract_actor*>(dst)->enqueue(
    make_pooled_element(nullptr, caf::make_message_id(),
                        std::forward<Ts>(xs)...),
    nullptr);
}

} // namespace herm
