#include "actors/binding_table.hpp"

namespace herm {

std::pair<uint32_t, binding&> binding_table::add(time_point now) {
  auto id = next_++;
  auto& b = bindings_[id];
  b.next_search = now;
  return {id, b};
}

binding* binding_table::find(uint32_t id) {
  auto i = bindings_.find(id);
  return i != bindings_.end() ? &i->second : nullptr;
}

std::vector<uint32_t> binding_table::bound_to(module_id m, uint32_t apo) const {
  std::vector<uint32_t> result;
  for (auto& [id, b] : bindings_)
    if (b.bound && b.target.module == m && (apo == 0 || b.target.apo == apo))
      result.push_back(id);
  return result;
}

caf::strong_actor_ptr binding_table::lose(uint32_t id, time_point now) {
  auto i = bindings_.find(id);
  if (i == bindings_.end())
    return nullptr;
  auto& b = i->second;
  if (b.rebind) {
    b.bound = false;
    b.next_search = now;
    return nullptr;
  }
  auto proxy = b.proxy.lock();
  bindings_.erase(i);
  return proxy;
}

std::optional<apo_ref> binding_table::close(uint32_t id, module_id self) {
  auto i = bindings_.find(id);
  if (i == bindings_.end())
    return std::nullopt;
  auto target = std::move(i->second.target);
  bool bound = i->second.bound;
  bindings_.erase(i);
  if (bound && target.module != self
      && bound_to(target.module, target.apo).empty())
    return target;
  return std::nullopt;
}

binding_table::due_list
binding_table::due(time_point now,
                   std::chrono::milliseconds watch_refresh) const {
  due_list result;
  for (auto& [id, b] : bindings_) {
    if (b.bound && now - b.last_watch >= watch_refresh)
      result.watch.push_back(id);
    if (!b.bound && b.rebind && !b.searching && b.next_search <= now)
      result.search.push_back(id);
  }
  return result;
}

} // namespace herm
