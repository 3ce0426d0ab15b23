#include "actors/discovery_table.hpp"

#include <algorithm>

namespace herm {

discovery_table::discovery_table(uint64_t key, size_t max_found,
                                 app_table& table, app_support_stats& stats)
  : ids_(key), max_found_(max_found), table_(table), stats_(&stats) {
  // nop
}

uint32_t discovery_table::start(apo_query q, module_id self, callback finish,
                                asl_outbox& out) {
  auto qid = ids_.next();
  while (running_.count(qid) != 0)
    qid = ids_.next();
  auto& d = running_[qid];
  d.query = std::move(q);
  for (auto& e : table_.match(d.query.by, d.query.pattern))
    d.found.insert(apo_ref{self, e.apo, e.name, e.type});
  d.finish = std::move(finish);
  if (!satisfied(qid)) {
    out.push(broadcast_module, asl_query{qid, d.query.by, d.query.pattern});
    ++stats_->queries_sent;
  }
  return qid;
}

bool discovery_table::satisfied(uint32_t qid) const {
  auto i = running_.find(qid);
  return i != running_.end() && i->second.query.first
         && !i->second.found.empty();
}

void discovery_table::on_query(module_id src, const asl_query& q,
                               asl_outbox& out) {
  auto matches = table_.match(q.by, q.pattern);
  if (matches.empty())
    return;
  ++stats_->queries_answered;
  asl_answer a{q.query_id, {}};
  for (auto& e : matches) {
    a.entries.push_back(std::move(e));
    if (a.entries.size() == max_answer_entries) {
      out.push(src, a);
      a.entries.clear();
    }
  }
  if (!a.entries.empty())
    out.push(src, std::move(a));
}

bool discovery_table::on_answer(module_id src, const asl_answer& a,
                                time_point now) {
  ++stats_->answers_received;
  for (auto& e : a.entries)
    if (!table_.learn(src, e, now, max_found_))
      ++stats_->remote_apos_refused;
  auto i = running_.find(a.query_id);
  if (i == running_.end())
    return false;
  auto& d = i->second;
  for (auto& e : a.entries)
    if (app_table::matches(d.query.by, d.query.pattern, e.name, e.type)) {
      apo_ref ref{src, e.apo, e.name, e.type};
      if (d.found.size() >= max_found_ && d.found.count(ref) == 0)
        ++stats_->discovery_entries_refused;
      else
        d.found.insert(std::move(ref));
    }
  return satisfied(a.query_id);
}

std::optional<discovery_table::finished>
discovery_table::finish(uint32_t qid, module_id self) {
  auto i = running_.find(qid);
  if (i == running_.end())
    return std::nullopt;
  finished result{std::move(i->second.finish),
                  {i->second.found.begin(), i->second.found.end()}};
  running_.erase(i);
  std::stable_partition(result.found.begin(), result.found.end(),
                        [&](const apo_ref& r) { return r.module == self; });
  return result;
}

std::vector<uint32_t> discovery_table::running() const {
  std::vector<uint32_t> result;
  for (auto& kv : running_)
    result.push_back(kv.first);
  return result;
}

} // namespace herm
