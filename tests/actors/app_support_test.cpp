// Actor-level tests of the Application Support Layer across 2 to 5 modules
// in one process (in-process links with Table 1 profiles, CAF's
// test_coordinator): registration, discovery, binding through proxies,
// requests through a router module and over an 8-byte-MTU CAN link, remote
// monitoring, rebinding, topics, and bad input.

#include <algorithm>

#include "caf/detail/simple_actor_clock.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/typed_event_based_actor.hpp"

#include "actors/app_table.hpp"
#include "actors/asl_wire.hpp"
#include "actors/marshal.hpp"
#include "actors/unexpected.hpp"
#include "actors/testing/sim_apps.hpp"
#include "tests/support/actor_fixture.hpp"

using namespace herm;
using namespace herm::test;
using namespace herm::testkit;
using namespace std::chrono_literals;

namespace {

module_id id_of(size_t i) {
  return static_cast<module_id>(0x10 + i);
}

/// What a test APO or subscriber saw.
struct seen {
  std::vector<std::string> texts;
  std::vector<int32_t> numbers;
  std::vector<caf::down_msg> downs;
  std::vector<caf::error> errors;
};

/// An APO that adds, echoes, fails on request, or never answers.
caf::behavior calculator(caf::event_based_actor* self,
                         std::shared_ptr<seen> log) {
  return {
    [](int32_t x, int32_t y) -> int32_t { return x + y; },
    [log](std::string& text) -> std::string {
      log->texts.push_back(text);
      return "echo: " + text;
    },
    [](atom::get) -> caf::result<int32_t> {
      return make_error(ec::invalid_parameter, "calculators do not get");
    },
    [self](atom::done) -> caf::result<int32_t> {
      // Never answers: the promise is kept but not delivered.
      auto rp = self->make_response_promise<int32_t>();
      return rp;
    },
    [log](route_info& r) -> uint32_t {
      // A HERM struct as a payload: travels by its inspect overload.
      log->texts.push_back(r.forwarding);
      return r.cost * 2;
    },
    [log](int32_t x) { log->numbers.push_back(x); },
  };
}

/// Records what a topic delivers and what its monitors say.
caf::behavior recorder(caf::event_based_actor* self, std::shared_ptr<seen> log) {
  self->set_down_handler([log](caf::down_msg& msg) { log->downs.push_back(msg); });
  return {
    [log](int32_t x) { log->numbers.push_back(x); },
    [log](std::string& x) { log->texts.push_back(x); },
    [self](atom::add, caf::actor& x) { self->monitor(x); },
  };
}

class asl_test : public actor_fixture {
public:
  asl_test() {
    cfg.unreachable_grace = 300ms;
    cfg.rebind_interval = 200ms;
    cfg.request_timeout = 2s;
    cfg.subscription_lease = 600ms;
  }

  /// Modules 0..n-1 with ids 0x10.., joined by `links`; `edit` may change
  /// the modules' configurations before they start.
  void build(size_t n,
             std::vector<std::pair<std::vector<size_t>, std::string>> links,
             std::function<void(sim_network&)> edit = nullptr) {
    net = std::make_unique<sim_network>(*this, test_prefix());
    for (size_t i = 0; i < n; ++i)
      net->add_module(id_of(i));
    for (auto& [members, kind] : links)
      net->connect(members, kind);
    if (edit)
      edit(*net);
    add_app_support(*this, *net, cfg);
    net->start();
    net->advance(2s); // routes converge, every ASL knows its id
  }

  app_support_actor asl(size_t i) {
    return apps_of(*net, i);
  }

  /// When the housekeeping ticks (and other delayed messages) on their way
  /// to module i's application support are due.
  std::vector<caf::actor_clock::time_point> ticks_pending_at(size_t i) {
    using clock = caf::detail::simple_actor_clock;
    auto dst = caf::actor_cast<caf::strong_actor_ptr>(asl(i));
    std::vector<caf::actor_clock::time_point> result;
    for (auto& entry : sched.clock().schedule())
      if (entry.second->subtype == clock::actor_msg_type
          && static_cast<clock::actor_msg&>(*entry.second).receiver == dst)
        result.push_back(entry.first);
    return result;
  }

  size_t ticks_pending(size_t i) {
    return ticks_pending_at(i).size();
  }

  /// Time until module i's next housekeeping tick.
  caf::timespan next_tick_in(size_t i) {
    auto at = ticks_pending_at(i);
    EXPECT_FALSE(at.empty());
    return at.empty() ? caf::timespan{0} : at.front() - sched.clock().now();
  }

  caf::actor spawn_calculator(std::shared_ptr<seen> log) {
    return track(sys().spawn(calculator, log));
  }

  caf::actor spawn_recorder(std::shared_ptr<seen> log) {
    return track(sys().spawn(recorder, log));
  }

  apo_ref add(size_t module, const std::string& name, const std::string& type,
              caf::actor apo) {
    auto res = call<apo_ref>(asl(module), atom::add_v, name, type, apo);
    EXPECT_TRUE(res) << render(res.error());
    return res ? std::get<0>(*res) : apo_ref{};
  }

  /// Runs a discovery and lets its timer fire.
  std::vector<apo_ref> find(size_t module, apo_query q) {
    auto result = std::make_shared<std::optional<std::vector<apo_ref>>>();
    auto hdl = asl(module);
    sys().spawn([=](caf::event_based_actor* self) {
      self->request(hdl, caf::infinite, atom::find_v, q)
        .then([=](std::vector<apo_ref>& xs) { *result = xs; },
              [=](caf::error& err) { ADD_FAILURE() << render(err); });
    });
    advance(std::chrono::milliseconds(q.timeout_ms + 10));
    return result->value_or(std::vector<apo_ref>{});
  }

  caf::expected<caf::actor> bind(size_t module, apo_ref ref) {
    auto res = call<caf::actor>(asl(module), atom::bind_v, ref);
    if (!res)
      return res.error();
    return std::get<0>(*res);
  }

  caf::expected<caf::actor> bind(size_t module, bind_request req) {
    auto result = std::make_shared<std::optional<caf::expected<caf::actor>>>();
    auto hdl = asl(module);
    sys().spawn([=](caf::event_based_actor* self) {
      self->request(hdl, caf::infinite, atom::bind_v, req)
        .then([=](caf::actor& x) { *result = x; },
              [=](caf::error& err) { *result = err; });
    });
    advance(std::chrono::milliseconds(req.timeout_ms + 10));
    if (!*result)
      return make_error(ec::timeout, "bind did not finish");
    return **result;
  }

  /// Sends a request from a fresh actor and runs until its answer (or until
  /// `wait` of simulated time passed).
  template <class R, class... Ts>
  caf::expected<R> ask(caf::actor dst, caf::timespan wait, Ts... xs) {
    auto result = std::make_shared<std::optional<caf::expected<R>>>();
    sys().spawn([=](caf::event_based_actor* self) {
      self->request(dst, caf::infinite, xs...)
        .then([=](R& r) { *result = r; },
              [=](caf::error& err) { *result = err; });
    });
    run();
    if (!*result)
      advance(wait);
    if (!*result)
      return make_error(ec::timeout, "no answer in the test");
    return **result;
  }

  app_support_stats stats(size_t i) {
    auto res = call<app_support_stats>(asl(i), atom::get_v, atom::stats_v);
    return res ? std::get<0>(*res) : app_support_stats{};
  }

  app_support_config cfg;
  std::unique_ptr<sim_network> net;
};

} // namespace

// -- application table and discovery ----------------------------------------------

TEST_F(asl_test, discovery_finds_apos_by_name_and_type_on_every_module) {
  build(3, {{{0, 1}, "ethernet"}, {{1, 2}, "can2.0"}});
  auto log = std::make_shared<seen>();
  auto a = add(1, "calc", "herm.example.calculator", spawn_calculator(log));
  auto b = add(2, "calc2", "herm.example.calculator", spawn_calculator(log));
  EXPECT_EQ(a.module, id_of(1));
  EXPECT_EQ(b.module, id_of(2));
  auto by_name = find(0, apo_query{query_by::name, "calc2", 200, false});
  ASSERT_EQ(by_name.size(), 1u);
  EXPECT_EQ(by_name[0], b);
  auto by_type = find(0, apo_query{query_by::type, "herm.example.calculator",
                                   200, false});
  EXPECT_EQ(by_type, (std::vector<apo_ref>{a, b}));
  // Local matches come first.
  auto from2 = find(2, apo_query{query_by::type, "herm.example.calculator",
                                 200, false});
  ASSERT_EQ(from2.size(), 2u);
  EXPECT_EQ(from2[0], b);
  EXPECT_TRUE(find(0, apo_query{query_by::name, "nobody", 200, false}).empty());
  // The querier's table now knows the remote APOs.
  auto table = call<std::vector<apo_info>>(asl(0), atom::get_v, atom::apps_v);
  ASSERT_TRUE(table);
  EXPECT_EQ(std::get<0>(*table).size(), 2u);
  EXPECT_EQ(stats(1).queries_answered + stats(2).queries_answered, 4u);
}

TEST_F(asl_test, registration_refuses_bad_names_and_double_registration) {
  build(2, {{{0, 1}, "ethernet"}});
  auto apo = spawn_calculator(std::make_shared<seen>());
  add(0, "calc", "t", apo);
  auto twice = call<apo_ref>(asl(0), atom::add_v, std::string{"again"},
                             std::string{"t"}, apo);
  ASSERT_FALSE(twice);
  EXPECT_TRUE(is(twice.error(), ec::already_exists)) << render(twice.error());
  auto empty = call<apo_ref>(asl(0), atom::add_v, std::string{}, std::string{"t"},
                             spawn_calculator(std::make_shared<seen>()));
  ASSERT_FALSE(empty);
  EXPECT_TRUE(is(empty.error(), ec::invalid_parameter));
  auto long_type = call<apo_ref>(asl(0), atom::add_v, std::string{"x"},
                                 std::string(256, 't'),
                                 spawn_calculator(std::make_shared<seen>()));
  ASSERT_FALSE(long_type);
  EXPECT_TRUE(is(long_type.error(), ec::invalid_parameter));
}

TEST_F(asl_test, an_apo_that_exits_is_withdrawn_everywhere) {
  build(2, {{{0, 1}, "ethernet"}});
  auto apo = spawn_calculator(std::make_shared<seen>());
  add(1, "calc", "t", apo);
  ASSERT_EQ(find(0, apo_query{query_by::name, "calc", 200, false}).size(), 1u);
  caf::anon_send_exit(apo, caf::exit_reason::user_shutdown);
  run();
  EXPECT_TRUE(find(0, apo_query{query_by::name, "calc", 200, false}).empty());
  auto table = call<std::vector<apo_info>>(asl(0), atom::get_v, atom::apps_v);
  EXPECT_TRUE(std::get<0>(*table).empty()); // the withdrawal reached module 0
  EXPECT_EQ(stats(1).withdrawn, 1u);
}

// -- binding and requests -----------------------------------------------------------

TEST_F(asl_test, requests_cross_a_router_and_an_8_byte_mtu_link) {
  // 0 -Ethernet- 1 -CAN (MTU 8)- 2: module 1 routes; every request and
  // response to 2 is fragmented into CAN frames and reassembled.
  build(3, {{{0, 1}, "ethernet"}, {{1, 2}, "can2.0"}});
  auto log = std::make_shared<seen>();
  add(2, "calc", "herm.example.calculator", spawn_calculator(log));
  auto proxy = bind(0, bind_request{query_by::name, "calc", 300, false});
  ASSERT_TRUE(proxy) << render(proxy.error());
  auto sum = ask<int32_t>(*proxy, 1s, int32_t{40}, int32_t{2});
  ASSERT_TRUE(sum) << render(sum.error());
  EXPECT_EQ(*sum, 42);
  std::string text(300, 'x');
  auto echo = ask<std::string>(*proxy, 1s, text);
  ASSERT_TRUE(echo) << render(echo.error());
  EXPECT_EQ(*echo, "echo: " + text);
  route_info r;
  r.cost = 21;
  r.forwarding = "CAN2.0-Ethernet";
  auto doubled = ask<uint32_t>(*proxy, 1s, r);
  ASSERT_TRUE(doubled) << render(doubled.error());
  EXPECT_EQ(*doubled, 42u);
  EXPECT_EQ(log->texts.back(), "CAN2.0-Ethernet");
  // A one-way message arrives too.
  caf::anon_send(*proxy, int32_t{7});
  run();
  EXPECT_EQ(log->numbers, std::vector<int32_t>{7});
  EXPECT_GE(net->stats(1).forwarded, 8u);
  EXPECT_EQ(stats(0).requests_sent, 3u);
  EXPECT_EQ(stats(2).requests_served, 3u);
  EXPECT_EQ(stats(2).oneway_delivered, 1u);
}

// A request marshalled elsewhere (hermctl call, which may not have the
// APO's types) goes through a proxy as it is, and its response comes back
// as raw bytes too; a raw_payload that is no APO payload is refused.
TEST_F(asl_test, a_raw_request_through_a_proxy_gets_a_raw_response) {
  build(3, {{{0, 1}, "ethernet"}, {{1, 2}, "can2.0"}});
  auto log = std::make_shared<seen>();
  add(2, "calc", "herm.example.calculator", spawn_calculator(log));
  auto proxy = bind(0, bind_request{query_by::name, "calc", 300, false});
  ASSERT_TRUE(proxy) << render(proxy.error());
  auto request = marshal(sys(), caf::make_message(int32_t{40}, int32_t{2}));
  ASSERT_TRUE(request);
  auto raw = ask<raw_payload>(*proxy, 1s, raw_payload{*request});
  ASSERT_TRUE(raw) << render(raw.error());
  auto sum = unmarshal(sys(), raw->bytes.data(), raw->bytes.size());
  ASSERT_TRUE(sum) << render(sum.error());
  ASSERT_TRUE(sum->match_elements<int32_t>()) << caf::to_string(*sum);
  EXPECT_EQ(sum->get_as<int32_t>(0), 42);
  // A request the APO does not take fails, typed, as any request does.
  auto odd = marshal(sys(), caf::make_message(2.5));
  ASSERT_TRUE(odd);
  auto failed = ask<raw_payload>(*proxy, 1s, raw_payload{*odd});
  ASSERT_FALSE(failed);
  EXPECT_EQ(failed.error().category(), caf::atom("herm")) << render(failed.error());
  auto bad = ask<raw_payload>(*proxy, 1s, raw_payload{byte_buffer{9, 9}});
  ASSERT_FALSE(bad);
  EXPECT_NE(render(bad.error()).find("not an APO payload of version 1"),
            std::string::npos)
    << render(bad.error());
  EXPECT_EQ(stats(0).requests_sent, 2u); // the bad one never left
}

TEST_F(asl_test, requests_and_responses_take_the_published_routes) {
  // 0 -Ethernet- 1 -CAN (MTU 8)- 2 as above, but modules 0 and 2 send on
  // the routes their agents publish (routing/fast_routes.hpp; the
  // simulation's packet observer, which keeps them on the agent's path, is
  // off there). Module 1 forwards, fragments and reassembles as before.
  build(3, {{{0, 1}, "ethernet"}, {{1, 2}, "can2.0"}}, [](sim_network& n) {
    for (size_t i : {0, 2}) {
      n.at(i).cfg.observer = nullptr;
      n.at(i).cfg.fast_routes = std::make_shared<route_cell>();
    }
  });
  auto log = std::make_shared<seen>();
  add(2, "calc", "herm.example.calculator", spawn_calculator(log));
  auto proxy = bind(0, bind_request{query_by::name, "calc", 300, false});
  ASSERT_TRUE(proxy) << render(proxy.error());
  for (int32_t i = 0; i < 5; ++i) {
    auto sum = ask<int32_t>(*proxy, 1s, int32_t{40}, i);
    ASSERT_TRUE(sum) << render(sum.error());
    EXPECT_EQ(*sum, 40 + i);
  }
  std::string text(300, 'x');
  auto echo = ask<std::string>(*proxy, 1s, text);
  ASSERT_TRUE(echo) << render(echo.error());
  EXPECT_EQ(*echo, "echo: " + text);
  EXPECT_EQ(stats(0).requests_sent, 6u);
  EXPECT_EQ(stats(2).requests_served, 6u);
  // Every request after the first route was in use and every response
  // after the first went straight to the channel; the router forwarded
  // them all.
  auto s0 = net->stats(0);
  auto s2 = net->stats(2);
  EXPECT_GE(s0.fast_sent, 5u);
  EXPECT_GE(s2.fast_sent, 5u);
  EXPECT_GE(s0.originated, s0.fast_sent + 1);
  EXPECT_GE(net->stats(1).forwarded, 12u);
  EXPECT_EQ(net->stats(1).fast_sent, 0u); // no cell: nothing published
}

TEST_F(asl_test, many_concurrent_requests_each_get_their_own_answer) {
  build(2, {{{0, 1}, "can2.0"}});
  add(1, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  auto proxy = bind(0, bind_request{query_by::name, "calc", 300, false});
  ASSERT_TRUE(proxy);
  auto answers = std::make_shared<std::map<int32_t, int32_t>>();
  auto dst = *proxy;
  sys().spawn([=](caf::event_based_actor* self) {
    for (int32_t i = 0; i < 50; ++i)
      self->request(dst, caf::infinite, i, int32_t{1000})
        .then([=](int32_t r) { (*answers)[i] = r; });
  });
  advance(2s);
  ASSERT_EQ(answers->size(), 50u);
  for (auto [i, r] : *answers)
    EXPECT_EQ(r, i + 1000);
}

TEST_F(asl_test, failures_arrive_as_typed_errors) {
  build(2, {{{0, 1}, "ethernet"}});
  auto ref = add(1, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  auto proxy = bind(0, ref);
  ASSERT_TRUE(proxy);
  // The APO's own error, with its context, crosses the network.
  auto own = ask<int32_t>(*proxy, 1s, atom::get_v);
  ASSERT_FALSE(own);
  EXPECT_TRUE(is(own.error(), ec::invalid_parameter)) << render(own.error());
  EXPECT_NE(render(own.error()).find("calculators do not get"), std::string::npos);
  // A message the APO has no handler for: HERM's invalid_parameter (CAF's
  // own codes never reach a user).
  auto unexpected = ask<int32_t>(*proxy, 1s, 1.5);
  ASSERT_FALSE(unexpected);
  EXPECT_TRUE(is(unexpected.error(), ec::invalid_parameter))
    << render(unexpected.error());
  // Something that cannot be marshalled (an actor handle) is refused here.
  auto refused = ask<int32_t>(*proxy, 1s, *proxy);
  ASSERT_FALSE(refused);
  EXPECT_TRUE(is(refused.error(), ec::invalid_parameter)) << render(refused.error());
  // An answer that never comes: the layer's deadline (2 s here).
  auto never = ask<int32_t>(*proxy, 3s, atom::done_v);
  ASSERT_FALSE(never);
  EXPECT_TRUE(is(never.error(), ec::timeout)) << render(never.error());
  EXPECT_EQ(stats(0).request_timeouts, 1u);
  // Oversized: over max_message after marshalling.
  auto big = ask<std::string>(*proxy, 1s, std::string(70 * 1024, 'b'));
  ASSERT_FALSE(big);
  EXPECT_TRUE(is(big.error(), ec::packet_too_large)) << render(big.error());
}

TEST_F(asl_test, binding_to_a_missing_apo_or_module_fails) {
  build(2, {{{0, 1}, "ethernet"}});
  auto ref = add(1, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  auto nowhere = bind(0, apo_ref{0x77, 1, "x", "t"});
  ASSERT_FALSE(nowhere);
  EXPECT_TRUE(is(nowhere.error(), routing_ec::no_route)) << render(nowhere.error());
  auto missing = bind(0, bind_request{query_by::name, "ghost", 200, false});
  ASSERT_FALSE(missing);
  EXPECT_TRUE(is(missing.error(), app_ec::not_found)) << render(missing.error());
  // A stale number: the proxy ends at once (the far end says it is gone).
  auto stale = ref;
  stale.apo += 1000;
  auto proxy = bind(0, stale);
  ASSERT_TRUE(proxy);
  auto log = std::make_shared<seen>();
  auto watcher = spawn_recorder(log);
  caf::anon_send(watcher, atom::add_v, *proxy);
  run();
  ASSERT_EQ(log->downs.size(), 1u);
  EXPECT_TRUE(is(log->downs[0].reason, app_ec::apo_gone)) << render(log->downs[0].reason);
  auto after = ask<int32_t>(*proxy, 1s, int32_t{1}, int32_t{2});
  ASSERT_FALSE(after);
}

TEST_F(asl_test, binding_to_a_local_apo_yields_the_apo_itself) {
  build(2, {{{0, 1}, "ethernet"}});
  auto apo = spawn_calculator(std::make_shared<seen>());
  auto ref = add(0, "calc", "t", apo);
  auto direct = bind(0, ref);
  ASSERT_TRUE(direct);
  EXPECT_EQ(*direct, apo);
  auto by_name = bind(0, bind_request{query_by::name, "calc", 100, false});
  ASSERT_TRUE(by_name);
  EXPECT_EQ(*by_name, apo);
}

// -- monitoring -----------------------------------------------------------------------

TEST_F(asl_test, a_monitor_of_a_proxy_learns_when_the_remote_apo_exits) {
  // Through an intermediate module: 0 - 1 - 2.
  build(3, {{{0, 1}, "ethernet"}, {{1, 2}, "ethernet"}});
  auto apo = spawn_calculator(std::make_shared<seen>());
  auto ref = add(2, "calc", "t", apo);
  auto proxy = bind(0, ref);
  ASSERT_TRUE(proxy);
  auto log = std::make_shared<seen>();
  auto watcher = spawn_recorder(log);
  caf::anon_send(watcher, atom::add_v, *proxy);
  run();
  EXPECT_TRUE(log->downs.empty());
  caf::anon_send_exit(apo, caf::exit_reason::user_shutdown);
  run();
  ASSERT_EQ(log->downs.size(), 1u);
  EXPECT_EQ(log->downs[0].source, proxy->address());
  EXPECT_EQ(log->downs[0].reason, caf::exit_reason::user_shutdown);
  auto after = ask<int32_t>(*proxy, 1s, int32_t{1}, int32_t{2});
  EXPECT_FALSE(after);
}

TEST_F(asl_test, a_monitor_of_a_proxy_learns_when_the_remote_module_dies) {
  build(3, {{{0, 1}, "ethernet"}, {{1, 2}, "can2.0"}});
  add(2, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  auto proxy = bind(0, bind_request{query_by::name, "calc", 300, false});
  ASSERT_TRUE(proxy);
  auto log = std::make_shared<seen>();
  auto watcher = spawn_recorder(log);
  caf::anon_send(watcher, atom::add_v, *proxy);
  run();
  net->kill(2);
  // Hellos stop; module 1 loses the neighbour, retracts the route; module 0
  // waits the grace period (300 ms here) before giving up.
  net->advance(1500ms);
  ASSERT_EQ(log->downs.size(), 1u);
  EXPECT_TRUE(is(log->downs[0].reason, routing_ec::no_route)) << render(log->downs[0].reason);
  auto after = ask<int32_t>(*proxy, 1s, int32_t{1}, int32_t{2});
  ASSERT_FALSE(after);
  EXPECT_EQ(stats(0).proxies_ended, 1u);
}

TEST_F(asl_test, a_pending_request_fails_when_the_module_becomes_unreachable) {
  build(2, {{{0, 1}, "ethernet"}});
  add(1, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  auto proxy = bind(0, bind_request{query_by::name, "calc", 300, false});
  ASSERT_TRUE(proxy);
  net->silence(0);
  // The request is lost on the silent link; the route goes away; the
  // requester hears no_route well before the 2 s request deadline.
  auto res = ask<int32_t>(*proxy, 1500ms, int32_t{1}, int32_t{2});
  ASSERT_FALSE(res);
  EXPECT_TRUE(is(res.error(), routing_ec::no_route)) << render(res.error());
  net->restore(0);
}

TEST_F(asl_test, a_rebinding_proxy_resumes_when_the_module_returns) {
  build(2, {{{0, 1}, "ethernet"}});
  add(1, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  auto proxy = bind(0, bind_request{query_by::name, "calc", 300, true});
  ASSERT_TRUE(proxy);
  ASSERT_TRUE(ask<int32_t>(*proxy, 1s, int32_t{1}, int32_t{1}));
  net->kill(1);
  net->advance(1500ms);
  auto gone = ask<int32_t>(*proxy, 1s, int32_t{1}, int32_t{2});
  ASSERT_FALSE(gone);
  EXPECT_TRUE(is(gone.error(), app_ec::apo_gone)) << render(gone.error());
  // The module comes back with a new calculator under the same name.
  net->start_module(1);
  net->advance(1s);
  add(1, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  net->advance(1s); // the next rebind search finds it
  auto back = ask<int32_t>(*proxy, 1s, int32_t{20}, int32_t{22});
  ASSERT_TRUE(back) << render(back.error());
  EXPECT_EQ(*back, 42);
}

// -- topics ---------------------------------------------------------------------------

TEST_F(asl_test, topics_reach_subscribers_on_every_module_late_joiners_included) {
  // Publisher on 4; subscribers on 0 and 2; a late joiner on 3.
  build(5, {{{0, 1}, "ethernet"}, {{1, 2}, "can2.0"}, {{2, 3, 4}, "can2.0"}});
  auto s0 = std::make_shared<seen>(), s2 = std::make_shared<seen>();
  auto sub0 = spawn_recorder(s0), sub2 = spawn_recorder(s2);
  ASSERT_TRUE(call<>(asl(0), atom::subscribe_v, std::string{"range"}, sub0));
  ASSERT_TRUE(call<>(asl(2), atom::subscribe_v, std::string{"range"}, sub2));
  net->advance(500ms);
  for (int32_t v = 1; v <= 3; ++v) {
    caf::anon_send(asl(4), atom::publish_v, std::string{"range"},
                   caf::make_message(v * 100));
    net->advance(100ms);
  }
  EXPECT_EQ(s0->numbers, (std::vector<int32_t>{100, 200, 300}));
  EXPECT_EQ(s2->numbers, (std::vector<int32_t>{100, 200, 300}));
  // A late joiner gets the last value at once, then the next ones.
  auto s3 = std::make_shared<seen>();
  auto sub3 = spawn_recorder(s3);
  ASSERT_TRUE(call<>(asl(3), atom::subscribe_v, std::string{"range"}, sub3));
  net->advance(100ms);
  EXPECT_EQ(s3->numbers, std::vector<int32_t>{300});
  caf::anon_send(asl(4), atom::publish_v, std::string{"range"},
                 caf::make_message(int32_t{400}));
  net->advance(100ms);
  EXPECT_EQ(s3->numbers, (std::vector<int32_t>{300, 400}))
    << "received " << stats(3).publications_received << ", sent "
    << stats(4).publications_sent << ", lost " << stats(3).publications_lost;
  EXPECT_EQ(s0->numbers.back(), 400);
  EXPECT_EQ(stats(0).publications_lost, 0u);
}

TEST_F(asl_test, a_dead_subscriber_stops_the_stream_to_its_module) {
  build(2, {{{0, 1}, "ethernet"}});
  auto s0 = std::make_shared<seen>();
  auto sub0 = spawn_recorder(s0);
  ASSERT_TRUE(call<>(asl(0), atom::subscribe_v, std::string{"vision"}, sub0));
  net->advance(300ms);
  caf::anon_send(asl(1), atom::publish_v, std::string{"vision"},
                 caf::make_message(std::string(100, 'v')));
  net->advance(100ms);
  ASSERT_EQ(s0->texts.size(), 1u);
  caf::anon_send_exit(sub0, caf::exit_reason::user_shutdown);
  net->advance(100ms);
  auto sent = stats(1).publications_sent;
  caf::anon_send(asl(1), atom::publish_v, std::string{"vision"},
                 caf::make_message(std::string(100, 'w')));
  net->advance(100ms);
  EXPECT_EQ(stats(1).publications_sent, sent); // unsubscribed: nothing sent
}

TEST_F(asl_test, subscribers_follow_a_publisher_that_moves) {
  build(3, {{{0, 1}, "ethernet"}, {{1, 2}, "ethernet"}});
  auto s0 = std::make_shared<seen>();
  auto sub0 = spawn_recorder(s0);
  ASSERT_TRUE(call<>(asl(0), atom::subscribe_v, std::string{"pose"}, sub0));
  net->advance(300ms);
  caf::anon_send(asl(2), atom::publish_v, std::string{"pose"},
                 caf::make_message(int32_t{1}));
  net->advance(100ms);
  net->kill(2);
  net->advance(1s);
  // The publisher comes back on module 1: it advertises, the subscriber's
  // module subscribes at once.
  caf::anon_send(asl(1), atom::publish_v, std::string{"pose"},
                 caf::make_message(int32_t{2}));
  net->advance(100ms);
  caf::anon_send(asl(1), atom::publish_v, std::string{"pose"},
                 caf::make_message(int32_t{3}));
  net->advance(100ms);
  EXPECT_EQ(s0->numbers, (std::vector<int32_t>{1, 2, 3}));
}

// -- bad input ------------------------------------------------------------------------

namespace {

using raw_log = std::vector<packet_delivered>;

} // namespace

TEST_F(asl_test, bad_input_is_dropped_and_counted_or_answered_with_an_error) {
  // Module 0 runs no ASL: the test speaks protocol 1 by hand from there.
  cfg.limits.max_total = 4096;
  net = std::make_unique<sim_network>(*this, test_prefix());
  net->add_module(id_of(0));
  net->add_module(id_of(1));
  net->connect({0, 1}, "ethernet");
  net->on_start = [this](size_t i, sim_network::module& m) {
    if (i == 1)
      m.apps = caf::actor_cast<caf::actor>(
        track(spawn_app_support(sys(), m.agent, cfg)));
  };
  net->start();
  net->advance(2s);
  auto ref = add(1, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  auto got = std::make_shared<raw_log>();
  auto rcv = track(sys().spawn(
    [got](network_receiver_actor::pointer) -> network_receiver_actor::behavior_type {
      return {[got](packet_delivered& x) { got->push_back(std::move(x)); }};
    }));
  caf::anon_send(net->at(0).agent, atom::subscribe_v, asl_protocol, rcv);
  auto send_raw = [&](byte_buffer bytes) {
    caf::anon_send(net->at(0).agent,
                   send_packet{id_of(1), asl_protocol, prio_normal, bytes});
    run();
  };
  auto enc = [](const asl_message& m) {
    byte_buffer out;
    encode(m, out);
    return out;
  };
  auto last_response = [&]() -> asl_response {
    if (got->empty())
      return {};
    auto m = decode_asl(got->back().payload.data(), got->back().payload.size());
    if (!m || !std::holds_alternative<asl_response>(*m))
      return {};
    return std::get<asl_response>(*m);
  };
  // Garbage: counted, nothing answered.
  send_raw({0x01});
  send_raw({0x07, 0x03, 0xFF});
  EXPECT_EQ(stats(1).rx_malformed, 2u);
  EXPECT_TRUE(got->empty());
  // A payload naming a type this module does not know: app_ec::unknown_type.
  byte_buffer unknown{apo_format_version, 1, 8};
  for (char c : std::string{"foo::bar"})
    unknown.push_back(static_cast<uint8_t>(c));
  unknown.push_back(0);
  send_raw(enc(asl_request{77, ref.apo, unknown}));
  auto r = last_response();
  EXPECT_EQ(r.request_id, 77u);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.error.code, static_cast<uint8_t>(app_ec::unknown_type));
  EXPECT_NE(r.error.context.find("foo::bar"), std::string::npos);
  EXPECT_EQ(stats(1).rx_unknown_type, 1u);
  // A payload that does not decode: invalid_parameter.
  send_raw(enc(asl_request{78, ref.apo, byte_buffer{apo_format_version, 1}}));
  r = last_response();
  EXPECT_EQ(r.request_id, 78u);
  EXPECT_EQ(r.error.code, static_cast<uint8_t>(ec::invalid_parameter));
  // An APO that is not there: apo_gone.
  auto good = marshal(sys(), caf::make_message(int32_t{1}, int32_t{2}));
  ASSERT_TRUE(good);
  send_raw(enc(asl_request{79, ref.apo + 1, *good}));
  r = last_response();
  EXPECT_EQ(r.request_id, 79u);
  EXPECT_EQ(r.error.code, static_cast<uint8_t>(app_ec::apo_gone));
  // The same request to the right APO is served.
  send_raw(enc(asl_request{80, ref.apo, *good}));
  r = last_response();
  EXPECT_EQ(r.request_id, 80u);
  ASSERT_TRUE(r.ok);
  auto sum = unmarshal(sys(), r.payload.data(), r.payload.size());
  ASSERT_TRUE(sum);
  EXPECT_EQ(sum->get_as<int32_t>(0), 3);
  // A response to a request nobody made: counted and dropped.
  send_raw(enc(asl_response{12345, true, *good, {}}));
  EXPECT_EQ(stats(1).rx_unexpected_response, 1u);
  // An oversized payload is refused by the unmarshal limits.
  byte_buffer huge(8192, 0);
  huge[0] = apo_format_version;
  send_raw(enc(asl_request{81, ref.apo, huge}));
  r = last_response();
  EXPECT_EQ(r.request_id, 81u);
  EXPECT_FALSE(r.ok);
  // The module still serves.
  auto proxy_ok = stats(1).requests_served;
  EXPECT_EQ(proxy_ok, 1u);
}

// An APO registered the moment its module starts (before any timer ran)
// already names its module in its reference.
TEST_F(asl_test, an_apo_registered_at_start_up_names_its_module) {
  net = std::make_unique<sim_network>(*this, test_prefix());
  net->add_module(id_of(0));
  add_app_support(*this, *net, cfg);
  net->start();
  auto log = std::make_shared<seen>();
  auto ref = add(0, "early", "t", spawn_calculator(log));
  EXPECT_EQ(ref.module, id_of(0));
}

// -- reliable mode ------------------------------------------------------------------
//
// Requests through a binding made with `reliable`: acknowledged end to end,
// retransmitted with backoff, delivered to the APO once per request, failed
// with a typed error only past their deadline (docs/reliability.md).

namespace {

/// A test module that runs no ASL and speaks protocol 1 by hand: what it
/// receives and a way to send.
struct raw_peer {
  std::shared_ptr<raw_log> got = std::make_shared<raw_log>();
  std::function<void(const asl_message&)> send;

  /// The ASL messages of type T received so far, in order.
  template <class T>
  std::vector<T> received() const {
    std::vector<T> result;
    for (auto& pkt : *got) {
      auto m = decode_asl(pkt.payload.data(), pkt.payload.size());
      if (m && std::holds_alternative<T>(*m))
        result.push_back(std::get<T>(*m));
    }
    return result;
  }
};

} // namespace

class asl_reliable_test : public asl_test {
public:
  /// Modules 0 and 1 joined by Ethernet; only module `with_asl` runs an ASL,
  /// the other is `raw`.
  void build_half_raw(size_t with_asl) {
    net = std::make_unique<sim_network>(*this, test_prefix());
    net->add_module(id_of(0));
    net->add_module(id_of(1));
    net->connect({0, 1}, "ethernet");
    net->on_start = [this, with_asl](size_t i, sim_network::module& m) {
      if (i == with_asl)
        m.apps = caf::actor_cast<caf::actor>(
          track(spawn_app_support(sys(), m.agent, cfg)));
    };
    net->start();
    net->advance(2s);
    auto other = 1 - with_asl;
    auto got = raw.got;
    auto rcv = track(sys().spawn(
      [got](network_receiver_actor::pointer)
        -> network_receiver_actor::behavior_type {
        return {[got](packet_delivered& x) { got->push_back(std::move(x)); }};
      }));
    caf::anon_send(net->at(other).agent, atom::subscribe_v, asl_protocol, rcv);
    auto agent = net->at(other).agent;
    auto dst = id_of(with_asl);
    raw.send = [this, agent, dst](const asl_message& msg) {
      byte_buffer bytes;
      encode(msg, bytes);
      caf::anon_send(agent, send_packet{dst, asl_protocol, prio_normal, bytes});
      run();
    };
    run();
  }

  /// Sends `xs` as a request through `dst` from a fresh actor; the answer
  /// (or error) lands in the returned slot once it arrives.
  template <class R, class... Ts>
  std::shared_ptr<std::vector<caf::expected<R>>> start_request(caf::actor dst,
                                                               Ts... xs) {
    auto result = std::make_shared<std::vector<caf::expected<R>>>();
    sys().spawn([=](caf::event_based_actor* self) {
      self->request(dst, caf::infinite, xs...)
        .then([=](R& r) { result->push_back(r); },
              [=](caf::error& err) { result->push_back(err); });
    });
    run();
    return result;
  }

  byte_buffer payload_of(caf::message msg) {
    auto bytes = marshal(sys(), msg);
    EXPECT_TRUE(bytes);
    return bytes ? *bytes : byte_buffer{};
  }

  raw_peer raw;
};

TEST_F(asl_reliable_test, a_lost_request_is_retransmitted_and_served_once) {
  build(2, {{{0, 1}, "ethernet"}});
  auto log = std::make_shared<seen>();
  add(1, "calc", "t", spawn_calculator(log));
  auto proxy = bind(0, bind_request{query_by::name, "calc", 300, false, true});
  ASSERT_TRUE(proxy) << render(proxy.error());
  // The link drops everything for 400 ms: the first copies are lost.
  net->silence(0);
  auto answer = start_request<std::string>(*proxy, std::string{"hello"});
  caf::anon_send(*proxy, int32_t{7});
  net->advance(400ms);
  EXPECT_TRUE(answer->empty());
  EXPECT_TRUE(log->texts.empty());
  net->restore(0);
  net->advance(3s);
  ASSERT_EQ(answer->size(), 1u);
  ASSERT_TRUE(answer->front()) << render(answer->front().error());
  EXPECT_EQ(*answer->front(), "echo: hello");
  // The APO ran once for each, whatever the number of copies.
  EXPECT_EQ(log->texts, std::vector<std::string>{"hello"});
  EXPECT_EQ(log->numbers, std::vector<int32_t>{7});
  auto s0 = stats(0), s1 = stats(1);
  EXPECT_EQ(s0.reliable_sent, 2u);
  EXPECT_GE(s0.retransmissions, 2u);
  EXPECT_EQ(s0.acks_received, 1u); // the one-way message's
  EXPECT_EQ(s0.pending_requests, 0u);
  EXPECT_EQ(s1.requests_served, 1u);
  EXPECT_EQ(s1.oneway_delivered, 1u);
  EXPECT_EQ(s1.cached_responses, 2u);
}

TEST_F(asl_reliable_test, a_lost_response_is_sent_again_from_the_cache_and_the_apo_runs_once) {
  build_half_raw(1);
  auto log = std::make_shared<seen>();
  auto ref = add(1, "calc", "t", spawn_calculator(log));
  auto text = payload_of(caf::make_message(std::string{"once"}));
  raw.send(asl_reliable_request{41, ref.apo, false, text});
  auto first = raw.received<asl_response>();
  ASSERT_EQ(first.size(), 1u);
  ASSERT_TRUE(first[0].ok);
  // The requester did not get it (lost) and sends the request again, now
  // and much later: the cached response each time, the APO is not asked.
  raw.send(asl_reliable_request{41, ref.apo, false, text});
  net->advance(5s);
  raw.send(asl_reliable_request{41, ref.apo, false, text});
  auto all = raw.received<asl_response>();
  ASSERT_EQ(all.size(), 3u);
  EXPECT_EQ(all[1], first[0]);
  EXPECT_EQ(all[2], first[0]);
  EXPECT_EQ(log->texts, std::vector<std::string>{"once"});
  EXPECT_EQ(stats(1).duplicates_suppressed, 2u);
  EXPECT_EQ(stats(1).requests_served, 1u);
  // The same request id from another module is another request; a plain
  // request is never deduplicated (it is never retransmitted either).
  raw.send(asl_request{41, ref.apo, text});
  EXPECT_EQ(log->texts.size(), 2u);
  // An APO error is cached like a value.
  auto get = payload_of(caf::make_message(atom::get_v));
  raw.send(asl_reliable_request{42, ref.apo, false, get});
  raw.send(asl_reliable_request{42, ref.apo, false, get});
  all = raw.received<asl_response>();
  ASSERT_EQ(all.size(), 6u);
  EXPECT_FALSE(all[4].ok);
  EXPECT_EQ(all[4], all[5]);
}

TEST_F(asl_reliable_test, a_duplicate_one_way_message_is_acknowledged_not_delivered_again) {
  build_half_raw(1);
  auto log = std::make_shared<seen>();
  auto ref = add(1, "calc", "t", spawn_calculator(log));
  auto seven = payload_of(caf::make_message(int32_t{7}));
  for (int i = 0; i < 3; ++i)
    raw.send(asl_reliable_request{9, ref.apo, true, seven});
  EXPECT_EQ(log->numbers, std::vector<int32_t>{7});
  auto acks = raw.received<asl_ack>();
  ASSERT_EQ(acks.size(), 3u);
  EXPECT_EQ(acks[0].request_id, 9u);
  EXPECT_TRUE(raw.received<asl_response>().empty());
  EXPECT_EQ(stats(1).duplicates_suppressed, 2u);
  EXPECT_EQ(stats(1).acks_sent, 3u);
  // A copy of a request still being served gets an ack ("keep waiting").
  auto never = payload_of(caf::make_message(atom::done_v));
  raw.send(asl_reliable_request{10, ref.apo, false, never});
  raw.send(asl_reliable_request{10, ref.apo, false, never});
  acks = raw.received<asl_ack>();
  ASSERT_EQ(acks.size(), 4u);
  EXPECT_EQ(acks[3].request_id, 10u);
}

TEST_F(asl_reliable_test, the_sender_retransmits_with_backoff_and_drops_a_late_duplicate) {
  cfg.retransmit_initial = 200ms;
  cfg.retransmit_max = 800ms;
  cfg.request_timeout = 10s;
  build_half_raw(0);
  apo_ref target{id_of(1), 7, "calc", "t"};
  auto res = call<caf::actor>(asl(0), atom::bind_v, target, true);
  ASSERT_TRUE(res) << render(res.error());
  auto proxy = std::get<0>(*res);
  auto answer = start_request<int32_t>(proxy, int32_t{40}, int32_t{2});
  auto copies = [&] { return raw.received<asl_reliable_request>(); };
  ASSERT_EQ(copies().size(), 1u);
  auto first = copies()[0];
  EXPECT_EQ(first.apo, 7u);
  EXPECT_FALSE(first.oneway);
  // Nothing comes back: copies after 200, 400 and 800 ms (then every
  // 800 ms), identical to the first.
  net->advance(250ms);
  EXPECT_EQ(copies().size(), 2u);
  net->advance(400ms);
  EXPECT_EQ(copies().size(), 3u);
  net->advance(800ms);
  EXPECT_EQ(copies().size(), 4u);
  for (auto& c : copies())
    EXPECT_EQ(c, first);
  EXPECT_EQ(stats(0).retransmissions, 3u);
  // "Being served": the sender only probes at the slowest pace.
  raw.send(asl_ack{first.request_id});
  auto before = copies().size();
  net->advance(700ms);
  EXPECT_EQ(copies().size(), before);
  // The response arrives, then a late copy of it: one answer.
  auto sum = payload_of(caf::make_message(int32_t{42}));
  raw.send(asl_response{first.request_id, true, sum, {}});
  raw.send(asl_response{first.request_id, true, sum, {}});
  raw.send(asl_ack{first.request_id});
  net->advance(3s);
  ASSERT_EQ(answer->size(), 1u);
  ASSERT_TRUE(answer->front()) << render(answer->front().error());
  EXPECT_EQ(*answer->front(), 42);
  auto s = stats(0);
  EXPECT_EQ(s.late_duplicates, 2u);
  EXPECT_EQ(s.acks_received, 1u);
  EXPECT_EQ(s.rx_unexpected_response, 0u);
  EXPECT_EQ(s.pending_requests, 0u);
  EXPECT_EQ(copies().size(), before); // no copy after the response
}

// Idle, the housekeeping tick slows to idle_tick; a request sent then
// brings it forward at once, so its retransmissions and deadline keep the
// fine tick's granularity.
TEST_F(asl_reliable_test, a_request_sent_while_idle_brings_the_slow_tick_forward) {
  cfg.idle_tick = 2s;
  cfg.retransmit_initial = 200ms;
  cfg.request_timeout = 1s;
  build_half_raw(0);
  apo_ref target{id_of(1), 7, "calc", "t"};
  auto res = call<caf::actor>(asl(0), atom::bind_v, target, true);
  ASSERT_TRUE(res) << render(res.error());
  auto proxy = std::get<0>(*res);
  net->advance(5s + 300ms);  // idle: the next tick is up to 2 s away
  auto answer = start_request<int32_t>(proxy, int32_t{40}, int32_t{2});
  auto copies = [&] { return raw.received<asl_reliable_request>(); };
  ASSERT_EQ(copies().size(), 1u);
  net->advance(250ms);
  EXPECT_EQ(copies().size(), 2u) << "the first retransmission waited for the idle tick";
  // No answer: the deadline (1 s) passes on the fine tick, not the next
  // idle one.
  net->advance(800ms);
  ASSERT_EQ(answer->size(), 1u);
  ASSERT_FALSE(answer->front());
  EXPECT_TRUE(is(answer->front().error(), ec::timeout))
    << render(answer->front().error());
  EXPECT_EQ(stats(0).request_timeouts, 1u);
}

TEST_F(asl_reliable_test, a_plain_request_sent_while_idle_leaves_the_slow_tick_alone) {
  cfg.idle_tick = 2s;
  cfg.request_timeout = 5s;
  build_half_raw(0);
  apo_ref target{id_of(1), 7, "calc", "t"};
  auto res = call<caf::actor>(asl(0), atom::bind_v, target, false);
  ASSERT_TRUE(res) << render(res.error());
  auto proxy = std::get<0>(*res);
  net->advance(5s + 300ms); // idle: the next tick is up to 2 s away
  ASSERT_EQ(ticks_pending(0), 1u);
  auto answer = start_request<int32_t>(proxy, int32_t{40}, int32_t{2});
  ASSERT_EQ(raw.received<asl_request>().size(), 1u);
  // The slow tick comes long before the deadline: bringing the fine one
  // forward would only leave it behind, superseded, to wake the loop.
  EXPECT_EQ(ticks_pending(0), 1u) << "a superseded slow tick was left behind";
  // The slow tick finds the request waiting and brings the fine tick: the
  // deadline passes on it, not on a later slow one.
  net->advance(4900ms);
  EXPECT_TRUE(answer->empty());
  net->advance(250ms);
  ASSERT_EQ(answer->size(), 1u);
  ASSERT_FALSE(answer->front());
  EXPECT_TRUE(is(answer->front().error(), ec::timeout))
    << render(answer->front().error());
}

TEST_F(asl_reliable_test, a_module_lost_while_idle_fails_a_plain_request_at_the_fine_tick) {
  cfg.idle_tick = 5s;
  cfg.request_timeout = 10s;
  build(2, {{{0, 1}, "ethernet"}});
  add(1, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  auto proxy = bind(0, bind_request{query_by::name, "calc", 300, false});
  ASSERT_TRUE(proxy);
  net->advance(6s);                    // idle: slow ticks
  net->advance(std::chrono::ceil<std::chrono::milliseconds>(next_tick_in(0))
               + 1ms); // just past one: the next is 5 s away
  ASSERT_GE(next_tick_in(0), 4s);
  net->silence(0);
  // The request leaves the slow tick alone (its deadline is 10 s away) and
  // is lost on the silent link. The route goes, the grace (300 ms) passes:
  // the fine tick that losing the route brought forward fails the request,
  // not the slow tick nor the deadline.
  auto answer = start_request<int32_t>(*proxy, int32_t{1}, int32_t{2});
  net->advance(2s);
  ASSERT_EQ(answer->size(), 1u);
  ASSERT_FALSE(answer->front());
  EXPECT_TRUE(is(answer->front().error(), routing_ec::no_route))
    << render(answer->front().error());
  net->restore(0);
}

TEST_F(asl_reliable_test, a_destination_gone_past_the_deadline_gives_no_route_not_sooner) {
  build(2, {{{0, 1}, "ethernet"}});
  add(1, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  auto proxy = bind(0, bind_request{query_by::name, "calc", 300, false, true});
  ASSERT_TRUE(proxy);
  auto watcher_log = std::make_shared<seen>();
  auto watcher = spawn_recorder(watcher_log);
  caf::anon_send(watcher, atom::add_v, *proxy);
  net->kill(1);
  auto answer = start_request<int32_t>(*proxy, int32_t{1}, int32_t{2});
  // Well past the unreachable grace (300 ms) but before the deadline
  // (request_timeout, 2 s): still waiting, the proxy still alive.
  net->advance(1800ms);
  EXPECT_TRUE(answer->empty());
  EXPECT_TRUE(watcher_log->downs.empty());
  net->advance(400ms);
  ASSERT_EQ(answer->size(), 1u);
  ASSERT_FALSE(answer->front());
  EXPECT_TRUE(is(answer->front().error(), routing_ec::no_route))
    << render(answer->front().error());
  EXPECT_EQ(stats(0).request_timeouts, 1u);
  EXPECT_EQ(stats(0).pending_requests, 0u);
}

TEST_F(asl_reliable_test, a_reliable_rebinding_proxy_carries_a_request_across_a_restart) {
  cfg.request_timeout = 5s;
  build(2, {{{0, 1}, "ethernet"}});
  auto before = std::make_shared<seen>();
  add(1, "calc", "t", spawn_calculator(before));
  // [reliable-bind]
  bind_request req{query_by::name, "calc", 300};
  req.rebind = true;   // follow the APO to a restarted module
  req.reliable = true; // acknowledged, retransmitted, delivered once
  // [reliable-bind-end]
  auto proxy = bind(0, req);
  ASSERT_TRUE(proxy);
  net->kill(1);
  auto answer = start_request<std::string>(*proxy, std::string{"x"});
  net->advance(1s);
  EXPECT_TRUE(answer->empty());
  // The module restarts with a new calculator under the same name: the
  // request waited and goes to it.
  net->start_module(1);
  net->advance(500ms);
  auto after = std::make_shared<seen>();
  add(1, "calc", "t", spawn_calculator(after));
  net->advance(2s);
  ASSERT_EQ(answer->size(), 1u);
  ASSERT_TRUE(answer->front()) << render(answer->front().error());
  EXPECT_EQ(*answer->front(), "echo: x");
  EXPECT_EQ(after->texts, std::vector<std::string>{"x"});
  EXPECT_TRUE(before->texts.empty());
}

TEST_F(asl_reliable_test, the_duplicate_cache_and_the_sender_tables_stay_bounded) {
  cfg.reliable_cache = 16;
  cfg.reliable_cache_ttl = 1s;
  build_half_raw(1);
  auto log = std::make_shared<seen>();
  auto ref = add(1, "calc", "t", spawn_calculator(log));
  auto x = payload_of(caf::make_message(int32_t{1}));
  for (uint64_t id = 1; id <= 100; ++id)
    raw.send(asl_reliable_request{id, ref.apo, true, x});
  EXPECT_EQ(log->numbers.size(), 100u);
  EXPECT_EQ(stats(1).cached_responses, 16u);
  // The newest are remembered: a copy of request 100 is suppressed.
  raw.send(asl_reliable_request{100, ref.apo, true, x});
  EXPECT_EQ(log->numbers.size(), 100u);
  // Entries expire after the ttl.
  net->advance(1500ms);
  EXPECT_EQ(stats(1).cached_responses, 0u);
  // Malformed reliable requests and acks are dropped and counted.
  auto before = stats(1).rx_malformed;
  byte_buffer bad{asl_wire_version, 13, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0};
  caf::anon_send(net->at(0).agent,
                 send_packet{id_of(1), asl_protocol, prio_normal, bad});
  run();
  EXPECT_EQ(stats(1).rx_malformed, before + 1);
}

TEST_F(asl_reliable_test, a_sender_holds_at_most_max_pending_requests) {
  cfg.max_pending = 8;
  build_half_raw(0);
  apo_ref target{id_of(1), 7, "calc", "t"};
  auto res = call<caf::actor>(asl(0), atom::bind_v, target, true);
  ASSERT_TRUE(res);
  auto proxy = std::get<0>(*res);
  std::vector<std::shared_ptr<std::vector<caf::expected<int32_t>>>> answers;
  for (int i = 0; i < 10; ++i)
    answers.push_back(start_request<int32_t>(proxy, int32_t{i}, int32_t{0}));
  size_t refused = 0;
  for (auto& a : answers)
    if (!a->empty() && !a->front() && is(a->front().error(), ec::queue_full))
      ++refused;
  EXPECT_EQ(refused, 2u);
  EXPECT_EQ(stats(0).pending_requests, 8u);
  // Past the deadline every one has its typed error and the table is empty.
  net->advance(3s);
  for (auto& a : answers)
    EXPECT_EQ(a->size(), 1u);
  EXPECT_EQ(stats(0).pending_requests, 0u);
}

// -- hostile input: remote control, bounds, guessable ids ------------------------------
//
// Module 1 runs an ASL; module 0 runs none and speaks protocol 1 by hand
// (raw), or packets are handed to the ASL as the routing agent would, with
// any source and with or without a verified signature.

class asl_hostile_test : public asl_reliable_test {
public:
  /// Hands `msg` to module 1's ASL as if the agent delivered it from `src`.
  void inject(module_id src, const asl_message& msg, bool authenticated) {
    byte_buffer bytes;
    encode(msg, bytes);
    caf::anon_send(asl(1), packet_delivered{src, asl_protocol, prio_normal, 1,
                                            bytes, authenticated});
    run();
  }

  apo_ref add_signed_only(size_t module, const std::string& name,
                          caf::actor apo) {
    auto res = call<apo_ref>(asl(module), atom::add_v, name, std::string{"t"},
                             apo, apo_access::signed_only);
    EXPECT_TRUE(res) << render(res.error());
    return res ? std::get<0>(*res) : apo_ref{};
  }

  std::vector<asl_response> responses() {
    return raw.received<asl_response>();
  }
};

TEST_F(asl_hostile_test, a_signed_only_apo_takes_remote_requests_only_when_signed) {
  build_half_raw(1);
  auto log = std::make_shared<seen>();
  auto ref = add_signed_only(1, "herm.control", spawn_calculator(log));
  auto hello = payload_of(caf::make_message(std::string{"link down"}));
  // Unsigned (a host without the key, or a keyless module): refused with a
  // typed error, counted, never delivered; one-way and reliable alike.
  inject(id_of(0), asl_request{41, ref.apo, hello}, false);
  inject(id_of(0), asl_request{0, ref.apo, hello}, false);
  inject(id_of(0), asl_reliable_request{42, ref.apo, false, hello}, false);
  EXPECT_TRUE(log->texts.empty());
  EXPECT_EQ(stats(1).rx_unauthorized, 3u);
  EXPECT_EQ(stats(1).requests_served, 0u);
  auto rs = responses();
  ASSERT_EQ(rs.size(), 2u);
  for (auto& r : rs) {
    EXPECT_FALSE(r.ok);
    EXPECT_EQ(r.error.code, static_cast<uint8_t>(app_ec::unauthorized));
    EXPECT_NE(r.error.context.find("herm.control"), std::string::npos);
  }
  // Signed and verified: served.
  inject(id_of(0), asl_request{43, ref.apo, hello}, true);
  EXPECT_EQ(log->texts, std::vector<std::string>{"link down"});
  rs = responses();
  ASSERT_EQ(rs.size(), 3u);
  EXPECT_TRUE(rs[2].ok);
  // An open APO takes unsigned requests as before.
  auto open = add(1, "calc", "t", spawn_calculator(log));
  inject(id_of(0), asl_request{44, open.apo, hello}, false);
  EXPECT_EQ(log->texts.size(), 2u);
  EXPECT_EQ(stats(1).rx_unauthorized, 3u);
}

TEST_F(asl_hostile_test, a_keyless_module_serves_remote_control_only_when_its_config_allows) {
  cfg.allow_unsigned_remote = true;
  build_half_raw(1);
  auto log = std::make_shared<seen>();
  auto ref = add_signed_only(1, "herm.control", spawn_calculator(log));
  inject(id_of(0), asl_request{41, ref.apo,
                               payload_of(caf::make_message(std::string{"x"}))},
         false);
  EXPECT_EQ(log->texts, std::vector<std::string>{"x"});
  EXPECT_EQ(stats(1).rx_unauthorized, 0u);
}

TEST_F(asl_hostile_test, signed_only_bindings_ask_the_keyed_agent_to_sign_in_every_data_mode) {
  // Both modules keyed, auth.data: discovery (unicast requests are not
  // signed unless asked).
  net = std::make_unique<sim_network>(*this, test_prefix());
  net->add_module(id_of(0));
  net->add_module(id_of(1));
  for (size_t i = 0; i < 2; ++i)
    net->at(i).cfg.auth.key = std::vector<uint8_t>(32, 0x33);
  net->connect({0, 1}, "ethernet");
  net->on_start = [this](size_t i, sim_network::module& m) {
    if (i == 0)
      m.apps = caf::actor_cast<caf::actor>(
        track(spawn_app_support(sys(), m.agent, cfg)));
  };
  net->start();
  net->advance(3s);
  auto got = raw.got;
  auto rcv = track(sys().spawn(
    [got](network_receiver_actor::pointer) -> network_receiver_actor::behavior_type {
      return {[got](packet_delivered& x) { got->push_back(std::move(x)); }};
    }));
  caf::anon_send(net->at(1).agent, atom::subscribe_v, asl_protocol, rcv);
  run();
  apo_ref target{id_of(1), 7, "herm.control", "herm.control/1"};
  auto plain = call<caf::actor>(asl(0), atom::bind_v, target);
  auto signed_ = call<caf::actor>(asl(0), atom::bind_v, target,
                                  apo_access::signed_only);
  ASSERT_TRUE(plain && signed_);
  start_request<std::string>(std::get<0>(*plain), std::string{"a"});
  start_request<std::string>(std::get<0>(*signed_), std::string{"b"});
  net->advance(100ms);
  std::vector<bool> authenticated;
  for (auto& pkt : *got) {
    auto m = decode_asl(pkt.payload.data(), pkt.payload.size());
    if (m && std::holds_alternative<asl_request>(*m))
      authenticated.push_back(pkt.authenticated);
  }
  EXPECT_EQ(authenticated, (std::vector<bool>{false, true}));
}

TEST_F(asl_hostile_test, apo_numbers_and_request_ids_do_not_follow_one_another) {
  build_half_raw(1);
  std::vector<uint32_t> numbers;
  for (int i = 0; i < 4; ++i)
    numbers.push_back(
      add(1, "n" + std::to_string(i), "t", spawn_calculator(std::make_shared<seen>()))
        .apo);
  for (size_t i = 1; i < numbers.size(); ++i) {
    EXPECT_NE(numbers[i], numbers[i - 1] + 1);
    EXPECT_NE(numbers[i], numbers[i - 1]);
  }
  // The permutation behind them gives distinct values (no repeats while
  // the counter runs) and never 0.
  scrambled_sequence<uint32_t> seq{12345};
  std::set<uint32_t> seen_values;
  for (int i = 0; i < 100000; ++i) {
    auto x = seq.next();
    EXPECT_NE(x, 0u);
    seen_values.insert(x);
  }
  EXPECT_EQ(seen_values.size(), 100000u);
  scrambled_sequence<uint64_t> ids{777};
  auto a = ids.next(), b = ids.next();
  EXPECT_NE(b, a + 1);
  EXPECT_NE(a, b);
}

TEST_F(asl_hostile_test, discovery_answers_fill_the_remote_table_only_up_to_its_bound) {
  cfg.max_remote_apos = 8;
  build_half_raw(1);
  asl_answer flood;
  for (uint32_t i = 1; i <= 20; ++i)
    flood.entries.push_back(asl_entry{i, "x" + std::to_string(i), "t"});
  inject(id_of(0), flood, false);
  EXPECT_EQ(stats(1).known_remote_apos, 8u);
  EXPECT_EQ(stats(1).remote_apos_refused, 12u);
  // Known entries are refreshed, never refused.
  flood.entries.resize(8);
  inject(id_of(0), flood, false);
  EXPECT_EQ(stats(1).remote_apos_refused, 12u);
  // A discovery collects at most max_remote_apos matches, whatever answers.
  auto result = std::make_shared<std::vector<apo_ref>>();
  auto hdl = asl(1);
  sys().spawn([=](caf::event_based_actor* self) {
    self->request(hdl, caf::infinite, atom::find_v,
                  apo_query{query_by::type, "t", 200, false})
      .then([=](std::vector<apo_ref>& xs) { *result = xs; });
  });
  run();
  auto queries = raw.received<asl_query>();
  ASSERT_FALSE(queries.empty());
  asl_answer answer{queries.back().query_id, {}};
  for (uint32_t i = 100; i < 120; ++i)
    answer.entries.push_back(asl_entry{i, "y", "t"});
  raw.send(answer);
  advance(300ms);
  EXPECT_EQ(result->size(), 8u);
  EXPECT_EQ(stats(1).discovery_entries_refused, 12u);
}

TEST_F(asl_hostile_test, watches_subscribers_and_publishers_stay_within_their_bounds) {
  cfg.max_watches = 4;
  cfg.max_topic_peers = 2;
  build_half_raw(1);
  std::vector<apo_ref> refs;
  for (int i = 0; i < 6; ++i)
    refs.push_back(add(1, "w" + std::to_string(i), "t",
                       spawn_calculator(std::make_shared<seen>())));
  for (auto& r : refs)
    inject(id_of(0), asl_watch{r.apo}, false);
  EXPECT_EQ(stats(1).watches, 4u);
  EXPECT_EQ(stats(1).watches_refused, 2u);
  // Publisher side: subscribers from five modules, two are kept.
  caf::anon_send(asl(1), atom::publish_v, std::string{"pose"},
                 caf::make_message(int32_t{1}));
  run();
  for (module_id m = 0x60; m < 0x65; ++m)
    inject(m, asl_subscribe{"pose", 1000}, false);
  EXPECT_EQ(stats(1).subscribers_refused, 3u);
  // Subscriber side: publications from five modules are all delivered, two
  // are tracked for gaps.
  auto log = std::make_shared<seen>();
  auto sub = spawn_recorder(log);
  ASSERT_TRUE(call<>(asl(1), atom::subscribe_v, std::string{"odom"}, sub));
  auto one = payload_of(caf::make_message(int32_t{7}));
  for (module_id m = 0x60; m < 0x65; ++m)
    inject(m, asl_publish{"odom", 1, one}, false);
  EXPECT_EQ(log->numbers.size(), 5u);
  EXPECT_EQ(stats(1).publishers_refused, 3u);
}

TEST_F(asl_hostile_test, a_module_serves_at_most_max_pending_requests_of_others) {
  cfg.max_pending = 2;
  build_half_raw(1);
  auto ref = add(1, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  auto never = payload_of(caf::make_message(atom::done_v));
  for (uint64_t id = 1; id <= 5; ++id)
    inject(id_of(0), asl_request{id, ref.apo, never}, false);
  EXPECT_EQ(stats(1).requests_served, 2u);
  EXPECT_EQ(stats(1).serving_refused, 3u);
  auto rs = responses();
  ASSERT_EQ(rs.size(), 3u);
  for (auto& r : rs)
    EXPECT_EQ(r.error.code, static_cast<uint8_t>(ec::queue_full));
}

TEST_F(asl_hostile_test, when_the_routing_agent_dies_callers_get_unavailable_not_a_caf_code) {
  build(2, {{{0, 1}, "ethernet"}});
  auto ref = add(1, "calc", "t", spawn_calculator(std::make_shared<seen>()));
  auto proxy = bind(0, ref);
  ASSERT_TRUE(proxy);
  auto waiting = start_request<int32_t>(*proxy, atom::done_v);
  caf::anon_send_exit(net->at(0).agent, caf::exit_reason::kill);
  run();
  ASSERT_EQ(waiting->size(), 1u);
  ASSERT_FALSE(waiting->front());
  EXPECT_TRUE(is(waiting->front().error(), app_ec::unavailable))
    << render(waiting->front().error());
  auto again = bind(0, ref);
  ASSERT_FALSE(again);
  EXPECT_TRUE(is(again.error(), app_ec::unavailable)) << render(again.error());
  auto found = call<std::vector<apo_ref>>(
    asl(0), atom::find_v, apo_query{query_by::name, "calc", 100, false});
  ASSERT_FALSE(found);
  EXPECT_TRUE(is(found.error(), app_ec::unavailable));
}

TEST(unexpected_messages, are_counted_and_logged_at_a_bounded_rate_without_content) {
  detail::unexpected_log log;
  auto t0 = std::chrono::steady_clock::now();
  int logged = 0;
  for (int i = 0; i < 1000; ++i)
    if (!log.admit("line", t0).empty())
      ++logged;
  EXPECT_EQ(logged, static_cast<int>(detail::unexpected_log::burst));
  // A second later one more line, saying how many were not logged.
  auto next = log.admit("line", t0 + 1s);
  EXPECT_EQ(next, "line (990 more not logged)");
  EXPECT_TRUE(log.admit("line", t0 + 1s).empty());
}

TEST_F(asl_test, an_apo_with_log_unexpected_drops_what_it_does_not_handle_and_counts_it) {
  build(2, {{{0, 1}, "ethernet"}});
  std::vector<std::string> lines;
  set_unexpected_sink([&](const std::string& l) { lines.push_back(l); });
  auto apo = track(sys().spawn([](caf::event_based_actor* self) -> caf::behavior {
    self->set_default_handler(log_unexpected);
    return {[](int32_t x) { return x; }};
  }));
  auto ref = add(1, "strict", "t", apo);
  auto proxy = bind(0, ref);
  ASSERT_TRUE(proxy);
  auto before = stats(1).unexpected_messages;
  auto res = ask<int32_t>(*proxy, 1s, std::string{"secret payload"});
  ASSERT_FALSE(res);
  EXPECT_TRUE(is(res.error(), ec::invalid_parameter)) << render(res.error());
  EXPECT_EQ(stats(1).unexpected_messages, before + 1);
  set_unexpected_sink(nullptr);
  ASSERT_FALSE(lines.empty());
  EXPECT_EQ(lines.back().find("secret payload"), std::string::npos) << lines.back();
  // Type names only ("@str" is CAF's portable name of std::string).
  EXPECT_NE(lines.back().find("(@str)"), std::string::npos) << lines.back();
}
