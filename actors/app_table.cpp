#include "actors/app_table.hpp"

namespace herm {

app_table::app_table(uint64_t key) : numbers_(key) {
  // nop
}

uint32_t app_table::add_local(std::string name, std::string type) {
  // Skip numbers still in use after a wrap.
  auto apo = numbers_.next();
  while (locals_.count(apo) != 0)
    apo = numbers_.next();
  locals_.emplace(apo, local_entry{std::move(name), std::move(type), {}});
  return apo;
}

std::set<module_id> app_table::remove_local(uint32_t apo) {
  auto i = locals_.find(apo);
  if (i == locals_.end())
    return {};
  auto result = std::move(i->second.watchers);
  watches_ -= result.size();
  locals_.erase(i);
  return result;
}

const app_table::local_entry* app_table::local(uint32_t apo) const {
  auto i = locals_.find(apo);
  return i != locals_.end() ? &i->second : nullptr;
}

bool app_table::matches(query_by by, const std::string& pattern,
                        const std::string& name, const std::string& type) {
  switch (by) {
    case query_by::name:
      return name == pattern;
    case query_by::type:
      return type == pattern;
    case query_by::any:
      return true;
  }
  return false;
}

std::vector<asl_entry> app_table::match(query_by by,
                                        const std::string& pattern) const {
  std::vector<asl_entry> result;
  for (auto& [apo, e] : locals_)
    if (matches(by, pattern, e.name, e.type))
      result.push_back(asl_entry{apo, e.name, e.type});
  return result;
}

bool app_table::watch(uint32_t apo, module_id m, size_t max_watches,
                      bool* refused) {
  auto i = locals_.find(apo);
  if (i == locals_.end())
    return false;
  auto& ws = i->second.watchers;
  if (ws.count(m) == 0) {
    if (watches_ >= max_watches) {
      if (refused != nullptr)
        *refused = true;
      return true;
    }
    ws.insert(m);
    ++watches_;
  }
  return true;
}

void app_table::unwatch(uint32_t apo, module_id m) {
  auto i = locals_.find(apo);
  if (i != locals_.end())
    watches_ -= i->second.watchers.erase(m);
}

void app_table::drop_watcher(module_id m) {
  for (auto& kv : locals_)
    watches_ -= kv.second.watchers.erase(m);
}

bool app_table::learn(module_id m, const asl_entry& e, time_point now,
                      size_t max_remotes) {
  auto key = std::make_pair(m, e.apo);
  auto i = remotes_.find(key);
  if (i == remotes_.end()) {
    if (remotes_.size() >= max_remotes)
      return false;
    remotes_.emplace(key, remote_entry{e.name, e.type, now});
    return true;
  }
  i->second = remote_entry{e.name, e.type, now};
  return true;
}

void app_table::forget(module_id m, uint32_t apo) {
  remotes_.erase({m, apo});
}

void app_table::forget_module(module_id m) {
  remotes_.erase(remotes_.lower_bound({m, 0}),
                 remotes_.upper_bound({m, UINT32_MAX}));
}

void app_table::expire(time_point now,
                       std::chrono::steady_clock::duration ttl) {
  for (auto i = remotes_.begin(); i != remotes_.end();)
    i = now - i->second.heard > ttl ? remotes_.erase(i) : std::next(i);
}

} // namespace herm
