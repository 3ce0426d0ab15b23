#include "actors/discovery_table.hpp"

#include <algorithm>

namespace herm {

discovery_table::discovery_table(uint64_t key, size_t max_found)
  : ids_(key), max_found_(max_found) {
  // nop
}

uint32_t discovery_table::start(apo_query q, std::vector<apo_ref> local,
                                callback finish) {
  auto qid = ids_.next();
  while (running_.count(qid) != 0)
    qid = ids_.next();
  auto& d = running_[qid];
  d.query = std::move(q);
  d.found.insert(std::make_move_iterator(local.begin()),
                 std::make_move_iterator(local.end()));
  d.finish = std::move(finish);
  return qid;
}

bool discovery_table::satisfied(uint32_t qid) const {
  auto i = running_.find(qid);
  return i != running_.end() && i->second.query.first
         && !i->second.found.empty();
}

bool discovery_table::answered(uint32_t qid, module_id src,
                               const std::vector<asl_entry>& entries) {
  auto i = running_.find(qid);
  if (i == running_.end())
    return false;
  auto& d = i->second;
  for (auto& e : entries)
    if (app_table::matches(d.query.by, d.query.pattern, e.name, e.type)) {
      apo_ref ref{src, e.apo, e.name, e.type};
      if (d.found.size() >= max_found_ && d.found.count(ref) == 0)
        ++stats_.discovery_entries_refused;
      else
        d.found.insert(std::move(ref));
    }
  return satisfied(qid);
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
