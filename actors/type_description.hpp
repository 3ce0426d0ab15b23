#pragma once

// Descriptions of message types: the name and type of each field, so that
// a tool on any module can print a value of a type its process was not
// built with (hermctl topic echo, call, record) and build one from text
// (topic pub, call). docs/user-guide.md, "Tools", gives the text form;
// docs/protocol.md, "Type descriptions", the grammar of field types.
//
// A description is registered once per process, next to the type:
//
//   herm::add_message_type<calc_request>(cfg, "calc_request",
//                                        {"a", "b", "op"});
//
// registers the type with the actor system configuration (as
// cfg.add_message_type does: no type-ID block needed) and its description;
// describe_type<T>(name, fields) only describes a type registered otherwise
// (in a type-ID block). The field types are derived from the C++ type: only
// the names are given, in the order `inspect` lists the fields.
//
// Descriptions this process learns from other modules (a control service
// asks the publisher of a value it cannot print) are kept apart, at most
// max_learned_descriptions of them (refusals counted), and never replace a
// local one. The registry is process-wide and thread-safe.

#include <array>
#include <chrono>
#include <cstdint>
#include <deque>
#include <list>
#include <map>
#include <optional>
#include <stdexcept>
#include <set>
#include <string>
#include <tuple>
#include <type_traits>
#include <typeindex>
#include <utility>
#include <vector>

#include "caf/actor_system_config.hpp"
#include "caf/error.hpp"
#include "caf/meta/annotation.hpp"
#include "caf/timestamp.hpp"
#include "caf/type_id.hpp"

#include "channels/error.hpp"

namespace herm {

/// One field: its name and its type in the grammar of docs/protocol.md
/// ("@u16", "@str", "list<double>", "map<@str,@i32>", "herm.srf04_reading").
struct field_description {
  std::string name;
  std::string type;
};

/// A message type: its portable name (the one on the wire) and its fields in
/// `inspect` order.
struct type_description {
  std::string name;
  std::vector<field_description> fields;
};

inline bool operator==(const field_description& a, const field_description& b) {
  return a.name == b.name && a.type == b.type;
}

inline bool operator==(const type_description& a, const type_description& b) {
  return a.name == b.name && a.fields == b.fields;
}

/// Most descriptions learned from other modules kept by one process.
constexpr size_t max_learned_descriptions = 1024;

/// Registers `d` as this process's own description of type `d.name`
/// (replacing an earlier one of the same name). `cpp_type`, if given, lets
/// descriptions of types that contain this one name it.
/// Errors: ec::invalid_parameter (empty or over-long name, a field type
/// outside the grammar).
caf::error register_description(type_description d,
                                 std::optional<std::type_index> cpp_type = {});

/// Keeps `d`, learned from another module, unless this process describes
/// the type itself or holds max_learned_descriptions already (then false,
/// counted in learned_descriptions_refused). Checks it like
/// register_description.
bool learn_description(const type_description& d);

/// The description of type `name`: this process's own, else a learned one.
std::optional<type_description> find_description(const std::string& name);

/// This process's own descriptions, sorted by name.
std::vector<type_description> local_descriptions();

/// Descriptions refused because max_learned_descriptions were held.
uint64_t learned_descriptions_refused();

/// Checks a field type against the grammar: "" if valid, else why not.
std::string check_field_type(const std::string& type);

namespace detail {

/// The portable name registered for C++ type `t`, or "".
std::string described_name(std::type_index t);

/// Lets descriptions of other types name C++ type `t` as `name`.
void register_described_name(std::type_index t, std::string name);

/// "a, b, op" as {"a", "b", "op"}.
std::vector<std::string> split_field_names(const char* names);

template <class T>
struct is_list : std::false_type {};
template <class T, class A>
struct is_list<std::vector<T, A>> : std::true_type {};
template <class T, class A>
struct is_list<std::list<T, A>> : std::true_type {};
template <class T, class A>
struct is_list<std::deque<T, A>> : std::true_type {};

template <class T>
struct is_set : std::false_type {};
template <class T, class C, class A>
struct is_set<std::set<T, C, A>> : std::true_type {};

template <class T>
struct is_map : std::false_type {};
template <class K, class V, class C, class A>
struct is_map<std::map<K, V, C, A>> : std::true_type {};

template <class T>
struct is_std_array : std::false_type {};
template <class T, size_t N>
struct is_std_array<std::array<T, N>> : std::true_type {};

template <class T>
struct is_duration : std::false_type {};
template <class R, class P>
struct is_duration<std::chrono::duration<R, P>> : std::true_type {};

template <class T>
struct is_tuple : std::false_type {};
template <class... Ts>
struct is_tuple<std::tuple<Ts...>> : std::true_type {};
template <class A, class B>
struct is_tuple<std::pair<A, B>> : std::true_type {};

/// Collects the field types `inspect` lists, skipping annotations.
class describer {
public:
  using result_type = void;
  static constexpr bool reads_state = true;
  static constexpr bool writes_state = false;

  template <class... Ts>
  void operator()(Ts&&... xs) {
    (add(xs), ...);
  }

  std::vector<std::string> types;
  /// Set when a field's type has no description in the grammar.
  std::string error;

private:
  template <class T>
  void add(T&) {
    if constexpr (!caf::meta::is_annotation<T>::value)
      types.push_back(type_of<T>());
  }

public:
  template <class T>
  std::string type_of();
};

template <class T, class = void>
struct has_inspect : std::false_type {};
template <class T>
struct has_inspect<T, std::void_t<decltype(inspect(std::declval<describer&>(),
                                                   std::declval<T&>()))>>
  : std::true_type {};

template <class... Ts>
std::string type_list(describer& d, std::tuple<Ts...>*) {
  std::string out;
  ((out += (out.empty() ? "" : ",") + d.type_of<Ts>()), ...);
  return out;
}

template <class T>
std::string describer::type_of() {
  using U = std::remove_cv_t<T>;
  if constexpr (std::is_same_v<U, bool>) {
    return "bool";
  } else if constexpr (std::is_enum_v<U>) {
    return type_of<std::underlying_type_t<U>>();
  } else if constexpr (std::is_integral_v<U>) {
    static_assert(sizeof(U) <= 8);
    return std::string{std::is_signed_v<U> ? "@i" : "@u"}
           + std::to_string(sizeof(U) * 8);
  } else if constexpr (std::is_same_v<U, float>) {
    return "float";
  } else if constexpr (std::is_same_v<U, double>) {
    return "double";
  } else if constexpr (std::is_same_v<U, std::string>) {
    return "@str";
  } else if constexpr (std::is_same_v<U, std::u16string>) {
    return "@u16str";
  } else if constexpr (std::is_same_v<U, std::u32string>) {
    return "@u32str";
  } else if constexpr (std::is_same_v<U, caf::timestamp>) {
    return "@timestamp";
  } else if constexpr (is_duration<U>::value) {
    return type_of<typename U::rep>();
  } else if constexpr (is_list<U>::value) {
    return "list<" + type_of<typename U::value_type>() + ">";
  } else if constexpr (is_set<U>::value) {
    return "set<" + type_of<typename U::value_type>() + ">";
  } else if constexpr (is_map<U>::value) {
    return "map<" + type_of<typename U::key_type>() + ","
           + type_of<typename U::mapped_type>() + ">";
  } else if constexpr (is_std_array<U>::value) {
    return "array<" + type_of<typename U::value_type>() + ","
           + std::to_string(std::tuple_size<U>::value) + ">";
  } else if constexpr (is_tuple<U>::value) {
    if constexpr (std::is_same_v<U, std::pair<typename U::first_type,
                                              typename U::second_type>>)
      return "tuple<" + type_of<typename U::first_type>() + ","
             + type_of<typename U::second_type>() + ">";
    else
      return "tuple<" + type_list(*this, static_cast<U*>(nullptr)) + ">";
  } else if constexpr (has_inspect<U>::value) {
    auto name = described_name(typeid(U));
    if (name.empty() && error.empty())
      error = std::string{"a field of type '"} + typeid(U).name()
              + "' has no description: describe that type first";
    return name.empty() ? "?" : name;
  } else {
    if (error.empty())
      error = std::string{"a field of type '"} + typeid(U).name()
              + "' has no portable encoding";
    return "?";
  }
}

} // namespace detail

/// Describes type `T`, registered in the actor system under `name`, with
/// one name per field in `inspect` order. Errors: ec::invalid_parameter
/// when the count of names differs from the fields, or a field's type
/// cannot be described (a struct not described yet: describe it first).
template <class T>
caf::error describe_type(std::string name, std::vector<std::string> fields) {
  detail::describer d;
  T value{};
  inspect(d, value);
  type_description desc{std::move(name), {}};
  if (d.error.empty() && d.types.size() != fields.size())
    d.error = std::to_string(d.types.size()) + " fields, "
              + std::to_string(fields.size()) + " names given";
  if (d.error.empty())
    for (size_t i = 0; i < fields.size(); ++i)
      desc.fields.push_back({std::move(fields[i]), d.types[i]});
  if (!d.error.empty())
    return make_error(ec::invalid_parameter,
                      "describing '" + desc.name + "': " + d.error);
  return register_description(std::move(desc), std::type_index{typeid(T)});
}

/// Registers message type `T` under `name` with the actor system (no type-ID
/// block needed) and describes its fields: one line per type. A
/// description error is thrown as std::invalid_argument (a programming
/// error, found at start-up).
template <class T>
caf::actor_system_config&
add_message_type(caf::actor_system_config& cfg, std::string name,
                 std::vector<std::string> fields) {
  cfg.add_message_type<T>(name);
  if (auto err = describe_type<T>(name, std::move(fields)))
    throw std::invalid_argument(render(err));
  return cfg;
}

/// The field names HERM_MESSAGE gave type `T`, if it did.
template <class T, class = void>
struct has_field_names : std::false_type {};
template <class T>
struct has_field_names<
  T, std::void_t<decltype(herm_field_names(static_cast<const T*>(nullptr)))>>
  : std::true_type {};

namespace detail {

template <caf::type_id_t I, caf::type_id_t End, bool Describe>
void describe_block_types(caf::error& first) {
  if constexpr (I < End) {
    using T = typename caf::type_by_id<I>::type;
    if constexpr (has_field_names<T>::value) {
      if constexpr (Describe) {
        auto err = describe_type<T>(
          caf::type_name_by_id<I>::value,
          split_field_names(herm_field_names(static_cast<const T*>(nullptr))));
        if (err && !first)
          first = std::move(err);
      } else {
        register_described_name(typeid(T), caf::type_name_by_id<I>::value);
      }
    }
    describe_block_types<I + 1, End, Describe>(first);
  }
}

} // namespace detail

/// Registers type-ID block `Block` with `cfg`, and describes every type in
/// it that HERM_MESSAGE declared, under its name in the block (the name on
/// the wire). A description error is thrown as std::invalid_argument.
template <class Block>
caf::actor_system_config& add_message_types(caf::actor_system_config& cfg) {
  cfg.add_message_types<Block>();
  caf::error err;
  // Names first, so that a type may contain one declared after it.
  detail::describe_block_types<Block::begin, Block::end, false>(err);
  detail::describe_block_types<Block::begin, Block::end, true>(err);
  if (err)
    throw std::invalid_argument(render(err));
  return cfg;
}

} // namespace herm

// -- HERM_MESSAGE ------------------------------------------------------------------

#define HERM_PP_CAT_(a, b) a##b
#define HERM_PP_CAT(a, b) HERM_PP_CAT_(a, b)
#define HERM_PP_NARG_(_1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, \
                      _14, _15, _16, _17, _18, _19, _20, _21, _22, _23, _24,  \
                      N, ...)                                                 \
  N
#define HERM_PP_NARG(...)                                                     \
  HERM_PP_NARG_(__VA_ARGS__, 24, 23, 22, 21, 20, 19, 18, 17, 16, 15, 14, 13,  \
                12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1)
#define HERM_PP_F1(x, a) , x.a
#define HERM_PP_F2(x, a, ...) , x.a HERM_PP_F1(x, __VA_ARGS__)
#define HERM_PP_F3(x, a, ...) , x.a HERM_PP_F2(x, __VA_ARGS__)
#define HERM_PP_F4(x, a, ...) , x.a HERM_PP_F3(x, __VA_ARGS__)
#define HERM_PP_F5(x, a, ...) , x.a HERM_PP_F4(x, __VA_ARGS__)
#define HERM_PP_F6(x, a, ...) , x.a HERM_PP_F5(x, __VA_ARGS__)
#define HERM_PP_F7(x, a, ...) , x.a HERM_PP_F6(x, __VA_ARGS__)
#define HERM_PP_F8(x, a, ...) , x.a HERM_PP_F7(x, __VA_ARGS__)
#define HERM_PP_F9(x, a, ...) , x.a HERM_PP_F8(x, __VA_ARGS__)
#define HERM_PP_F10(x, a, ...) , x.a HERM_PP_F9(x, __VA_ARGS__)
#define HERM_PP_F11(x, a, ...) , x.a HERM_PP_F10(x, __VA_ARGS__)
#define HERM_PP_F12(x, a, ...) , x.a HERM_PP_F11(x, __VA_ARGS__)
#define HERM_PP_F13(x, a, ...) , x.a HERM_PP_F12(x, __VA_ARGS__)
#define HERM_PP_F14(x, a, ...) , x.a HERM_PP_F13(x, __VA_ARGS__)
#define HERM_PP_F15(x, a, ...) , x.a HERM_PP_F14(x, __VA_ARGS__)
#define HERM_PP_F16(x, a, ...) , x.a HERM_PP_F15(x, __VA_ARGS__)
#define HERM_PP_F17(x, a, ...) , x.a HERM_PP_F16(x, __VA_ARGS__)
#define HERM_PP_F18(x, a, ...) , x.a HERM_PP_F17(x, __VA_ARGS__)
#define HERM_PP_F19(x, a, ...) , x.a HERM_PP_F18(x, __VA_ARGS__)
#define HERM_PP_F20(x, a, ...) , x.a HERM_PP_F19(x, __VA_ARGS__)
#define HERM_PP_F21(x, a, ...) , x.a HERM_PP_F20(x, __VA_ARGS__)
#define HERM_PP_F22(x, a, ...) , x.a HERM_PP_F21(x, __VA_ARGS__)
#define HERM_PP_F23(x, a, ...) , x.a HERM_PP_F22(x, __VA_ARGS__)
#define HERM_PP_F24(x, a, ...) , x.a HERM_PP_F23(x, __VA_ARGS__)

/// Makes a plain struct a HERM message type in one line, in the struct's
/// namespace: its `inspect` overload (the fields in the order given) and
/// the names of its fields, which herm::add_message_types turns into the
/// type's description (so that hermctl prints and parses it by field
/// name). Up to 24 fields.
///
///   struct calc_request { int32_t a = 0; int32_t b = 0; std::string op; };
///   HERM_MESSAGE(calc_request, a, b, op)
#define HERM_MESSAGE(type, ...)                                               \
  template <class Inspector>                                                  \
  typename Inspector::result_type inspect(Inspector& f, type& x) {            \
    return f(caf::meta::type_name(#type) HERM_PP_CAT(                         \
      HERM_PP_F, HERM_PP_NARG(__VA_ARGS__))(x, __VA_ARGS__));                 \
  }                                                                           \
  [[maybe_unused]] inline const char* herm_field_names(const type*) {         \
    return #__VA_ARGS__;                                                      \
  }
