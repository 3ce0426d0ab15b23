#include "channels/drivers/medium_dir.hpp"

#include <dirent.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "channels/drivers/posix.hpp"

namespace herm::medium_dir {

std::string station_file(uint64_t station) {
  return std::to_string(station) + ".sock";
}

uint64_t parse_station_file(const char* name, uint64_t min, uint64_t max) {
  uint64_t n = 0;
  size_t i = 0;
  for (; name[i] >= '0' && name[i] <= '9'; ++i) {
    if (i >= 3)
      return 0;
    n = n * 10 + static_cast<uint64_t>(name[i] - '0');
  }
  if (i == 0 || name[0] == '0' || std::strcmp(name + i, ".sock") != 0)
    return 0;
  return n >= min && n <= max ? n : 0;
}

uint64_t parse_number(const std::string& str, uint64_t min, uint64_t max) {
  if (str.empty() || str.size() > 3)
    return 0;
  uint64_t n = 0;
  for (auto c : str) {
    if (c < '0' || c > '9')
      return 0;
    n = n * 10 + static_cast<uint64_t>(c - '0');
  }
  return n >= min && n <= max ? n : 0;
}

sockaddr_un unix_addr(const std::string& path) {
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, path.data(),
              std::min(path.size(), sizeof(addr.sun_path) - 1));
  return addr;
}

probe_result probe_socket(const std::string& path) {
  posix::unique_fd fd{::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0)};
  if (!fd)
    return probe_result::live; // cannot tell: assume taken
  auto addr = unix_addr(path);
  if (::connect(fd.get(), reinterpret_cast<sockaddr*>(&addr), sizeof(addr))
      == 0)
    return probe_result::live;
  switch (errno) {
    case ECONNREFUSED:
      return probe_result::stale;
    case ENOENT:
      return probe_result::absent;
    default:
      return probe_result::live; // e.g. EACCES: somebody else's, keep off
  }
}

std::vector<uint64_t> list_stations(const std::string& dir, uint64_t min,
                                    uint64_t max) {
  std::vector<uint64_t> result;
  if (auto* d = ::opendir(dir.c_str())) {
    while (auto* e = ::readdir(d))
      if (auto n = parse_station_file(e->d_name, min, max))
        result.push_back(n);
    ::closedir(d);
  }
  std::sort(result.begin(), result.end());
  return result;
}

int make_dirs(const std::string& path) {
  std::string prefix;
  size_t pos = 0;
  while (pos != std::string::npos) {
    pos = path.find('/', pos + 1);
    prefix = path.substr(0, pos);
    if (prefix.empty())
      continue;
    if (::mkdir(prefix.c_str(), 0777) != 0 && errno != EEXIST)
      return errno;
  }
  struct stat st;
  if (::stat(path.c_str(), &st) != 0)
    return errno;
  return S_ISDIR(st.st_mode) ? 0 : ENOTDIR;
}

std::string join_numbers(const std::vector<uint64_t>& xs) {
  std::string result;
  for (auto x : xs)
    result += (result.empty() ? "" : ", ") + std::to_string(x);
  return result;
}

} // namespace herm::medium_dir
