#pragma once

#include <cstdint>
#include <set>
#include <string>

#include "caf/error.hpp"
#include "caf/expected.hpp"

#include "channels/link_profile.hpp"
#include "channels/error.hpp"
#include "channels/messages.hpp"

namespace herm {

/// Reads a device's options with errors that name the device, the option and
/// what was expected: "device 'fw0': option 'loss' expects a number in
/// [0, 1], got 'lots'". Remembers which keys were read so that `finish` can
/// refuse unknown (misspelled) options.
class option_reader {
public:
  explicit option_reader(const device_config& cfg);

  /// The option's text, or `fallback` when absent.
  std::string str(const std::string& key, std::string fallback = "");

  /// True when the option is present.
  bool has(const std::string& key);

  caf::expected<uint64_t> u64(const std::string& key, uint64_t fallback,
                              uint64_t min, uint64_t max);

  caf::expected<double> real(const std::string& key, double fallback,
                             double min, double max);

  caf::expected<bool> flag(const std::string& key, bool fallback);

  /// Resolves the link profile: option "profile" names a built-in profile
  /// (default `default_profile`), "bandwidth", "mtu", "delay_coef" and
  /// "frame_overhead_bits" override its fields.
  caf::expected<link_profile> profile(const std::string& default_profile);

  /// ec::invalid_parameter naming every option that was never read, and
  /// the ones that were (the options the driver knows, when it reads them
  /// all before calling finish, as every built-in kind does).
  caf::error finish() const;

  /// An error of kind `code` prefixed with "device 'NAME': ".
  caf::error fail(ec code, const std::string& what) const;

private:
  const device_config& cfg_;
  std::set<std::string> used_;
};

/// Formats a double without trailing zeros ("0.25", "1").
std::string format_double(double x);

} // namespace herm
