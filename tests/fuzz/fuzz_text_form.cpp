// Fuzz target: the text form of APO payloads (actors/text_form.hpp), which
// the control service uses to print every value a tool asks for (hermctl
// topic echo, call, record) from whatever bytes the network delivered.
//
// Properties checked for every input:
// - payload_to_text is total: a text value or ec::invalid_parameter, never
//   an exception or a crash, whatever the bytes (described types of HERM's
//   own block are known: the decoder walks them by their descriptions);
// - what it prints can be read back: the value's JSON dump parses;
// - text_to_payload of a decoded value whose types are all described
//   gives a canonical payload: its text makes the very same payload again
//   (the round trip through hermctl's pub and echo is lossless; the input
//   may have been non-canonical, e.g. a set out of order).

#include <cstddef>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "actors/runtime/error.hpp"
#include "actors/text_form.hpp"
#include "actors/type_description.hpp"
#include "tests/fuzz/fuzz_support.hpp"

namespace {

struct nested {
  int16_t a = 0;
  std::string b;
};

struct outer {
  std::vector<nested> items;
  std::map<std::string, double> values;
  std::set<uint8_t> flags;
};

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, nested& x) {
  return f(x.a, x.b);
}

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, outer& x) {
  return f(x.items, x.values, x.flags);
}

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  HERM_FUZZ_CHECK(!herm::describe_type<nested>("fz::nested", {"a", "b"}));
  HERM_FUZZ_CHECK(!herm::describe_type<outer>("fz::outer",
                                              {"items", "values", "flags"}));
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto text = herm::payload_to_text(data, size);
  if (!text) {
    HERM_FUZZ_CHECK(herm::is(text.error(), herm::ec::invalid_parameter));
    return 0;
  }
  auto dumped = text->value.dump(-1, ' ', false,
                                 herm::ordered_json::error_handler_t::replace);
  HERM_FUZZ_CHECK(!herm::ordered_json::parse(dumped, nullptr, false).is_discarded());
  if (!text->undescribed.empty() || text->types.empty())
    return 0;
  auto again = herm::text_to_payload(text->value, text->types);
  if (!again)
    return 0; // e.g. a float that prints as a double of another width
  // The payload it makes is canonical (sets and maps sorted), so its text
  // makes the same payload again; the input itself may not have been.
  auto text2 = herm::payload_to_text(again->data(), again->size());
  HERM_FUZZ_CHECK(text2);
  auto again2 = herm::text_to_payload(text2->value, text2->types);
  HERM_FUZZ_CHECK(again2 && *again2 == *again);
  return 0;
}
