#include "apps/testbed/runner.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <thread>

namespace herm::testbed {

using namespace std::chrono_literals;

bool has(const std::string& line, const std::string& what) {
  return line.find(what) != std::string::npos;
}

runner::runner(std::string bin_dir, bool quiet)
  : bin_(std::move(bin_dir)), quiet_(quiet), start_(clock_type::now()) {
  // nop
}

runner::~runner() {
  for (auto& [name, c] : children_)
    if (c.pid > 0) {
      ::kill(c.pid, SIGKILL);
      ::waitpid(c.pid, nullptr, 0);
    }
}

std::string runner::bin(const std::string& name) const {
  return bin_ + "/" + name;
}

void runner::spawn(const std::string& name, std::vector<std::string> argv) {
  auto& c = children_[name];
  c.name = name;
  c.argv = std::move(argv);
  start(c);
}

void runner::restart(const std::string& name) {
  start(children_.at(name));
}

void runner::signal(const std::string& name, int sig) {
  auto& c = children_.at(name);
  if (c.pid > 0)
    ::kill(c.pid, sig);
}

int runner::reap(const std::string& name, std::chrono::milliseconds timeout) {
  auto& c = children_.at(name);
  auto deadline = clock_type::now() + timeout;
  while (c.pid > 0 && clock_type::now() < deadline) {
    int status = 0;
    if (::waitpid(c.pid, &status, WNOHANG) == c.pid) {
      pump(50ms);
      c.pid = -1;
      return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    }
    pump(20ms);
  }
  return -1;
}

void runner::pump(std::chrono::milliseconds dt) {
  auto deadline = clock_type::now() + dt;
  do {
    std::vector<pollfd> fds;
    std::vector<child*> owners;
    for (auto& [name, c] : children_)
      if (c.fd >= 0) {
        fds.push_back({c.fd, POLLIN, 0});
        owners.push_back(&c);
      }
    auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
      deadline - clock_type::now());
    if (fds.empty()) {
      std::this_thread::sleep_for(std::max(left, 0ms));
      return;
    }
    if (::poll(fds.data(), fds.size(), static_cast<int>(std::max<int64_t>(left.count(), 0))) <= 0)
      continue;
    for (size_t i = 0; i < fds.size(); ++i) {
      if ((fds[i].revents & (POLLIN | POLLHUP)) == 0)
        continue;
      char buf[4096];
      auto n = ::read(fds[i].fd, buf, sizeof(buf));
      auto& c = *owners[i];
      if (n <= 0) {
        ::close(c.fd);
        c.fd = -1;
        continue;
      }
      c.partial.append(buf, static_cast<size_t>(n));
      size_t pos;
      while ((pos = c.partial.find('\n')) != std::string::npos) {
        auto line = c.partial.substr(0, pos);
        c.partial.erase(0, pos + 1);
        c.lines.push_back(line);
        print(c.name, line);
      }
    }
  } while (clock_type::now() < deadline);
}

std::optional<std::string>
runner::wait_line(const std::string& name, size_t from,
          const std::function<bool(const std::string&)>& pred,
          std::chrono::milliseconds timeout) {
  auto deadline = clock_type::now() + timeout;
  auto& c = children_.at(name);
  size_t i = from;
  for (;;) {
    for (; i < c.lines.size(); ++i)
      if (pred(c.lines[i]))
        return c.lines[i];
    if (clock_type::now() >= deadline)
      return std::nullopt;
    pump(20ms);
  }
}

void runner::expect_line(const std::string& event_name, const std::string& name,
                 size_t from, std::chrono::milliseconds timeout,
                 const std::vector<std::string>& parts,
                 const std::string& missing) {
  auto found = wait_line(name, from, [&parts](const std::string& l) {
    return std::all_of(parts.begin(), parts.end(),
                       [&l](const std::string& p) { return has(l, p); });
  }, timeout);
  event(found.has_value(), event_name, found ? *found : missing);
}

const std::string& runner::line(const std::string& name, size_t i) const {
  return children_.at(name).lines.at(i);
}

size_t runner::mark(const std::string& name) const {
  return children_.at(name).lines.size();
}

std::pair<int, std::string> runner::run(const std::vector<std::string>& argv,
                                        bool show) {
  // Not popen: while the command runs, the children's pipes must still be
  // drained, or a module logging at debug level fills its pipe, blocks in
  // its log and stops answering the very command that waits for it.
  int fds[2];
  if (argv.empty() || ::pipe2(fds, O_CLOEXEC) != 0)
    return {-1, "cannot run a command: no pipe"};
  // Only our end: the command's output stays a blocking pipe.
  ::fcntl(fds[0], F_SETFL, O_NONBLOCK);
  std::vector<char*> args;
  for (auto& a : argv)
    args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  auto pid = ::fork();
  if (pid == 0) {
    ::dup2(fds[1], STDOUT_FILENO);
    ::dup2(fds[1], STDERR_FILENO);
    ::execvp(args[0], args.data());
    ::_exit(127);
  }
  // A command that hangs (or a grandchild that keeps the pipe open) must
  // not hang the run: killed after run_limit.
  auto deadline = clock_type::now() + run_limit;
  ::close(fds[1]);
  std::string out;
  int status = 0;
  bool open = true;
  bool exited = pid < 0;
  while (open || !exited) {
    char buf[4096];
    ssize_t n = -1;
    while (open && (n = ::read(fds[0], buf, sizeof(buf))) != 0) {
      if (n < 0) {
        if (errno != EINTR)
          break; // EAGAIN: nothing more for now
        continue;
      }
      out.append(buf, static_cast<size_t>(n));
    }
    if (open && n == 0)
      open = false;
    if (!exited && ::waitpid(pid, &status, WNOHANG) == pid)
      exited = true;
    if ((open || !exited) && clock_type::now() >= deadline) {
      if (!exited) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, nullptr, 0);
      }
      ::close(fds[0]);
      out += "\n(killed after " + std::to_string(run_limit.count()) + " s)";
      if (show)
        std::cout << "           | " << out << "\n" << std::flush;
      return {-1, out};
    }
    if (open || !exited)
      pump(10ms);
  }
  ::close(fds[0]);
  if (show) {
    std::istringstream in{out};
    for (std::string line; std::getline(in, line);)
      std::cout << "           | " << line << "\n";
    std::cout << std::flush;
  }
  if (pid < 0)
    return {-1, "cannot run a command: fork failed"};
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

void runner::say(const std::string& text) {
  std::cout << "\n" << stamp() << " == " << text << "\n" << std::flush;
}

void runner::event(bool ok, const std::string& name, const std::string& detail) {
  std::cout << stamp() << " EVENT " << (ok ? "ok " : "FAILED ") << name
            << ": " << detail << "\n"
            << std::flush;
  if (!ok)
    ++failed_;
  ++events_;
}



std::string runner::stamp() const {
  char buf[32];
  auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(
              clock_type::now() - start_)
              .count();
  std::snprintf(buf, sizeof(buf), "%7.3f", ms / 1000.0);
  return buf;
}

void runner::print(const std::string& name, const std::string& line) {
  if (quiet_ && line.find("packet ") != std::string::npos)
    return;
  char head[48];
  std::snprintf(head, sizeof(head), "%s %-7s| ", stamp().c_str(),
                name.c_str());
  std::cout << head << line << "\n" << std::flush;
}

void runner::start(child& c) {
  // A previous life that did not exit when asked: it goes now, or two
  // would run (two boards on one line) and this one could not be killed.
  if (c.pid > 0) {
    ::kill(c.pid, SIGKILL);
    ::waitpid(c.pid, nullptr, 0);
    c.pid = -1;
  }
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    return;
  // Built before fork: the child only calls async-signal-safe functions.
  std::vector<char*> args;
  for (auto& a : c.argv)
    args.push_back(a.data());
  args.push_back(nullptr);
  c.pid = ::fork();
  if (c.pid == 0) {
    ::dup2(fds[1], STDOUT_FILENO);
    ::dup2(fds[1], STDERR_FILENO);
    ::execv(args[0], args.data());
    ::_exit(127);
  }
  ::close(fds[1]);
  if (c.fd >= 0)
    ::close(c.fd);
  c.fd = fds[0];
  c.partial.clear();
}

} // namespace herm::testbed
