#pragma once

// Options of the "serial" link kind (channels/drivers/serial.cpp), resolved
// without touching the device: character framing ("8N1"), flow control,
// standard baud rates and the link profile. Header-only so that tests check
// the defaults (e.g. USB CDC-ACM) without hardware.
//
// Options (all optional):
//   profile    built-in link profile; default "rs232c", or "usb1.1" for
//              paths starting with /dev/ttyACM (USB CDC-ACM)
//   baud       a standard rate, 1200 .. 4000000 bit/s; default: the
//              profile's bandwidth if that is a standard rate, else 115200
//   bandwidth  routing bandwidth in bit/s; default: the baud rate when the
//              baud rate was given or came from the profile, else (USB
//              profiles, whose link is faster than any baud rate) the
//              profile's bandwidth
//   mtu        frame payload in bytes, 1 .. 255; default: the profile's,
//              at most 255
//   delay_coef, frame_overhead_bits   as for every profile
//   framing    DATA PARITY STOP: 8N1 (default), 8E1, 8O1, 8N2, 8E2, 8O2
//   flow       none (default), rtscts, xonxoff
//   exclusive  true (default): the driver holds flock(LOCK_EX) on the
//              line, so no other HERM driver (or flock-aware serial tool)
//              opens it; false: flock(LOCK_SH), shared with other
//              non-exclusive drivers. A line another process holds is
//              refused either way. The lock dies with its holder (also on
//              SIGKILL); see serial.cpp for why TIOCEXCL is not used.

#include <cstdint>
#include <optional>
#include <string>

#include "caf/expected.hpp"

#include "channels/error.hpp"
#include "channels/drivers/serial_framing.hpp"
#include "channels/drivers/params.hpp"
#include "channels/messages.hpp"
#include "channels/options.hpp"

namespace herm::serial {

// -- character framing -------------------------------------------------------------

enum class parity : uint8_t { none, even, odd };

/// How the UART frames each byte on the line.
struct char_format {
  uint8_t data_bits = 8;
  parity par = parity::none;
  uint8_t stop_bits = 1;

  /// Bits on the line per byte: start + data + parity + stop (10 for 8N1).
  unsigned bits_per_char() const {
    return 1u + data_bits + (par == parity::none ? 0u : 1u) + stop_bits;
  }
};

/// Parses "8N1" style text: data bits 5..8, parity N, E or O (either case),
/// stop bits 1 or 2. The driver additionally requires 8 data bits.
inline std::optional<char_format> parse_char_format(const std::string& text) {
  if (text.size() != 3 || text[0] < '5' || text[0] > '8')
    return std::nullopt;
  char_format result;
  result.data_bits = static_cast<uint8_t>(text[0] - '0');
  switch (text[1]) {
    case 'N':
    case 'n':
      result.par = parity::none;
      break;
    case 'E':
    case 'e':
      result.par = parity::even;
      break;
    case 'O':
    case 'o':
      result.par = parity::odd;
      break;
    default:
      return std::nullopt;
  }
  if (text[2] != '1' && text[2] != '2')
    return std::nullopt;
  result.stop_bits = static_cast<uint8_t>(text[2] - '0');
  return result;
}

inline std::string to_string(const char_format& x) {
  std::string result;
  result += static_cast<char>('0' + x.data_bits);
  result += x.par == parity::none ? 'N' : x.par == parity::even ? 'E' : 'O';
  result += static_cast<char>('0' + x.stop_bits);
  return result;
}

// -- flow control ------------------------------------------------------------------

enum class flow_control : uint8_t { none, rtscts, xonxoff };

inline std::optional<flow_control> parse_flow_control(const std::string& x) {
  if (x == "none")
    return flow_control::none;
  if (x == "rtscts")
    return flow_control::rtscts;
  if (x == "xonxoff")
    return flow_control::xonxoff;
  return std::nullopt;
}

inline const char* to_string(flow_control x) {
  switch (x) {
    case flow_control::none: return "none";
    case flow_control::rtscts: return "rtscts";
    case flow_control::xonxoff: return "xonxoff";
  }
  return "none";
}

// -- baud rates --------------------------------------------------------------------

/// The termios rates from 1200 to 4000000 bit/s that Linux defines (Bxxx).
constexpr uint32_t standard_bauds[] = {
  1200,    1800,    2400,    4800,    9600,    19200,   38400,   57600,
  115200,  230400,  460800,  500000,  576000,  921600,  1000000, 1152000,
  1500000, 2000000, 2500000, 3000000, 3500000, 4000000};

constexpr bool is_standard_baud(uint64_t x) {
  for (auto b : standard_bauds)
    if (b == x)
      return true;
  return false;
}

/// Baud rate used when the profile's bandwidth is not a standard rate.
constexpr uint32_t fallback_baud = 115200;

/// Reads option `key` as a standard baud rate; the error names the device,
/// the option and the accepted rates.
inline caf::expected<uint64_t> read_baud(option_reader& opts,
                                         const std::string& key,
                                         uint64_t fallback) {
  auto text = opts.str(key);
  auto val = opts.u64(key, fallback, 0, UINT64_MAX);
  if (val && is_standard_baud(*val))
    return *val;
  std::string rates;
  for (auto b : standard_bauds)
    rates += (rates.empty() ? "" : ", ") + std::to_string(b);
  return opts.fail(ec::invalid_parameter,
                   "option '" + key + "' expects a standard baud rate ("
                     + rates + "), got '" + text + "'");
}

// -- settings ----------------------------------------------------------------------

/// Everything the driver needs to open and run the line.
struct settings {
  /// Device name (device_config::name), for error messages.
  std::string device;
  /// Path of the tty, e.g. /dev/ttyUSB0.
  std::string path;
  link_profile profile;
  uint64_t baud = 0;
  char_format format;
  flow_control flow = flow_control::none;
  bool exclusive = true;
  /// The link's bandwidth is the baud rate and follows set_param("baud").
  bool bandwidth_follows_baud = true;

  /// Escaped framing (see serial_framing.hpp) is needed with XON/XOFF.
  bool escaped() const {
    return flow == flow_control::xonxoff;
  }
};

/// True for paths of USB CDC-ACM devices (/dev/ttyACM0, ...).
inline bool is_cdc_acm_path(const std::string& path) {
  return path.rfind("/dev/ttyACM", 0) == 0;
}

/// Resolves a device_config of kind "serial". Errors: ec::invalid_parameter
/// naming the device and the option; unknown options are refused.
inline caf::expected<settings> read_settings(const device_config& cfg) {
  option_reader opts{cfg};
  settings result;
  result.device = cfg.name;
  result.path = cfg.interface;
  if (result.path.empty())
    return opts.fail(ec::invalid_parameter,
                     "no serial line given (the interface of a serial device "
                     "is a tty path such as /dev/ttyUSB0)");
  if (auto err = read_into(result.profile,
                           opts.profile(is_cdc_acm_path(result.path)
                                          ? "usb1.1"
                                          : "rs232c")))
    return err;
  if (opts.has("mtu")) {
    if (result.profile.mtu > max_mtu)
      return opts.fail(ec::invalid_parameter,
                       "option 'mtu' expects an integer in [1, "
                         + std::to_string(max_mtu) + "], got '"
                         + opts.str("mtu") + "'");
  } else if (result.profile.mtu > max_mtu) {
    result.profile.mtu = max_mtu;
  }
  // The built-in profile's rate, before option "bandwidth" changed it.
  auto* base = find_profile(result.profile.name);
  auto profile_rate = base != nullptr ? base->bandwidth_bps : 0;
  bool explicit_baud = opts.has("baud");
  if (auto err = read_into(result.baud,
                           read_baud(opts, "baud",
                                     is_standard_baud(profile_rate)
                                       ? profile_rate
                                       : fallback_baud)))
    return err;
  if (opts.has("bandwidth"))
    result.bandwidth_follows_baud = false;
  else if (explicit_baud || is_standard_baud(profile_rate))
    result.profile.bandwidth_bps = result.baud;
  else
    result.bandwidth_follows_baud = false;
  auto framing = opts.str("framing", "8N1");
  auto format = parse_char_format(framing);
  if (!format)
    return opts.fail(ec::invalid_parameter,
                     "option 'framing' expects DATA PARITY STOP such as 8N1, "
                     "8E1, 8O1 or 8N2, got '"
                       + framing + "'");
  if (format->data_bits != 8)
    return opts.fail(ec::invalid_parameter,
                     "option 'framing': the serial link carries binary frames "
                     "and needs 8 data bits, got '"
                       + framing + "'");
  result.format = *format;
  auto flow_text = opts.str("flow", "none");
  auto flow = parse_flow_control(flow_text);
  if (!flow)
    return opts.fail(ec::invalid_parameter,
                     "option 'flow' expects none, rtscts or xonxoff, got '"
                       + flow_text + "'");
  result.flow = *flow;
  if (auto err = read_into(result.exclusive, opts.flag("exclusive", true)))
    return err;
  if (auto err = opts.finish())
    return err;
  return result;
}

} // namespace herm::serial
