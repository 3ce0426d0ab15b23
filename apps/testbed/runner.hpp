#pragma once

// herm-testbed's process runner: starts the modules and tools of the
// testbed as child processes, reads everything they print into a trace
// (each line prefixed with the time since start and the child's name), and
// checks expected events against what they printed. One thread: the
// runner polls its children's pipes only while the caller waits in one of
// its calls (pump, wait_line, reap). Every child still running is killed
// (SIGKILL) and reaped when the runner is destroyed.

#include <sys/types.h>

#include <chrono>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace herm::testbed {

using clock_type = std::chrono::steady_clock;

/// True if `line` contains `what`.
bool has(const std::string& line, const std::string& what);

/// One child process, over all its lives (restart starts it again).
struct child {
  std::string name;
  std::vector<std::string> argv;
  pid_t pid = -1;
  /// The read end of its stdout and stderr, -1 once it closed.
  int fd = -1;
  /// What it printed after its last newline.
  std::string partial;
  /// Every line it printed, over all its lives. Grows with the run: the
  /// testbed's runs are bounded (seconds to minutes).
  std::vector<std::string> lines;
};

class runner {
public:
  /// The longest a command of run() may take.
  static constexpr std::chrono::seconds run_limit{60};

  /// `bin_dir`: where the testbed's programs are. `quiet`: leave lines
  /// with "packet " out of the printed trace (they are still recorded).
  runner(std::string bin_dir, bool quiet);

  ~runner();

  runner(const runner&) = delete;
  runner& operator=(const runner&) = delete;

  /// `bin_dir`/`name`.
  std::string bin(const std::string& name) const;

  /// Starts `argv` (argv[0] a path) as the child `name`.
  void spawn(const std::string& name, std::vector<std::string> argv);

  /// Starts the child `name` again with its argv.
  void restart(const std::string& name);

  /// Sends `sig` to the child `name` if it runs.
  void signal(const std::string& name, int sig);

  /// Waits for `name` to exit (after a signal, or on its own); returns its
  /// exit status (128 + signal when killed), or -1 if it did not exit
  /// within `timeout` or was not running.
  int reap(const std::string& name, std::chrono::milliseconds timeout);

  /// Reads every child's output for `dt`, printing it as a trace.
  void pump(std::chrono::milliseconds dt);

  /// Pumps until `pred` holds for some line `name` printed after `from`
  /// (an index into its lines); returns that line, or nothing after
  /// `timeout`.
  std::optional<std::string>
  wait_line(const std::string& name, size_t from,
            const std::function<bool(const std::string&)>& pred,
            std::chrono::milliseconds timeout);

  /// wait_line for a line holding every one of `parts`, then the event
  /// `event_name`: ok with the line found, failed with `missing` when none
  /// came in time.
  void expect_line(const std::string& event_name, const std::string& name,
                   size_t from, std::chrono::milliseconds timeout,
                   const std::vector<std::string>& parts,
                   const std::string& missing);

  /// The `i`th line `name` printed.
  const std::string& line(const std::string& name, size_t i) const;

  /// How many lines `name` printed so far (a mark for wait_line's `from`).
  size_t mark(const std::string& name) const;

  /// Runs a command to completion (hermctl; argv[0] a path or found on the
  /// PATH), printing its output indented when `show`; returns its exit
  /// status (-1 if it did not exit within run_limit: then it is killed;
  /// 127 if it could not start) and output.
  /// The children's output is read (pumped) meanwhile, so that none of
  /// them blocks on a full pipe while the command waits for it.
  std::pair<int, std::string> run(const std::vector<std::string>& argv,
                                  bool show = true);

  /// Prints a step's heading.
  void say(const std::string& text);

  /// Prints "EVENT ok NAME: detail" or "EVENT FAILED NAME: detail" and
  /// counts it.
  void event(bool ok, const std::string& name, const std::string& detail);

  int failed() const {
    return failed_;
  }

  int events() const {
    return events_;
  }

private:
  std::string stamp() const;

  void print(const std::string& name, const std::string& line);

  void start(child& c);

  std::string bin_;
  bool quiet_;
  clock_type::time_point start_;
  std::map<std::string, child> children_;
  int failed_ = 0;
  int events_ = 0;
};

} // namespace herm::testbed
