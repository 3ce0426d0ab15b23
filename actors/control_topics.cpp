#include "actors/control_topics.hpp"

#include <cctype>
#include <deque>
#include <map>
#include <set>

#include "caf/actor_system.hpp"
#include "caf/blocking_actor.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/others.hpp"
#include "caf/stateful_actor.hpp"

#include "actors/control_json.hpp"
#include "actors/marshal.hpp"
#include "actors/runtime/error.hpp"
#include "actors/text_form.hpp"
#include "actors/type_description.hpp"

namespace herm::control_topics {

namespace {

using namespace control_json;
using ms = std::chrono::milliseconds;

/// Most topics one session follows.
constexpr size_t max_stream_topics = 64;

/// How long a session waits for another module's descriptions.
constexpr ms describe_timeout{3000};

/// Most type names one "types" request asks for.
constexpr size_t max_type_names = 64;

/// The error's sentence (its context), else its rendering.
std::string sentence(const caf::error& err) {
  if (err.context().match_elements<std::string>())
    return err.context().get_as<std::string>(0);
  return render(err);
}

ordered_json description_json(const type_description& d) {
  ordered_json fields = ordered_json::array();
  for (auto& f : d.fields) {
    ordered_json field;
    field["name"] = f.name;
    field["type"] = f.type;
    fields.push_back(std::move(field));
  }
  ordered_json out;
  out["name"] = d.name;
  out["fields"] = std::move(fields);
  return out;
}

/// Most type names one stream remembers having described.
constexpr size_t max_described = 4096;

/// Appends the description of `type` and of every described type its
/// fields name, each once (`seen`, at most max_described names), at most
/// max_type_names to one `out`.
void describe_into(const std::string& type, std::set<std::string>& seen,
                   ordered_json& out) {
  if (out.size() >= max_type_names || seen.size() >= max_described
      || !seen.insert(type).second)
    return;
  auto d = find_description(type);
  if (!d)
    return;
  out.push_back(description_json(*d));
  for (auto& f : d->fields) {
    // The names inside a field type: split at the grammar's punctuation.
    std::string word;
    for (auto c : f.type + ",") {
      if (c == '<' || c == '>' || c == ',') {
        if (!word.empty() && word[0] != '@' && !std::isdigit(
              static_cast<unsigned char>(word[0])))
          describe_into(word, seen, out);
        word.clear();
      } else {
        word += c;
      }
    }
  }
}

// -- stream sessions -----------------------------------------------------------

struct stream_state {
  static inline const char* name = "herm.control.stream";

  caf::actor writer;
  control_actor control;
  module_id self_id = no_module;
  stream_options opts;
  /// Types whose description went out in a line already (raw mode).
  std::set<std::string> described;
  /// (module, type) pairs asked for already.
  std::set<std::pair<module_id, std::string>> asked;
  /// Values waiting while a description is asked for.
  std::deque<topic_sample> backlog;
  bool waiting = false;
  uint64_t dropped = 0;
};

using stream_actor = caf::stateful_actor<stream_state>;

/// Renders `s` and sends its line; false (nothing sent) when it first needs
/// descriptions from its publisher, which are then asked for.
bool emit(stream_actor* self, const topic_sample& s) {
  auto& st = self->state;
  auto text = payload_to_text(s.payload.data(), s.payload.size());
  if (text && !text->undescribed.empty() && s.publisher != st.self_id) {
    json missing = json::array();
    for (auto& t : text->undescribed)
      if (st.asked.emplace(s.publisher, t).second)
        missing.push_back(t);
    if (!missing.empty()) {
      st.waiting = true;
      json req{{"cmd", "types"},
               {"names", missing},
               {"module", to_hex(s.publisher)},
               {"timeout_ms", describe_timeout.count()}};
      auto done = [self] {
        self->state.waiting = false;
        auto& backlog = self->state.backlog;
        while (!backlog.empty() && !self->state.waiting) {
          auto next = std::move(backlog.front());
          backlog.pop_front();
          if (!emit(self, next)) {
            backlog.push_front(std::move(next));
            break;
          }
        }
      };
      self->request(st.control, 2 * describe_timeout, dump(req))
        .then(
          [done](std::string& reply) {
            auto j = json::parse(reply, nullptr, false);
            if (is_ok_reply(j))
              learn_descriptions(j["result"]);
            done();
          },
          [done](caf::error&) { done(); });
      return false;
    }
  }
  // Ordered, so that a struct's fields keep their order.
  ordered_json line;
  line["topic"] = s.topic;
  line["publisher"] = to_hex(s.publisher);
  line["seq"] = s.seq;
  line["time_ns"] = s.time.time_since_epoch().count();
  if (text) {
    line["types"] = text->types;
    line["value"] = std::move(text->value);
    if (!text->undescribed.empty())
      line["undescribed"] = text->undescribed;
  } else {
    line["error"] = sentence(text.error());
  }
  if (st.opts.raw) {
    line["payload"] = to_hex_bytes(s.payload.data(), s.payload.size());
    auto descs = ordered_json::array();
    if (text)
      for (auto& t : text->types)
        describe_into(t, st.described, descs);
    if (!descs.empty())
      line["descriptions"] = descs;
  }
  if (st.dropped > 0) {
    line["dropped"] = st.dropped;
    st.dropped = 0;
  }
  self->send(st.writer,
             line.dump(-1, ' ', false, json::error_handler_t::replace));
  return true;
}

caf::behavior stream_fun(stream_actor* self, app_support_actor apps,
                         control_actor control, module_id self_id,
                         caf::actor writer, stream_options opts) {
  auto& init = self->state;
  init.writer = writer;
  init.control = std::move(control);
  init.self_id = self_id;
  init.opts = std::move(opts);
  self->monitor(writer);
  self->set_down_handler([self](caf::down_msg&) { self->quit(); });
  for (auto& t : init.opts.topics)
    self->request(apps, std::chrono::seconds(10), atom::subscribe_v, t,
                  caf::actor_cast<caf::actor>(self), atom::sample_v)
      .then([] {},
            [self](caf::error& err) {
              self->send(self->state.writer,
                         dump(json{{"error", render(err)}}));
              self->quit();
            });
  return {
    [self](topic_sample& s) {
      auto& st = self->state;
      if (st.waiting) {
        if (st.backlog.size() < max_backlog)
          st.backlog.push_back(std::move(s));
        else
          ++st.dropped;
        return;
      }
      if (!emit(self, s))
        st.backlog.push_front(std::move(s));
    },
  };
}

// -- calls ---------------------------------------------------------------------

void call_fun(caf::blocking_actor* self) {
  self->receive([self](caf::actor& apo, apo_ref& ref, caf::message& request,
                       uint32_t timeout_ms) -> std::string {
    std::string reply;
    auto describe = [&](const caf::message& msg) {
      ordered_json result;
      result["apo"] = ref.name;
      result["module"] = to_hex(ref.module);
      result["type"] = ref.type;
      // A remote APO called through a proxy with a raw_payload answers
      // with one: its bytes as they came.
      auto payload = msg.match_elements<raw_payload>()
                       ? caf::expected<byte_buffer>{msg.get_as<raw_payload>(0).bytes}
                       : marshal(self->system(), msg);
      if (!payload) {
        result["types"] = ordered_json::array();
        result["value"] = nullptr;
        result["error"] = sentence(payload.error());
      } else if (auto text = payload_to_text(payload->data(), payload->size())) {
        result["types"] = text->types;
        result["value"] = std::move(text->value);
        if (!text->undescribed.empty())
          result["undescribed"] = text->undescribed;
      } else {
        return error_reply(text.error());
      }
      ordered_json out;
      out["ok"] = true;
      out["result"] = std::move(result);
      return out.dump(-1, ' ', false, json::error_handler_t::replace);
    };
    self->request(apo, ms(timeout_ms), std::move(request))
      // The APO's own errors, and CAF's about the APO (it exited, it does
      // not take the request's types) as HERM's.
      .receive([&](caf::error& err) { reply = error_reply(typed_error(err)); },
               caf::others >> [&](caf::message_view& x)
                                -> caf::result<caf::message> {
                 reply = describe(x.move_content_to_message());
                 return caf::message{};
               });
    return reply;
  });
}

} // namespace

stream_options parse_stream(const json& req, std::string& why) {
  stream_options opts;
  auto ti = req.find("topics");
  if (ti == req.end() || !ti->is_array() || ti->empty()
      || ti->size() > max_stream_topics) {
    why = "\"topics\" must be an array of 1 to "
          + std::to_string(max_stream_topics) + " topic names";
    return opts;
  }
  for (auto& t : *ti) {
    if (!t.is_string() || t.get<std::string>().empty()
        || t.get<std::string>().size() > 255) {
      why = "a topic name is a string of 1 to 255 bytes, got " + dump(t);
      return opts;
    }
    opts.topics.push_back(t.get<std::string>());
  }
  auto ri = req.find("raw");
  opts.raw = ri != req.end() && ri->is_boolean() && ri->get<bool>();
  return opts;
}

caf::actor spawn_stream(caf::actor_system& sys, app_support_actor apps,
                        control_actor control, module_id self_id,
                        caf::actor writer, stream_options opts) {
  return sys.spawn(stream_fun, std::move(apps), std::move(control), self_id,
                   std::move(writer), std::move(opts));
}

caf::actor spawn_call(caf::actor_system& sys) {
  return sys.spawn<caf::detached>(call_fun);
}

std::vector<std::string> type_names_of(const json& req) {
  std::vector<std::string> types;
  auto type = string_field(req, "type");
  for (size_t start = 0; !type.empty() && start <= type.size();) {
    // A comma inside <...> belongs to the type (map<K,V>).
    auto depth = 0;
    size_t end = start;
    for (; end < type.size(); ++end) {
      if (type[end] == '<')
        ++depth;
      else if (type[end] == '>')
        --depth;
      else if (type[end] == ',' && depth == 0)
        break;
    }
    types.push_back(type.substr(start, end - start));
    start = end + 1;
  }
  return types;
}

byte_buffer payload_of(const json& req, std::string& why) {
  auto vi = req.find("value");
  if (vi == req.end()) {
    why = "a \"value\" is needed (the text form: a JSON value)";
    return {};
  }
  auto value = ordered_json::parse(vi->dump());
  auto types = type_names_of(req);
  if (types.empty()) {
    auto t = default_type(value);
    if (t.empty()) {
      why = "give the value's \"type\" (it cannot be told from "
            + vi->dump() + ")";
      return {};
    }
    types.push_back(t);
  }
  auto payload = text_to_payload(value, types);
  if (!payload) {
    why = sentence(payload.error());
    return {};
  }
  return std::move(*payload);
}

json descriptions_json(const json& names) {
  auto out = ordered_json::array();
  if (!names.is_array())
    return json::array();
  std::set<std::string> seen;
  for (auto& name : names)
    if (name.is_string())
      describe_into(name.get<std::string>(), seen, out);
  return json::parse(out.dump());
}

void learn_descriptions(const json& result) {
  if (!result.is_array())
    return;
  size_t n = 0;
  for (auto& d : result) {
    if (++n > max_type_names || !d.is_object())
      return;
    type_description desc;
    desc.name = string_field(d, "name");
    auto fi = d.find("fields");
    if (desc.name.empty() || fi == d.end() || !fi->is_array())
      continue;
    for (auto& f : *fi)
      if (f.is_object())
        desc.fields.push_back({string_field(f, "name"), string_field(f, "type")});
    learn_description(desc);
  }
}

json topics_json(const std::vector<topic_info>& rows) {
  json out = json::array();
  for (auto& r : rows) {
    json subs = json::array(), pubs = json::array();
    for (auto m : r.remote_subscribers)
      subs.push_back(to_hex(m));
    for (auto m : r.publishers)
      pubs.push_back(to_hex(m));
    out.push_back({{"topic", r.topic},
                   {"publishing", r.publishing},
                   {"seq", r.seq},
                   {"local_subscribers", r.local_subscribers},
                   {"remote_subscribers", subs},
                   {"publishers", pubs},
                   {"type", r.type}});
  }
  return out;
}

json merge_topics(const std::vector<json>& per_module) {
  struct row {
    std::set<std::string> publishers, subscribers;
    std::string type;
    /// Each answering publisher's last sequence number (rates: its increase).
    std::map<std::string, uint32_t> seqs;
  };
  // The rows come from other modules (an open APO): anything of the wrong
  // shape is passed over, never thrown on or read past.
  auto field = [](const json& j, const char* key) -> const json* {
    if (!j.is_object())
      return nullptr;
    auto i = j.find(key);
    return i != j.end() ? &*i : nullptr;
  };
  auto text = [&](const json& j, const char* key) {
    auto* v = field(j, key);
    return v != nullptr && v->is_string() ? v->get<std::string>() : std::string{};
  };
  std::map<std::string, row> rows;
  for (auto& m : per_module) {
    auto module = text(m, "module");
    auto* topics = field(m, "topics");
    if (topics == nullptr || !topics->is_array())
      continue;
    for (auto& t : *topics) {
      auto name = text(t, "topic");
      if (name.empty())
        continue;
      auto& r = rows[name];
      auto* publishing = field(t, "publishing");
      if (publishing != nullptr && publishing->is_boolean() && publishing->get<bool>()) {
        r.publishers.insert(module);
        auto* seq = field(t, "seq");
        if (seq != nullptr && seq->is_number_unsigned() && !module.empty())
          r.seqs[module] = seq->get<uint32_t>();
      }
      auto* local = field(t, "local_subscribers");
      if (local != nullptr && local->is_number_integer() && local->get<int64_t>() > 0)
        r.subscribers.insert(module);
      // What this module heard of others: modules it heard publishing,
      // modules holding a subscription to it. So modules that did not
      // answer (a microcontroller board has no herm.info) are listed too.
      for (auto key : {"publishers", "remote_subscribers"}) {
        auto* ids = field(t, key);
        if (ids == nullptr || !ids->is_array())
          continue;
        auto& into = key[0] == 'p' ? r.publishers : r.subscribers;
        for (auto& id : *ids)
          if (id.is_string())
            into.insert(id.get<std::string>());
      }
      auto type = text(t, "type");
      if (!type.empty())
        r.type = type;
    }
  }
  json out = json::array();
  for (auto& [name, r] : rows)
    out.push_back({{"topic", name},
                   {"type", r.type},
                   {"publishers", r.publishers},
                   {"subscribers", r.subscribers},
                   {"seqs", r.seqs}});
  return out;
}

} // namespace herm::control_topics
