// Type descriptions and the text form of APO payloads
// (actors/type_description.hpp, actors/text_form.hpp): field types derived
// from C++ types, HERM_MESSAGE and add_message_types, payload -> text for
// described, built-in and undescribed types, text -> payload byte for byte
// equal to marshal's canonical output, refusals with the field named, every
// prefix of a payload decoded without harm, and the bound on learned
// descriptions.

#include "actors/text_form.hpp"
#include "actors/type_description.hpp"

#include <cmath>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/make_message.hpp"

#include "actors/marshal.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"

namespace text_test {

enum class mode : uint8_t { idle = 0, run = 3 };

struct point {
  int32_t x = 0;
  int32_t y = 0;
};
HERM_MESSAGE(point, x, y)

struct reading {
  std::string name;
  double value = 0;
  bool valid = false;
  mode m = mode::idle;
  std::vector<uint16_t> samples;
  std::map<std::string, int32_t> tags;
  std::set<int64_t> ids;
  point where;
  std::vector<point> path;
};
HERM_MESSAGE(reading, name, value, valid, m, samples, tags, ids, where, path)

/// Registered, never described: printed as its name and bytes.
struct opaque {
  uint32_t secret = 0;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, opaque& x) {
  return f(caf::meta::type_name("opaque"), x.secret);
}

} // namespace text_test

CAF_BEGIN_TYPE_ID_BLOCK(text_form_test, caf::id_block::herm::end)
  // `reading` before `point`: names are registered before descriptions.
  CAF_ADD_TYPE_ID(text_form_test, (text_test::reading))
  CAF_ADD_TYPE_ID(text_form_test, (text_test::point))
  CAF_ADD_TYPE_ID(text_form_test, (text_test::opaque))
CAF_END_TYPE_ID_BLOCK(text_form_test)

using namespace herm;
using namespace text_test;

namespace {

struct config : caf::actor_system_config {
  config() {
    configure(*this);
    herm::add_message_types<caf::id_block::text_form_test>(*this);
  }
};

class text_form_test : public ::testing::Test {
protected:
  config cfg;
  caf::actor_system sys{cfg};

  byte_buffer bytes_of(const caf::message& msg) {
    auto p = marshal(sys, msg);
    EXPECT_TRUE(p) << render(p.error());
    return p ? *p : byte_buffer{};
  }

  text_value text_of(const caf::message& msg) {
    auto p = bytes_of(msg);
    auto t = payload_to_text(p.data(), p.size());
    EXPECT_TRUE(t) << render(t.error());
    return t ? *t : text_value{};
  }

  static reading sample() {
    reading r;
    r.name = "sonar";
    r.value = 1.5;
    r.valid = true;
    r.m = mode::run;
    r.samples = {3, 1, 2};
    r.tags = {{"b", -2}, {"a", 1}};
    r.ids = {9, -4};
    r.where = {7, -8};
    r.path = {{1, 2}, {3, 4}};
    return r;
  }
};

TEST_F(text_form_test, field_types_come_from_the_cpp_type_and_names_from_the_macro) {
  auto d = find_description("text_test::reading");
  ASSERT_TRUE(d);
  std::vector<field_description> want{
    {"name", "@str"},         {"value", "double"},
    {"valid", "bool"},        {"m", "@u8"},
    {"samples", "list<@u16>"}, {"tags", "map<@str,@i32>"},
    {"ids", "set<@i64>"},     {"where", "text_test::point"},
    {"path", "list<text_test::point>"}};
  EXPECT_EQ(d->fields, want);
  EXPECT_FALSE(find_description("text_test::opaque"));
}

TEST_F(text_form_test, a_wrong_count_of_names_or_an_undescribed_field_is_refused) {
  auto err = describe_type<point>("p", {"x"});
  EXPECT_TRUE(is(err, ec::invalid_parameter));
  EXPECT_NE(render(err).find("2 fields, 1 names given"), std::string::npos);
  auto err2 = describe_type<reading>("r", {"a", "b", "c", "d", "e", "f", "g",
                                           "h", "i", "j"});
  EXPECT_TRUE(is(err2, ec::invalid_parameter));
}

TEST_F(text_form_test, a_described_struct_prints_by_field_name_in_order) {
  auto t = text_of(caf::make_message(sample()));
  EXPECT_EQ(t.types, std::vector<std::string>{"text_test::reading"});
  EXPECT_TRUE(t.undescribed.empty());
  EXPECT_EQ(t.value.dump(),
            R"({"name":"sonar","value":1.5,"valid":true,"m":3,)"
            R"("samples":[3,1,2],"tags":{"a":1,"b":-2},"ids":[-4,9],)"
            R"("where":{"x":7,"y":-8},"path":[{"x":1,"y":2},{"x":3,"y":4}]})");
}

TEST_F(text_form_test, built_in_types_print_as_json_values) {
  auto t = text_of(caf::make_message(std::string{"hi"}, int32_t{-5},
                                     uint64_t{18446744073709551615u}, true,
                                     3.25, std::numeric_limits<float>::infinity(),
                                     std::nan("")));
  EXPECT_EQ(t.value.dump(),
            R"(["hi",-5,18446744073709551615,true,3.25,"inf","nan"])");
  EXPECT_EQ(t.types, (std::vector<std::string>{"@str", "@i32", "@u64", "bool",
                                               "double", "float", "double"}));
  auto empty = text_of(caf::make_message());
  EXPECT_TRUE(empty.value.is_null());
}

TEST_F(text_form_test, an_undescribed_type_prints_as_its_name_and_bytes) {
  auto t = text_of(caf::make_message(opaque{0x01020304}, int32_t{1}));
  EXPECT_EQ(t.undescribed, std::vector<std::string>{"text_test::opaque"});
  EXPECT_EQ(t.value.dump(),
            R"([{"@type":"text_test::opaque","@bytes":"04030201044069333201000000"}])");
  // What follows cannot be found: it stays in the bytes (04 bytes of the
  // @i32's name and value included).
  EXPECT_EQ(t.types, std::vector<std::string>{"text_test::opaque"});
}

TEST_F(text_form_test, text_makes_the_same_bytes_as_marshal) {
  auto want = bytes_of(caf::make_message(sample()));
  // Keys and set elements out of order: sorted as std::map and std::set do.
  auto v = ordered_json::parse(
    R"({"name":"sonar","value":1.5,"valid":true,"m":3,"samples":[3,1,2],)"
    R"("tags":{"b":-2,"a":1},"ids":[9,-4],"where":{"x":7,"y":-8},)"
    R"("path":[{"x":1,"y":2},{"x":3,"y":4}]})");
  auto got = text_to_payload(v, {"text_test::reading"});
  ASSERT_TRUE(got) << render(got.error());
  EXPECT_EQ(*got, want);
  auto several = text_to_payload(ordered_json::parse(R"(["hi", -5, "nan"])"),
                                 {"@str", "@i16", "double"});
  ASSERT_TRUE(several);
  auto m = unmarshal(sys, several->data(), several->size());
  ASSERT_TRUE(m) << render(m.error());
  ASSERT_TRUE((m->match_elements<std::string, int16_t, double>()));
  EXPECT_EQ(m->get_as<int16_t>(1), -5);
  EXPECT_TRUE(std::isnan(m->get_as<double>(2)));
}

TEST_F(text_form_test, text_that_does_not_fit_is_refused_naming_the_field) {
  auto why = [](const char* json, std::vector<std::string> types) {
    auto r = text_to_payload(ordered_json::parse(json), types);
    EXPECT_FALSE(r);
    return r ? std::string{} : render(r.error());
  };
  auto has = [](const std::string& s, const char* part) {
    return s.find(part) != std::string::npos;
  };
  EXPECT_TRUE(has(why(R"({"x":1})", {"text_test::point"}),
                  "field 'y' of 'text_test::point' is missing"));
  EXPECT_TRUE(has(why(R"({"x":1,"y":2,"z":3})", {"text_test::point"}),
                  "has no field 'z'"));
  EXPECT_TRUE(has(why(R"({"x":2147483648,"y":0})", {"text_test::point"}),
                  "field 'x': 2147483648 does not fit a signed 32-bit"));
  EXPECT_TRUE(has(why("300", {"@u8"}), "300 does not fit an unsigned 8-bit"));
  EXPECT_TRUE(has(why("-1", {"@u32"}), "does not fit an unsigned 32-bit"));
  EXPECT_TRUE(has(why("\"x\"", {"@i32"}), "does not fit a signed 32-bit"));
  EXPECT_TRUE(has(why("[1,1]", {"@strset"}), "does not fit the key type"));
  EXPECT_TRUE(has(why(R"(["a","a"])", {"@strset"}), "appears twice"));
  EXPECT_TRUE(has(why("1", {"text_test::opaque"}), "has no description here"));
  EXPECT_TRUE(has(why("[1]", {"list<@i32>"}), "is a field type"));
  EXPECT_TRUE(has(why("1", {"@nope"}), "unknown type '@nope'"));
  EXPECT_TRUE(has(why("[1]", {"@i32", "@i32"}), "2 types need an array"));
}

TEST_F(text_form_test, every_prefix_and_trailing_byte_is_handled) {
  auto p = bytes_of(caf::make_message(sample(), std::string{"tail"}));
  for (size_t n = 0; n < p.size(); ++n) {
    auto t = payload_to_text(p.data(), n);
    EXPECT_FALSE(t) << "prefix of " << n << " bytes decoded";
  }
  auto whole = payload_to_text(p.data(), p.size());
  ASSERT_TRUE(whole);
  p.push_back(0);
  auto extra = payload_to_text(p.data(), p.size());
  ASSERT_FALSE(extra);
  EXPECT_NE(render(extra.error()).find("1 trailing bytes"), std::string::npos);
  // Flipping every byte never crashes (results vary).
  p.pop_back();
  for (size_t i = 0; i < p.size(); ++i) {
    auto q = p;
    q[i] ^= 0xFF;
    (void) payload_to_text(q.data(), q.size());
  }
}

TEST_F(text_form_test, learned_descriptions_are_bounded_and_never_replace_local_ones) {
  EXPECT_TRUE(learn_description({"text_test::point", {{"a", "@u8"}}}));
  EXPECT_EQ(find_description("text_test::point")->fields[0].name, "x");
  EXPECT_FALSE(learn_description({"bad", {{"f", "list<"}}}));
  auto before = learned_descriptions_refused();
  size_t kept = 0;
  for (size_t i = 0; i < max_learned_descriptions + 10; ++i)
    kept += learn_description({"learned" + std::to_string(i), {{"v", "@u8"}}});
  EXPECT_LE(kept, max_learned_descriptions);
  EXPECT_GE(learned_descriptions_refused() - before, 10u);
  // A known one is refreshed even when full.
  EXPECT_TRUE(learn_description({"learned0", {{"w", "@u16"}}}));
  EXPECT_EQ(find_description("learned0")->fields[0].type, "@u16");
}

TEST_F(text_form_test, the_type_grammar_is_checked) {
  EXPECT_EQ(check_field_type("map<@str,list<set<@i8>>>"), "");
  EXPECT_EQ(check_field_type("array<double,3>"), "");
  EXPECT_EQ(check_field_type("tuple<@u8,@str,foo::bar>"), "");
  EXPECT_NE(check_field_type("map<@str>"), "");
  EXPECT_NE(check_field_type("array<double,0>"), "");
  EXPECT_NE(check_field_type("list<@u8"), "");
  EXPECT_NE(check_field_type("bad name"), "");
  std::string deep;
  for (int i = 0; i < 20; ++i)
    deep += "list<";
  deep += "@u8";
  for (int i = 0; i < 20; ++i)
    deep += ">";
  EXPECT_NE(check_field_type(deep), "");
}

} // namespace
