#include "actors/config.hpp"

#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <initializer_list>
#include <sstream>
#include <utility>
#include <vector>

#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include "actors/runtime/error.hpp"
#include "channels/link_driver.hpp"
#include "channels/link_profile.hpp"
#include "routing/auth.hpp"
#include "routing/module_id.hpp"

namespace herm {

namespace {

// -- errors -------------------------------------------------------------------

// The first error ends parsing. Inside this file it travels as an exception
// (yaml-cpp throws its own anyway); parse_config catches both once and turns
// them into a caf::error, so none leaves this file.
struct config_failure {
  std::string text;
};

/// Longest quoted value in an error message; longer ones are cut.
constexpr size_t max_quoted = 60;

/// How a value looks in "got ...": 'text', a list, a map or nothing.
std::string describe(const YAML::Node& x) {
  switch (x.Type()) {
    case YAML::NodeType::Scalar: {
      auto& s = x.Scalar();
      if (s.size() > max_quoted)
        return "'" + s.substr(0, max_quoted) + "...'";
      return "'" + s + "'";
    }
    case YAML::NodeType::Sequence:
      return "a list";
    case YAML::NodeType::Map:
      return "a map";
    default:
      return "nothing";
  }
}

/// 1-based line of a node, or `fallback` for nodes without a position.
int line_of(const YAML::Node& x, int fallback) {
  auto l = x.Mark().line;
  return l >= 0 ? l + 1 : fallback;
}

/// "a, b or c".
std::string one_of(const std::vector<std::string>& xs) {
  std::string out;
  for (size_t i = 0; i < xs.size(); ++i) {
    if (i > 0)
      out += i + 1 == xs.size() ? " or " : ", ";
    out += xs[i];
  }
  return out;
}

std::string link_kind_names() {
  std::vector<std::string> xs;
  for (auto* k : link_kinds())
    xs.emplace_back(k->name);
  return one_of(xs);
}

std::string profile_names() {
  std::vector<std::string> xs;
  for (auto& p : builtin_profiles())
    xs.push_back(p.name);
  return one_of(xs);
}

std::string category_names() {
  std::string out;
  for (int i = 0; i <= static_cast<int>(module_category::other); ++i)
    out += (i == 0 ? "" : ", ")
           + std::string{to_string(static_cast<module_category>(i))};
  return out;
}

// -- fields ---------------------------------------------------------------------

/// One key of a mapping with its value, where it is and its path for errors.
struct field {
  std::string path;
  YAML::Node value;
  /// Line of the key.
  int key_line = 0;

  /// Line to blame for a bad value: the value's own, except for an empty
  /// value, whose position yaml-cpp puts at the next token.
  int line() const {
    return value.IsNull() ? key_line : line_of(value, key_line);
  }
};

class parser {
public:
  explicit parser(const std::string& file) : file_(file) {
    // nop
  }

  [[noreturn]] void fail(int line, const std::string& path,
                         const std::string& what) const {
    auto text = file_ + ":" + std::to_string(line) + ": ";
    if (!path.empty())
      text += path + ": ";
    throw config_failure{text + what};
  }

  [[noreturn]] void expected(const field& f, const std::string& what) const {
    fail(f.line(), f.path, "expected " + what + ", got " + describe(f.value));
  }

  // -- mappings ---------------------------------------------------------------

  /// A mapping's keys in file order. Refuses non-map nodes (a missing or
  /// empty section is an empty map), non-scalar keys, duplicate keys and,
  /// when `known` is not empty, keys outside it.
  std::vector<field> entries(const YAML::Node& node, const std::string& path,
                             int line, const std::string& what,
                             const std::vector<std::string>& known = {}) const {
    std::vector<field> out;
    if (node.IsNull())
      return out;
    if (!node.IsMap())
      fail(line_of(node, line), path,
           "expected " + what + ", got " + describe(node));
    for (auto kv : node) {
      auto key_line = line_of(kv.first, line);
      if (!kv.first.IsScalar())
        fail(key_line, path, "expected a key, got " + describe(kv.first));
      auto& key = kv.first.Scalar();
      auto sub = path.empty() ? key : path + "." + key;
      for (auto& prev : out)
        if (prev.path == sub)
          fail(key_line, sub, "duplicate key (first at line "
                                + std::to_string(prev.key_line) + ")");
      if (!known.empty()) {
        bool ok = false;
        for (auto& k : known)
          ok = ok || k == key;
        if (!ok)
          fail(key_line, sub, "unknown key (expected " + one_of(known) + ")");
      }
      out.push_back(field{sub, kv.second, key_line});
    }
    return out;
  }

  static const field* find(const std::vector<field>& fs,
                           const std::string& path) {
    for (auto& f : fs)
      if (f.path == path)
        return &f;
    return nullptr;
  }

  /// The field at `path`, or a "missing" error at `line` (the mapping's).
  const field& require(const std::vector<field>& fs, const std::string& path,
                       int line, const std::string& what) const {
    if (auto* f = find(fs, path))
      return *f;
    fail(line, path, "missing (required: " + what + ")");
  }

  // -- scalars --------------------------------------------------------------

  /// A scalar's text; empty text only when `allow_empty`.
  std::string text(const field& f, const std::string& what,
                   bool allow_empty = false) const {
    if (!f.value.IsScalar() || (!allow_empty && f.value.Scalar().empty()))
      expected(f, what);
    return f.value.Scalar();
  }

  /// A decimal integer in [min, max].
  uint64_t integer(const field& f, uint64_t min, uint64_t max) const {
    auto what = "an integer in [" + std::to_string(min) + ", "
                + std::to_string(max) + "]";
    if (!f.value.IsScalar())
      expected(f, what);
    auto& s = f.value.Scalar();
    bool digits = !s.empty() && s.size() <= 20;
    for (auto c : s)
      digits = digits && c >= '0' && c <= '9';
    if (!digits)
      expected(f, what);
    errno = 0;
    auto val = std::strtoull(s.c_str(), nullptr, 10);
    if (errno != 0 || val < min || val > max)
      expected(f, what);
    return val;
  }

  /// A finite number in [min, max].
  double number(const field& f, double min, double max) const {
    auto what = "a number in [" + format(min) + ", " + format(max) + "]";
    if (!f.value.IsScalar() || f.value.Scalar().empty())
      expected(f, what);
    auto& s = f.value.Scalar();
    errno = 0;
    char* end = nullptr;
    auto val = std::strtod(s.c_str(), &end);
    if (errno != 0 || *end != '\0' || !std::isfinite(val) || val < min
        || val > max)
      expected(f, what);
    return val;
  }

  std::string choice(const field& f,
                     const std::vector<std::string>& xs) const {
    if (f.value.IsScalar())
      for (auto& x : xs)
        if (f.value.Scalar() == x)
          return x;
    expected(f, one_of(xs));
  }

  std::chrono::milliseconds millis(const field& f, uint64_t min,
                                   uint64_t max) const {
    return std::chrono::milliseconds{
      static_cast<std::chrono::milliseconds::rep>(integer(f, min, max))};
  }

  /// An option's text: a scalar as written, a list of scalars joined with
  /// ",".
  std::string option(const field& f) const {
    static const std::string what = "a scalar or a list of scalars";
    if (f.value.IsScalar())
      return f.value.Scalar();
    if (!f.value.IsSequence())
      expected(f, what);
    std::string out;
    size_t i = 0;
    for (auto x : f.value) {
      field item{f.path + "[" + std::to_string(i) + "]", x, f.line()};
      if (!x.IsScalar())
        expected(item, "a scalar");
      out += (i++ == 0 ? "" : ",") + x.Scalar();
    }
    return out;
  }

  /// Calls `item(node, path, line)` for each entry of the list section `f`
  /// ("channels[0]", ...); null is an empty list, anything else but a list
  /// is refused as not `what`.
  template <class F>
  void each_item(const field& f, const std::string& what, F item) const {
    if (f.value.IsNull())
      return;
    if (!f.value.IsSequence())
      expected(f, what);
    size_t i = 0;
    for (auto node : f.value)
      item(node, f.path + "[" + std::to_string(i++) + "]",
           line_of(node, f.line()));
  }

  // -- sections -------------------------------------------------------------

  void module(const field& f, file_config& cfg) const {
    auto fs = entries(f.value, f.path, f.key_line, "a map",
                      {"name", "id", "hello_interval_ms", "hello_loss",
                       "update_every", "hold_factor", "announce_every",
                       "limits"});
    auto line = f.key_line;
    auto& r = cfg.module.routing;
    cfg.name = module_name(require(fs, "module.name", line, name_rule));
    if (auto* x = find(fs, "module.id"))
      r.id = module_id_of(*x);
    if (auto* x = find(fs, "module.hello_interval_ms"))
      r.hello_interval = millis(*x, 4, 65535);
    if (auto* x = find(fs, "module.hello_loss"))
      r.hello_loss = number(*x, 1, 100);
    if (auto* x = find(fs, "module.update_every"))
      r.update_every = static_cast<uint32_t>(integer(*x, 1, 1000));
    if (auto* x = find(fs, "module.hold_factor"))
      r.hold_factor = number(*x, 1, 1000);
    if (auto* x = find(fs, "module.announce_every"))
      r.announce_every = static_cast<uint32_t>(integer(*x, 1, 1000000));
    if (auto* x = find(fs, "module.limits"))
      limits(*x, r);
  }

  /// module.limits: bounds on routing state (routing_config, route_limits).
  void limits(const field& f, routing_config& r) const {
    auto fs = entries(f.value, f.path, f.key_line, "a map",
                      {"destinations", "destinations_per_neighbour", "routes",
                       "neighbours", "neighbours_per_channel", "floods"});
    auto get = [&](const char* key, uint64_t max, size_t& out) {
      if (auto* x = find(fs, f.path + "." + key))
        out = static_cast<size_t>(integer(*x, 1, max));
    };
    get("destinations", 65534, r.limits.destinations);
    get("destinations_per_neighbour", 65534, r.limits.per_neighbour);
    get("routes", 1048576, r.limits.routes);
    get("neighbours", 65536, r.max_neighbours);
    get("neighbours_per_channel", 65536, r.max_neighbours_per_channel);
    get("floods", 1048576, r.max_floods);
  }

  static constexpr const char* name_rule
    = "a name of 1 to 64 characters from [A-Za-z0-9_.-]";

  std::string module_name(const field& f) const {
    if (!f.value.IsScalar())
      expected(f, name_rule);
    auto& s = f.value.Scalar();
    bool ok = !s.empty() && s.size() <= 64;
    for (auto c : s)
      ok = ok
           && ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z')
               || (c >= '0' && c <= '9') || c == '_' || c == '.' || c == '-');
    if (!ok)
      expected(f, name_rule);
    return s;
  }

  module_id module_id_of(const field& f) const {
    if (f.value.IsScalar()) {
      auto& s = f.value.Scalar();
      if (s == "dynamic")
        return no_module;
      if (auto cat = parse_module_category(s))
        return static_pool(*cat).first;
      if (auto id = parse_module_id(s); id && is_unicast(*id))
        return *id;
    }
    expected(f, "a module id (0x0001..0xFFFE), \"dynamic\" or a category ("
                  + category_names() + ")");
  }

  void log(const field& f, file_config& cfg) const {
    auto fs = entries(f.value, f.path, f.key_line, "a map",
                      {"level", "format"});
    if (auto* x = find(fs, "log.level"))
      cfg.log_level
        = choice(*x, {"trace", "debug", "info", "warn", "error", "off"});
    if (auto* x = find(fs, "log.format"))
      cfg.log_format = choice(*x, {"text", "json"});
  }

  void scheduler(const field& f, file_config& cfg) const {
    auto fs = entries(f.value, f.path, f.key_line, "a map",
                      {"policy", "threads", "busy_poll_us"});
    if (auto* x = find(fs, "scheduler.policy"))
      cfg.scheduler = choice(*x, {"loop", "sharing", "stealing"});
    if (auto* x = find(fs, "scheduler.threads"))
      cfg.threads = static_cast<size_t>(integer(*x, 0, 256));
    if (auto* x = find(fs, "scheduler.busy_poll_us"))
      cfg.busy_poll_us = static_cast<size_t>(integer(*x, 0, 100000));
  }

  /// Pre-shared key authentication of the network (routing/auth.hpp). The
  /// key is read here, from a file with strict permissions; it never
  /// appears in errors or logs.
  void auth(const field& f, file_config& cfg) const {
    auto fs = entries(f.value, f.path, f.key_line, "a map",
                      {"key_file", "key_id", "tag_bytes", "data", "challenge"});
    auto& a = cfg.module.routing.auth;
    a = auth_config{};
    auto& kf = require(fs, "auth.key_file", f.key_line,
                       "the path of a key file");
    auto path = text(kf, "the path of a key file");
    if (auto* x = find(fs, "auth.key_id"))
      a.key_id = static_cast<uint8_t>(integer(*x, 0, 255));
    if (auto* x = find(fs, "auth.tag_bytes")) {
      auto n = choice(*x, {"8", "16"});
      a.tag_bytes = static_cast<uint8_t>(n == "8" ? 8 : 16);
    }
    if (auto* x = find(fs, "auth.data"))
      a.data = choice(*x, {"discovery", "all"}) == "all" ? auth_data::all
                                                          : auth_data::discovery;
    if (auto* x = find(fs, "auth.challenge"))
      a.challenge = choice(*x, {"true", "false"}) == "true";
    std::vector<uint8_t> key;
    auto err = read_key(path, key);
    if (!err.empty())
      fail(kf.line(), kf.path, err);
    a.key = std::move(key);
  }

  /// Returns true when the section names a socket (or turns it off).
  bool control(const field& f, file_config& cfg) const {
    auto fs = entries(f.value, f.path, f.key_line, "a map",
                      {"socket", "allow_unsigned_remote"});
    if (auto* u = find(fs, "control.allow_unsigned_remote"))
      cfg.module.apps.allow_unsigned_remote
        = choice(*u, {"true", "false"}) == "true";
    auto* x = find(fs, "control.socket");
    if (x == nullptr)
      return false;
    // sockaddr_un::sun_path holds 108 bytes with the terminating NUL.
    auto path = text(*x, "a socket path of at most 107 bytes or \"off\"");
    if (path.size() > 107)
      expected(*x, "a socket path of at most 107 bytes or \"off\"");
    cfg.control_socket = path == "off" ? std::string{} : path;
    return true;
  }

  void apps(const field& f, file_config& cfg) const {
    auto fs = entries(f.value, f.path, f.key_line, "a map",
                      {"tick_ms", "idle_tick_ms", "request_timeout_ms",
                       "unreachable_grace_ms",
                       "rebind_interval_ms", "watch_refresh_ms",
                       "subscription_lease_ms", "remote_entry_ttl_ms",
                       "max_pending"});
    constexpr uint64_t day = 86'400'000;
    // Each apps.*_ms key: the member it sets and its bounds in milliseconds.
    struct millis_key {
      const char* key;
      std::chrono::milliseconds app_support_config::*member;
      uint64_t min;
      uint64_t max;
    };
    static constexpr millis_key millis_keys[] = {
      {"apps.tick_ms", &app_support_config::tick, 1, 60'000},
      {"apps.idle_tick_ms", &app_support_config::idle_tick, 1, 60'000},
      {"apps.request_timeout_ms", &app_support_config::request_timeout, 1, day},
      {"apps.unreachable_grace_ms", &app_support_config::unreachable_grace, 0,
       day},
      {"apps.rebind_interval_ms", &app_support_config::rebind_interval, 1, day},
      {"apps.watch_refresh_ms", &app_support_config::watch_refresh, 1, day},
      {"apps.subscription_lease_ms", &app_support_config::subscription_lease,
       3, day},
      {"apps.remote_entry_ttl_ms", &app_support_config::remote_entry_ttl, 1,
       day},
    };
    auto& a = cfg.module.apps;
    for (auto& k : millis_keys)
      if (auto* x = find(fs, k.key))
        a.*k.member = millis(*x, k.min, k.max);
    if (auto* x = find(fs, "apps.max_pending"))
      a.max_pending = static_cast<size_t>(integer(*x, 1, 1'000'000));
  }

  void channels(const field& f, file_config& cfg) const {
    each_item(f, "a list of channels", [&](const YAML::Node& node,
                                            const std::string& path, int line) {
      auto fs = entries(node, path, line,
                        "a map with name, kind and interface");
      device_config dev;
      dev.name = text(require(fs, path + ".name", line, "a channel name"),
                      "a channel name");
      for (size_t j = 0; j < cfg.module.devices.size(); ++j)
        if (cfg.module.devices[j].name == dev.name)
          fail(find(fs, path + ".name")->line(), path + ".name",
               "duplicate channel name '" + dev.name + "' (first at line "
                 + std::to_string(cfg.device_lines[j]) + ")");
      auto& kind = require(fs, path + ".kind", line,
                           "a link kind: " + link_kind_names());
      if (!kind.value.IsScalar() || find_link_kind(kind.value.Scalar()) == nullptr)
        expected(kind, "a link kind (" + link_kind_names() + ")");
      dev.kind = kind.value.Scalar();
      dev.interface = text(require(fs, path + ".interface", line,
                                   "the interface, e.g. 127.0.0.1:47000"),
                           "an interface");
      auto prefix = path.size() + 1;
      for (auto& x : fs) {
        auto key = x.path.substr(prefix);
        if (key == "name" || key == "kind" || key == "interface")
          continue;
        if (key == "profile") {
          if (!x.value.IsScalar() || find_profile(x.value.Scalar()) == nullptr)
            expected(x, "a built-in profile (" + profile_names() + ")");
        } else if (key == "bandwidth") {
          integer(x, 1, 100'000'000'000ull);
        } else if (key == "mtu") {
          integer(x, 1, 65535);
        } else if (key == "delay_coef") {
          number(x, 0.001, 1000);
        }
        dev.options[key] = option(x);
      }
      std::map<std::string, int> key_lines;
      for (auto& x : fs)
        key_lines[x.path.substr(prefix)] = x.line();
      cfg.module.devices.push_back(std::move(dev));
      cfg.device_key_lines.push_back(std::move(key_lines));
      cfg.device_lines.push_back(line);
    });
  }

  void apos(const field& f, file_config& cfg) const {
    each_item(f, "a list of APOs", [&](const YAML::Node& node,
                                       const std::string& path, int line) {
      auto fs = entries(node, path, line, "a map with name and kind",
                        {"name", "kind", "type", "options"});
      apo_config apo;
      apo.line = line;
      auto& name = require(fs, path + ".name", line, "an APO name");
      apo.name = text(name, "a name of 1 to 255 bytes");
      if (apo.name.size() > 255)
        expected(name, "a name of 1 to 255 bytes");
      for (auto& prev : cfg.apos)
        if (prev.name == apo.name)
          fail(name.line(), name.path, "duplicate APO name '" + apo.name
                                         + "' (first at line "
                                         + std::to_string(prev.line) + ")");
      apo.kind = text(require(fs, path + ".kind", line, "an APO kind"),
                      "an APO kind");
      apo.type = "herm." + apo.kind;
      if (auto* x = find(fs, path + ".type"))
        apo.type = text(*x, "an interface type name");
      if (auto* x = find(fs, path + ".options")) {
        auto prefix = x->path.size() + 1;
        for (auto& opt : entries(x->value, x->path, x->line(),
                                 "a map of options"))
          apo.options[opt.path.substr(prefix)] = option(opt);
      }
      cfg.apos.push_back(std::move(apo));
    });
  }

  file_config document(const YAML::Node& root) const {
    file_config cfg;
    cfg.path = file_;
    auto fs = entries(root, "", 1, "a map of sections",
                      {"module", "log", "scheduler", "control", "apps",
                       "channels", "apos", "auth"});
    // The module first: the control socket's default needs its name.
    module(require(fs, "module", 1, "the module's name and id"), cfg);
    bool has_socket = false;
    for (auto& f : fs) {
      if (f.path == "log")
        log(f, cfg);
      else if (f.path == "scheduler")
        scheduler(f, cfg);
      else if (f.path == "control")
        has_socket = control(f, cfg);
      else if (f.path == "apps")
        apps(f, cfg);
      else if (f.path == "channels")
        channels(f, cfg);
      else if (f.path == "apos")
        apos(f, cfg);
      else if (f.path == "auth")
        auth(f, cfg);
    }
    if (!has_socket)
      cfg.control_socket = default_control_socket(cfg.name);
    // A keyed module takes remote control only signed: no way around it.
    if (cfg.module.apps.allow_unsigned_remote && cfg.module.routing.auth.enabled())
      for (auto& f : fs)
        if (f.path == "control")
          for (auto& x : entries(f.value, f.path, f.key_line, "a map"))
            if (x.path == "control.allow_unsigned_remote")
              fail(x.line(), x.path,
                   "expected false with auth (a keyed module takes remote "
                   "control only signed), got 'true'");
    return cfg;
  }

private:
  static std::string format(double x) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%g", x);
    return buf;
  }

  const std::string& file_;
};

// -- expansion bound -------------------------------------------------------------

/// Most a document may expand to, bytes: scalars' text plus node_cost per
/// node, every alias counted as a full copy of what it refers to (that is
/// what walking the document reads, and what copying values into a
/// file_config allocates). A 1 MiB file without aliases stays far below;
/// an alias bomb (a large string or a nested list repeated through
/// aliases) is refused before the document is built or walked.
constexpr uint64_t max_expanded_bytes = 8 * 1024 * 1024;

/// What one node counts for on top of its text.
constexpr uint64_t node_cost = 8;

/// Measures the expanded size of one YAML document from the parser's
/// events, in memory proportional to the file (one size per anchor, one
/// level per nesting depth), and fails with the line and field of the node
/// that crosses max_expanded_bytes, or of an alias inside the node it
/// refers to (a cycle, which no walk would finish).
class expansion_meter : public YAML::EventHandler {
public:
  explicit expansion_meter(const parser& p) : parser_(p) {
    // nop
  }

  void OnDocumentStart(const YAML::Mark&) override {
  }

  void OnDocumentEnd() override {
  }

  void OnNull(const YAML::Mark& mark, YAML::anchor_t anchor) override {
    leaf(mark, anchor, nullptr, node_cost);
  }

  void OnScalar(const YAML::Mark& mark, const std::string&,
                YAML::anchor_t anchor, const std::string& value) override {
    leaf(mark, anchor, &value, node_cost + value.size());
  }

  void OnAlias(const YAML::Mark& mark, YAML::anchor_t anchor) override {
    auto path = place(nullptr);
    if (anchor >= sizes_.size() || sizes_[anchor] == unknown)
      parser_.fail(mark.line + 1, path,
                   "alias inside the node it refers to (a cycle)");
    add(mark, path, sizes_[anchor]);
  }

  void OnSequenceStart(const YAML::Mark& mark, const std::string&,
                       YAML::anchor_t anchor,
                       YAML::EmitterStyle::value) override {
    open(mark, anchor, false);
  }

  void OnSequenceEnd() override {
    close();
  }

  void OnMapStart(const YAML::Mark& mark, const std::string&,
                  YAML::anchor_t anchor, YAML::EmitterStyle::value) override {
    open(mark, anchor, true);
  }

  void OnMapEnd() override {
    close();
  }

private:
  static constexpr uint64_t unknown = UINT64_MAX;

  struct level {
    bool map = false;
    bool want_key = true;
    std::string path;
    std::string key;
    size_t index = 0;
    YAML::anchor_t anchor = YAML::NullAnchor;
    uint64_t start = 0;
  };

  /// The field path of the node that starts now (as config errors write
  /// it: a.b[2].c); advances the enclosing node's position.
  std::string place(const std::string* scalar) {
    if (levels_.empty())
      return {};
    auto& top = levels_.back();
    auto join = [&](const std::string& key) {
      return top.path.empty() ? key : top.path + "." + key;
    };
    if (!top.map)
      return top.path + "[" + std::to_string(top.index++) + "]";
    if (top.want_key) {
      top.want_key = false;
      top.key = scalar == nullptr ? "?" : scalar->substr(0, max_quoted);
      return join(top.key);
    }
    top.want_key = true;
    return join(top.key);
  }

  void add(const YAML::Mark& mark, const std::string& path, uint64_t cost) {
    if (cost > max_expanded_bytes - total_)
      parser_.fail(mark.line + 1, path,
                   "the document expands to more than "
                     + std::to_string(max_expanded_bytes / (1024 * 1024))
                     + " MiB here (aliases repeat what they refer to)");
    total_ += cost;
  }

  void define(YAML::anchor_t anchor, uint64_t size) {
    if (anchor == YAML::NullAnchor)
      return;
    if (anchor >= sizes_.size())
      sizes_.resize(anchor + 1, unknown);
    sizes_[anchor] = size;
  }

  void leaf(const YAML::Mark& mark, YAML::anchor_t anchor,
            const std::string* value, uint64_t cost) {
    auto path = place(value);
    add(mark, path, cost);
    define(anchor, cost);
  }

  void open(const YAML::Mark& mark, YAML::anchor_t anchor, bool map) {
    level next;
    next.map = map;
    next.path = place(nullptr);
    next.anchor = anchor;
    next.start = total_;
    add(mark, next.path, node_cost);
    if (anchor != YAML::NullAnchor) {
      if (anchor >= sizes_.size())
        sizes_.resize(anchor + 1, unknown);
      sizes_[anchor] = unknown; // open: an alias to it is a cycle
    }
    levels_.push_back(std::move(next));
  }

  void close() {
    if (levels_.empty())
      return;
    define(levels_.back().anchor, total_ - levels_.back().start);
    levels_.pop_back();
  }

  const parser& parser_;
  std::vector<level> levels_;
  std::vector<uint64_t> sizes_; // by anchor; unknown while open
  uint64_t total_ = 0;
};

/// Counts the nodes of one YAML document and remembers the first one's line.
struct document_counter : YAML::EventHandler {
  size_t nodes = 0;
  int line = 1;

  void node(const YAML::Mark& mark) {
    if (nodes++ == 0)
      line = mark.line + 1;
  }
  void OnDocumentStart(const YAML::Mark&) override {}
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark& mark, YAML::anchor_t) override {
    node(mark);
  }
  void OnAlias(const YAML::Mark& mark, YAML::anchor_t) override {
    node(mark);
  }
  void OnScalar(const YAML::Mark& mark, const std::string&, YAML::anchor_t,
                const std::string&) override {
    node(mark);
  }
  void OnSequenceStart(const YAML::Mark& mark, const std::string&,
                       YAML::anchor_t, YAML::EmitterStyle::value) override {
    node(mark);
  }
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {
    node(mark);
  }
  void OnMapEnd() override {}
};

} // namespace

caf::expected<file_config> parse_config(const std::string& text,
                                        const std::string& path) {
  parser p{path};
  try {
    // Not YAML::LoadAll: yaml-cpp 0.7 reports empty documents for ever on
    // some inputs (a lone ","; found by fuzz_config). Reading at most two
    // documents through the event parser is bounded.
    std::istringstream in{text};
    YAML::Parser events{in};
    // Bounds the expansion before YAML::Load and the walk (alias bombs).
    expansion_meter first{p};
    events.HandleNextDocument(first);
    document_counter second;
    if (events.HandleNextDocument(second) && second.nodes > 0)
      p.fail(second.line, "", "expected one YAML document, got a second one here");
    return p.document(YAML::Load(text));
  } catch (const config_failure& e) {
    return make_error(ec::invalid_config, e.text);
  } catch (const YAML::Exception& e) {
    auto line = e.mark.line >= 0 ? e.mark.line + 1 : 1;
    return make_error(ec::invalid_config,
                      path + ":" + std::to_string(line) + ": " + e.msg);
  }
}

caf::error check_channels(const file_config& cfg) {
  auto& devs = cfg.module.devices;
  for (size_t i = 0; i < devs.size(); ++i) {
    auto& dev = devs[i];
    auto* kind = find_link_kind(dev.kind);
    if (kind == nullptr || kind->check == nullptr)
      continue;
    auto err = kind->check(dev);
    if (!err)
      continue;
    auto& ctx = err.context();
    auto what = ctx.match_elements<std::string>() ? ctx.get_as<std::string>(0)
                                                  : render(err);
    // The field names the channel already.
    auto prefix = "device '" + dev.name + "': ";
    if (what.rfind(prefix, 0) == 0)
      what.erase(0, prefix.size());
    // Which key the message is about: an option it names ("option
    // 'peers'", one of the unknown options), else the interface.
    auto unknown = what.find("unknown option");
    auto unknown_end = what.find(" for link kind");
    auto names = [&](const std::string& key) {
      if (what.find("option '" + key + "'") != std::string::npos)
        return true;
      return unknown != std::string::npos && unknown_end != std::string::npos
             && what.substr(unknown, unknown_end - unknown)
                    .find("'" + key + "'")
                  != std::string::npos;
    };
    static const std::map<std::string, int> none;
    auto& keys = i < cfg.device_key_lines.size() ? cfg.device_key_lines[i]
                                                 : none;
    auto at = "channels[" + std::to_string(i) + "]";
    auto blame = [&](int line, const std::string& field) {
      return make_error(ec::invalid_config, cfg.path + ":"
                                              + std::to_string(line) + ": "
                                              + field + ": " + what);
    };
    for (auto& [key, line] : keys)
      if (key != "name" && key != "kind" && key != "interface" && names(key))
        return blame(line, at + "." + key);
    if (what.find("interface") != std::string::npos
        || what.find("directory") != std::string::npos
        || what.find("segment") != std::string::npos)
      if (auto k = keys.find("interface"); k != keys.end())
        return blame(k->second, at + ".interface");
    return blame(i < cfg.device_lines.size() ? cfg.device_lines[i] : 0,
                 at + " '" + dev.name + "'");
  }
  return caf::none;
}

caf::expected<file_config> load_config(const std::string& path) {
  // Config files are small; a bound keeps a mistaken path (a device, a
  // log) from being read whole.
  constexpr size_t max_size = 1024 * 1024;
  auto fail = [&](const std::string& why) {
    return make_error(ec::invalid_config, path + ": cannot read: " + why);
  };
  auto* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr)
    return fail(std::strerror(errno));
  std::string text;
  char buf[4096];
  size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof(buf), f)) > 0 && text.size() <= max_size)
    text.append(buf, n);
  auto err = std::ferror(f) ? errno : 0;
  std::fclose(f);
  if (err != 0)
    return fail(std::strerror(err));
  if (text.size() > max_size)
    return fail("larger than 1 MiB");
  return parse_config(text, path);
}

std::string default_control_socket(const std::string& name) {
  auto uid = ::geteuid();
  if (uid == 0)
    return "/run/herm/" + name + ".sock";
  if (auto* dir = std::getenv("XDG_RUNTIME_DIR"); dir != nullptr && *dir != '\0')
    return std::string{dir} + "/herm/" + name + ".sock";
  return "/tmp/herm-" + std::to_string(uid) + "/" + name + ".sock";
}

} // namespace herm
