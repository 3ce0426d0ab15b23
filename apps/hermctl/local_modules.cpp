#include "apps/hermctl/local_modules.hpp"

#include <dirent.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <ostream>

#include "actors/config.hpp"
#include "actors/control.hpp"
#include "actors/runtime/error.hpp"
#include "apps/hermctl/format.hpp"

namespace hermctl {

namespace {

constexpr const char* suffix = ".sock";
constexpr size_t suffix_len = 5;

/// How many names ambiguous_message lists before it only counts.
constexpr size_t listed_names = 8;

bool ends_with_sock(const std::string& s) {
  return s.size() > suffix_len
         && s.compare(s.size() - suffix_len, suffix_len, suffix) == 0;
}

} // namespace

std::string runtime_dir() {
  if (auto* dir = std::getenv("HERM_RUNTIME_DIR"); dir != nullptr && *dir != '\0')
    return dir;
  auto path = herm::default_control_socket("hermd");
  return path.substr(0, path.rfind('/'));
}

std::string socket_of(const std::string& name) {
  return runtime_dir() + "/" + name + suffix;
}

bool is_live(const std::string& path) {
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (path.empty() || path.size() >= sizeof(addr.sun_path))
    return false;
  std::memcpy(addr.sun_path, path.data(), path.size());
  int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (fd < 0)
    return false;
  auto rc = ::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr));
  // A full backlog (EAGAIN) still means someone listens.
  bool live = rc == 0 || errno == EAGAIN || errno == EINPROGRESS;
  ::close(fd);
  return live;
}

std::vector<local_socket> scan_runtime_dir(const std::string& dir) {
  std::vector<local_socket> found;
  auto* d = ::opendir(dir.c_str());
  if (d == nullptr)
    return found;
  // Entries are read in directory order and sorted afterwards; the bound
  // keeps a directory full of junk from costing more than its first files.
  while (auto* e = ::readdir(d)) {
    std::string file = e->d_name;
    if (!ends_with_sock(file))
      continue;
    auto path = dir + "/" + file;
    struct stat sb;
    if (::lstat(path.c_str(), &sb) != 0 || !S_ISSOCK(sb.st_mode))
      continue;
    found.push_back({file.substr(0, file.size() - suffix_len), path, false});
    if (found.size() == max_local_sockets)
      break;
  }
  ::closedir(d);
  std::sort(found.begin(), found.end(),
            [](const local_socket& a, const local_socket& b) { return a.name < b.name; });
  for (auto& s : found)
    s.live = is_live(s.path);
  return found;
}

module_choice choose_module(const std::vector<local_socket>& sockets,
                            const std::string& preferred) {
  module_choice c;
  size_t live = 0;
  for (auto& s : sockets) {
    if (!s.live)
      continue;
    if (++live == 1)
      c.chosen = s;
    if (s.name == preferred) {
      c.kind = module_choice::use;
      c.chosen = s;
      return c;
    }
  }
  if (live == 0)
    return module_choice{};
  if (live == 1)
    c.kind = module_choice::use;
  else
    c = module_choice{module_choice::ambiguous, {}};
  return c;
}

std::string using_line(const local_socket& s) {
  return "hermctl: using module '" + s.name + "' (" + s.path + ")";
}

std::string ambiguous_message(const std::vector<local_socket>& sockets,
                              const std::string& dir) {
  std::string names;
  size_t live = 0;
  for (auto& s : sockets) {
    if (!s.live)
      continue;
    if (++live <= listed_names)
      names += (names.empty() ? "" : ", ") + s.name;
  }
  if (live > listed_names)
    names += " and " + std::to_string(live - listed_names) + " more";
  return std::to_string(live) + " modules run here (" + names + "; in " + dir
         + "): choose one with --name NAME or -s PATH (hermctl modules lists "
           "them)";
}

std::vector<module_row> list_modules(const std::vector<local_socket>& sockets,
                                     std::chrono::milliseconds timeout) {
  std::vector<module_row> rows;
  for (auto& s : sockets) {
    if (!s.live)
      continue;
    module_row r{s.name, "-", s.path, {}};
    auto reply = herm::control_call(
      s.path, R"({"cmd":"info","timeout_ms":)" + std::to_string(timeout.count()) + "}",
      timeout + std::chrono::seconds(1));
    if (!reply) {
      r.error = reply.error().context().match_elements<std::string>()
                  ? reply.error().context().get_as<std::string>(0)
                  : herm::render(reply.error());
    } else {
      auto j = json::parse(*reply, nullptr, false);
      auto result = j.is_object() && j.value("ok", false) ? j.value("result", json{})
                                                          : json{};
      if (result.is_object()) {
        r.name = result.value("name", s.name);
        r.module = result.value("module", std::string{"-"});
      } else {
        auto err = j.is_object() ? j.value("error", json::object()) : json::object();
        r.error = err.is_object() ? err.value("message", std::string{"not a control reply"})
                                  : std::string{"not a control reply"};
      }
    }
    rows.push_back(std::move(r));
  }
  return rows;
}

void show_modules(std::ostream& out, const std::vector<module_row>& rows,
                  const std::string& dir, bool json_out) {
  if (json_out) {
    json j = json::array();
    for (auto& r : rows)
      j.push_back({{"name", r.name},
                   {"module", r.module == "-" ? json(nullptr) : json(r.module)},
                   {"socket", r.socket},
                   {"error", r.error}});
    print_json(out, j);
    return;
  }
  if (rows.empty()) {
    out << "no modules running (no live control socket in " << dir << ")\n";
    return;
  }
  std::vector<row> table;
  for (auto& r : rows)
    table.push_back({r.name, r.module, r.socket});
  print_table(out, {"NAME", "MODULE", "SOCKET"}, table);
  for (auto& r : rows)
    if (!r.error.empty())
      out << r.socket << ": " << r.error << '\n';
}

} // namespace hermctl
