#include "actors/runtime/system.hpp"

#include "caf/actor_system_config.hpp"
#include "caf/atom.hpp"

#include "actors/runtime/error.hpp"
#include "actors/runtime/loop_scheduler.hpp"
#include "actors/runtime/type_ids.hpp"

namespace herm {

namespace {

void register_types(caf::actor_system_config& cfg) {
  cfg.add_message_types<caf::id_block::herm_channels>();
  cfg.add_message_types<caf::id_block::herm_routing>();
  cfg.add_message_types<caf::id_block::herm_asl>();
  cfg.add_error_category(caf::atom("herm"),
                         [](uint8_t code, caf::atom_value,
                            const caf::message& ctx) -> std::string {
                           std::string result = "herm.";
                           result += error_name(code);
                           if (ctx.match_elements<std::string>()) {
                             result += ": ";
                             result += ctx.get_as<std::string>(0);
                           }
                           return result;
                         });
}

} // namespace

void configure(caf::actor_system_config& cfg,
               const std::string& scheduler_policy, size_t threads,
               size_t busy_poll_us) {
  register_types(cfg);
  if (scheduler_policy == "stealing")
    cfg.set("scheduler.policy", caf::atom("stealing"));
  else if (scheduler_policy == "sharing")
    cfg.set("scheduler.policy", caf::atom("sharing"));
  else
    load_loop_scheduler(cfg, busy_poll_us);
  if (threads > 0)
    cfg.set("scheduler.max-threads", threads);
  cfg.set("logger.verbosity", caf::atom("quiet"));
}

void configure_for_testing(caf::actor_system_config& cfg) {
  register_types(cfg);
  cfg.set("scheduler.policy", caf::atom("testing"));
  cfg.set("logger.inline-output", true);
  cfg.set("logger.verbosity", caf::atom("quiet"));
}

} // namespace herm
