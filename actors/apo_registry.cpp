#include "actors/apo_registry.hpp"

#include "actors/asl_errors.hpp"
#include "actors/runtime/error.hpp"

namespace herm {

apo_registry::apo_registry(uint64_t key, size_t max_watches,
                           app_support_stats& stats)
  : table_(key), max_watches_(max_watches), stats_(&stats) {
  // nop
}

caf::expected<uint32_t> apo_registry::add(std::string name, std::string type,
                                          const caf::actor& apo,
                                          apo_access access) {
  if (auto err = asl_error::check_label("an APO name", name))
    return err;
  if (auto err = asl_error::check_label("an APO type", type))
    return err;
  if (!apo)
    return make_error(ec::invalid_parameter, "invalid actor handle");
  if (auto known = number_of(apo.address()))
    return make_error(ec::already_exists,
                      "that actor is registered already (as '"
                        + table_.local(known)->name + "')");
  auto id = table_.add_local(std::move(name), std::move(type));
  apos_.emplace(id, apo);
  numbers_.emplace(apo.address(), id);
  if (access == apo_access::signed_only)
    signed_only_.insert(id);
  ++stats_->registered;
  return id;
}

const caf::actor* apo_registry::find(uint32_t apo) const {
  auto i = apos_.find(apo);
  return i != apos_.end() ? &i->second : nullptr;
}

uint32_t apo_registry::number_of(const caf::actor_addr& who) const {
  auto i = numbers_.find(who);
  return i != numbers_.end() ? i->second : 0;
}

std::optional<std::string> apo_registry::remove(uint32_t apo,
                                                const caf::error& reason,
                                                asl_outbox& out) {
  auto entry = table_.local(apo);
  if (entry == nullptr)
    return std::nullopt;
  auto name = entry->name;
  auto watchers = table_.remove_local(apo);
  signed_only_.erase(apo);
  if (auto i = apos_.find(apo); i != apos_.end()) {
    numbers_.erase(i->second.address());
    apos_.erase(i);
  }
  ++stats_->withdrawn;
  for (auto m : watchers)
    out.push(m, asl_down{apo, to_wire(reason)});
  out.push(broadcast_module, asl_withdraw{apo, name});
  return name;
}

void apo_registry::on_watch(module_id src, const asl_watch& w,
                            module_id self, asl_outbox& out) {
  bool refused = false;
  if (!table_.watch(w.apo, src, max_watches_, &refused))
    out.push(src, asl_down{w.apo, to_wire(asl_error::no_such_apo(w.apo, self))});
  else if (refused)
    ++stats_->watches_refused;
}

std::vector<apo_info> apo_registry::list(module_id self, time_point now) const {
  std::vector<apo_info> result;
  for (auto& [apo, e] : table_.locals())
    result.push_back(apo_info{apo_ref{self, apo, e.name, e.type}, true,
                              static_cast<uint32_t>(e.watchers.size()), 0});
  for (auto& [key, e] : table_.remotes())
    result.push_back(apo_info{
      apo_ref{key.first, key.second, e.name, e.type}, false, 0,
      static_cast<uint32_t>(
        std::chrono::duration_cast<std::chrono::milliseconds>(now - e.heard)
          .count())});
  return result;
}

} // namespace herm
