#include "channels/tx_backlog.hpp"

#include <algorithm>
#include <cassert>

namespace herm {

tx_backlog::tx_backlog(size_t max_bytes) : max_bytes_(max_bytes) {
  // nop
}

bool tx_backlog::admit(uint8_t prio, size_t cost) {
  auto cls = std::min<size_t>(prio, classes - 1);
  if (bytes_ + cost <= max_bytes_)
    return true;
  // What evicting every less urgent packet not yet started would free.
  size_t freeable = 0;
  for (auto c = cls + 1; c < classes; ++c)
    for (auto& p : queues_[c])
      if (p.next == 0 && !(c == started_ && &p == &queues_[c].front()))
        freeable += p.bytes;
  if (bytes_ - freeable + cost > max_bytes_) {
    ++stats_.refused[cls];
    return false;
  }
  for (auto c = classes - 1; c > cls && bytes_ + cost > max_bytes_; --c) {
    auto& q = queues_[c];
    // Newest first; never the started packet at the front.
    while (!q.empty() && bytes_ + cost > max_bytes_) {
      auto& p = q.back();
      if (p.next != 0 || (c == started_ && q.size() == 1))
        break;
      bytes_ -= p.bytes;
      --packets_;
      ++stats_.evicted[c];
      q.pop_back();
    }
  }
  assert(bytes_ + cost <= max_bytes_);
  return true;
}

void tx_backlog::open(uint8_t prio, bool started) {
  auto cls = std::min<size_t>(prio, classes - 1);
  auto& q = queues_[cls];
  if (started) {
    assert(started_ == classes);
    q.emplace_front();
    started_ = cls;
  } else {
    q.emplace_back();
  }
  open_ = cls;
  open_front_ = started;
  open_priority_ = prio;
  ++packets_;
}

void tx_backlog::append(link_addr dst, const uint8_t* data, size_t size) {
  assert(open_ < classes);
  auto& q = queues_[open_];
  auto& p = open_front_ ? q.front() : q.back();
  p.frames.push_back(frame{dst, open_priority_, byte_buffer(data, data + size)});
  p.bytes += size + frame_overhead;
  bytes_ += size + frame_overhead;
  stats_.peak_bytes = std::max(stats_.peak_bytes, bytes_);
}

std::deque<tx_backlog::packet>* tx_backlog::current() noexcept {
  if (started_ < classes)
    return &queues_[started_];
  for (auto& q : queues_)
    if (!q.empty())
      return &q;
  return nullptr;
}

const std::deque<tx_backlog::packet>* tx_backlog::current() const noexcept {
  return const_cast<tx_backlog*>(this)->current();
}

const tx_backlog::frame* tx_backlog::front() const noexcept {
  auto* q = current();
  if (q == nullptr)
    return nullptr;
  auto& p = q->front();
  // An opened packet may have no frame yet (its first frames still coming).
  if (p.next >= p.frames.size())
    return nullptr;
  return &p.frames[p.next];
}

void tx_backlog::pop() {
  auto* q = current();
  assert(q != nullptr && !q->empty());
  auto& p = q->front();
  assert(p.next < p.frames.size());
  auto n = p.frames[p.next].bytes.size() + frame_overhead;
  p.frames[p.next].bytes = byte_buffer{}; // free early
  ++p.next;
  p.bytes -= n;
  bytes_ -= n;
  auto cls = static_cast<size_t>(q - queues_.data());
  if (p.next == p.frames.size()) {
    q->pop_front();
    --packets_;
    if (started_ == cls)
      started_ = classes;
    if (open_ == cls && open_front_)
      open_ = classes;
  } else {
    started_ = cls;
  }
}

size_t tx_backlog::peek(tx_frame* out, size_t max) const noexcept {
  size_t k = 0;
  // Takes packet p's remaining frames; false when p has none left (an
  // opened packet whose frames are still coming: front() stops there too).
  auto take = [&](const packet& p) {
    if (p.next >= p.frames.size())
      return false;
    for (auto i = p.next; i < p.frames.size() && k < max; ++i) {
      auto& f = p.frames[i];
      out[k++] = tx_frame{f.dst, f.bytes.data(), f.bytes.size(), f.priority};
    }
    return true;
  };
  // The started packet first, then by class, FIFO within a class: what
  // current() picks after each packet is done.
  if (started_ < classes && !take(queues_[started_].front()))
    return k;
  for (size_t c = 0; c < classes; ++c) {
    auto& q = queues_[c];
    for (size_t i = c == started_ ? 1 : 0; i < q.size() && k < max; ++i)
      if (!take(q[i]))
        return k;
  }
  return k;
}

void tx_backlog::pop(size_t n) {
  for (size_t i = 0; i < n; ++i)
    pop();
}

} // namespace herm
