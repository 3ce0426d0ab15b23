#pragma once

// The control service's topic and call commands (internal to herm_control;
// docs/protocol.md, "Control requests", lists them): streams of a topic's
// values as text, the network-wide topic list, and requests to any APO by
// name with values in the text form (actors/text_form.hpp).

#include <chrono>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "caf/actor.hpp"
#include "caf/fwd.hpp"

#include "actors/app_support.hpp"
#include "actors/control.hpp"

namespace herm::control_topics {

using json = nlohmann::json;

/// Values of one stream session ("cmd": "subscribe").
struct stream_options {
  std::vector<std::string> topics;
  /// Each line also carries the payload (hex) and, the first time a type
  /// appears, its description: what hermctl record stores.
  bool raw = false;
};

/// Reads "topics" (a non-empty array of topic names, at most 64) and "raw"
/// from a request; an error sentence in `why` if they are malformed.
stream_options parse_stream(const json& req, std::string& why);

/// Most values a session holds while it waits for a description; more are
/// dropped (counted in the next line's "dropped").
constexpr size_t max_backlog = 1024;

/// Spawns a session that subscribes `writer`'s stream to `opts.topics` in
/// sample mode (app_support_actor) and sends `writer` one JSON line
/// (std::string) per value: {"topic", "publisher", "seq", "time_ns",
/// "types", "value"[, "undescribed", "payload", "descriptions",
/// "dropped"]}. A value of a type this process cannot describe makes it
/// ask the publisher's control service (through `control`, request
/// "types") once per module and type, and wait (bounded) for the answer.
/// Ends when `writer` ends; its subscriptions end with it.
caf::actor spawn_stream(caf::actor_system& sys, app_support_actor apps,
                        control_actor control, module_id self_id,
                        caf::actor writer, stream_options opts);

/// Spawns a detached actor that sends one request to an APO and answers
/// with its reply in the text form: it takes (caf::actor apo, apo_ref,
/// caf::message request, uint32_t timeout_ms) and replies a std::string
/// (a request that is a raw_payload, sent through a proxy, gets a
/// raw_payload reply, printed from its bytes)
/// reply line ({"ok": true, "result": {...}} or an error reply). Detached
/// because it waits for a reply of any type, which only a blocking receive
/// can. It ends after answering.
caf::actor spawn_call(caf::actor_system& sys);

/// The type names of a request's "type" (several separated by commas; a
/// comma inside <...> belongs to its type); empty without one.
std::vector<std::string> type_names_of(const json& req);

/// The request of a call or a publication from its "value" (text form) and
/// "type" (a type name, or several separated by commas; default: inferred
/// from the value): the payload, or an error sentence in `why`.
byte_buffer payload_of(const json& req, std::string& why);

/// The descriptions this process has of `names` (a JSON array of strings)
/// and of the described types their fields contain, as a JSON array of
/// {"name", "fields": [{"name", "type"}]}; at most 64.
json descriptions_json(const json& names);

/// Keeps the descriptions of a "types" reply (learned from another module).
void learn_descriptions(const json& result);

/// Merges the local topic lists of several modules ({"module": "0x40",
/// "topics": rows} each) into one row per topic: publishers (modules that
/// publish it, and those the others heard publishing it), subscribers
/// (modules with a local subscriber, and those holding a subscription with
/// the others), type.
json merge_topics(const std::vector<json>& per_module);

/// One module's topic rows as JSON.
json topics_json(const std::vector<topic_info>& rows);

} // namespace herm::control_topics
