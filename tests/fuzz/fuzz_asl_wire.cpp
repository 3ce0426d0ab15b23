// Fuzz target: decode_asl and peek_asl_kind (actors/asl_wire.hpp,
// docs/protocol.md "APO messages"): discovery queries and answers, requests,
// responses, watch/unwatch/down, withdraw, the topic messages, reliable
// requests and acks.
//
// Properties checked for every input:
// - decode_asl is total: a message or ec::invalid_parameter;
// - a decoded message agrees with peek_asl_kind;
// - the format is canonical: the message re-encodes to exactly the input,
//   and decoding that again gives an equal message;
// - decoded values respect the documented bounds (answer entries, string
//   lengths, query_by, non-zero response, reliable-request and ack ids,
//   empty pattern for "any").

#include <cstddef>
#include <cstdint>
#include <variant>

#include "actors/asl_wire.hpp"
#include "actors/runtime/error.hpp"
#include "tests/fuzz/fuzz_support.hpp"

using namespace herm;

namespace {

byte_buffer out;

void check_bounds(const asl_message& m) {
  auto str = [](const std::string& s) {
    HERM_FUZZ_CHECK(s.size() <= max_asl_string);
  };
  if (auto* q = std::get_if<asl_query>(&m)) {
    HERM_FUZZ_CHECK(static_cast<uint8_t>(q->by) <= 2);
    HERM_FUZZ_CHECK(q->by != query_by::any || q->pattern.empty());
    str(q->pattern);
  } else if (auto* a = std::get_if<asl_answer>(&m)) {
    HERM_FUZZ_CHECK(a->entries.size() <= max_answer_entries);
    for (auto& e : a->entries) {
      str(e.name);
      str(e.type);
    }
  } else if (auto* r = std::get_if<asl_response>(&m)) {
    HERM_FUZZ_CHECK(r->request_id != 0);
    if (!r->ok)
      str(r->error.context);
  } else if (auto* d = std::get_if<asl_down>(&m)) {
    str(d->reason.context);
  } else if (auto* w = std::get_if<asl_withdraw>(&m)) {
    str(w->name);
  } else if (auto* s = std::get_if<asl_subscribe>(&m)) {
    str(s->topic);
  } else if (auto* u = std::get_if<asl_unsubscribe>(&m)) {
    str(u->topic);
  } else if (auto* p = std::get_if<asl_publish>(&m)) {
    str(p->topic);
  } else if (auto* v = std::get_if<asl_advertise>(&m)) {
    str(v->topic);
  } else if (auto* rr = std::get_if<asl_reliable_request>(&m)) {
    HERM_FUZZ_CHECK(rr->request_id != 0);
  } else if (auto* k = std::get_if<asl_ack>(&m)) {
    HERM_FUZZ_CHECK(k->request_id != 0);
  }
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto kind = peek_asl_kind(data, size);
  HERM_FUZZ_CHECK(kind || is(kind.error(), ec::invalid_parameter));
  auto msg = decode_asl(data, size);
  if (!msg) {
    HERM_FUZZ_CHECK(is(msg.error(), ec::invalid_parameter));
    return 0;
  }
  HERM_FUZZ_CHECK(kind);
  HERM_FUZZ_CHECK(static_cast<size_t>(*kind) == msg->index() + 1);
  check_bounds(*msg);
  out.clear();
  encode(*msg, out);
  HERM_FUZZ_CHECK(out.size() == size);
  HERM_FUZZ_CHECK(std::equal(out.begin(), out.end(), data));
  auto again = decode_asl(out.data(), out.size());
  HERM_FUZZ_CHECK(again);
  HERM_FUZZ_CHECK(*again == *msg);
  return 0;
}
