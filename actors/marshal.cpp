#include "actors/marshal.hpp"

#include <algorithm>
#include <array>
#include <cstring>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/atom.hpp"
#include "caf/deserializer.hpp"
#include "caf/duration.hpp"
#include "caf/detail/message_data.hpp"
#include "caf/intrusive_ptr.hpp"
#include "caf/sec.hpp"
#include "caf/serializer.hpp"
#include "caf/type_erased_value.hpp"
#include "caf/uniform_type_info_map.hpp"

#include "actors/runtime/error.hpp"
#include "channels/le_codec.hpp"
#include "channels/thread_cache.hpp"

namespace herm {

namespace {

// -- helpers -------------------------------------------------------------------

/// Longest type name on the wire, in bytes.
constexpr size_t max_type_name = 255;

bool is_no_context(const caf::error& err) {
  return err.category() == caf::atom("system")
         && err.code() == static_cast<uint8_t>(caf::sec::no_context);
}

const char* not_data_reason = "holds an actor handle, group, caf::message or "
                              "caf::error; APO payloads carry plain data only";

// -- encoder -------------------------------------------------------------------

/// Writes HERM's APO encoding. Constructed without an execution unit on
/// purpose: CAF then refuses every value that needs the actor system (actor
/// handles, groups, nested messages) with sec::no_context instead of
/// registering local actors for remote lookup.
class apo_serializer final : public caf::serializer {
public:
  explicit apo_serializer(byte_buffer& out)
    : caf::serializer(static_cast<caf::execution_unit*>(nullptr)), out_(out) {
    // nop
  }

  const std::string& reason() const {
    return reason_;
  }

  caf::error begin_object(uint16_t&, std::string&) override {
    return fail(not_data_reason);
  }

  caf::error end_object() override {
    return caf::none;
  }

  caf::error begin_sequence(size_t& n) override {
    out_.leb128(n);
    return caf::none;
  }

  caf::error end_sequence() override {
    return caf::none;
  }

  caf::error apply_raw(size_t n, void* data) override {
    out_.bytes(data, n);
    return caf::none;
  }

protected:
  caf::error apply_impl(int8_t& x) override {
    return put(static_cast<uint8_t>(x));
  }
  caf::error apply_impl(uint8_t& x) override {
    return put(x);
  }
  caf::error apply_impl(int16_t& x) override {
    return put(static_cast<uint16_t>(x));
  }
  caf::error apply_impl(uint16_t& x) override {
    return put(x);
  }
  caf::error apply_impl(int32_t& x) override {
    return put(static_cast<uint32_t>(x));
  }
  caf::error apply_impl(uint32_t& x) override {
    return put(x);
  }
  caf::error apply_impl(int64_t& x) override {
    return put(static_cast<uint64_t>(x));
  }
  caf::error apply_impl(uint64_t& x) override {
    return put(x);
  }

  caf::error apply_impl(float& x) override {
    static_assert(sizeof(float) == 4, "float must be IEEE 754 binary32");
    uint32_t bits;
    std::memcpy(&bits, &x, sizeof(bits));
    return put(bits);
  }

  caf::error apply_impl(double& x) override {
    static_assert(sizeof(double) == 8, "double must be IEEE 754 binary64");
    uint64_t bits;
    std::memcpy(&bits, &x, sizeof(bits));
    return put(bits);
  }

  caf::error apply_impl(long double&) override {
    return fail("holds a long double, which has no portable encoding");
  }

  caf::error apply_impl(std::string& x) override {
    out_.leb128(x.size()).bytes(x.data(), x.size());
    return caf::none;
  }

  caf::error apply_impl(std::u16string& x) override {
    out_.leb128(x.size() * 2);
    for (auto c : x)
      out_.u16(static_cast<uint16_t>(c));
    return caf::none;
  }

  caf::error apply_impl(std::u32string& x) override {
    out_.leb128(x.size() * 4);
    for (auto c : x)
      out_.u32(static_cast<uint32_t>(c));
    return caf::none;
  }

private:
  template <class T>
  caf::error put(T x) {
    out_.le(x);
    return caf::none;
  }

  caf::error fail(std::string what) {
    reason_ = std::move(what);
    return make_error(ec::invalid_parameter, reason_);
  }

  le_writer out_;
  std::string reason_;
};

// -- decoder -------------------------------------------------------------------

/// Reads HERM's APO encoding from [pos, end). Every read checks the bytes
/// left first; every length or count is checked against the bytes left and
/// the limits before CAF allocates for it (CAF resizes byte buffers right
/// after begin_sequence). No execution unit, so actor handles are refused.
class apo_deserializer final : public caf::deserializer {
public:
  apo_deserializer(le_reader in, const unmarshal_limits& limits)
    : caf::deserializer(static_cast<caf::execution_unit*>(nullptr)),
      in_(in),
      limits_(limits) {
    // nop
  }

  const std::string& reason() const {
    return reason_;
  }

  size_t remaining() const {
    return in_.left();
  }

  size_t offset() const {
    return in_.pos();
  }

  /// Starts counting values anew for the next top-level element.
  void start_element() {
    values_ = 0;
    depth_ = 0;
    reason_.clear();
  }

  /// Reads a LEB128 length or count (minimal form, at most 64 bits).
  caf::error read_leb128(uint64_t& x) {
    auto start = std::to_string(offset());
    switch (in_.leb128(x)) {
      case leb128_status::ok:
        return caf::none;
      case leb128_status::truncated:
        return fail("truncated in a length at offset " + start);
      case leb128_status::too_long: // 10 bytes: only above 64 bits
        return fail("length at offset " + start + " exceeds 64 bits");
      case leb128_status::not_minimal:
        break;
    }
    return fail("length at offset " + start
                + " is not in minimal LEB128 form");
  }

  /// Reads a string of `n` bytes after checking both bounds.
  caf::error read_text(size_t max, const char* what, std::string& x) {
    uint64_t n = 0;
    if (auto err = read_leb128(n))
      return err;
    if (n > max)
      return fail(std::string{what} + " of " + std::to_string(n)
                  + " bytes exceeds the limit of " + std::to_string(max));
    if (n > remaining())
      return truncated(n);
    in_.str(static_cast<size_t>(n), x);
    return caf::none;
  }

  caf::error fail(std::string what) {
    reason_ = std::move(what);
    return make_error(ec::invalid_parameter, reason_);
  }

  caf::error begin_object(uint16_t&, std::string&) override {
    return fail(not_data_reason);
  }

  caf::error end_object() override {
    return caf::none;
  }

  caf::error begin_sequence(size_t& n) override {
    ++values_;
    if (depth_ + 1 > limits_.max_depth)
      return fail("value " + std::to_string(values_) + " nests deeper than "
                  + std::to_string(limits_.max_depth) + " levels");
    uint64_t count = 0;
    if (auto err = read_leb128(count))
      return err;
    if (count > limits_.max_sequence)
      return fail("value " + std::to_string(values_) + " announces "
                  + std::to_string(count) + " elements, above the limit of "
                  + std::to_string(limits_.max_sequence));
    if (count > remaining())
      return fail("value " + std::to_string(values_) + " announces "
                  + std::to_string(count) + " elements but only "
                  + std::to_string(remaining()) + " bytes follow");
    ++depth_;
    n = static_cast<size_t>(count);
    return caf::none;
  }

  caf::error end_sequence() override {
    if (depth_ > 0)
      --depth_;
    return caf::none;
  }

  caf::error apply_raw(size_t n, void* data) override {
    if (n > remaining())
      return truncated(n);
    std::memcpy(data, in_.bytes(n), n);
    return caf::none;
  }

protected:
  caf::error apply_impl(int8_t& x) override {
    return get_signed<uint8_t>(x);
  }
  caf::error apply_impl(uint8_t& x) override {
    return get(x);
  }
  caf::error apply_impl(int16_t& x) override {
    return get_signed<uint16_t>(x);
  }
  caf::error apply_impl(uint16_t& x) override {
    return get(x);
  }
  caf::error apply_impl(int32_t& x) override {
    return get_signed<uint32_t>(x);
  }
  caf::error apply_impl(uint32_t& x) override {
    return get(x);
  }
  caf::error apply_impl(int64_t& x) override {
    return get_signed<uint64_t>(x);
  }
  caf::error apply_impl(uint64_t& x) override {
    return get(x);
  }

  caf::error apply_impl(float& x) override {
    uint32_t bits = 0;
    if (auto err = get(bits))
      return err;
    std::memcpy(&x, &bits, sizeof(bits));
    return caf::none;
  }

  caf::error apply_impl(double& x) override {
    uint64_t bits = 0;
    if (auto err = get(bits))
      return err;
    std::memcpy(&x, &bits, sizeof(bits));
    return caf::none;
  }

  caf::error apply_impl(long double&) override {
    ++values_;
    return fail("value " + std::to_string(values_)
                + " is a long double, which has no portable encoding");
  }

  caf::error apply_impl(std::string& x) override {
    ++values_;
    return read_text(limits_.max_string, "string", x);
  }

  caf::error apply_impl(std::u16string& x) override {
    return read_units(x, "UTF-16 string", "UTF-16 string of odd byte length");
  }

  caf::error apply_impl(std::u32string& x) override {
    return read_units(x, "UTF-32 string",
                      "UTF-32 string whose byte length is not a multiple of 4");
  }

  /// Reads a string of little-endian code units of Char's width, at most
  /// the string limit in bytes. `what` names it in errors; `bad_length` says
  /// what is wrong when the byte length is not a multiple of the width.
  template <class Char>
  caf::error read_units(std::basic_string<Char>& x, const char* what,
                        const char* bad_length) {
    using unit = std::conditional_t<sizeof(Char) == 2, uint16_t, uint32_t>;
    ++values_;
    std::string raw;
    if (auto err = read_text(limits_.max_string, what, raw))
      return err;
    if (raw.size() % sizeof(unit) != 0)
      return fail("value " + std::to_string(values_) + ": " + bad_length);
    x.clear();
    x.reserve(raw.size() / sizeof(unit));
    for (size_t i = 0; i < raw.size(); i += sizeof(unit))
      x.push_back(static_cast<Char>(
        load_le<unit>(reinterpret_cast<const uint8_t*>(raw.data() + i))));
    return caf::none;
  }

private:
  caf::error truncated(uint64_t needed) {
    return fail("truncated in value " + std::to_string(values_) + " (needs "
                + std::to_string(needed) + " bytes at offset "
                + std::to_string(offset()) + ", "
                + std::to_string(remaining()) + " left)");
  }

  template <class T>
  caf::error get(T& x) {
    ++values_;
    if (sizeof(T) > remaining())
      return truncated(sizeof(T));
    x = in_.le<T>();
    return caf::none;
  }

  // Two's complement on the wire; the conversion is defined via memcpy.
  template <class U, class S>
  caf::error get_signed(S& x) {
    U tmp = 0;
    if (auto err = get(tmp))
      return err;
    std::memcpy(&x, &tmp, sizeof(x));
    return caf::none;
  }

  le_reader in_;
  const unmarshal_limits& limits_;
  size_t values_ = 0;
  size_t depth_ = 0;
  std::string reason_;
};

/// The values of an unmarshalled message: up to four in place, the rest in
/// a vector, the object itself from the thread's block cache
/// (channels/thread_cache.hpp). CAF's dynamic_message_data takes two
/// blocks (itself and its vector) for the same.
class unmarshalled_data final : public caf::detail::message_data,
                                public block_cached {
public:
  unmarshalled_data() = default;

  unmarshalled_data(const unmarshalled_data& other)
    : caf::detail::message_data(other) {
    for (size_t i = 0; i < other.size_; ++i)
      append(other.at(i).copy());
  }

  using block_cached::operator new;
  using block_cached::operator delete;

  void append(caf::type_erased_value_ptr x) {
    type_token_ = (type_token_ << 6) | x->type().first;
    if (size_ < in_place)
      first_[size_] = std::move(x);
    else
      rest_.emplace_back(std::move(x));
    ++size_;
  }

  unmarshalled_data* copy() const override {
    return new unmarshalled_data(*this);
  }

  void* get_mutable(size_t pos) override {
    return at(pos).get_mutable();
  }

  caf::error load(size_t pos, caf::deserializer& source) override {
    return at(pos).load(source);
  }

  size_t size() const noexcept override {
    return size_;
  }

  uint32_t type_token() const noexcept override {
    return type_token_;
  }

  caf::rtti_pair type(size_t pos) const noexcept override {
    return at(pos).type();
  }

  const void* get(size_t pos) const noexcept override {
    return at(pos).get();
  }

  std::string stringify(size_t pos) const override {
    return at(pos).stringify();
  }

  using caf::detail::message_data::copy;

  caf::type_erased_value_ptr copy(size_t pos) const override {
    return at(pos).copy();
  }

  caf::error save(size_t pos, caf::serializer& sink) const override {
    return at(pos).save(sink);
  }

private:
  static constexpr size_t in_place = 4;

  caf::type_erased_value& at(size_t pos) const noexcept {
    return pos < in_place ? *first_[pos] : *rest_[pos - in_place];
  }

  std::array<caf::type_erased_value_ptr, in_place> first_;
  std::vector<caf::type_erased_value_ptr> rest_;
  size_t size_ = 0;
  // As CAF's dynamic_message_data computes it.
  uint32_t type_token_ = 0xFFFFFFFF;
};

static_assert(alignof(unmarshalled_data) <= __STDCPP_DEFAULT_NEW_ALIGNMENT__,
              "cached blocks have the default new alignment");

std::string element_prefix(size_t i, const std::string& name) {
  return "element " + std::to_string(i) + " (" + name + "): ";
}

caf::error element_error(size_t i, const std::string& name,
                         const std::string& reason, const caf::error& err) {
  if (!reason.empty())
    return make_error(ec::invalid_parameter, element_prefix(i, name) + reason);
  if (is_no_context(err))
    return make_error(ec::invalid_parameter,
                      element_prefix(i, name) + not_data_reason);
  return make_error(ec::invalid_parameter,
                    element_prefix(i, name) + render(err));
}

} // namespace

// -- public interface ----------------------------------------------------------

namespace {

/// Appends the encoding of `msg` to `out`.
caf::error marshal_to(caf::actor_system& sys, const caf::message& msg,
                      byte_buffer& out) {
  le_writer w{out};
  w.u8(apo_format_version).leb128(msg.size());
  apo_serializer sink{out};
  auto& types = sys.types();
  for (size_t i = 0; i < msg.size(); ++i) {
    auto rtti = msg.type(i);
    const std::string& name = types.portable_name(rtti);
    if (name.empty() || name == types.default_type_name()
        || name.size() > max_type_name)
      return make_error(ec::invalid_parameter,
                        "element " + std::to_string(i) + ": type '"
                          + (rtti.second != nullptr ? rtti.second->name()
                                                    : "?")
                          + "' has no portable name in the actor system");
    w.leb128(name.size()).bytes(name.data(), name.size());
    if (auto err = msg.save(i, sink))
      return element_error(i, name, sink.reason(), err);
  }
  return caf::none;
}

} // namespace

caf::expected<byte_buffer> marshal(caf::actor_system& sys,
                                   const caf::message& msg) {
  // Its storage usually comes back to the cache once the message that
  // carries it is sent (app_support.cpp, recycle_payload). A payload may
  // also be kept (a parked reliable request, a topic's last value): then
  // it holds no more than it grew to, 512 bytes, or twice the payload this
  // thread marshalled last. That last size is the first guess: a stream of
  // 1,400-byte payloads takes a kept buffer that fits at once instead of
  // growing one of 512 bytes by doubling (about four allocations a
  // message; docs/performance.md, allocations).
  thread_local size_t last_size = 0;
  auto out = take_buffer(std::max<size_t>(128, last_size),
                         std::max<size_t>(512, 2 * last_size));
  if (auto err = marshal_to(sys, msg, out))
    return err;
  last_size = out.size();
  return out;
}

caf::expected<caf::message> unmarshal(caf::actor_system& sys,
                                      const uint8_t* data, size_t size,
                                      const unmarshal_limits& limits) {
  if (size > limits.max_total)
    return make_error(ec::invalid_parameter,
                      "payload of " + std::to_string(size)
                        + " bytes exceeds the limit of "
                        + std::to_string(limits.max_total));
  if (size == 0 || data == nullptr)
    return make_error(ec::invalid_parameter, "empty payload");
  if (data[0] != apo_format_version)
    return make_error(ec::invalid_parameter,
                      "unsupported APO format version "
                        + std::to_string(data[0]) + " (this peer speaks "
                        + std::to_string(apo_format_version) + ")");
  apo_deserializer source{le_reader{data, size, 1}, limits};
  uint64_t count = 0;
  if (auto err = source.read_leb128(count))
    return make_error(ec::invalid_parameter,
                      "element count: " + source.reason());
  if (count > limits.max_elements)
    return make_error(ec::invalid_parameter,
                      "message of " + std::to_string(count)
                        + " elements exceeds the limit of "
                        + std::to_string(limits.max_elements));
  if (count > source.remaining())
    return make_error(ec::invalid_parameter,
                      "message announces " + std::to_string(count)
                        + " elements but only "
                        + std::to_string(source.remaining())
                        + " bytes follow");
  auto& types = sys.types();
  caf::intrusive_ptr<unmarshalled_data> values;
  if (count > 0)
    values.reset(new unmarshalled_data, false);
  // Reused per thread: no allocation per element for the type name.
  thread_local std::string name;
  for (size_t i = 0; i < count; ++i) {
    source.start_element();
    name.clear();
    if (auto err = source.read_text(max_type_name, "type name", name))
      return make_error(ec::invalid_parameter, "element " + std::to_string(i)
                                                 + ": " + source.reason());
    auto value = types.make_value(name);
    if (!value)
      return make_error(app_ec::unknown_type, "element " + std::to_string(i)
                                                 + ": unknown type '" + name
                                                 + "'");
    source.start_element();
    if (auto err = value->load(source))
      return element_error(i, name, source.reason(), err);
    // CAF's own types may hold enums whose range their loaders do not
    // check; printing an out-of-range time unit reads past CAF's table of
    // unit names (CAF prints every message an actor drops).
    if (name == "@duration") {
      auto unit = static_cast<const caf::duration*>(value->get())->unit;
      if (static_cast<uint32_t>(unit)
          > static_cast<uint32_t>(caf::time_unit::nanoseconds))
        return make_error(ec::invalid_parameter,
                          "element " + std::to_string(i)
                            + " (@duration): time unit "
                            + std::to_string(static_cast<uint32_t>(unit))
                            + " is out of range");
    }
    values->append(std::move(value));
  }
  if (source.remaining() != 0)
    return make_error(ec::invalid_parameter,
                      std::to_string(source.remaining())
                        + " trailing bytes after the last element (offset "
                        + std::to_string(source.offset()) + ")");
  caf::message result;
  if (values)
    result = caf::message{caf::message::data_ptr{values.detach(), false}};
  // Only the canonical encoding of a message is valid: this refuses
  // booleans other than 0 and 1, unsorted or duplicate map keys and any
  // other input that would decode to the same value as different bytes.
  // (The buffer is reused per thread: no allocation once warmed up.)
  thread_local byte_buffer again;
  again.clear();
  if (auto err = marshal_to(sys, result, again))
    return err;
  if (again.capacity() > 64 * 1024)
    again.shrink_to_fit(); // keep at most one large payload's worth
  if (again.size() != size || !std::equal(again.begin(), again.end(), data)) {
    size_t at = 0;
    while (at < size && at < again.size() && again[at] == data[at])
      ++at;
    return make_error(ec::invalid_parameter,
                      "non-canonical encoding: differs from the canonical "
                      "form at offset "
                        + std::to_string(at));
  }
  return result;
}

} // namespace herm
