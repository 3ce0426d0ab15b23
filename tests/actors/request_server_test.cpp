// The serving side of requests (actors/request_server.hpp), time passed in
// and the outbox read directly: who may reach a signed_only APO, unknown
// APOs, duplicates of reliable requests answered from the cache, the bound
// on requests served, and the responses that go back.

#include <chrono>
#include <optional>
#include <variant>
#include <vector>

#include "actors/asl_errors.hpp"
#include "actors/request_server.hpp"
#include "tests/support/actor_fixture.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

using time_point = request_server::time_point;

const time_point t0{};

constexpr module_id self = 0x10;
constexpr module_id a = 0x21;

class request_server_test : public herm::test::actor_fixture {
public:
  request_server_test() {
    echo = *registry.add("echo", "demo.echo", apo(), apo_access::open);
    ctl = *registry.add("ctl", "herm.control", apo(), apo_access::signed_only);
  }

  caf::actor apo() {
    return track(sys().spawn([]() -> caf::behavior { return {[](int) {}}; }));
  }

  std::unique_ptr<request_server> server(size_t max_serving = 2,
                                         bool allow_unsigned = false) {
    return std::make_unique<request_server>(
      request_server::config{max_serving, 10s, allow_unsigned}, registry,
      reliable, stats);
  }

  /// The one message in the outbox (emptied).
  asl_message sent() {
    EXPECT_EQ(out.items.size(), 1u);
    auto result = out.items.empty() ? asl_message{} : out.items.front().msg;
    last_signed = !out.items.empty() && out.items.front().sign;
    out.items.clear();
    return result;
  }

  /// The error of the one response in the outbox.
  caf::error sent_error() {
    auto msg = sent();
    auto r = std::get_if<asl_response>(&msg);
    if (r == nullptr || r->ok)
      return caf::none;
    return from_wire(r->error);
  }

  app_support_stats stats;
  apo_registry registry{1, 8, stats};
  reliable_requests reliable{reliable_requests::config{}, stats};
  asl_outbox out;
  uint32_t echo = 0;
  uint32_t ctl = 0;
  bool last_signed = false;
};

TEST_F(request_server_test, signed_only_apos_take_remote_requests_only_when_allowed) {
  struct row {
    const char* what;
    bool to_ctl;
    bool authenticated;
    bool allow_unsigned;
    bool admitted;
  };
  std::vector<row> rows{
    {"an open APO, unsigned", false, false, false, true},
    {"a signed_only APO, unsigned", true, false, false, false},
    {"a signed_only APO, signed and verified", true, true, false, true},
    {"a signed_only APO on a keyless module that allows it", true, false,
     true, true},
  };
  uint64_t refused = 0;
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    auto srv = server(2, r.allow_unsigned);
    auto apo = r.to_ctl ? ctl : echo;
    EXPECT_EQ(srv->admit(a, 5, apo, false, r.authenticated, self, out),
              r.admitted);
    if (r.admitted) {
      EXPECT_TRUE(out.items.empty());
      continue;
    }
    EXPECT_TRUE(is(sent_error(), app_ec::unauthorized));
    EXPECT_TRUE(last_signed);
    EXPECT_EQ(stats.rx_unauthorized, ++refused);
  }
}

TEST_F(request_server_test, a_request_for_an_unknown_apo_is_answered_apo_gone) {
  auto srv = server();
  EXPECT_FALSE(srv->admit(a, 5, echo + ctl + 1, false, false, self, out));
  EXPECT_TRUE(is(sent_error(), app_ec::apo_gone));
  EXPECT_FALSE(last_signed);
  // A one-way message has nobody to tell.
  EXPECT_FALSE(srv->admit(a, 0, echo + ctl + 1, false, false, self, out));
  EXPECT_TRUE(out.items.empty());
  EXPECT_EQ(stats.rx_unknown_apo, 2u);
}

TEST_F(request_server_test, an_undecodable_payload_is_answered_with_its_error) {
  auto srv = server();
  srv->malformed(a, 5, ctl, make_error(app_ec::unknown_type, "type x"), self,
                 out);
  auto err = sent_error();
  EXPECT_TRUE(is(err, app_ec::unknown_type));
  EXPECT_EQ(context_of(err), "module 0x10: type x");
  EXPECT_TRUE(last_signed); // ctl's answers travel signed
}

TEST_F(request_server_test, a_reliable_request_runs_once_and_its_copies_get_the_cached_answer) {
  auto srv = server();
  ASSERT_TRUE(srv->admit(a, 5, echo, true, false, self, out));
  auto local = srv->accept(a, 5, echo, false, true, t0, self, out);
  ASSERT_TRUE(local && *local != 0);
  EXPECT_TRUE(out.items.empty());
  // A copy while the APO works on it: acked, not admitted.
  EXPECT_FALSE(srv->admit(a, 5, echo, true, false, self, out));
  EXPECT_TRUE(std::holds_alternative<asl_ack>(sent()));
  srv->reply(*local, byte_buffer{7, 7}, out);
  auto msg = sent();
  auto r = std::get_if<asl_response>(&msg);
  ASSERT_NE(r, nullptr);
  EXPECT_EQ(r->request_id, 5u);
  EXPECT_TRUE(r->ok);
  EXPECT_EQ(r->payload, (byte_buffer{7, 7}));
  // A copy after the answer: the same answer again.
  EXPECT_FALSE(srv->admit(a, 5, echo, true, false, self, out));
  EXPECT_TRUE(sent() == asl_message{*r});
  EXPECT_EQ(stats.duplicates_suppressed, 2u);
  EXPECT_EQ(stats.requests_served, 1u);
  EXPECT_EQ(stats.acks_sent, 1u);
  // The APO answering twice: the second goes nowhere.
  srv->reply(*local, byte_buffer{8}, out);
  EXPECT_TRUE(out.items.empty());
}

TEST_F(request_server_test, one_way_messages_are_delivered_and_a_reliable_one_is_acked) {
  auto srv = server();
  EXPECT_EQ(srv->accept(a, 0, echo, true, false, t0, self, out), 0u);
  EXPECT_TRUE(out.items.empty());
  EXPECT_EQ(srv->accept(a, 9, echo, true, true, t0, self, out), 0u);
  EXPECT_TRUE(std::holds_alternative<asl_ack>(sent()));
  EXPECT_FALSE(srv->admit(a, 9, echo, true, false, self, out));
  EXPECT_TRUE(std::holds_alternative<asl_ack>(sent()));
  EXPECT_EQ(stats.oneway_delivered, 2u);
  EXPECT_EQ(stats.acks_sent, 2u);
  EXPECT_EQ(srv->serving(), 0u);
}

TEST_F(request_server_test, requests_served_at_once_stay_within_the_bound) {
  auto srv = server(2);
  EXPECT_TRUE(srv->accept(a, 1, ctl, false, false, t0, self, out));
  EXPECT_TRUE(srv->accept(a, 2, echo, false, true, t0, self, out));
  EXPECT_FALSE(srv->accept(a, 3, ctl, false, true, t0, self, out));
  EXPECT_TRUE(is(sent_error(), ec::queue_full));
  EXPECT_TRUE(last_signed);
  EXPECT_EQ(stats.serving_refused, 1u);
  EXPECT_EQ(srv->serving(), 2u);
  // The refused reliable request was not remembered: its copy is new.
  EXPECT_TRUE(srv->admit(a, 3, ctl, true, true, self, out));
  // Served requests expire at their deadline; then there is room again.
  srv->expire(t0 + 9999ms);
  EXPECT_EQ(srv->serving(), 2u);
  srv->expire(t0 + 10s);
  EXPECT_EQ(srv->serving(), 0u);
  EXPECT_TRUE(srv->accept(a, 3, ctl, false, true, t0 + 10s, self, out));
}

TEST_F(request_server_test, an_apo_error_goes_back_as_an_error_response) {
  auto srv = server();
  auto local = srv->accept(a, 4, ctl, false, false, t0, self, out);
  ASSERT_TRUE(local);
  srv->reply(*local, asl_error::from_apo(caf::sec::request_receiver_down),
             out);
  EXPECT_TRUE(is(sent_error(), app_ec::apo_gone));
  EXPECT_TRUE(last_signed);
}

} // namespace
