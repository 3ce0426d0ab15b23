// The ASL's errors (actors/asl_errors.hpp): how they cross the wire and
// come back, what CAF's own codes become, label bounds, deadline errors.

#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <vector>

#include "caf/sec.hpp"

#include "actors/asl_errors.hpp"
#include "actors/runtime/error.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

TEST(asl_errors, errors_cross_the_wire_and_come_back_the_same) {
  struct row {
    const char* what;
    caf::error err;
    std::string context_back;
  };
  std::vector<row> rows{
    {"no error", caf::error{}, ""},
    {"an ASL code with a text", make_error(app_ec::apo_gone, "gone"), "gone"},
    {"a NAL code", make_error(routing_ec::no_route, "no route"), "no route"},
    {"a generic code without context", make_error(ec::timeout), ""},
    {"a text cut at 255 bytes", make_error(ec::timeout, std::string(300, 'x')),
     std::string(255, 'x')},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    auto w = to_wire(r.err);
    auto back = from_wire(w);
    // (An empty caf::error has neither code nor category to compare.)
    ASSERT_EQ(!back, !r.err);
    if (!r.err) {
      EXPECT_EQ(w.code, 0u);
      continue;
    }
    EXPECT_EQ(w.code, r.err.code());
    EXPECT_EQ(back.code(), r.err.code());
    EXPECT_EQ(back.category(), r.err.category());
    EXPECT_EQ(context_of(back), r.context_back);
  }
}

TEST(asl_errors, cafs_own_codes_never_reach_a_requester) {
  EXPECT_TRUE(is(asl_error::from_apo(caf::sec::request_receiver_down),
                 app_ec::apo_gone));
  EXPECT_TRUE(is(asl_error::from_apo(caf::sec::unexpected_message),
                 ec::invalid_parameter));
  auto own = make_error(ec::queue_full, "busy");
  EXPECT_EQ(asl_error::from_apo(own), own);
}

TEST(asl_errors, labels_are_1_to_255_bytes) {
  struct row {
    size_t size;
    bool ok;
  };
  std::vector<row> rows{{0, false}, {1, true}, {255, true}, {256, false}};
  for (auto& r : rows) {
    auto err = asl_error::check_label("a topic", std::string(r.size, 't'));
    EXPECT_EQ(!err, r.ok) << r.size;
    if (err) {
      EXPECT_TRUE(is(err, ec::invalid_parameter));
      EXPECT_EQ(context_of(err), "a topic must be 1 to 255 bytes, got "
                                   + std::to_string(r.size));
    }
  }
}

TEST(asl_errors, a_passed_deadline_says_why) {
  struct row {
    const char* what;
    bool reliable;
    module_id target;
    bool reachable;
    std::string context;
  };
  std::vector<row> rows{
    {"a plain request", false, no_module, false,
     "no response from module 0x21 within 100 ms"},
    {"a reliable one without a target", true, no_module, false,
     "no APO to send it to within 100 ms"},
    {"a reliable one to an unreachable module", true, 0x22, false,
     "module 0x22 stayed unreachable within 100 ms"},
    {"a reliable one, reachable", true, 0x22, true,
     "no response from module 0x21 within 100 ms"},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    auto err = asl_error::deadline(r.reliable, r.target, r.reachable, 0x21,
                                   100ms);
    EXPECT_EQ(context_of(err), r.context);
  }
  EXPECT_TRUE(is(asl_error::deadline(false, 0, false, 1, 1ms), ec::timeout));
  EXPECT_TRUE(is(asl_error::deadline(true, no_module, false, 1, 1ms),
                 app_ec::apo_gone));
  EXPECT_TRUE(is(asl_error::deadline(true, 2, false, 1, 1ms),
                 routing_ec::no_route));
}

} // namespace

// The one mapping of CAF's own codes to HERM's (actors/runtime/error.hpp):
// what the control service and the embedding helpers hand users.
TEST(typed_error, cafs_codes_become_hermes_and_hermes_pass_through) {
  struct row {
    caf::error in;
    caf::error want;
    const char* context_has;
  };
  std::vector<row> rows{
    {caf::make_error(caf::sec::request_timeout), make_error(ec::timeout),
     "no response in time"},
    {caf::make_error(caf::sec::request_receiver_down), make_error(app_ec::apo_gone),
     "exited before it answered"},
    {caf::make_error(caf::sec::unexpected_message), make_error(ec::invalid_parameter),
     "does not handle a message of this type"},
    {caf::make_error(caf::sec::no_such_group_module), make_error(app_ec::unavailable),
     "no_such_group_module"},
    {make_error(routing_ec::no_route, "far"), make_error(routing_ec::no_route), "far"},
  };
  // No error stays none (CAF 0.17's code() of none is not to be asked).
  EXPECT_FALSE(typed_error(caf::error{}));
  for (auto& r : rows) {
    auto out = typed_error(r.in);
    EXPECT_EQ(out.code(), r.want.code()) << render(r.in);
    EXPECT_EQ(out.category(), r.want.category()) << render(r.in);
    EXPECT_NE(render(out).find(r.context_has), std::string::npos) << render(out);
  }
}

