// The control service's topics, publications, calls and streams
// (docs/protocol.md, "Control requests"); the JSON and the helpers they
// use are in actors/control_topics.hpp.

#include <algorithm>
#include <chrono>
#include <memory>
#include <vector>

#include "caf/actor_cast.hpp"
#include "caf/actor_system.hpp"
#include "caf/event_based_actor.hpp"

#include "actors/control_state.hpp"
#include "actors/control_topics.hpp"
#include "actors/marshal.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/type_ids.hpp"
#include "actors/text_form.hpp"

namespace herm::control_detail {

/// This module's topics, or with "all": true every module's, merged: the
/// modules are those whose control service answers a discovery.
void cmd_topics(control_impl self, const json& req, ms timeout,
                reply_promise rp) {
  auto& apps = self->state.m.apps;
  auto ai = req.find("all");
  if (ai == req.end() || !ai->is_boolean() || !ai->get<bool>()) {
    self->request(apps, timeout, atom::get_v, atom::topics_v)
      .then(
        [rp](std::vector<topic_info>& rows) mutable {
          rp.deliver(ok_reply(control_topics::topics_json(rows)));
        },
        fail_with(rp));
    return;
  }
  with_self_id(self, timeout, rp, [=](routing_stats& rs) {
    apo_query q{query_by::name, info_apo_name, discovery_ms, false};
    self->request(apps, timeout + ms(discovery_ms), atom::find_v, std::move(q))
      .then(
        [=](std::vector<apo_ref>& found) {
          auto rows = std::make_shared<std::vector<json>>();
          auto unanswered = std::make_shared<json>(json::array());
          auto join = std::make_shared<join_counter>();
          std::set<module_id> modules{rs.self};
          for (auto& ref : found)
            if (ref.type == info_apo_type)
              modules.insert(ref.module);
          join->pending = modules.size();
          join->done = [rp, rows, unanswered]() mutable {
            rp.deliver(ok_reply({{"topics", control_topics::merge_topics(*rows)},
                                 {"modules", rows->size()},
                                 {"unanswered", *unanswered}}));
          };
          for (auto m : modules)
            resolve(self, m, rs.self, timeout,
                    [=](caf::expected<caf::actor> dest) {
                      if (!dest) {
                        unanswered->push_back(to_hex(m));
                        join->finish_one();
                        return;
                      }
                      self->request(*dest, timeout,
                                    std::string{R"({"cmd":"topics"})"})
                        .then(
                          [=](std::string& text) {
                            auto j = json::parse(text, nullptr, false);
                            if (is_ok_reply(j))
                              rows->push_back(
                                {{"module", to_hex(m)}, {"topics", j["result"]}});
                            else
                              unanswered->push_back(to_hex(m));
                            join->finish_one();
                          },
                          [=](caf::error&) {
                            self->state.info_proxies.erase(m);
                            unanswered->push_back(to_hex(m));
                            join->finish_one();
                          });
                    },
                    true);
        },
        fail_with(rp));
  });
}

/// Publishes a value given in the text form ("value", "type") or as a
/// marshalled payload in hex ("payload": what hermctl play sends).
void cmd_publish(control_impl self, const json& req, ms timeout,
                 reply_promise rp) {
  auto topic = string_field(req, "topic");
  std::string why;
  byte_buffer payload;
  if (req.count("payload") > 0) {
    auto bytes = from_hex_bytes(string_field(req, "payload"));
    if (bytes)
      payload = std::move(*bytes);
    else
      why = "\"payload\": " + render(bytes.error());
  } else {
    payload = control_topics::payload_of(req, why);
  }
  if (!why.empty()) {
    rp.deliver(error_reply("invalid_parameter", why));
    return;
  }
  auto size = payload.size();
  auto type = first_type_name(payload.data(), payload.size());
  self->request(self->state.m.apps, timeout, atom::publish_v, topic,
                raw_payload{std::move(payload)})
    .then(
      [rp, topic, size, type]() mutable {
        rp.deliver(ok_reply({{"topic", topic}, {"type", type}, {"bytes", size}}));
      },
      fail_with(rp));
}

namespace {

/// Binds to the APO `ref` (the APO itself when local, else a proxy),
/// sends it `msg` and relays its reply in the text form.
void call_bound(control_impl self, apo_ref ref, caf::message msg, ms timeout,
                reply_promise rp) {
  self->request(self->state.m.apps, timeout, atom::bind_v, ref)
    .then(
      [=](caf::actor& apo) mutable {
        auto helper = control_topics::spawn_call(self->system());
        self
          ->request(helper, timeout + ms(1000), apo, ref, std::move(msg),
                    static_cast<uint32_t>(timeout.count()))
          .then([rp](std::string& reply) mutable { rp.deliver(reply); },
                fail_with(rp));
      },
      fail_with(rp));
}

/// Sends the local APO `ref` the request of `req` and relays its reply.
void call_local(control_impl self, const json& req, apo_ref ref, ms timeout,
                reply_promise rp) {
  std::string why;
  auto payload = control_topics::payload_of(req, why);
  if (!why.empty()) {
    rp.deliver(error_reply("invalid_parameter", why));
    return;
  }
  auto msg = unmarshal(self->system(), payload.data(), payload.size());
  if (!msg) {
    rp.deliver(error_reply(msg.error()));
    return;
  }
  call_bound(self, std::move(ref), std::move(*msg), timeout, rp);
}

/// Calls the remote APO `ref` through a proxy with `payload` as it is
/// (raw_payload: this process need not have the APO's types) and relays
/// its reply in the text form.
void call_remote(control_impl self, apo_ref ref, byte_buffer payload,
                 ms timeout, reply_promise rp) {
  call_bound(self, std::move(ref),
             caf::make_message(raw_payload{std::move(payload)}), timeout, rp);
}

} // namespace

/// A request to the APO named "apo", wherever it runs: a local one is
/// called here; a remote one through a proxy, as any application calls
/// it (no remote control of its module is needed), with the request built
/// here from the text form. Types this process does not describe are
/// asked of that module's open herm.info first.
void cmd_call(control_impl self, const json& req, ms timeout,
              reply_promise rp) {
  auto name = string_field(req, "apo");
  if (name.empty() || name.size() > 255) {
    rp.deliver(error_reply("invalid_parameter",
                           "\"apo\" must name an APO (1 to 255 bytes)"));
    return;
  }
  with_self_id(self, timeout, rp, [=](routing_stats& rs) {
    apo_query q{query_by::name, name, discovery_ms, true};
    self
      ->request(self->state.m.apps, timeout + ms(discovery_ms), atom::find_v,
                std::move(q))
      .then(
        [=](std::vector<apo_ref>& found) mutable {
          if (found.empty()) {
            rp.deliver(error_reply(make_error(
              app_ec::not_found, "no APO named '" + name + "' answered")));
            return;
          }
          // A local match first.
          auto ref = found.front();
          for (auto& r : found)
            if (r.module == rs.self)
              ref = r;
          if (ref.module == rs.self) {
            call_local(self, req, ref, timeout, rp);
            return;
          }
          std::string why;
          auto payload = control_topics::payload_of(req, why);
          if (why.empty()) {
            call_remote(self, ref, std::move(payload), timeout, rp);
            return;
          }
          auto names = control_topics::type_names_of(req);
          if (names.empty()) {
            rp.deliver(error_reply("invalid_parameter", why));
            return;
          }
          // Learn what the APO's module says of the types, then try again.
          // Both share what is left of the caller's budget after the
          // discovery (control_deadline: timeout + discovery_ms), so the
          // caller gets a typed timeout, never silence.
          auto until = std::chrono::steady_clock::now() + timeout
                       + ms(discovery_ms);
          auto ask_timeout = std::max(ms(1), timeout / 2);
          json ask{{"cmd", "types"}, {"names", names},
                   {"module", to_hex(ref.module)},
                   {"timeout_ms", ask_timeout.count()}};
          self
            ->request(caf::actor_cast<control_actor>(self),
                      ask_timeout + ms(discovery_ms), dump(ask))
            .then(
              [=](std::string& reply) mutable {
                auto j = json::parse(reply, nullptr, false);
                if (is_ok_reply(j))
                  control_topics::learn_descriptions(j["result"]);
                std::string again;
                auto bytes = control_topics::payload_of(req, again);
                auto left = std::chrono::duration_cast<ms>(
                  until - std::chrono::steady_clock::now());
                if (!again.empty())
                  rp.deliver(error_reply("invalid_parameter", again));
                else
                  call_remote(self, ref, std::move(bytes),
                              std::max(ms(1), left), rp);
              },
              fail_with(rp));
        },
        fail_with(rp));
  });
}

/// A stream of values of topics, written by `writer` (control_actor).
void open_stream(control_impl self, const std::string& text,
                 caf::actor writer,
                 caf::typed_response_promise<std::string> rp) {
  auto req = json::parse(text, nullptr, false);
  std::string why;
  control_topics::stream_options opts;
  if (req.is_discarded() || !req.is_object())
    why = "a request is one JSON object with a \"cmd\"";
  else if (req.count("module") > 0)
    why = "a stream runs on the local module (topics reach it from every "
          "module)";
  else
    opts = control_topics::parse_stream(req, why);
  if (!why.empty()) {
    rp.deliver(error_reply("invalid_parameter", why));
    return;
  }
  with_self_id(self, default_control_timeout, rp,
               [self, rp, writer, opts](routing_stats& rs) mutable {
                 control_topics::spawn_stream(
                   self->system(), self->state.m.apps,
                   caf::actor_cast<control_actor>(self), rs.self, writer, opts);
                 rp.deliver(ok_reply({{"topics", opts.topics},
                                      {"module", to_hex(rs.self)}}));
               });
}

} // namespace herm::control_detail
