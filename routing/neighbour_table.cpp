#include "routing/neighbour_table.hpp"

#include <algorithm>

namespace herm {

neighbour_table::neighbour_table() : neighbour_table(limits{}) {
}

neighbour_table::neighbour_table(limits lim) : limits_(lim) {
}

neighbour_table::hello_result
neighbour_table::heard(const next_hop& from, module_id id, uint64_t instance,
                       std::chrono::milliseconds interval, time_point now) {
  auto i = neighbours_.find(from);
  auto result = hello_result::refreshed;
  if (i == neighbours_.end()) {
    auto& here = on_channel_[from.channel];
    if (neighbours_.size() >= limits_.total || here >= limits_.per_channel) {
      if (here == 0)
        on_channel_.erase(from.channel);
      ++refused_;
      return hello_result::refused;
    }
    ++here;
    i = neighbours_.emplace(from, neighbour{}).first;
    result = hello_result::added;
  } else if (i->second.instance != instance) {
    result = hello_result::restarted;
  }
  departed_.erase(from);
  auto& n = i->second;
  n.id = id;
  n.instance = instance;
  n.last_hello = now;
  n.interval = interval;
  return result;
}

void neighbour_table::erase(std::map<next_hop, neighbour>::iterator i) {
  auto c = on_channel_.find(i->first.channel);
  if (c != on_channel_.end() && --c->second == 0)
    on_channel_.erase(c);
  neighbours_.erase(i);
}

bool neighbour_table::goodbye(const next_hop& from, uint64_t instance) {
  auto i = neighbours_.find(from);
  if (i == neighbours_.end() || i->second.instance != instance)
    return false;
  erase(i);
  departed_[from] = departure{instance, ++next_departure_};
  if (departed_.size() > limits_.total) {
    // Bound: forget the oldest goodbye. O(n), and only a goodbye of a
    // neighbour held (its hello came first) gets here.
    departed_.erase(std::min_element(departed_.begin(), departed_.end(),
                                     [](const auto& x, const auto& y) {
                                       return x.second.order < y.second.order;
                                     }));
  }
  return true;
}

bool neighbour_table::departed(const next_hop& from, uint64_t instance) const {
  auto d = departed_.find(from);
  return d != departed_.end() && d->second.instance == instance;
}

void neighbour_table::remove_channel(channel_id ch) {
  auto i = neighbours_.lower_bound(next_hop{ch, 0});
  while (i != neighbours_.end() && i->first.channel == ch)
    i = neighbours_.erase(i);
  on_channel_.erase(ch);
}

std::vector<next_hop> neighbour_table::expire(time_point now,
                                              std::vector<neighbour>* was) {
  std::vector<next_hop> lost;
  for (auto i = neighbours_.begin(); i != neighbours_.end();) {
    auto next = std::next(i);
    if (now - i->second.last_hello > silence_limit(i->second)) {
      lost.push_back(i->first);
      if (was != nullptr)
        was->push_back(i->second);
      erase(i);
    }
    i = next;
  }
  return lost;
}

std::optional<neighbour_table::time_point>
neighbour_table::next_expiry() const {
  std::optional<time_point> first;
  for (auto& [at, n] : neighbours_) {
    // expire() drops it once the silence exceeds the limit.
    auto t = n.last_hello + silence_limit(n) + duration{1};
    if (!first || t < *first)
      first = t;
  }
  return first;
}

neighbour_table::duration
neighbour_table::silence_limit(const neighbour& n) const {
  auto interval = std::max(n.interval, limits_.hello_interval);
  return std::chrono::duration_cast<duration>(interval * limits_.hello_loss);
}

const neighbour_table::neighbour*
neighbour_table::find(const next_hop& at) const {
  auto i = neighbours_.find(at);
  return i != neighbours_.end() ? &i->second : nullptr;
}

} // namespace herm
