// Fuzz target: unmarshal (actors/marshal.hpp, docs/protocol.md "APO
// payloads"), the decoder of every APO payload a module receives.
//
// Properties checked for every input:
// - unmarshal is total: a message, ec::invalid_parameter or
//   app_ec::unknown_type (a type name this module does not know);
// - the format is canonical: a decoded message re-marshals to exactly the
//   input, and unmarshalling that again gives the same message;
// - limits only ever refuse: what decodes under tight unmarshal_limits
//   decodes under the defaults to the same message, and a decoded message
//   has no more elements than max_elements;
// - a decoded message can be printed (caf::to_string): CAF prints every
//   message an actor does not handle (its default handler, print_and_drop),
//   so a payload that cannot be printed crashes whichever APO it reaches
//   (regression seed corpus/marshal/regression-duration-unit: a
//   caf::duration with an out-of-range time unit; unmarshal now refuses it).
//
// One actor system for the whole run (configured like a module's, with
// herm::configure), created in LLVMFuzzerInitialize and never destroyed: the
// codec needs only its type registry.

#include <cstddef>
#include <cstdint>
#include <string>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/message.hpp"

#include "actors/marshal.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "tests/fuzz/fuzz_support.hpp"

namespace {

caf::actor_system* sys = nullptr;

bool refused_properly(const caf::error& err) {
  return herm::is(err, herm::ec::invalid_parameter)
         || herm::is(err, herm::app_ec::unknown_type);
}

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  auto* cfg = new caf::actor_system_config;
  herm::configure(*cfg);
  cfg->set("scheduler.max-threads", 1);
  sys = new caf::actor_system(*cfg);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  herm::unmarshal_limits defaults;
  auto msg = herm::unmarshal(*sys, data, size, defaults);
  herm::unmarshal_limits tight;
  tight.max_elements = 3;
  tight.max_string = 16;
  tight.max_sequence = 8;
  tight.max_depth = 2;
  tight.max_total = 256;
  auto small = herm::unmarshal(*sys, data, size, tight);
  if (!small)
    HERM_FUZZ_CHECK(refused_properly(small.error()));
  if (!msg) {
    HERM_FUZZ_CHECK(refused_properly(msg.error()));
    HERM_FUZZ_CHECK(!small);
    return 0;
  }
  HERM_FUZZ_CHECK(msg->size() <= defaults.max_elements);
  auto text = caf::to_string(*msg);
  if (small) {
    HERM_FUZZ_CHECK(small->size() <= tight.max_elements);
    HERM_FUZZ_CHECK(caf::to_string(*small) == text);
  }
  auto bytes = herm::marshal(*sys, *msg);
  HERM_FUZZ_CHECK(bytes);
  HERM_FUZZ_CHECK(bytes->size() == size);
  HERM_FUZZ_CHECK(std::equal(bytes->begin(), bytes->end(), data));
  auto again = herm::unmarshal(*sys, bytes->data(), bytes->size(), defaults);
  HERM_FUZZ_CHECK(again);
  HERM_FUZZ_CHECK(caf::to_string(*again) == text);
  return 0;
}
