#pragma once

// Finding the modules that run on this machine: their control sockets in
// the runtime directory (docs/user-guide.md, "Which socket" and
// "modules"). hermctl uses it when no -s, --name or $HERM_CONTROL says
// which module to talk to, and for `hermctl modules`.
//
// The runtime directory is $HERM_RUNTIME_DIR when set and not empty, else
// the directory of herm::default_control_socket (/run/herm for root, else
// $XDG_RUNTIME_DIR/herm, else /tmp/herm-UID): where hermd puts NAME.sock
// when its configuration has no control.socket.
//
// scan_runtime_dir and list_modules touch the file system and sockets;
// choose_module and the message functions are pure.

#include <chrono>
#include <cstddef>
#include <iosfwd>
#include <string>
#include <vector>

namespace hermctl {

/// Most sockets looked at in one directory; the rest are ignored (a
/// runtime directory holds one socket per module).
constexpr size_t max_local_sockets = 256;

/// A control socket found in the runtime directory.
struct local_socket {
  /// The file name without ".sock": the module name hermd derived it from.
  std::string name;
  /// The socket's full path.
  std::string path;
  /// Whether a connection to it succeeded when scanned (a socket file left
  /// by a module that died is not live).
  bool live = false;

  friend bool operator==(const local_socket& a, const local_socket& b) {
    return a.name == b.name && a.path == b.path && a.live == b.live;
  }
};

/// The directory scanned for control sockets (see above).
std::string runtime_dir();

/// The socket of module `name` in the runtime directory: `DIR/NAME.sock`
/// (for an unset $HERM_RUNTIME_DIR, herm::default_control_socket(name)).
std::string socket_of(const std::string& name);

/// True if something accepts connections at `path` (a non-blocking
/// connect succeeds, or the listener's backlog is full).
bool is_live(const std::string& path);

/// The sockets `NAME.sock` in `dir` (other files, directories and names
/// not ending in ".sock" are skipped), sorted by name, at most
/// max_local_sockets, each probed with is_live. A missing or unreadable
/// directory gives none.
std::vector<local_socket> scan_runtime_dir(const std::string& dir);

/// What to talk to when nothing named a socket.
struct module_choice {
  enum kind_t {
    /// Nothing live: fall back to socket_of("hermd") and its usual error.
    none,
    /// `chosen` is the one live module, or the live one named "hermd".
    use,
    /// Several live modules, none named "hermd": the user must name one.
    ambiguous,
  };
  kind_t kind = none;
  local_socket chosen;
};

/// Picks from `sockets` (as scan_runtime_dir gives them; dead ones are
/// ignored): the only live one; else the live one named `preferred`; else
/// ambiguous (two or more) or none. O(n).
module_choice choose_module(const std::vector<local_socket>& sockets,
                            const std::string& preferred = "hermd");

/// The line hermctl prints on stderr when it picked `s` itself:
/// "hermctl: using module 'sensor' (/run/user/0/herm/sensor.sock)".
std::string using_line(const local_socket& s);

/// The error for several live modules: "N modules run here (a, b, c; in
/// DIR): choose one with --name NAME or -s PATH (hermctl modules lists
/// them)". Names past the first 8 are counted, not listed.
std::string ambiguous_message(const std::vector<local_socket>& sockets,
                              const std::string& dir);

/// A live module as `hermctl modules` lists it.
struct module_row {
  /// The name the module gives in its "info" reply; its socket's name
  /// when it did not answer.
  std::string name;
  /// "0x30", or "-" when it did not answer.
  std::string module;
  std::string socket;
  /// Empty, or why "info" failed (one line).
  std::string error;
};

/// Asks each live socket for "info" (each waiting at most `timeout`) and
/// returns one row per live socket, in the order given. Dead sockets are
/// left out.
std::vector<module_row> list_modules(const std::vector<local_socket>& sockets,
                                     std::chrono::milliseconds timeout);

/// `hermctl modules`: a table NAME, MODULE, SOCKET (and a line per module
/// that did not answer), or "no modules running (no live control socket in
/// DIR)" when `rows` is empty; with `json_out`, a list of {"name",
/// "module", "socket", "error"} objects ("module" null when unknown).
void show_modules(std::ostream& out, const std::vector<module_row>& rows,
                  const std::string& dir, bool json_out);

} // namespace hermctl
