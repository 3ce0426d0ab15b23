#include "actors/asl_wire.hpp"

#include <algorithm>
#include <cassert>
#include <iterator>
#include <string>
#include <type_traits>
#include <utility>

#include "actors/runtime/error.hpp"
#include "channels/le_codec.hpp"

namespace herm {

namespace {

// -- layout ----------------------------------------------------------------------

// Kind k is alternative k - 1 of asl_message: encode writes the kind from the
// variant's index.
template <asl_kind K, class T>
constexpr bool kind_is
  = std::is_same_v<std::variant_alternative_t<static_cast<size_t>(K) - 1,
                                              asl_message>,
                   T>;
static_assert(kind_is<asl_kind::query, asl_query>);
static_assert(kind_is<asl_kind::answer, asl_answer>);
static_assert(kind_is<asl_kind::request, asl_request>);
static_assert(kind_is<asl_kind::response, asl_response>);
static_assert(kind_is<asl_kind::watch, asl_watch>);
static_assert(kind_is<asl_kind::unwatch, asl_unwatch>);
static_assert(kind_is<asl_kind::down, asl_down>);
static_assert(kind_is<asl_kind::withdraw, asl_withdraw>);
static_assert(kind_is<asl_kind::subscribe, asl_subscribe>);
static_assert(kind_is<asl_kind::unsubscribe, asl_unsubscribe>);
static_assert(kind_is<asl_kind::publish, asl_publish>);
static_assert(kind_is<asl_kind::advertise, asl_advertise>);
static_assert(kind_is<asl_kind::reliable_request, asl_reliable_request>);
static_assert(kind_is<asl_kind::ack, asl_ack>);
static_assert(std::variant_size_v<asl_message> == 14);

/// Version and kind.
constexpr size_t head_size = 2;

/// Smallest answer entry: apo and two empty strings.
constexpr size_t min_entry_size = 4 + 1 + 1;

constexpr uint8_t max_kind = static_cast<uint8_t>(asl_kind::ack);
constexpr uint8_t max_query_by = static_cast<uint8_t>(query_by::any);

/// Kind names for errors, by kind value (0 is no kind).
constexpr const char* kind_names[] = {
  "?", "query", "answer", "request", "response", "watch", "unwatch", "down",
  "withdraw", "subscribe", "unsubscribe", "publish", "advertise",
  "reliable request", "ack",
};
static_assert(std::size(kind_names) == size_t{max_kind} + 1);

const char* name_of(asl_kind k) {
  auto i = static_cast<size_t>(k);
  return i < std::size(kind_names) ? kind_names[i] : "?";
}

std::string num(size_t x) {
  return std::to_string(x);
}

std::string n_bytes(size_t n) {
  return num(n) + (n == 1 ? " byte" : " bytes");
}

caf::error bad(const char* who, const std::string& what) {
  return make_error(ec::invalid_parameter, std::string{who} + ": " + what);
}

/// How many bytes of `s` go on the wire: all of it up to max_asl_string,
/// otherwise the longest prefix that does not split a UTF-8 sequence (the
/// bytes from the cut on are dropped whole). Input that is not UTF-8 is cut
/// at exactly max_asl_string.
size_t wire_length(const std::string& s) {
  if (s.size() <= max_asl_string)
    return s.size();
  auto continuation = [&](size_t i) {
    return (static_cast<uint8_t>(s[i]) & 0xC0) == 0x80;
  };
  auto n = max_asl_string;
  // s[n] is the first byte dropped; a UTF-8 sequence has at most 3
  // continuation bytes after its lead byte.
  for (int i = 0; i < 3 && continuation(n); ++i)
    --n;
  return continuation(n) ? max_asl_string : n;
}

// -- writing ---------------------------------------------------------------------

/// Appends little-endian integers (le_writer), strings and payloads.
struct writer : le_writer {
  using le_writer::le_writer;

  /// A name, type or topic: longer than max_asl_string is the caller's error
  /// (sent truncated when assertions are off).
  void str(const std::string& s) {
    assert(s.size() <= max_asl_string);
    text(s);
  }

  /// Free text (an error context): truncated to max_asl_string bytes.
  void text(const std::string& s) {
    auto n = wire_length(s);
    u8(static_cast<uint8_t>(n));
    bytes(s.data(), n);
  }

  /// The last field: the rest of the message, no length.
  void rest(const byte_buffer& b) {
    bytes(b.data(), b.size());
  }

  void error(const wire_error& e) {
    u64(e.category);
    u8(e.code);
    text(e.context);
  }

  // -- one field by its type ----------------------------------------------------

  template <class T>
  void field(T x) {
    static_assert(std::is_unsigned_v<T>, "an unsigned integer");
    le(x);
  }

  void field(bool x) {
    u8(x ? 1 : 0);
  }

  void field(const std::string& s) {
    str(s);
  }

  void field(const byte_buffer& b) {
    rest(b);
  }

  void field(const wire_error& e) {
    error(e);
  }

  template <class... Ts>
  void fields(const Ts&... xs) {
    (field(xs), ...);
  }
};

void put(writer& w, const asl_query& x) {
  w.u32(x.query_id);
  w.u8(static_cast<uint8_t>(x.by));
  if (x.by == query_by::any)
    w.u8(0); // pattern ignored, sent empty
  else
    w.str(x.pattern);
}

void put(writer& w, const asl_answer& x) {
  w.u32(x.query_id);
  w.u8_counted(x.entries, max_answer_entries, [&w](const asl_entry& e) {
    w.u32(e.apo);
    w.str(e.name);
    w.str(e.type);
  });
}

void put(writer& w, const asl_request& x) {
  w.fields(x.request_id, x.apo, x.payload);
}

void put(writer& w, const asl_response& x) {
  w.fields(x.request_id, x.ok);
  if (x.ok)
    w.rest(x.payload);
  else
    w.error(x.error);
}

void put(writer& w, const asl_watch& x) {
  w.fields(x.apo);
}

void put(writer& w, const asl_unwatch& x) {
  w.fields(x.apo);
}

void put(writer& w, const asl_down& x) {
  w.fields(x.apo, x.reason);
}

void put(writer& w, const asl_withdraw& x) {
  w.fields(x.apo, x.name);
}

void put(writer& w, const asl_subscribe& x) {
  w.fields(x.topic, x.lease_ms);
}

void put(writer& w, const asl_unsubscribe& x) {
  w.fields(x.topic);
}

void put(writer& w, const asl_publish& x) {
  w.fields(x.topic, x.seq, x.payload);
}

void put(writer& w, const asl_advertise& x) {
  w.fields(x.topic);
}

void put(writer& w, const asl_reliable_request& x) {
  w.fields(x.request_id, x.apo, x.oneway, x.payload);
}

void put(writer& w, const asl_ack& x) {
  w.fields(x.request_id);
}

// -- reading ---------------------------------------------------------------------

/// Names of the three fields of a wire_error in error messages.
struct error_fields {
  const char* category;
  const char* code;
  const char* context;
};

/// Reads the fields of one message of kind `who`, after the header. Every
/// read checks the bytes left first and fails with an error naming the
/// field; strings are allocated only once their bytes are known present.
struct reader {
  const char* who;
  le_reader in;
  /// The answer entry being read, from 1; 0 outside entries.
  size_t entry = 0;
  /// The buffer `in` reads, when the payload may take it over (the
  /// payload is the last field: nothing is read after it).
  byte_buffer* whole = nullptr;

  size_t left() const noexcept {
    return in.left();
  }

  caf::error fail(const std::string& what) const {
    if (entry == 0)
      return bad(who, what);
    return bad(who, "entry " + num(entry) + ": " + what);
  }

  caf::error need(const char* field, size_t n) const {
    if (left() >= n)
      return caf::none;
    return fail(std::string{field} + " truncated (needs " + n_bytes(n) + ", "
                + num(left()) + " left)");
  }

  // -- one field by its type ----------------------------------------------------

  /// An unsigned integer of sizeof(T) bytes.
  template <class T>
  caf::error field(const char* name, T& x) {
    static_assert(std::is_unsigned_v<T>, "an unsigned integer");
    if (auto err = need(name, sizeof(T)))
      return err;
    x = in.le<T>();
    return caf::none;
  }

  /// One byte, 0 or 1.
  caf::error field(const char* name, bool& x) {
    uint8_t b = 0;
    if (auto err = field(name, b))
      return err;
    if (b > 1)
      return fail(std::string{name} + " is " + num(b) + ", expected 0 or 1");
    x = b == 1;
    return caf::none;
  }

  /// The last field: the rest of the message.
  caf::error field(const char*, byte_buffer& x) {
    if (whole != nullptr && in.ok()) {
      auto at = in.pos();
      (void) in.bytes(in.left()); // at the end, as rest() leaves it
      x = std::move(*whole);
      whole = nullptr;
      x.erase(x.begin(), x.begin() + static_cast<ptrdiff_t>(at));
      return caf::none;
    }
    in.rest(x);
    return caf::none;
  }

  /// A 1-byte length and that many bytes.
  caf::error field(const char* name, std::string& x) {
    if (left() < 1)
      return fail(std::string{name} + " length truncated (needs 1 byte, 0 left)");
    size_t n = in.u8();
    if (auto err = need(name, n))
      return err;
    in.str(n, x);
    return caf::none;
  }

  /// Named fields in wire order ("apo", x.apo, "name", x.name, ...); the
  /// first that fails is the result.
  caf::error fields() {
    return caf::none;
  }

  template <class T, class... Ts>
  caf::error fields(const char* name, T& x, Ts&... more) {
    if (auto err = field(name, x))
      return err;
    return fields(more...);
  }

  caf::error error(const error_fields& f, wire_error& x) {
    if (auto err = field(f.category, x.category))
      return err;
    if (auto err = field(f.code, x.code))
      return err;
    return field(f.context, x.context);
  }
};

caf::error get(reader& r, asl_query& x) {
  uint8_t by = 0;
  if (auto err = r.fields("query_id", x.query_id, "by", by))
    return err;
  if (by > max_query_by)
    return r.fail("by " + num(by) + " unknown (0 name, 1 type, 2 any)");
  x.by = static_cast<query_by>(by);
  if (auto err = r.fields("pattern", x.pattern))
    return err;
  if (x.by == query_by::any && !x.pattern.empty())
    return r.fail("by any with a " + num(x.pattern.size())
                  + "-byte pattern (must be empty)");
  return caf::none;
}

caf::error get(reader& r, asl_answer& x) {
  uint8_t count = 0;
  if (auto err = r.fields("query_id", x.query_id, "count", count))
    return err;
  if (auto why = counted_list_problem(count, max_answer_entries,
                                      min_entry_size, r.left());
      !why.empty())
    return r.fail(why);
  x.entries.resize(count);
  for (size_t i = 0; i < count; ++i) {
    r.entry = i + 1;
    auto& e = x.entries[i];
    if (auto err = r.fields("apo", e.apo, "name", e.name, "type", e.type))
      return err;
  }
  r.entry = 0;
  return caf::none;
}

caf::error get(reader& r, asl_request& x) {
  return r.fields("request_id", x.request_id, "apo", x.apo, "payload",
                  x.payload);
}

/// A request_id that must not be 0, and why.
caf::error numbered(reader& r, uint64_t& request_id, const char* why) {
  if (auto err = r.fields("request_id", request_id))
    return err;
  if (request_id == 0)
    return r.fail(std::string{"request_id 0 ("} + why + ")");
  return caf::none;
}

caf::error get(reader& r, asl_response& x) {
  if (auto err = numbered(r, x.request_id,
                          "one-way requests get no response"))
    return err;
  if (auto err = r.fields("ok", x.ok))
    return err;
  if (x.ok)
    return r.fields("payload", x.payload);
  return r.error({"error.category", "error.code", "error.context"}, x.error);
}

caf::error get(reader& r, asl_watch& x) {
  return r.fields("apo", x.apo);
}

caf::error get(reader& r, asl_unwatch& x) {
  return r.fields("apo", x.apo);
}

caf::error get(reader& r, asl_down& x) {
  if (auto err = r.fields("apo", x.apo))
    return err;
  return r.error({"reason.category", "reason.code", "reason.context"},
                 x.reason);
}

caf::error get(reader& r, asl_withdraw& x) {
  return r.fields("apo", x.apo, "name", x.name);
}

caf::error get(reader& r, asl_subscribe& x) {
  return r.fields("topic", x.topic, "lease_ms", x.lease_ms);
}

caf::error get(reader& r, asl_unsubscribe& x) {
  return r.fields("topic", x.topic);
}

caf::error get(reader& r, asl_publish& x) {
  return r.fields("topic", x.topic, "seq", x.seq, "payload", x.payload);
}

caf::error get(reader& r, asl_advertise& x) {
  return r.fields("topic", x.topic);
}

caf::error get(reader& r, asl_reliable_request& x) {
  if (auto err = numbered(r, x.request_id,
                          "reliable requests are numbered"))
    return err;
  return r.fields("apo", x.apo, "oneway", x.oneway, "payload", x.payload);
}

caf::error get(reader& r, asl_ack& x) {
  return numbered(r, x.request_id, "reliable requests are numbered");
}

template <class T>
caf::expected<asl_message> decode_as(reader& r) {
  T x;
  if (auto err = get(r, x))
    return err;
  if (r.left() != 0)
    return r.fail(num(r.left())
                  + (r.left() == 1 ? " trailing byte" : " trailing bytes"));
  return asl_message{std::move(x)};
}

} // namespace

// -- public interface ------------------------------------------------------------

void encode(const asl_message& x, byte_buffer& out) {
  writer w{out};
  w.u8(asl_wire_version);
  w.u8(static_cast<uint8_t>(x.index() + 1));
  std::visit([&w](const auto& y) { put(w, y); }, x);
}

caf::expected<asl_kind> peek_asl_kind(const uint8_t* data, size_t size) {
  if (size == 0 || data == nullptr)
    return bad("asl", "empty message");
  if (data[0] != asl_wire_version)
    return bad("asl", "version " + num(data[0]) + ", expected "
                        + num(asl_wire_version));
  if (size < head_size)
    return bad("asl", "kind truncated (needs 1 byte, 0 left)");
  auto kind = data[1];
  if (kind == 0 || kind > max_kind)
    return bad("asl", "unknown kind " + num(kind));
  return static_cast<asl_kind>(kind);
}

namespace {

caf::expected<asl_message> decode_asl(const uint8_t* data, size_t size,
                                      byte_buffer* whole) {
  auto kind = peek_asl_kind(data, size);
  if (!kind)
    return std::move(kind.error());
  reader r{name_of(*kind), le_reader{data, size, head_size}};
  r.whole = whole;
  switch (*kind) {
    case asl_kind::query:
      return decode_as<asl_query>(r);
    case asl_kind::answer:
      return decode_as<asl_answer>(r);
    case asl_kind::request:
      return decode_as<asl_request>(r);
    case asl_kind::response:
      return decode_as<asl_response>(r);
    case asl_kind::watch:
      return decode_as<asl_watch>(r);
    case asl_kind::unwatch:
      return decode_as<asl_unwatch>(r);
    case asl_kind::down:
      return decode_as<asl_down>(r);
    case asl_kind::withdraw:
      return decode_as<asl_withdraw>(r);
    case asl_kind::subscribe:
      return decode_as<asl_subscribe>(r);
    case asl_kind::unsubscribe:
      return decode_as<asl_unsubscribe>(r);
    case asl_kind::publish:
      return decode_as<asl_publish>(r);
    case asl_kind::advertise:
      return decode_as<asl_advertise>(r);
    case asl_kind::reliable_request:
      return decode_as<asl_reliable_request>(r);
    case asl_kind::ack:
      return decode_as<asl_ack>(r);
  }
  return bad("asl", "unknown kind " + num(data[1])); // not reached
}

} // namespace

caf::expected<asl_message> decode_asl(const uint8_t* data, size_t size) {
  return decode_asl(data, size, nullptr);
}

caf::expected<asl_message> decode_asl(byte_buffer&& message) {
  return decode_asl(message.data(), message.size(), &message);
}

// -- equality --------------------------------------------------------------------

bool operator==(const wire_error& a, const wire_error& b) {
  return a.category == b.category && a.code == b.code
         && a.context == b.context;
}

bool operator==(const asl_query& a, const asl_query& b) {
  return a.query_id == b.query_id && a.by == b.by && a.pattern == b.pattern;
}

bool operator==(const asl_entry& a, const asl_entry& b) {
  return a.apo == b.apo && a.name == b.name && a.type == b.type;
}

bool operator==(const asl_answer& a, const asl_answer& b) {
  return a.query_id == b.query_id && a.entries == b.entries;
}

bool operator==(const asl_request& a, const asl_request& b) {
  return a.request_id == b.request_id && a.apo == b.apo
         && a.payload == b.payload;
}

bool operator==(const asl_response& a, const asl_response& b) {
  if (a.request_id != b.request_id || a.ok != b.ok)
    return false;
  return a.ok ? a.payload == b.payload : a.error == b.error;
}

bool operator==(const asl_watch& a, const asl_watch& b) {
  return a.apo == b.apo;
}

bool operator==(const asl_unwatch& a, const asl_unwatch& b) {
  return a.apo == b.apo;
}

bool operator==(const asl_down& a, const asl_down& b) {
  return a.apo == b.apo && a.reason == b.reason;
}

bool operator==(const asl_withdraw& a, const asl_withdraw& b) {
  return a.apo == b.apo && a.name == b.name;
}

bool operator==(const asl_subscribe& a, const asl_subscribe& b) {
  return a.topic == b.topic && a.lease_ms == b.lease_ms;
}

bool operator==(const asl_unsubscribe& a, const asl_unsubscribe& b) {
  return a.topic == b.topic;
}

bool operator==(const asl_publish& a, const asl_publish& b) {
  return a.topic == b.topic && a.seq == b.seq && a.payload == b.payload;
}

bool operator==(const asl_advertise& a, const asl_advertise& b) {
  return a.topic == b.topic;
}

bool operator==(const asl_reliable_request& a, const asl_reliable_request& b) {
  return a.request_id == b.request_id && a.apo == b.apo
         && a.oneway == b.oneway && a.payload == b.payload;
}

bool operator==(const asl_ack& a, const asl_ack& b) {
  return a.request_id == b.request_id;
}

} // namespace herm
