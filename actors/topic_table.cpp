#include "actors/topic_table.hpp"

#include <algorithm>

namespace herm {

namespace {

template <class Map>
void expire_leases(Map& subs, topic_table::time_point now) {
  for (auto i = subs.begin(); i != subs.end();)
    i = i->second < now ? subs.erase(i) : std::next(i);
}

} // namespace

topic_table::topic_table(size_t max_peers) : max_peers_(max_peers) {
  // nop
}

topic_table::topic* topic_table::find(const std::string& name) {
  auto i = topics_.find(name);
  return i != topics_.end() ? &i->second : nullptr;
}

// -- publisher side -----------------------------------------------------------

topic_table::topic& topic_table::publish(const std::string& name,
                                         caf::message msg, byte_buffer payload,
                                         time_point now, bool& first) {
  auto& t = topics_[name];
  first = !t.publishing;
  t.publishing = true;
  ++t.seq;
  t.has_last = true;
  t.last = std::move(msg);
  t.last_payload = std::move(payload);
  expire_leases(t.remote_subs, now);
  return t;
}

const topic_table::topic*
topic_table::subscribed(const std::string& name, module_id src,
                        std::chrono::milliseconds lease, time_point now) {
  auto t = find(name);
  if (t == nullptr || !t->publishing)
    return nullptr;
  bool fresh = t->remote_subs.count(src) == 0;
  if (fresh && t->remote_subs.size() >= max_peers_) {
    ++stats_.subscribers_refused;
    return nullptr;
  }
  t->remote_subs[src] = now + std::min(lease, max_lease);
  return fresh && t->has_last ? t : nullptr;
}

void topic_table::unsubscribed(const std::string& name, module_id src) {
  if (auto t = find(name))
    t->remote_subs.erase(src);
}

// -- subscriber side ----------------------------------------------------------

topic_table::topic* topic_table::subscribe(const std::string& name,
                                           const caf::actor& sub) {
  auto& t = topics_[name];
  if (std::find(t.local_subs.begin(), t.local_subs.end(), sub)
      != t.local_subs.end())
    return nullptr;
  t.local_subs.push_back(sub);
  return &t;
}

std::vector<std::string> topic_table::unsubscribe(const caf::actor_addr& who,
                                                  const std::string* only) {
  std::vector<std::string> result;
  for (auto i = topics_.begin(); i != topics_.end();) {
    auto& t = i->second;
    if (only == nullptr || i->first == *only) {
      auto before = t.local_subs.size();
      t.local_subs.erase(std::remove_if(t.local_subs.begin(),
                                        t.local_subs.end(),
                                        [&](const caf::actor& a) {
                                          return a.address() == who;
                                        }),
                         t.local_subs.end());
      if (before > 0 && t.local_subs.empty()) {
        result.push_back(i->first);
        t.last_seq.clear();
      }
    }
    if (t.local_subs.empty() && !t.publishing)
      i = topics_.erase(i);
    else
      ++i;
  }
  return result;
}

const topic_table::topic*
topic_table::received(const std::string& name, module_id src, uint32_t seq) {
  auto t = find(name);
  if (t == nullptr || t->local_subs.empty())
    return nullptr; // no longer interested; the lease runs out
  auto last = t->last_seq.find(src);
  if (last != t->last_seq.end()) {
    if (seq == last->second)
      return nullptr; // the same value again (a late joiner's copy)
    if (seq > last->second + 1)
      stats_.publications_lost += seq - last->second - 1;
    last->second = seq;
  } else if (t->last_seq.size() < max_peers_) {
    t->last_seq.emplace(src, seq);
  } else {
    // Delivered, but its gaps and repeats go unnoticed.
    ++stats_.publishers_refused;
  }
  return t;
}

// -- both ---------------------------------------------------------------------

void topic_table::module_lost(module_id m) {
  for (auto& kv : topics_) {
    kv.second.remote_subs.erase(m);
    kv.second.last_seq.erase(m);
  }
}

std::vector<std::string> topic_table::housekeep(time_point now) {
  std::vector<std::string> due;
  for (auto& [name, t] : topics_) {
    if (!t.local_subs.empty() && t.next_refresh <= now)
      due.push_back(name);
    expire_leases(t.remote_subs, now);
  }
  return due;
}

} // namespace herm
