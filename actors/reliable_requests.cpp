#include "actors/reliable_requests.hpp"

#include <algorithm>
#include <cmath>

#include "actors/app_support.hpp"

namespace herm {

reliable_requests::reliable_requests(config cfg, app_support_stats& stats)
  : cfg_(cfg), stats_(&stats) {
  // nop
}

// -- sender: round trips ------------------------------------------------------

reliable_requests::ms reliable_requests::rto(module_id dst) const {
  auto e = estimate(dst);
  if (e == nullptr)
    return cfg_.rto_initial;
  auto result = ms(static_cast<int64_t>(e->srtt + 4 * e->rttvar + 0.5));
  return std::clamp(result, cfg_.rto_min, cfg_.rto_max);
}

const reliable_requests::rtt_estimate*
reliable_requests::estimate(module_id dst) const {
  auto i = rtt_.find(dst);
  return i != rtt_.end() ? &i->second : nullptr;
}

void reliable_requests::sample(module_id dst,
                               std::chrono::duration<double, std::milli> rtt) {
  auto r = rtt.count();
  auto [i, fresh] = rtt_.try_emplace(dst);
  auto& e = i->second;
  if (fresh) {
    e.srtt = r;
    e.rttvar = r / 2;
  } else {
    e.rttvar = 0.75 * e.rttvar + 0.25 * std::abs(e.srtt - r);
    e.srtt = 0.875 * e.srtt + 0.125 * r;
  }
}

// -- sender: the schedule of one request --------------------------------------

bool reliable_requests::send(transmission& tx, module_id dst, time_point now) {
  if (tx.sends >= cfg_.max_transmissions) {
    defer(tx, now);
    return false;
  }
  if (tx.sends == 0 || tx.dst != dst) {
    tx.sends = 0;
    tx.acked = false;
    tx.first_sent = now;
    tx.rto = rto(dst);
  } else {
    ++stats_->retransmissions;
    tx.rto = std::min(tx.acked ? cfg_.rto_max : tx.rto * 2, cfg_.rto_max);
  }
  ++tx.sends;
  tx.dst = dst;
  tx.next_send = now + tx.rto;
  return true;
}

void reliable_requests::wait(transmission& tx, time_point now) {
  if (!tx.waited) {
    tx.waited = true;
    ++stats_->reliable_waited;
  }
  defer(tx, now);
}

void reliable_requests::defer(transmission& tx, time_point now) const {
  tx.next_send = now + cfg_.tick;
}

void reliable_requests::acknowledged(transmission& tx, time_point now) const {
  tx.acked = true;
  tx.next_send = now + cfg_.rto_max;
}

void reliable_requests::answered(const transmission& tx, time_point now) {
  if (tx.sends == 1)
    sample(tx.dst, now - tx.first_sent);
}

void reliable_requests::complete(uint64_t rid) {
  if (!completed_.insert(rid).second)
    return;
  completed_order_.push_back(rid);
  while (completed_order_.size() > cfg_.cache_size) {
    completed_.erase(completed_order_.front());
    completed_order_.pop_front();
  }
}

bool reliable_requests::late(uint64_t rid) {
  if (completed_.count(rid) == 0)
    return false;
  ++stats_->late_duplicates;
  return true;
}

// -- receiver: duplicate suppression ------------------------------------------

const reliable_requests::cached_reply*
reliable_requests::duplicate(module_id src, uint64_t rid) {
  auto i = cache_.find(key{src, rid});
  if (i == cache_.end())
    return nullptr;
  ++stats_->duplicates_suppressed;
  return &i->second;
}

reliable_requests::cached_reply&
reliable_requests::remember(module_id src, uint64_t rid, bool done,
                            bool oneway, time_point now) {
  while (!cache_order_.empty() && cache_.size() >= cfg_.cache_size) {
    cache_.erase(cache_order_.front().first);
    cache_order_.pop_front();
  }
  key k{src, rid};
  cache_order_.emplace_back(k, now + cfg_.cache_ttl);
  auto& c = cache_[k];
  c.done = done;
  c.oneway = oneway;
  return c;
}

void reliable_requests::respond(module_id src, uint64_t rid,
                                const asl_response& r) {
  if (auto i = cache_.find(key{src, rid}); i != cache_.end()) {
    i->second.done = true;
    i->second.response = r;
  }
}

void reliable_requests::expire(time_point now) {
  while (!cache_order_.empty() && cache_order_.front().second <= now) {
    cache_.erase(cache_order_.front().first);
    cache_order_.pop_front();
  }
}

} // namespace herm
