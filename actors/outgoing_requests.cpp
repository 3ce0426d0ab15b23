#include "actors/outgoing_requests.hpp"

#include <algorithm>

#include "actors/app_support.hpp"
#include "actors/asl_errors.hpp"
#include "actors/runtime/error.hpp"

namespace herm {

outgoing_requests::outgoing_requests(uint64_t key, size_t max_pending,
                                     reliable_requests& reliable,
                                     app_support_stats& stats)
  : ids_(key), max_(max_pending), reliable_(reliable), stats_(&stats) {
  // nop
}

std::pair<uint64_t, outgoing&> outgoing_requests::add(outgoing out) {
  auto rid = ids_.next();
  return {rid, spare_.emplace(requests_, rid, std::move(out))->second};
}

outgoing* outgoing_requests::expecting(uint64_t rid, module_id src, bool ack) {
  auto i = requests_.find(rid);
  if (i != requests_.end()) {
    auto& out = i->second;
    if (out.tx.dst == src && !(out.reliable && out.tx.sends == 0)
        && !(ack && !out.reliable))
      return &out;
  }
  if (!reliable_.late(rid))
    ++stats_->rx_unexpected_response;
  return nullptr;
}

outgoing_requests::response_step
outgoing_requests::on_response(module_id src, const asl_response& r,
                               time_point now,
                               const binding_table& bindings) {
  response_step step;
  auto out = expecting(r.request_id, src, false);
  if (out == nullptr)
    return step;
  if (out->reliable) {
    reliable_.answered(out->tx, now);
    if (!r.ok && !out->oneway) {
      // The APO is not there (any more): a rebinding proxy's request waits
      // for the next target instead of failing.
      auto err = from_wire(r.error);
      auto b = bindings.find(out->binding);
      if (is(err, app_ec::apo_gone) && b != nullptr && b->rebind) {
        out->tx.sends = 0;
        step.kind = response_step::rebind;
        step.binding = out->binding;
        step.error = std::move(err);
        return step;
      }
    }
    reliable_.complete(r.request_id);
    if (out->oneway) {
      spare_.erase(requests_, r.request_id);
      return step;
    }
  }
  ++stats_->responses_received;
  step.kind = response_step::reply;
  step.out = take(r.request_id);
  return step;
}

void outgoing_requests::on_ack(module_id src, const asl_ack& a,
                               time_point now) {
  auto out = expecting(a.request_id, src, true);
  if (out == nullptr)
    return;
  ++stats_->acks_received;
  if (out->oneway) {
    reliable_.answered(out->tx, now);
    reliable_.complete(a.request_id);
    spare_.erase(requests_, a.request_id);
    return;
  }
  // Being served: probe at the slowest pace until the response comes.
  reliable_.acknowledged(out->tx, now);
}

outgoing outgoing_requests::take(uint64_t rid) {
  auto i = requests_.find(rid);
  auto result = std::move(i->second);
  spare_.erase(requests_, i);
  return result;
}

template <class Pred>
std::vector<outgoing> outgoing_requests::take_if(Pred pred) {
  std::vector<outgoing> result;
  for (auto i = requests_.begin(); i != requests_.end();) {
    if (pred(i->second)) {
      result.push_back(std::move(i->second));
      i = spare_.erase(requests_, i);
    } else {
      ++i;
    }
  }
  return result;
}

std::vector<outgoing> outgoing_requests::take_waiting_on(uint32_t binding,
                                                         module_id dst,
                                                         bool keep_reliable) {
  return take_if([&](const outgoing& out) {
    return (binding != 0 ? out.binding == binding : out.tx.dst == dst)
           && !(keep_reliable && out.reliable);
  });
}

std::vector<outgoing> outgoing_requests::take_expired(time_point now) {
  return take_if([&](const outgoing& out) { return out.deadline <= now; });
}

std::vector<uint64_t>
outgoing_requests::due(time_point now, const std::vector<uint32_t>& forced,
                       bool unacked_only) const {
  std::vector<uint64_t> result;
  for (auto& [rid, out] : requests_) {
    if (!out.reliable)
      continue;
    bool force = std::find(forced.begin(), forced.end(), out.binding)
                   != forced.end()
                 && !(unacked_only && out.tx.acked);
    if (force || out.tx.next_send <= now)
      result.push_back(rid);
  }
  return result;
}

std::vector<outgoing> outgoing_requests::take_all() {
  return take_if([](const outgoing&) { return true; });
}

} // namespace herm
