#pragma once

// hermctl's everyday verbs for data: topic list, echo, hz and pub, call,
// record and play (docs/user-guide.md, "Tools"). They speak to one
// module's control socket: topics reach it from every module, and a call
// finds its APO anywhere. Values print and parse in the text form
// (actors/text_form.hpp).

#include <cstdint>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

namespace hermctl {

class bag;

/// Adds one line of a raw topic stream (`subscribe` with `raw`,
/// docs/protocol.md) to the recording `b`, with the type descriptions it
/// carries. False, and nothing added, for a line that holds no value: a
/// note of values dropped, or a line that is not JSON or lacks a field of
/// the right type (topic, publisher as a module id, seq, time_ns, payload
/// as hex). The stream's end with an error throws topic_failure.
bool record_line(bag& b, const std::string& line);

/// Ends a topic command: `message` to stderr, `status` the exit status
/// (hermctl's: 1 failed, 2 usage, 3 no module).
struct topic_failure {
  int status;
  std::string message;
};

class topic_commands {
public:
  /// Adds the subcommands to `app`.
  explicit topic_commands(CLI::App& app);

  /// True if one of them was given.
  bool parsed() const;

  /// False for the one that needs no module (record --info).
  bool needs_module() const;

  /// Runs the one given against the control socket at `path`; returns the
  /// exit status or throws topic_failure.
  int run(const std::string& path, uint32_t timeout_ms, bool json_out);

private:
  CLI::App* topic_ = nullptr;
  CLI::App* list_ = nullptr;
  CLI::App* echo_ = nullptr;
  CLI::App* hz_ = nullptr;
  CLI::App* pub_ = nullptr;
  CLI::App* call_ = nullptr;
  CLI::App* record_ = nullptr;
  CLI::App* play_ = nullptr;

  std::string topic;
  std::string value;
  std::string type;
  std::string apo;
  uint64_t count = 0;
  uint64_t window = 10000;
  double rate = 0;
  bool raw = false;
  std::string output;
  std::vector<std::string> topics;
  std::string info_file;
  double duration_s = 0;
  /// record without topics: control connections it may hold for streams.
  size_t max_subscriptions = 8;
  std::string file;
  double play_rate = 1.0;
  bool loop = false;
  std::vector<std::string> remaps;
};

} // namespace hermctl
