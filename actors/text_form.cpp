#include "actors/text_form.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <optional>

#include "actors/marshal.hpp"
#include "actors/type_description.hpp"
#include "channels/error.hpp"
#include "channels/hex.hpp"

namespace herm {

namespace {

/// Deepest nesting of types, in descriptions and in values.
constexpr size_t max_depth = 16;

/// Longest type name on the wire.
constexpr size_t max_name = 255;

/// Unsigned LEB128, minimal form.
void put_leb(byte_buffer& out, uint64_t x) {
  while (x >= 0x80) {
    out.push_back(static_cast<uint8_t>((x & 0x7F) | 0x80));
    x >>= 7;
  }
  out.push_back(static_cast<uint8_t>(x));
}

// -- the grammar of types ------------------------------------------------------------

enum class kind {
  boolean, sint, uint, f32, f64, str, u16str, u32str, unit, list, set, map,
  array, tuple, named, error_code,
};

struct node {
  kind k = kind::unit;
  /// Bytes of an integer, or code-unit bytes of a u16/u32 string.
  size_t width = 0;
  /// Elements of an array.
  size_t count = 0;
  /// A named type's name.
  std::string name;
  std::vector<node> kids;
};

node prim(kind k, size_t width = 0) {
  node n;
  n.k = k;
  n.width = width;
  return n;
}

std::optional<node> primitive(const std::string& s) {
  static const std::map<std::string, node> table{
    {"bool", prim(kind::boolean)},     {"float", prim(kind::f32)},
    {"double", prim(kind::f64)},       {"@i8", prim(kind::sint, 1)},
    {"@i16", prim(kind::sint, 2)},     {"@i32", prim(kind::sint, 4)},
    {"@i64", prim(kind::sint, 8)},     {"@u8", prim(kind::uint, 1)},
    {"@u16", prim(kind::uint, 2)},     {"@u32", prim(kind::uint, 4)},
    {"@u64", prim(kind::uint, 8)},     {"@str", prim(kind::str)},
    {"@u16str", prim(kind::u16str, 2)}, {"@u32str", prim(kind::u32str, 4)},
    {"@timestamp", prim(kind::sint, 8)}, {"@timespan", prim(kind::sint, 8)},
    {"@atom", prim(kind::uint, 8)},    {"@unit", prim(kind::unit)},
    {"@error", prim(kind::error_code)},
  };
  if (auto i = table.find(s); i != table.end())
    return i->second;
  if (s == "@strset") {
    node n = prim(kind::set);
    n.kids.push_back(prim(kind::str));
    return n;
  }
  return std::nullopt;
}

/// Recursive-descent parser of one type; errors say what was expected.
class type_parser {
public:
  explicit type_parser(const std::string& s) : s_(s) {
  }

  std::optional<node> parse(std::string& why) {
    auto n = type(0, why);
    if (n && pos_ != s_.size()) {
      why = "unexpected '" + s_.substr(pos_) + "' in type '" + s_ + "'";
      return std::nullopt;
    }
    return n;
  }

private:
  std::optional<node> type(size_t depth, std::string& why) {
    if (depth >= max_depth) {
      why = "type '" + s_ + "' nests deeper than 16 levels";
      return std::nullopt;
    }
    auto start = pos_;
    while (pos_ < s_.size() && s_[pos_] != '<' && s_[pos_] != ','
           && s_[pos_] != '>')
      ++pos_;
    auto word = s_.substr(start, pos_ - start);
    if (word.empty()) {
      why = "a type is missing in '" + s_ + "'";
      return std::nullopt;
    }
    if (pos_ < s_.size() && s_[pos_] == '<') {
      ++pos_;
      node n;
      size_t want = 0; // 0: any number (tuple)
      if (word == "list" || word == "std::vector") {
        n.k = kind::list;
        want = 1;
      } else if (word == "set") {
        n.k = kind::set;
        want = 1;
      } else if (word == "map") {
        n.k = kind::map;
        want = 2;
      } else if (word == "array") {
        n.k = kind::array;
        want = 1;
      } else if (word == "tuple") {
        n.k = kind::tuple;
      } else {
        why = "unknown type constructor '" + word + "<' in '" + s_ + "'";
        return std::nullopt;
      }
      for (;;) {
        auto kid = type(depth + 1, why);
        if (!kid)
          return std::nullopt;
        n.kids.push_back(std::move(*kid));
        if (n.k == kind::array && n.kids.size() == 1) {
          if (!expect(',', why) || !number(n.count, why))
            return std::nullopt;
        }
        if (pos_ < s_.size() && s_[pos_] == ',' && n.k != kind::array
            && (want == 0 || n.kids.size() < want)) {
          ++pos_;
          continue;
        }
        break;
      }
      if (!expect('>', why))
        return std::nullopt;
      if (want > 0 && n.kids.size() != want) {
        why = "'" + word + "<' takes " + std::to_string(want)
              + " types in '" + s_ + "'";
        return std::nullopt;
      }
      return n;
    }
    if (auto p = primitive(word))
      return p;
    if (word.size() > max_name || word[0] == '@') {
      why = "unknown type '" + word + "'";
      return std::nullopt;
    }
    for (auto c : word)
      if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_'
            || c == '.' || c == ':')) {
        why = "a type name has letters, digits, '_', '.' and ':' only: '"
              + word + "'";
        return std::nullopt;
      }
    node n;
    n.k = kind::named;
    n.name = word;
    return n;
  }

  bool expect(char c, std::string& why) {
    if (pos_ < s_.size() && s_[pos_] == c) {
      ++pos_;
      return true;
    }
    why = std::string{"expected '"} + c + "' in type '" + s_ + "'";
    return false;
  }

  bool number(size_t& out, std::string& why) {
    auto start = pos_;
    out = 0;
    while (pos_ < s_.size() && std::isdigit(static_cast<unsigned char>(s_[pos_]))
           && pos_ - start < 7)
      out = out * 10 + static_cast<size_t>(s_[pos_++] - '0');
    if (pos_ == start || out == 0) {
      why = "an array needs a size from 1 in '" + s_ + "'";
      return false;
    }
    return true;
  }

  const std::string& s_;
  size_t pos_ = 0;
};

std::optional<node> parse_type(const std::string& s, std::string& why) {
  return type_parser{s}.parse(why);
}

// -- decoding ------------------------------------------------------------------------

enum class status { ok, opaque, truncated };

class decoder {
public:
  decoder(const uint8_t* data, size_t size) : p_(data), size_(size) {
  }

  size_t offset() const {
    return off_;
  }

  size_t left() const {
    return size_ - off_;
  }

  bool fixed(size_t n, uint64_t& out) {
    if (left() < n)
      return false;
    out = 0;
    for (size_t i = 0; i < n; ++i)
      out |= uint64_t{p_[off_ + i]} << (8 * i);
    off_ += n;
    return true;
  }

  bool leb(uint64_t& out) {
    out = 0;
    for (size_t i = 0; i < 10; ++i) {
      if (left() == 0)
        return false;
      auto b = p_[off_++];
      out |= uint64_t{b & 0x7Fu} << (7 * i);
      if ((b & 0x80) == 0)
        return true;
    }
    return false;
  }

  bool bytes(size_t n, std::string& out) {
    if (left() < n)
      return false;
    out.assign(reinterpret_cast<const char*>(p_ + off_), n);
    off_ += n;
    return true;
  }

  /// Everything left as {"@type": name, "@bytes": hex}.
  ordered_json opaque(const std::string& name) {
    ordered_json j;
    j["@type"] = name;
    j["@bytes"] = to_hex_bytes(p_ + off_, left());
    off_ = size_;
    return j;
  }

  status value(const node& n, size_t depth, ordered_json& out,
               std::vector<std::string>& undescribed) {
    if (depth >= max_depth)
      return status::truncated;
    uint64_t x = 0;
    switch (n.k) {
      case kind::boolean:
        if (!fixed(1, x))
          return status::truncated;
        out = x != 0;
        return status::ok;
      case kind::uint:
        if (!fixed(n.width, x))
          return status::truncated;
        out = x;
        return status::ok;
      case kind::sint: {
        if (!fixed(n.width, x))
          return status::truncated;
        auto bits = 8 * n.width;
        int64_t v = bits == 64 ? static_cast<int64_t>(x)
                               : static_cast<int64_t>(x << (64 - bits))
                                   >> (64 - bits);
        out = v;
        return status::ok;
      }
      case kind::f32: {
        if (!fixed(4, x))
          return status::truncated;
        auto bits = static_cast<uint32_t>(x);
        float f;
        std::memcpy(&f, &bits, 4);
        out = number_json(f);
        return status::ok;
      }
      case kind::f64: {
        if (!fixed(8, x))
          return status::truncated;
        double d;
        std::memcpy(&d, &x, 8);
        out = number_json(d);
        return status::ok;
      }
      case kind::str: {
        std::string s;
        if (!leb(x) || x > left() || !bytes(x, s))
          return status::truncated;
        out = std::move(s);
        return status::ok;
      }
      case kind::u16str:
      case kind::u32str: {
        if (!leb(x) || x > left() || x % n.width != 0)
          return status::truncated;
        out = ordered_json::array();
        for (uint64_t i = 0; i < x / n.width; ++i) {
          uint64_t unit = 0;
          fixed(n.width, unit);
          out.push_back(unit);
        }
        return status::ok;
      }
      case kind::unit:
        out = nullptr;
        return status::ok;
      case kind::error_code: {
        uint64_t code = 0, category = 0;
        if (!fixed(1, code) || !fixed(8, category))
          return status::truncated;
        out = ordered_json::object();
        out["code"] = code;
        out["category"] = category;
        return status::ok;
      }
      case kind::list:
      case kind::set:
      case kind::map: {
        if (!leb(x) || x > left())
          return status::truncated;
        auto string_keys = n.k == kind::map && n.kids[0].k == kind::str;
        out = string_keys ? ordered_json::object() : ordered_json::array();
        for (uint64_t i = 0; i < x; ++i) {
          ordered_json k, v;
          auto s = value(n.kids[0], depth + 1, k, undescribed);
          if (s == status::ok && n.k == kind::map)
            s = value(n.kids[1], depth + 1, v, undescribed);
          if (string_keys) {
            if (k.is_string())
              out[k.get<std::string>()] = std::move(v);
          } else if (n.k == kind::map)
            out.push_back(ordered_json::array({std::move(k), std::move(v)}));
          else
            out.push_back(std::move(k));
          if (s != status::ok)
            return s;
        }
        return status::ok;
      }
      case kind::array:
      case kind::tuple: {
        out = ordered_json::array();
        auto count = n.k == kind::array ? n.count : n.kids.size();
        for (size_t i = 0; i < count; ++i) {
          ordered_json v;
          auto s = value(n.kids[n.k == kind::array ? 0 : i], depth + 1, v,
                         undescribed);
          out.push_back(std::move(v));
          if (s != status::ok)
            return s;
        }
        return status::ok;
      }
      case kind::named:
        return named(n.name, depth, out, undescribed);
    }
    return status::truncated;
  }

  status named(const std::string& name, size_t depth, ordered_json& out,
               std::vector<std::string>& undescribed) {
    if (auto p = primitive(name))
      return value(*p, depth, out, undescribed);
    std::string why;
    if (name.rfind("std::vector<", 0) == 0)
      if (auto n = parse_type(name, why))
        return value(*n, depth, out, undescribed);
    auto d = find_description(name);
    if (!d) {
      undescribed.push_back(name);
      out = opaque(name);
      return status::opaque;
    }
    out = ordered_json::object();
    for (auto& f : d->fields) {
      auto n = parse_type(f.type, why);
      if (!n) {
        undescribed.push_back(name);
        out[f.name] = opaque(name);
        return status::opaque;
      }
      ordered_json v;
      auto s = value(*n, depth + 1, v, undescribed);
      out[f.name] = std::move(v);
      if (s != status::ok)
        return s;
    }
    return status::ok;
  }

private:
  template <class F>
  static ordered_json number_json(F f) {
    if (std::isnan(f))
      return "nan";
    if (std::isinf(f))
      return f > 0 ? "inf" : "-inf";
    return static_cast<double>(f);
  }

  const uint8_t* p_;
  size_t size_;
  size_t off_ = 0;
};

// -- encoding ------------------------------------------------------------------------

class encoder {
public:
  explicit encoder(byte_buffer& out) : out_(out) {
  }

  /// "" on success, else why not.
  std::string value(const node& n, const ordered_json& v,
                    const std::string& where, size_t depth) {
    if (depth >= max_depth)
      return where + "nests deeper than 16 levels";
    switch (n.k) {
      case kind::boolean:
        if (!v.is_boolean())
          return where + "expected true or false, got " + v.dump();
        out_.push_back(v.get<bool>() ? 1 : 0);
        return {};
      case kind::uint: {
        auto bits = 8 * n.width;
        uint64_t max = bits == 64 ? ~uint64_t{0} : (uint64_t{1} << bits) - 1;
        if (!v.is_number_integer() || (v.is_number_integer() && !v.is_number_unsigned() && v.get<int64_t>() < 0)
            || v.get<uint64_t>() > max)
          return where + v.dump() + " does not fit an unsigned " +
                 std::to_string(bits) + "-bit integer";
        fixed(v.get<uint64_t>(), n.width);
        return {};
      }
      case kind::sint: {
        auto bits = 8 * n.width;
        if (!v.is_number_integer()
            || (v.is_number_unsigned()
                && v.get<uint64_t>() > uint64_t{std::numeric_limits<int64_t>::max()}))
          return where + v.dump() + " does not fit a signed "
                 + std::to_string(bits) + "-bit integer";
        auto x = v.get<int64_t>();
        if (bits < 64) {
          auto lim = int64_t{1} << (bits - 1);
          if (x < -lim || x >= lim)
            return where + v.dump() + " does not fit a signed "
                   + std::to_string(bits) + "-bit integer";
        }
        fixed(static_cast<uint64_t>(x), n.width);
        return {};
      }
      case kind::f32:
      case kind::f64: {
        double d = 0;
        if (v.is_number()) {
          d = v.get<double>();
        } else if (v.is_string() && v == "nan") {
          d = std::numeric_limits<double>::quiet_NaN();
        } else if (v.is_string() && (v == "inf" || v == "-inf")) {
          d = v == "inf" ? std::numeric_limits<double>::infinity()
                         : -std::numeric_limits<double>::infinity();
        } else {
          return where + "expected a number (or \"nan\", \"inf\", \"-inf\"), got "
                 + v.dump();
        }
        if (n.k == kind::f32) {
          auto f = static_cast<float>(d);
          uint32_t bits;
          std::memcpy(&bits, &f, 4);
          fixed(bits, 4);
        } else {
          uint64_t bits;
          std::memcpy(&bits, &d, 8);
          fixed(bits, 8);
        }
        return {};
      }
      case kind::str: {
        if (!v.is_string())
          return where + "expected a string, got " + v.dump();
        auto& s = v.get_ref<const std::string&>();
        put_leb(out_, s.size());
        out_.insert(out_.end(), s.begin(), s.end());
        return {};
      }
      case kind::u16str:
      case kind::u32str: {
        if (!v.is_array())
          return where + "expected an array of code units, got " + v.dump();
        put_leb(out_, v.size() * n.width);
        node unit = prim(kind::uint, n.width);
        for (auto& c : v)
          if (auto why = value(unit, c, where, depth + 1); !why.empty())
            return why;
        return {};
      }
      case kind::unit:
        if (!v.is_null())
          return where + "expected null, got " + v.dump();
        return {};
      case kind::error_code: {
        if (!v.is_object() || !v.contains("code") || !v.contains("category"))
          return where + "expected {\"code\": N, \"category\": N}";
        if (auto why = value(prim(kind::uint, 1), v["code"], where, depth + 1);
            !why.empty())
          return why;
        return value(prim(kind::uint, 8), v["category"], where, depth + 1);
      }
      case kind::list:
        if (!v.is_array())
          return where + "expected an array, got " + v.dump();
        put_leb(out_, v.size());
        for (size_t i = 0; i < v.size(); ++i)
          if (auto why = value(n.kids[0], v[i], where + "[" + std::to_string(i) + "] ", depth + 1);
              !why.empty())
            return why;
        return {};
      case kind::set:
      case kind::map:
        return sorted(n, v, where, depth);
      case kind::array:
      case kind::tuple: {
        auto count = n.k == kind::array ? n.count : n.kids.size();
        if (!v.is_array() || v.size() != count)
          return where + "expected an array of " + std::to_string(count)
                 + " values, got " + v.dump();
        for (size_t i = 0; i < count; ++i)
          if (auto why = value(n.kids[n.k == kind::array ? 0 : i], v[i],
                               where + "[" + std::to_string(i) + "] ", depth + 1);
              !why.empty())
            return why;
        return {};
      }
      case kind::named:
        return named(n.name, v, where, depth);
    }
    return where + "cannot be written";
  }

  std::string named(const std::string& name, const ordered_json& v,
                    const std::string& where, size_t depth) {
    std::string why;
    if (auto p = primitive(name))
      return value(*p, v, where, depth);
    if (name.rfind("std::vector<", 0) == 0) {
      auto n = parse_type(name, why);
      return n ? value(*n, v, where, depth) : where + why;
    }
    auto d = find_description(name);
    if (!d)
      return where + "type '" + name + "' has no description here";
    if (!v.is_object())
      return where + "expected an object with the fields of '" + name
             + "', got " + v.dump();
    for (auto& item : v.items()) {
      const auto& key = item.key();
      auto known = std::any_of(d->fields.begin(), d->fields.end(),
                               [&](auto& f) { return f.name == key; });
      if (!known)
        return where + "'" + name + "' has no field '" + key + "'";
    }
    for (auto& f : d->fields) {
      auto i = v.find(f.name);
      if (i == v.end())
        return where + "field '" + f.name + "' of '" + name + "' is missing";
      auto n = parse_type(f.type, why);
      if (!n)
        return where + why;
      if (auto err = value(*n, *i, where + "field '" + f.name + "': ", depth + 1);
          !err.empty())
        return err;
    }
    return {};
  }

private:
  /// Sets and maps: keys must be integers or strings (their C++ order is
  /// then known), written in ascending order, without duplicates.
  std::string sorted(const node& n, const ordered_json& v,
                     const std::string& where, size_t depth) {
    auto& key = n.kids[0];
    if (key.k != kind::sint && key.k != kind::uint && key.k != kind::str
        && key.k != kind::boolean)
      return where + "sets and maps with keys of this type cannot be written "
                     "from text";
    std::vector<std::pair<ordered_json, const ordered_json*>> items;
    if (n.k == kind::map && v.is_object() && key.k == kind::str) {
      for (auto& [k, x] : v.items())
        items.emplace_back(ordered_json(k), &x);
    } else if (v.is_array()) {
      for (auto& x : v) {
        if (n.k == kind::map) {
          if (!x.is_array() || x.size() != 2)
            return where + "a map entry is [key, value], got " + x.dump();
          items.emplace_back(x[0], &x[1]);
        } else {
          items.emplace_back(x, nullptr);
        }
      }
    } else {
      return where + "expected an array, got " + v.dump();
    }
    for (auto& it : items) {
      auto ok = key.k == kind::str       ? it.first.is_string()
                : key.k == kind::boolean ? it.first.is_boolean()
                                         : it.first.is_number_integer();
      if (!ok)
        return where + "key " + it.first.dump() + " does not fit the key type";
    }
    auto less = [&](const auto& a, const auto& b) {
      if (key.k == kind::str)
        return a.first.template get_ref<const std::string&>()
               < b.first.template get_ref<const std::string&>();
      if (key.k == kind::boolean)
        return a.first.template get<bool>() < b.first.template get<bool>();
      if (key.k == kind::uint)
        return a.first.template get<uint64_t>() < b.first.template get<uint64_t>();
      return a.first.template get<int64_t>() < b.first.template get<int64_t>();
    };
    std::stable_sort(items.begin(), items.end(), less);
    put_leb(out_, items.size());
    for (size_t i = 0; i < items.size(); ++i) {
      if (i > 0 && !less(items[i - 1], items[i]))
        return where + "key " + items[i].first.dump() + " appears twice";
      if (auto why = value(key, items[i].first, where, depth + 1); !why.empty())
        return why;
      if (n.k == kind::map)
        if (auto why = value(n.kids[1], *items[i].second,
                             where + "[" + items[i].first.dump() + "] ",
                             depth + 1);
            !why.empty())
          return why;
    }
    return {};
  }

  void fixed(uint64_t x, size_t n) {
    for (size_t i = 0; i < n; ++i)
      out_.push_back(static_cast<uint8_t>(x >> (8 * i)));
  }

  byte_buffer& out_;
};

} // namespace

std::string check_field_type(const std::string& type) {
  std::string why;
  if (!parse_type(type, why))
    return why;
  return {};
}

caf::expected<text_value> payload_to_text_impl(const uint8_t* data,
                                               size_t size);

caf::expected<text_value> payload_to_text(const uint8_t* data, size_t size) {
  try {
    return payload_to_text_impl(data, size);
  } catch (const std::exception& e) {
    // nlohmann refuses a shape we failed to foresee: an error, not a crash.
    return make_error(ec::invalid_parameter, e.what());
  }
}

caf::expected<text_value> payload_to_text_impl(const uint8_t* data,
                                               size_t size) {
  auto bad = [](std::string why) {
    return make_error(ec::invalid_parameter, std::move(why));
  };
  decoder d{data, size};
  uint64_t version = 0, count = 0;
  if (!d.fixed(1, version) || version != apo_format_version)
    return bad("not an APO payload of version 1");
  if (!d.leb(count) || count > d.left())
    return bad("truncated element count");
  text_value out;
  std::vector<ordered_json> values;
  for (uint64_t i = 0; i < count; ++i) {
    uint64_t len = 0;
    std::string name;
    if (!d.leb(len) || len == 0 || len > max_name || !d.bytes(len, name))
      return bad("element " + std::to_string(i) + ": truncated type name");
    out.types.push_back(name);
    ordered_json v;
    auto s = d.named(name, 0, v, out.undescribed);
    values.push_back(std::move(v));
    if (s == status::truncated)
      return bad("element " + std::to_string(i) + " (" + name
                 + "): truncated or nested too deeply at offset "
                 + std::to_string(d.offset()));
    if (s == status::opaque)
      break;
  }
  if (d.left() > 0)
    return bad(std::to_string(d.left()) + " trailing bytes after the last "
               "element");
  if (count == 1)
    out.value = std::move(values[0]);
  else if (count > 1)
    out.value = ordered_json(values);
  return out;
}

caf::expected<byte_buffer>
text_to_payload_impl(const ordered_json& value,
                     const std::vector<std::string>& types);

caf::expected<byte_buffer> text_to_payload(const ordered_json& value,
                                           const std::vector<std::string>& types) {
  try {
    return text_to_payload_impl(value, types);
  } catch (const std::exception& e) {
    return make_error(ec::invalid_parameter, e.what());
  }
}

caf::expected<byte_buffer>
text_to_payload_impl(const ordered_json& value,
                     const std::vector<std::string>& types) {
  auto bad = [](std::string why) {
    return make_error(ec::invalid_parameter, std::move(why));
  };
  if (types.empty())
    return bad("no type given");
  if (types.size() > 1 && (!value.is_array() || value.size() != types.size()))
    return bad(std::to_string(types.size())
               + " types need an array of as many values");
  byte_buffer out;
  out.push_back(apo_format_version);
  put_leb(out, types.size());
  encoder e{out};
  for (size_t i = 0; i < types.size(); ++i) {
    auto& name = types[i];
    if (name.empty() || name.size() > max_name)
      return bad("a type name has 1 to 255 bytes");
    std::string why;
    if (!parse_type(name, why))
      return bad(why);
    if (name.find('<') != std::string::npos
        && name.rfind("std::vector<", 0) != 0)
      return bad("'" + name + "' is a field type; a value's type is the "
                 "name of a registered type (@i32, @str, a described struct)");
    put_leb(out, name.size());
    out.insert(out.end(), name.begin(), name.end());
    auto& v = types.size() > 1 ? value[i] : value;
    auto where = types.size() > 1 ? "value " + std::to_string(i) + ": "
                                  : std::string{};
    if (auto err = e.named(name, v, where, 0); !err.empty())
      return bad(err);
  }
  return out;
}

std::string default_type(const ordered_json& value) {
  if (value.is_string())
    return "@str";
  if (value.is_boolean())
    return "bool";
  if (value.is_number_integer())
    return "@i64";
  if (value.is_number())
    return "double";
  return {};
}

std::string to_hex_bytes(const uint8_t* data, size_t size) {
  static constexpr char digits[] = "0123456789abcdef";
  std::string out;
  out.reserve(2 * size);
  for (size_t i = 0; i < size; ++i) {
    out += digits[data[i] >> 4];
    out += digits[data[i] & 0x0F];
  }
  return out;
}

caf::expected<byte_buffer> from_hex_bytes(const std::string& hex) {
  if (hex.size() % 2 != 0)
    return make_error(ec::invalid_parameter, "odd number of hex digits");
  byte_buffer out;
  out.reserve(hex.size() / 2);
  for (size_t i = 0; i < hex.size(); i += 2) {
    auto hi = hex_digit(hex[i]), lo = hex_digit(hex[i + 1]);
    if (hi < 0 || lo < 0)
      return make_error(ec::invalid_parameter,
                        "not a hex digit at offset " + std::to_string(i));
    out.push_back(static_cast<uint8_t>(hi << 4 | lo));
  }
  return out;
}

std::string first_type_name(const uint8_t* data, size_t size) {
  decoder d{data, size};
  uint64_t version = 0, count = 0, len = 0;
  std::string name;
  if (!d.fixed(1, version) || !d.leb(count) || count == 0 || !d.leb(len)
      || len == 0 || len > max_name || !d.bytes(len, name))
    return {};
  return name;
}

} // namespace herm
