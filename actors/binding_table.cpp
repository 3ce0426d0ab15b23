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

void binding_table::watch(binding& b, module_id self, time_point now,
                          asl_outbox& out) {
  b.last_watch = now;
  if (b.target.module != self)
    out.push(b.target.module, asl_watch{b.target.apo});
}

void binding_table::bind(binding& b, const apo_ref& ref, module_id self,
                         time_point now, asl_outbox& out) {
  b.bound = true;
  b.target = ref;
  watch(b, self, now, out);
}

std::vector<caf::strong_actor_ptr> binding_table::take_proxies() {
  std::vector<caf::strong_actor_ptr> result;
  for (auto& kv : bindings_)
    if (auto p = kv.second.proxy.lock())
      result.push_back(std::move(p));
  bindings_.clear();
  return result;
}

void binding_table::close(uint32_t id, module_id self, asl_outbox& out) {
  auto i = bindings_.find(id);
  if (i == bindings_.end())
    return;
  auto target = std::move(i->second.target);
  bool bound = i->second.bound;
  bindings_.erase(i);
  if (bound && target.module != self
      && bound_to(target.module, target.apo).empty())
    out.push(target.module, asl_unwatch{target.apo});
}

std::vector<binding_table::search>
binding_table::housekeep(time_point now,
                         std::chrono::milliseconds watch_refresh,
                         std::chrono::milliseconds rebind_interval,
                         module_id self, asl_outbox& out) {
  std::vector<search> result;
  for (auto& [id, b] : bindings_) {
    if (b.bound && now - b.last_watch >= watch_refresh)
      watch(b, self, now, out);
    if (!b.bound && b.rebind && !b.searching && b.next_search <= now) {
      b.searching = true;
      auto ms = static_cast<uint32_t>(rebind_interval.count() / 2);
      result.push_back(search{id, apo_query{b.by, b.pattern, ms, true}});
    }
  }
  return result;
}

bool binding_table::found(uint32_t id, const std::vector<apo_ref>& found,
                          module_id self, time_point now,
                          std::chrono::milliseconds rebind_interval,
                          asl_outbox& out) {
  auto b = find(id);
  if (b == nullptr)
    return false;
  b->searching = false;
  b->next_search = now + rebind_interval;
  if (found.empty() || b->bound)
    return false;
  bind(*b, found.front(), self, now, out);
  return true;
}

} // namespace herm
