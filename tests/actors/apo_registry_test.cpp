// The APOs registered on a module (actors/apo_registry.hpp), the outbox
// read directly: registration and its refusals, access, withdrawal told to
// watchers and everyone, watches and their bound, the table for people.

#include <chrono>
#include <string>
#include <variant>
#include <vector>

#include "actors/apo_registry.hpp"
#include "actors/asl_errors.hpp"
#include "tests/support/actor_fixture.hpp"

using namespace herm;
using namespace std::chrono_literals;

namespace {

constexpr module_id self = 0x10;
constexpr module_id a = 0x21;
constexpr module_id b = 0x22;

class apo_registry_test : public herm::test::actor_fixture {
public:
  caf::actor apo() {
    return track(sys().spawn([]() -> caf::behavior { return {[](int) {}}; }));
  }

  app_support_stats stats;
  asl_outbox out;
};

TEST_F(apo_registry_test, registration_refuses_bad_labels_bad_handles_and_doubles) {
  apo_registry reg{1, 8, stats};
  auto known = apo();
  ASSERT_TRUE(reg.add("first", "t", known, apo_access::open));
  struct row {
    const char* what;
    std::string name;
    std::string type;
    caf::actor hdl;
    ec code;
  };
  std::vector<row> rows{
    {"an empty name", "", "t", apo(), ec::invalid_parameter},
    {"a name of 256 bytes", std::string(256, 'n'), "t", apo(),
     ec::invalid_parameter},
    {"an empty type", "n", "", apo(), ec::invalid_parameter},
    {"an invalid handle", "n", "t", caf::actor{}, ec::invalid_parameter},
    {"an actor registered already", "n", "t", known, ec::already_exists},
  };
  for (auto& r : rows) {
    SCOPED_TRACE(r.what);
    auto added = reg.add(r.name, r.type, r.hdl, apo_access::open);
    ASSERT_FALSE(added);
    EXPECT_TRUE(is(added.error(), r.code));
  }
  EXPECT_TRUE(reg.add(std::string(255, 'n'), "t", apo(), apo_access::open));
  EXPECT_EQ(stats.registered, 2u);
  EXPECT_EQ(reg.table().locals().size(), 2u);
}

TEST_F(apo_registry_test, apos_are_found_by_number_and_by_handle) {
  apo_registry reg{1, 8, stats};
  auto open = apo();
  auto ctl = apo();
  auto n1 = *reg.add("echo", "demo.echo", open, apo_access::open);
  auto n2 = *reg.add("ctl", "herm.control", ctl, apo_access::signed_only);
  EXPECT_NE(n1, n2);
  ASSERT_NE(reg.find(n1), nullptr);
  EXPECT_EQ(*reg.find(n1), open);
  EXPECT_EQ(reg.number_of(ctl.address()), n2);
  EXPECT_EQ(reg.number_of(apo().address()), 0u);
  EXPECT_FALSE(reg.signed_only(n1));
  EXPECT_TRUE(reg.signed_only(n2));
  auto rows = reg.list(self, {});
  ASSERT_EQ(rows.size(), 2u);
  for (auto& row : rows) {
    EXPECT_TRUE(row.local);
    EXPECT_EQ(row.ref.module, self);
  }
}

TEST_F(apo_registry_test, a_withdrawal_is_told_to_watchers_and_broadcast) {
  apo_registry reg{1, 8, stats};
  auto hdl = apo();
  auto n = *reg.add("echo", "demo.echo", hdl, apo_access::signed_only);
  reg.on_watch(a, asl_watch{n}, self, out);
  reg.on_watch(b, asl_watch{n}, self, out);
  EXPECT_TRUE(out.items.empty());
  EXPECT_EQ(reg.table().watches(), 2u);
  auto name = reg.remove(n, make_error(app_ec::apo_gone, "bye"), out);
  ASSERT_TRUE(name);
  EXPECT_EQ(*name, "echo");
  ASSERT_EQ(out.items.size(), 3u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(out.items[i].dst, i == 0 ? a : b);
    auto& down = std::get<asl_down>(out.items[i].msg);
    EXPECT_EQ(down.apo, n);
    EXPECT_EQ(context_of(from_wire(down.reason)), "bye");
  }
  EXPECT_EQ(out.items[2].dst, broadcast_module);
  EXPECT_TRUE((out.items[2].msg == asl_message{asl_withdraw{n, "echo"}}));
  EXPECT_EQ(reg.find(n), nullptr);
  EXPECT_EQ(reg.number_of(hdl.address()), 0u);
  EXPECT_FALSE(reg.signed_only(n));
  EXPECT_EQ(reg.table().watches(), 0u);
  EXPECT_EQ(stats.withdrawn, 1u);
  out.items.clear();
  EXPECT_FALSE(reg.remove(n, caf::none, out));
  EXPECT_TRUE(out.items.empty());
}

TEST_F(apo_registry_test, watches_stay_within_the_bound_and_unknown_apos_are_told_gone) {
  apo_registry reg{1, 2, stats};
  auto n = *reg.add("echo", "demo.echo", apo(), apo_access::open);
  struct row {
    module_id src;
    uint32_t apo;
    size_t watches;
    uint64_t refused;
    bool told_gone;
  };
  std::vector<row> rows{
    {a, n, 1, 0, false},     {a, n, 1, 0, false}, // a renewal
    {b, n, 2, 0, false},     {0x23, n, 2, 1, false},
    {0x23, n + 1, 2, 1, true},
  };
  for (auto& r : rows) {
    reg.on_watch(r.src, asl_watch{r.apo}, self, out);
    EXPECT_EQ(reg.table().watches(), r.watches);
    EXPECT_EQ(stats.watches_refused, r.refused);
    EXPECT_EQ(out.items.size(), r.told_gone ? 1u : 0u);
    if (r.told_gone) {
      auto& down = std::get<asl_down>(out.items[0].msg);
      EXPECT_TRUE(is(from_wire(down.reason), app_ec::apo_gone));
    }
    out.items.clear();
  }
  reg.on_unwatch(a, asl_unwatch{n});
  EXPECT_EQ(reg.table().watches(), 1u);
}

} // namespace
