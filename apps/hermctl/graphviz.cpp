// Rendering DOT with graphviz (apps/hermctl/graphviz.hpp).

#include "apps/hermctl/graphviz.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <sstream>

namespace hermctl {

bool have_dot() {
  auto* path = std::getenv("PATH");
  if (path == nullptr)
    return false;
  std::istringstream dirs{path};
  for (std::string dir; std::getline(dirs, dir, ':');)
    if (!dir.empty() && ::access((dir + "/dot").c_str(), X_OK) == 0)
      return true;
  return false;
}

std::optional<std::string> render_dot(const std::string& graph,
                                      const std::string& format,
                                      const std::string& file) {
  int fds[2];
  if (::pipe(fds) != 0)
    return "cannot run dot: pipe failed";
  auto pid = ::fork();
  if (pid < 0)
    return "cannot run dot: fork failed";
  if (pid == 0) {
    ::dup2(fds[0], STDIN_FILENO);
    ::close(fds[0]);
    ::close(fds[1]);
    auto fmt = "-T" + format;
    ::execlp("dot", "dot", fmt.c_str(), "-o", file.c_str(),
             static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ::close(fds[0]);
  size_t done = 0;
  while (done < graph.size()) {
    auto n = ::write(fds[1], graph.data() + done, graph.size() - done);
    if (n <= 0)
      break;
    done += static_cast<size_t>(n);
  }
  ::close(fds[1]);
  int st = 0;
  ::waitpid(pid, &st, 0);
  if (!WIFEXITED(st) || WEXITSTATUS(st) != 0)
    return "dot -T" + format + " failed writing " + file;
  return std::nullopt;
}

} // namespace hermctl
