#pragma once

// A module's configuration file (YAML), as hermd reads it and as users who
// embed HERM can read it too: identity and addressing, channels, APOs to
// load, logging, scheduler and the local control endpoint. The format is
// documented in docs/user-guide.md ("Configuration reference").
//
// Pure: parsing does no I/O but reading the file, opens no device and starts
// no actor. Every error names the file, the line and the field and says what
// was expected: "robot.yaml:12: channels[1].mtu: expected an integer in
// [1, 65535], got 'big'". A config that parses is complete: hermd starts
// everything it names or nothing.

#include <chrono>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "caf/expected.hpp"

#include "actors/module.hpp"

namespace herm {

/// One APO that hermd loads at start: an instance of a registered APO kind
/// (see apo_kinds in apps/hermd), registered under `name` and `type`.
struct apo_config {
  std::string name;
  /// The factory that makes it ("collector", "srf04_batcher", ...).
  std::string kind;
  /// The interface it speaks; defaults to "herm.<kind>".
  std::string type;
  /// Kind-specific options, as text (numbers as written, lists comma-joined).
  std::map<std::string, std::string> options;
  /// Line of the entry in the file, for errors found later (0: unknown).
  int line = 0;
};

/// Everything a config file says.
struct file_config {
  /// Module name for logs and the default control socket ("main").
  std::string name;
  /// Identity, timers, channels (module.devices: one per `channels` entry)
  /// and the application layer's settings.
  module_config module;
  /// Line of each channel entry, parallel to module.devices.
  std::vector<int> device_lines;
  /// Line of each key of each channel entry ("interface", "peers", ...),
  /// parallel to module.devices: where check_channels puts an error.
  std::vector<std::map<std::string, int>> device_key_lines;
  std::vector<apo_config> apos;
  /// trace, debug, info, warn, error or off.
  std::string log_level = "info";
  /// text (human-readable, default) or json (one object per line).
  std::string log_format = "text";
  /// "loop" (default), "sharing" or "stealing"; see herm::configure.
  std::string scheduler = "loop";
  /// Worker threads of "sharing" and "stealing"; 0: one per core (CAF's
  /// default). One by default, see configure() in actors/runtime/system.hpp.
  size_t threads = 1;
  /// The loop scheduler's busy-poll before it sleeps, microseconds; 0: off.
  size_t busy_poll_us = 0;
  /// Path of the local control socket; empty: none.
  std::string control_socket;
  /// The file it came from.
  std::string path;
};

/// Parses `text` as a config file named `path` (for error messages). Every
/// error is ec::invalid_config with the context
/// "PATH:LINE: FIELD: expected WHAT, got 'VALUE'" (LINE 1-based; FIELD a path
/// such as channels[0].mtu, list indexes 0-based), YAML syntax errors as
/// "PATH:LINE: MESSAGE". The first error ends parsing.
caf::expected<file_config> parse_config(const std::string& text,
                                        const std::string& path);

/// Reads and parses the file at `path`. A file that cannot be read (or is
/// larger than 1 MiB) is ec::invalid_config naming it and the reason:
/// "PATH: cannot read: No such file or directory".
caf::expected<file_config> load_config(const std::string& path);

/// Checks every channel's interface and options with its link kind's own
/// check (link_kind::check: the parser the driver's open runs first, which
/// touches no device), so that what a start would refuse is a
/// configuration error instead: ec::invalid_config with the context
/// "PATH:LINE: channels[I].KEY: WHAT" when the driver's message names an
/// option (or the interface), "PATH:LINE: channels[I] 'NAME': WHAT" (the
/// entry's line) otherwise. hermd runs it on --check, at start and on
/// reload; parse_config does not (a program may add its kinds later).
/// O(channels x options).
caf::error check_channels(const file_config& cfg);

/// The default control socket of a module named `name`:
/// /run/herm/NAME.sock for root, else $XDG_RUNTIME_DIR/herm/NAME.sock, else
/// /tmp/herm-UID/NAME.sock.
std::string default_control_socket(const std::string& name);

} // namespace herm
