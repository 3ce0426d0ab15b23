#pragma once

// Runs child processes for multi-process tests: stdout captured line by
// line, bounded waits, and the child killed if the test ends first.

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <optional>
#include <string>
#include <vector>

namespace herm::test {

class child_process {
public:
  explicit child_process(std::vector<std::string> argv) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0)
      return;
    pid_ = ::fork();
    if (pid_ == 0) {
      ::dup2(fds[1], STDOUT_FILENO);
      std::vector<char*> args;
      for (auto& a : argv)
        args.push_back(a.data());
      args.push_back(nullptr);
      ::execv(args[0], args.data());
      ::_exit(127);
    }
    ::close(fds[1]);
    fd_ = fds[0];
  }

  child_process(const child_process&) = delete;
  child_process& operator=(const child_process&) = delete;

  ~child_process() {
    if (pid_ > 0 && !status_) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    if (fd_ >= 0)
      ::close(fd_);
  }

  bool started() const {
    return pid_ > 0;
  }

  pid_t pid() const {
    return pid_;
  }

  /// True while the child has not exited (reaps it if it has).
  bool running() {
    if (pid_ <= 0 || status_)
      return false;
    int st = 0;
    if (::waitpid(pid_, &st, WNOHANG) == pid_) {
      status_ = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
      return false;
    }
    return true;
  }

  /// Everything the child printed so far.
  const std::string& output() const {
    return out_;
  }

  /// Reads until a line starting with `prefix` appears; returns that line.
  std::optional<std::string> wait_for_line(const std::string& prefix,
                                           std::chrono::milliseconds timeout) {
    auto deadline = std::chrono::steady_clock::now() + timeout;
    size_t scanned = 0;
    for (;;) {
      size_t pos;
      while ((pos = out_.find('\n', scanned)) != std::string::npos) {
        auto line = out_.substr(scanned, pos - scanned);
        scanned = pos + 1;
        if (line.rfind(prefix, 0) == 0)
          return line;
      }
      auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0 || !read_some(left))
        return std::nullopt;
    }
  }

  /// Waits for the child to exit; returns its exit status or -1 on timeout
  /// (the child is then killed).
  int wait(std::chrono::milliseconds timeout) {
    auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!status_) {
      int st = 0;
      auto res = ::waitpid(pid_, &st, WNOHANG);
      if (res == pid_) {
        status_ = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
        break;
      }
      if (std::chrono::steady_clock::now() > deadline) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, nullptr, 0);
        status_ = -1;
        break;
      }
      read_some(std::chrono::milliseconds(20));
    }
    while (read_some(std::chrono::milliseconds(0))) {
    }
    return *status_;
  }

  /// Like wait_for_line, for a line that contains `part` anywhere (log
  /// lines start with a time stamp).
  std::optional<std::string>
  wait_for_line_containing(const std::string& part,
                           std::chrono::milliseconds timeout) {
    auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      size_t pos;
      while ((pos = out_.find('\n', scanned_any_)) != std::string::npos) {
        auto line = out_.substr(scanned_any_, pos - scanned_any_);
        scanned_any_ = pos + 1;
        if (line.find(part) != std::string::npos)
          return line;
      }
      auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0 || !read_some(left))
        return std::nullopt;
    }
  }

  void signal(int sig) {
    if (pid_ > 0 && !status_)
      ::kill(pid_, sig);
  }

  void terminate() {
    if (pid_ > 0 && !status_)
      ::kill(pid_, SIGTERM);
  }

private:
  bool read_some(std::chrono::milliseconds timeout) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout.count())) <= 0)
      return false;
    char buf[4096];
    auto n = ::read(fd_, buf, sizeof(buf));
    if (n <= 0)
      return false;
    out_.append(buf, static_cast<size_t>(n));
    return true;
  }

  pid_t pid_ = -1;
  int fd_ = -1;
  std::string out_;
  /// Where wait_for_line_containing goes on from.
  size_t scanned_any_ = 0;
  std::optional<int> status_;
};

} // namespace herm::test
