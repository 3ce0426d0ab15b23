// The JSON side of the control service: replies, HERM's types as JSON,
// request fields (actors/control_json.hpp).

#include "actors/control_json.hpp"

#include "caf/sec.hpp"

#include "actors/runtime/error.hpp"
#include "routing/metric.hpp"

namespace herm::control_json {

std::string dump(const json& j) {
  return j.dump(-1, ' ', false, json::error_handler_t::replace);
}

std::string ok_reply(json result) {
  return dump(json{{"ok", true}, {"result", std::move(result)}});
}

std::string error_reply(const std::string& code, const std::string& message) {
  return dump(json{{"ok", false},
                   {"error", {{"code", code}, {"message", message}}}});
}

namespace {

/// CAF's codes as HERM's own (typed_error), but for one: the service's
/// requests go to this module's core actors, so a receiver that is down is
/// one of them (app_ec::unavailable). A call of an APO maps its errors with
/// typed_error first (a receiver down is then the APO: apo_gone).
caf::error herm_error(const caf::error& err) {
  if (err == caf::sec::request_receiver_down)
    return make_error(app_ec::unavailable,
                      "a core actor of this module (IO manager, routing agent "
                      "or application support) has stopped");
  return typed_error(err);
}

/// "no_route" for herm's errors; CAF's are HERM's by then. An error of
/// another category (none is expected) by its rendering's head.
std::string error_code(const caf::error& raw) {
  auto err = herm_error(raw);
  if (!err)
    return "none";
  if (err.category() == caf::atom("herm"))
    return error_name(err.code());
  auto text = render(err);
  return text.substr(0, text.find(':'));
}

/// The error's context when it is a sentence, else the whole rendering.
std::string error_message(const caf::error& raw) {
  auto err = herm_error(raw);
  if (err && err.context().match_elements<std::string>())
    return err.context().get_as<std::string>(0);
  return render(err);
}

} // namespace

bool is_ok_reply(const json& reply) {
  if (!reply.is_object())
    return false;
  auto i = reply.find("ok");
  return i != reply.end() && i->is_boolean() && i->get<bool>();
}

std::string error_reply(const caf::error& err) {
  return error_reply(error_code(err), error_message(err));
}

// -- HERM's types ----------------------------------------------------------------------

json cost_json(uint64_t cost) {
  return cost >= infinite_metric ? json(nullptr) : json(cost);
}

json to_json(const link_profile& p) {
  return {{"name", p.name},
          {"bandwidth_bps", p.bandwidth_bps},
          {"mtu", p.mtu},
          {"multi_access", p.multi_access},
          {"delay_coef", p.delay_coef},
          {"cost", p.bandwidth_bps > 0 ? cost_json(link_cost(p)) : json(nullptr)}};
}

json to_json(const channel_stats& s) {
  return {{"tx_packets", s.tx_packets},
          {"tx_bytes", s.tx_bytes},
          {"tx_frames", s.tx_frames},
          {"tx_dropped", s.tx_dropped},
          {"rx_packets", s.rx_packets},
          {"rx_bytes", s.rx_bytes},
          {"rx_frames", s.rx_frames},
          {"rx_malformed", s.rx_malformed},
          {"rx_reassembly_dropped", s.rx_reassembly_dropped},
          {"rx_duplicates", s.rx_duplicates},
          {"rx_orphans", s.rx_orphans},
          {"rx_kernel_dropped", s.rx_kernel_dropped},
          {"rx_queue_dropped", s.rx_queue_dropped},
          {"rx_peers_unrecorded", s.rx_peers_unrecorded},
          {"tx_overload", {{"control", s.tx_overload_control},
                           {"high", s.tx_overload_high},
                           {"normal", s.tx_overload_normal},
                           {"bulk", s.tx_overload_bulk}}},
          {"backlog_bytes", s.backlog_bytes},
          {"backlog_peak_bytes", s.backlog_peak_bytes},
          {"backlog_limit_bytes", s.backlog_limit_bytes},
          {"tx_bundles", s.tx_bundles},
          {"rx_bundles", s.rx_bundles}};
}

json to_json(const channel_entry& e) {
  return {{"id", e.id},
          {"device", e.request.device},
          {"address", e.request.address},
          {"persistent", e.request.persistent},
          {"routed", !e.request.local},
          {"state", e.state},
          {"last_error", e.last_error},
          {"restarts", e.restarts},
          {"kind", e.info.kind},
          {"local", e.info.local},
          {"profile", to_json(e.info.profile)},
          {"max_packet", e.info.max_packet},
          {"peers", e.info.peers},
          {"stats", nullptr}};
}

json to_json(const routing_stats& s) {
  return {{"self", to_hex(s.self)},
          {"instance", s.instance},
          {"assigned", s.assigned},
          {"renumberings", s.renumberings},
          {"reachable", s.reachable},
          {"delivered", s.delivered},
          {"forwarded", s.forwarded},
          {"originated", s.originated},
          {"dropped_no_route", s.dropped_no_route},
          {"dropped_hop_limit", s.dropped_hop_limit},
          {"dropped_no_receiver", s.dropped_no_receiver},
          {"broadcasts_originated", s.broadcasts_originated},
          {"broadcasts_relayed", s.broadcasts_relayed},
          {"dropped_duplicate", s.dropped_duplicate},
          {"rx_malformed", s.rx_malformed},
          {"rx_unknown_neighbour", s.rx_unknown_neighbour},
          {"rx_refused_routes", s.rx_refused_routes},
          {"rx_goodbyes", s.rx_goodbyes},
          {"tx_hellos", s.tx_hellos},
          {"tx_updates", s.tx_updates},
          {"tx_update_entries", s.tx_update_entries},
          {"tx_claims", s.tx_claims},
          {"tx_conflicts", s.tx_conflicts},
          {"tx_seqno_requests", s.tx_seqno_requests},
          {"rx_auth_failed", s.rx_auth_failed},
          {"rx_replayed", s.rx_replayed},
          {"rx_unsigned", s.rx_unsigned},
          {"rx_auth_table_full", s.rx_auth_table_full},
          {"tx_signed", s.tx_signed},
          {"rx_auth_challenged", s.rx_auth_challenged},
          {"rx_challenge_failed", s.rx_challenge_failed},
          {"tx_challenges", s.tx_challenges},
          {"tx_challenge_replies", s.tx_challenge_replies},
          {"id_conflicts", s.id_conflicts},
          {"id_conflict", s.id_conflict_instance == 0
                            ? json(nullptr)
                            : json{{"instance", s.id_conflict_instance},
                                   {"heard", s.id_conflict_heard}}},
          {"destinations", s.destinations},
          {"routes", s.routes},
          {"neighbours", s.neighbours},
          {"rx_routes_over_limit", s.rx_routes_over_limit},
          {"rx_routes_over_share", s.rx_routes_over_share},
          {"rx_neighbours_over_limit", s.rx_neighbours_over_limit},
          {"seqno_requests_over_limit", s.seqno_requests_over_limit},
          {"floods_evicted", s.floods_evicted},
          {"flood_ids_evicted", s.flood_ids_evicted},
          {"sources_evicted", s.sources_evicted},
          {"fast_sent", s.fast_sent},
          {"fast_routes_refused", s.fast_routes_refused},
          {"fast_delivered", s.fast_delivered},
          {"fast_forwarded", s.fast_forwarded}};
}

json to_json(const app_support_stats& s) {
  return {{"local_apos", s.local_apos},
          {"known_remote_apos", s.known_remote_apos},
          {"live_bindings", s.live_bindings},
          {"pending_requests", s.pending_requests},
          {"registered", s.registered},
          {"withdrawn", s.withdrawn},
          {"queries_sent", s.queries_sent},
          {"queries_answered", s.queries_answered},
          {"answers_received", s.answers_received},
          {"requests_sent", s.requests_sent},
          {"oneway_sent", s.oneway_sent},
          {"requests_served", s.requests_served},
          {"oneway_delivered", s.oneway_delivered},
          {"responses_received", s.responses_received},
          {"request_timeouts", s.request_timeouts},
          {"proxies_ended", s.proxies_ended},
          {"published", s.published},
          {"publications_sent", s.publications_sent},
          {"publications_received", s.publications_received},
          {"publications_delivered", s.publications_delivered},
          {"publications_lost", s.publications_lost},
          {"rx_malformed", s.rx_malformed},
          {"rx_unknown_apo", s.rx_unknown_apo},
          {"rx_unknown_type", s.rx_unknown_type},
          {"rx_unexpected_response", s.rx_unexpected_response},
          {"tx_refused", s.tx_refused},
          {"dropped_no_route", s.dropped_no_route},
          {"rx_unauthorized", s.rx_unauthorized},
          {"serving_refused", s.serving_refused},
          {"remote_apos_refused", s.remote_apos_refused},
          {"discovery_entries_refused", s.discovery_entries_refused},
          {"watches", s.watches},
          {"watches_refused", s.watches_refused},
          {"subscribers_refused", s.subscribers_refused},
          {"publishers_refused", s.publishers_refused},
          {"unexpected_messages", s.unexpected_messages},
          {"reliable", {{"sent", s.reliable_sent},
                        {"retransmissions", s.retransmissions},
                        {"duplicates_suppressed", s.duplicates_suppressed},
                        {"acks_sent", s.acks_sent},
                        {"acks_received", s.acks_received},
                        {"late_duplicates", s.late_duplicates},
                        {"waited_for_route", s.reliable_waited},
                        {"cached_responses", s.cached_responses}}}};
}

json to_json(const neighbour_info& n) {
  json cost = json::array();
  for (auto c : n.cost)
    cost.push_back(cost_json(c));
  return {{"module", to_hex(n.id)},
          {"channel", n.channel},
          {"link_address", n.link_address},
          {"instance", n.instance},
          {"link_kind", n.link_kind},
          {"cost", std::move(cost)},
          {"last_heard_ms", n.last_heard_ms},
          {"duplicate_id", n.duplicate_id}};
}

json to_json(const apo_info& a) {
  return {{"module", to_hex(a.ref.module)},
          {"apo", a.ref.apo},
          {"name", a.ref.name},
          {"type", a.ref.type},
          {"local", a.local},
          {"watchers", a.watchers},
          {"age_ms", a.age_ms}};
}

json to_json(const route_info& r, const std::vector<neighbour_info>& ns) {
  json j{{"destination", to_hex(r.destination)},
         {"size_class", r.size_class},
         {"size_class_bytes", r.size_class < size_classes
                                ? json(size_class_bytes[r.size_class])
                                : json(nullptr)},
         {"channel", r.channel},
         {"neighbour", r.neighbour},
         {"neighbour_module", nullptr},
         {"link_kind", nullptr},
         {"link_cost", nullptr},
         {"cost", cost_json(r.cost)},
         {"hops", r.hops},
         {"forwarding", r.forwarding},
         {"selected", r.selected},
         {"feasible", r.feasible}};
  for (auto& n : ns)
    if (n.channel == r.channel && n.link_address == r.neighbour) {
      j["neighbour_module"] = to_hex(n.id);
      j["link_kind"] = n.link_kind;
      if (r.size_class < n.cost.size())
        j["link_cost"] = cost_json(n.cost[r.size_class]);
      break;
    }
  return j;
}

// -- request fields ------------------------------------------------------------------------

std::optional<module_id> module_field(const json& v) {
  if (v.is_string())
    return parse_module_id(v.get<std::string>());
  if (v.is_number_unsigned() && v.get<uint64_t>() <= 0xFFFF)
    return static_cast<module_id>(v.get<uint64_t>());
  return std::nullopt;
}

std::optional<uint32_t> uint_field(const json& req, const char* key,
                                   uint32_t fallback, uint32_t lo, uint32_t hi) {
  auto i = req.find(key);
  if (i == req.end())
    return fallback;
  if (!i->is_number_unsigned() || i->get<uint64_t>() < lo
      || i->get<uint64_t>() > hi)
    return std::nullopt;
  return static_cast<uint32_t>(i->get<uint64_t>());
}

std::string string_field(const json& req, const char* key) {
  auto i = req.find(key);
  return i != req.end() && i->is_string() ? i->get<std::string>() : std::string{};
}

} // namespace herm::control_json
