#include "actors/topic_table.hpp"

#include <algorithm>

#include "actors/app_support.hpp"
#include "actors/text_form.hpp"

namespace herm {

namespace {

template <class Map>
void expire_leases(Map& subs, topic_table::time_point now) {
  for (auto i = subs.begin(); i != subs.end();)
    i = i->second < now ? subs.erase(i) : std::next(i);
}

} // namespace

topic_table::topic_table(size_t max_peers, std::chrono::milliseconds lease,
                         app_support_stats& stats)
  : max_peers_(max_peers), lease_(lease), stats_(&stats) {
  // nop
}

const topic_table::topic* topic_table::find(const std::string& name) const {
  auto i = topics_.find(name);
  return i != topics_.end() ? &i->second : nullptr;
}

void topic_table::announce(const std::string& name, topic& t, module_id dst,
                           time_point now, asl_outbox& out) {
  out.push(dst, asl_subscribe{name, static_cast<uint32_t>(lease_.count())});
  t.next_refresh = now + lease_ / 3;
}

void topic_table::send_last(const std::string& name, const topic& t,
                            module_id dst, asl_outbox& out) {
  out.push(dst, asl_publish{name, t.seq, t.last_payload});
  ++stats_->publications_sent;
}

// -- this module's publishers and subscribers ---------------------------------

const topic_table::topic&
topic_table::publish(const std::string& name, caf::message msg,
                     byte_buffer payload, time_point now, asl_outbox& out) {
  auto& t = topics_[name];
  if (!t.publishing) {
    t.publishing = true;
    // Subscribers that are already waiting answer with a subscription.
    out.push(broadcast_module, asl_advertise{name});
  }
  ++stats_->published;
  ++t.seq;
  t.has_last = true;
  t.last = std::move(msg);
  t.last_payload = std::move(payload);
  t.last_type = first_type_name(t.last_payload.data(), t.last_payload.size());
  expire_leases(t.remote_subs, now);
  for (auto& kv : t.remote_subs)
    send_last(name, t, kv.first, out);
  return t;
}

const topic_table::topic* topic_table::subscribe(const std::string& name,
                                                 const caf::actor& sub,
                                                 time_point now,
                                                 asl_outbox& out,
                                                 bool samples) {
  auto& t = topics_[name];
  auto& subs = samples ? t.sample_subs : t.local_subs;
  if (std::find(subs.begin(), subs.end(), sub) != subs.end())
    return nullptr;
  auto first = !t.interested();
  subs.push_back(sub);
  if (first)
    announce(name, t, broadcast_module, now, out);
  return &t;
}

void topic_table::unsubscribe(const caf::actor_addr& who,
                              const std::string* only, asl_outbox& out) {
  for (auto i = topics_.begin(); i != topics_.end();) {
    auto& t = i->second;
    if (only == nullptr || i->first == *only) {
      auto before = t.interested();
      for (auto* subs : {&t.local_subs, &t.sample_subs})
        subs->erase(std::remove_if(subs->begin(), subs->end(),
                                   [&](const caf::actor& a) {
                                     return a.address() == who;
                                   }),
                    subs->end());
      if (before && !t.interested()) {
        out.push(broadcast_module, asl_unsubscribe{i->first});
        t.last_seq.clear();
      }
    }
    if (!t.interested() && !t.publishing)
      i = topics_.erase(i);
    else
      ++i;
  }
}

// -- other modules ------------------------------------------------------------

void topic_table::on_subscribe(module_id src, const asl_subscribe& s,
                               time_point now, asl_outbox& out) {
  auto i = topics_.find(s.topic);
  if (i == topics_.end() || !i->second.publishing)
    return;
  auto& t = i->second;
  bool fresh = t.remote_subs.count(src) == 0;
  if (fresh && t.remote_subs.size() >= max_peers_) {
    ++stats_->subscribers_refused;
    return;
  }
  t.remote_subs[src] = now + std::min(std::chrono::milliseconds(s.lease_ms),
                                      max_lease);
  if (fresh && t.has_last)
    send_last(s.topic, t, src, out); // a late joiner
}

void topic_table::on_unsubscribe(module_id src, const asl_unsubscribe& u) {
  if (auto i = topics_.find(u.topic); i != topics_.end())
    i->second.remote_subs.erase(src);
}

void topic_table::on_advertise(module_id src, const asl_advertise& a,
                               time_point now, asl_outbox& out) {
  if (auto i = topics_.find(a.topic);
      i != topics_.end() && i->second.interested())
    announce(a.topic, i->second, src, now, out);
}

const topic_table::topic* topic_table::on_publish(module_id src,
                                                  const asl_publish& p) {
  ++stats_->publications_received;
  auto i = topics_.find(p.topic);
  if (i == topics_.end() || !i->second.interested())
    return nullptr; // no longer interested; the lease runs out
  auto& t = i->second;
  auto last = t.last_seq.find(src);
  if (last != t.last_seq.end()) {
    if (p.seq == last->second)
      return nullptr; // the same value again (a late joiner's copy)
    if (p.seq > last->second + 1)
      stats_->publications_lost += p.seq - last->second - 1;
    last->second = p.seq;
  } else if (t.last_seq.size() < max_peers_) {
    t.last_seq.emplace(src, p.seq);
  } else {
    // Delivered, but its gaps and repeats go unnoticed.
    ++stats_->publishers_refused;
  }
  t.last_type = first_type_name(p.payload.data(), p.payload.size());
  return &t;
}

std::vector<topic_info> topic_table::list() const {
  std::vector<topic_info> rows;
  for (auto& [name, t] : topics_) {
    topic_info row;
    row.topic = name;
    row.publishing = t.publishing;
    row.local_subscribers
      = static_cast<uint32_t>(t.local_subs.size() + t.sample_subs.size());
    for (auto& kv : t.remote_subs)
      row.remote_subscribers.push_back(kv.first);
    for (auto& kv : t.last_seq)
      row.publishers.push_back(kv.first);
    row.type = t.last_type;
    row.seq = t.seq;
    rows.push_back(std::move(row));
  }
  return rows;
}

void topic_table::module_lost(module_id m) {
  for (auto& kv : topics_) {
    kv.second.remote_subs.erase(m);
    kv.second.last_seq.erase(m);
  }
}

void topic_table::housekeep(time_point now, asl_outbox& out) {
  for (auto& [name, t] : topics_) {
    if (t.interested() && t.next_refresh <= now)
      announce(name, t, broadcast_module, now, out);
    expire_leases(t.remote_subs, now);
  }
}

} // namespace herm
