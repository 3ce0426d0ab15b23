#include "channels/options.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <type_traits>

#include "channels/error.hpp"

namespace herm {

namespace {

/// Marks `key` as read; its text, or nullptr when absent.
const std::string* take(const device_config& cfg, std::set<std::string>& used,
                        const std::string& key) {
  used.insert(key);
  auto i = cfg.options.find(key);
  return i == cfg.options.end() ? nullptr : &i->second;
}

/// "option 'KEY' expects WHAT, got 'TEXT'".
std::string expects(const std::string& key, const std::string& what,
                    const std::string& text) {
  return "option '" + key + "' expects " + what + ", got '" + text + "'";
}

/// The number `parse` (strtoull- or strtod-like) reads from the whole of
/// `text`; nullopt when the text is empty, has anything after the number,
/// is out of the type's range (errno set) or is not finite.
template <class Parse>
auto parse_whole(const std::string& text, Parse parse)
  -> std::optional<decltype(parse(text.c_str(), nullptr))> {
  errno = 0;
  char* end = nullptr;
  auto val = parse(text.c_str(), &end);
  if (text.empty() || errno != 0 || *end != '\0')
    return std::nullopt;
  if constexpr (std::is_floating_point_v<decltype(val)>)
    if (!std::isfinite(val))
      return std::nullopt;
  return val;
}

/// A number option: `fallback` when absent (`found` null), else its text
/// parsed by `parse` when within [min, max], else an error of `reader` that
/// says it expects `kind` in that range (bounds written by `format`).
template <class T, class Parse, class Format>
caf::expected<T> read_number(const option_reader& reader,
                             const std::string* found, const std::string& key,
                             T fallback, T min, T max, Parse parse,
                             const char* kind, Format format) {
  if (found == nullptr)
    return fallback;
  auto val = parse_whole(*found, parse);
  if (val && *val >= min && *val <= max)
    return *val;
  return reader.fail(ec::invalid_parameter,
                     expects(key,
                             std::string{kind} + " in [" + format(min) + ", "
                               + format(max) + "]",
                             *found));
}

} // namespace

option_reader::option_reader(const device_config& cfg) : cfg_(cfg) {
  // Options every kind understands; reading them is optional.
}

bool option_reader::has(const std::string& key) {
  used_.insert(key);
  return cfg_.options.count(key) > 0;
}

std::string option_reader::str(const std::string& key, std::string fallback) {
  auto* text = take(cfg_, used_, key);
  return text == nullptr ? fallback : *text;
}

caf::error option_reader::fail(ec code, const std::string& what) const {
  return make_error(code, "device '" + cfg_.name + "': " + what);
}

caf::expected<uint64_t> option_reader::u64(const std::string& key,
                                           uint64_t fallback, uint64_t min,
                                           uint64_t max) {
  auto parse = [](const char* str, char** end) {
    // strtoull would wrap a negative number around: refuse the sign.
    if (*str == '-') {
      *end = const_cast<char*>(str);
      return 0ull;
    }
    return std::strtoull(str, end, 10);
  };
  auto format = [](uint64_t x) { return std::to_string(x); };
  return read_number(*this, take(cfg_, used_, key), key, fallback, min, max,
                     parse, "an integer", format);
}

caf::expected<double> option_reader::real(const std::string& key,
                                          double fallback, double min,
                                          double max) {
  auto parse = [](const char* str, char** end) {
    return std::strtod(str, end);
  };
  return read_number(*this, take(cfg_, used_, key), key, fallback, min, max,
                     parse, "a number", format_double);
}

caf::expected<bool> option_reader::flag(const std::string& key,
                                        bool fallback) {
  auto* found = take(cfg_, used_, key);
  if (found == nullptr)
    return fallback;
  auto& t = *found;
  if (t == "true" || t == "1" || t == "yes" || t == "on")
    return true;
  if (t == "false" || t == "0" || t == "no" || t == "off")
    return false;
  return fail(ec::invalid_parameter, expects(key, "true or false", t));
}

caf::expected<link_profile>
option_reader::profile(const std::string& default_profile) {
  auto name = str("profile", default_profile);
  auto* base = find_profile(name);
  if (base == nullptr) {
    std::string known;
    for (auto& p : builtin_profiles())
      known += (known.empty() ? "" : ", ") + p.name;
    return fail(ec::invalid_parameter, "option 'profile': unknown profile '"
                                         + name + "' (known: " + known + ")");
  }
  auto result = *base;
  auto bw = u64("bandwidth", result.bandwidth_bps, 1, 100'000'000'000ull);
  if (!bw)
    return bw.error();
  auto mtu = u64("mtu", result.mtu, 1, 65'507);
  if (!mtu)
    return mtu.error();
  auto coef = real("delay_coef", result.delay_coef, 0.001, 1000.0);
  if (!coef)
    return coef.error();
  auto ovh = u64("frame_overhead_bits", result.frame_overhead_bits, 0, 1u << 16);
  if (!ovh)
    return ovh.error();
  result.bandwidth_bps = *bw;
  result.mtu = static_cast<uint32_t>(*mtu);
  result.delay_coef = *coef;
  result.frame_overhead_bits = static_cast<uint32_t>(*ovh);
  return result;
}

caf::error option_reader::finish() const {
  // At most this many unknown options named (a file may hold thousands).
  constexpr size_t max_named = 8;
  std::string unknown;
  size_t count = 0;
  for (auto& kv : cfg_.options)
    if (used_.count(kv.first) == 0 && count++ < max_named)
      unknown += (unknown.empty() ? "'" : ", '") + kv.first + "'";
  if (count == 0)
    return caf::none;
  if (count > max_named)
    unknown += " and " + std::to_string(count - max_named) + " more";
  // Every option the driver reads has been read by now: those it knows.
  std::string known;
  for (auto& k : used_)
    known += (known.empty() ? "" : ", ") + k;
  return fail(ec::invalid_parameter, "unknown option(s) " + unknown
                                       + " for link kind '" + cfg_.kind
                                       + "' (known: " + known + ")");
}

std::string format_double(double x) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.6g", x);
  return buf;
}

} // namespace herm
