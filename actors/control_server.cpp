// The control service's local endpoint: a Unix-domain stream socket served
// by threads of its own (blocking I/O belongs here, never in an actor), and
// the client side hermctl uses. One JSON request per line, one JSON reply
// per line.
//
// Threads: one accepts connections and starts one worker thread per client,
// at most max_clients at once, so that a slow or idle client never holds up
// another (a client beyond the bound gets a "busy" reply and is closed). A
// worker disconnects its client after client_idle without a byte, or when a
// request line is not complete line_deadline after its first byte. Local
// commands (hermd's reload) still run one at a time. Stopping the server
// wakes every thread through the stop pipe and joins them.

#include "actors/control.hpp"
#include "actors/control_json.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <deque>
#include <filesystem>
#include <future>
#include <list>
#include <memory>
#include <mutex>
#include <system_error>
#include <thread>

#include <nlohmann/json.hpp>

#include "caf/actor_system.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/sec.hpp"
#include "caf/send.hpp"

#include "actors/runtime/error.hpp"

namespace herm {

namespace {

using json = nlohmann::json;
using control_json::error_reply;
using clock_type = std::chrono::steady_clock;

/// Longest request or reply line, newline excluded.
constexpr size_t max_line = 64 * 1024;

/// A client that sends nothing for this long is disconnected, so that idle
/// clients cannot hold the endpoint's slots.
constexpr std::chrono::seconds client_idle{30};

/// A request line must be complete this long after its first byte: a client
/// that trickles bytes (one every few seconds) is cut off, not served for
/// ever.
constexpr std::chrono::seconds line_deadline{10};

/// Clients served at once; one more gets a "busy" reply and is closed.
constexpr size_t max_clients = 16;

/// Lines a stream (topic echo, record) holds for a client that reads slowly;
/// more are dropped, and the client hears how many in a {"dropped": N} line.
constexpr size_t max_stream_lines = 4096;

/// After a line over max_line, the rest of it is read and dropped (so that
/// the client, still writing, is not reset before it reads its error reply)
/// up to this many bytes and for at most drain_time.
constexpr size_t max_drain = 16 * 1024 * 1024;
constexpr std::chrono::seconds drain_time{5};

std::string errno_text(int err) {
  return std::strerror(err);
}

/// Fills `addr` for `path`; false if the path does not fit.
bool make_address(const std::string& path, sockaddr_un& addr) {
  std::memset(&addr, 0, sizeof(addr));
  addr.sun_family = AF_UNIX;
  if (path.empty() || path.size() >= sizeof(addr.sun_path))
    return false;
  std::memcpy(addr.sun_path, path.data(), path.size());
  return true;
}

/// Closes a descriptor when it goes out of scope.
struct fd_guard {
  int fd = -1;
  ~fd_guard() {
    if (fd >= 0)
      ::close(fd);
  }
  int release() {
    auto x = fd;
    fd = -1;
    return x;
  }
};

/// Waits until `fd` is ready for `events` or `deadline` passes; also returns
/// (false) when `stop_fd` becomes readable.
bool wait_ready(int fd, short events, clock_type::time_point deadline,
                int stop_fd = -1) {
  for (;;) {
    // Rounded up: false only once the deadline has passed (callers tell a
    // timeout from a stop by the clock).
    auto left = std::chrono::ceil<std::chrono::milliseconds>(
      deadline - clock_type::now());
    if (left.count() <= 0)
      return false;
    pollfd p[2] = {{fd, events, 0}, {stop_fd, POLLIN, 0}};
    auto n = ::poll(p, stop_fd >= 0 ? 2 : 1,
                    static_cast<int>(std::min<int64_t>(left.count(), 1000)));
    if (n < 0 && errno != EINTR)
      return false;
    if (n <= 0)
      continue;
    if (stop_fd >= 0 && p[1].revents != 0)
      return false;
    if (p[0].revents != 0)
      return true;
  }
}

/// Writes all of `data`; false on error or when `deadline` passes.
bool write_all(int fd, const std::string& data, clock_type::time_point deadline) {
  size_t done = 0;
  while (done < data.size()) {
    auto n = ::send(fd, data.data() + done, data.size() - done,
                    MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n > 0) {
      done += static_cast<size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR)
      continue;
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)
        && wait_ready(fd, POLLOUT, deadline))
      continue;
    return false;
  }
  return true;
}

class server_impl : public control_server {
public:
  server_impl(caf::actor_system& sys, control_actor service, std::string path,
              local_commands locals, int listen_fd, int stop_read,
              int stop_write, ino_t inode)
    : sys_(sys),
      service_(std::move(service)),
      path_(std::move(path)),
      locals_(std::move(locals)),
      listen_fd_(listen_fd),
      stop_read_(stop_read),
      stop_write_(stop_write),
      inode_(inode),
      // Written by a worker that ends, so the accept loop reaps it without
      // waking on a timer. Without it (no eventfd) the loop reaps on the
      // next connection instead, and at the latest when it stops.
      reaped_fd_(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)) {
    thread_ = std::thread{[this] { run(); }};
  }

  ~server_impl() override {
    char c = 1;
    [[maybe_unused]] auto n = ::write(stop_write_, &c, 1);
    if (thread_.joinable())
      thread_.join(); // it joins the workers
    ::close(listen_fd_);
    ::close(stop_read_);
    ::close(stop_write_);
    if (reaped_fd_ >= 0)
      ::close(reaped_fd_);
    // Remove the socket file only if it is still ours (not a successor's).
    struct stat sb;
    if (::lstat(path_.c_str(), &sb) == 0 && sb.st_ino == inode_)
      ::unlink(path_.c_str());
  }

  const std::string& socket_path() const {
    return path_;
  }

private:
  /// A thread serving one client.
  struct worker {
    std::thread thread;
    std::atomic<bool> done{false};
  };

  void run() {
    std::list<std::unique_ptr<worker>> workers;
    auto reap = [&] {
      for (auto i = workers.begin(); i != workers.end();) {
        if ((*i)->done.load()) {
          (*i)->thread.join();
          i = workers.erase(i);
        } else {
          ++i;
        }
      }
      clients_ = workers.size();
    };
    for (;;) {
      pollfd p[3] = {{listen_fd_, POLLIN, 0},
                     {stop_read_, POLLIN, 0},
                     {reaped_fd_, POLLIN, 0}};
      // Sleeps until a client connects, a worker ends or we stop: an idle
      // module's control service costs no wake-ups.
      auto n = ::poll(p, reaped_fd_ >= 0 ? 3 : 2, -1);
      if (n < 0 && errno == EINTR)
        continue;
      if (n < 0 || p[1].revents != 0)
        break;
      if (reaped_fd_ >= 0 && p[2].revents != 0) {
        uint64_t ended = 0;
        [[maybe_unused]] auto r = ::read(reaped_fd_, &ended, sizeof(ended));
      }
      reap();
      if (p[0].revents == 0)
        continue;
      int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0)
        continue;
      if (workers.size() >= max_clients) {
        refuse(fd, "too many control clients (" + std::to_string(max_clients)
                     + " connected); try again");
        continue;
      }
      auto w = std::make_unique<worker>();
      auto* raw = w.get();
      try {
        w->thread = std::thread{[this, fd, raw] {
          serve_client(fd);
          ::close(fd);
          raw->done = true;
          if (reaped_fd_ >= 0) {
            uint64_t one = 1;
            [[maybe_unused]] auto r = ::write(reaped_fd_, &one, sizeof(one));
          }
        }};
      } catch (const std::system_error& ex) {
        refuse(fd, std::string{"cannot serve another client: "} + ex.what());
        continue;
      }
      workers.push_back(std::move(w));
      clients_ = workers.size();
    }
    // Stopping: every worker sees the stop pipe (or ends its reply soon).
    for (auto& w : workers)
      w->thread.join();
    clients_ = 0;
  }

  /// Answers a client that cannot be served with one error line, closes it.
  void refuse(int fd, const std::string& why) {
    ++clients_refused_;
    write_all(fd, error_reply("busy", why) + '\n',
              clock_type::now() + std::chrono::milliseconds(100));
    ::close(fd);
  }

  /// Answers every line from one client until it closes, idles, trickles or
  /// breaks the line bound.
  void serve_client(int fd) {
    std::string buf;
    // When the first byte of the line in progress arrived.
    auto line_start = clock_type::now();
    for (;;) {
      auto nl = buf.find('\n');
      if (nl != std::string::npos) {
        auto line = buf.substr(0, nl);
        buf.erase(0, nl + 1);
        line_start = clock_type::now();
        if (!line.empty() && line.back() == '\r')
          line.pop_back();
        if (line.find_first_not_of(" \t") == std::string::npos)
          continue;
        if (is_stream(line)) {
          // The connection is the stream's until either side ends it.
          stream(fd, line);
          return;
        }
        if (!write_all(fd, answer(line) + '\n',
                       clock_type::now() + std::chrono::seconds(5)))
          return;
        continue;
      }
      if (buf.size() > max_line) {
        ++lines_too_long_;
        write_all(fd,
                  error_reply("invalid_request",
                              "request line longer than "
                                + std::to_string(max_line) + " bytes")
                    + '\n',
                  clock_type::now() + std::chrono::seconds(5));
        drain_line(fd);
        return;
      }
      auto partial = buf.find_first_not_of(" \t\r") != std::string::npos;
      auto deadline = partial ? line_start + line_deadline
                              : clock_type::now() + client_idle;
      if (!wait_ready(fd, POLLIN, deadline, stop_read_)) {
        if (clock_type::now() >= deadline) {
          ++clients_timed_out_;
          if (partial)
            write_all(fd,
                      error_reply("timeout",
                                  "request line not complete within "
                                    + std::to_string(line_deadline.count())
                                    + " s")
                        + '\n',
                      clock_type::now() + std::chrono::milliseconds(100));
        }
        return;
      }
      char chunk[4096];
      auto n = ::recv(fd, chunk, sizeof(chunk), MSG_DONTWAIT);
      if (n < 0 && (errno == EINTR || errno == EAGAIN))
        continue;
      if (n <= 0) {
        // A last request without its newline still gets its answer.
        if (n == 0 && partial && buf.size() <= max_line)
          write_all(fd, answer(buf) + '\n',
                    clock_type::now() + std::chrono::seconds(5));
        return;
      }
      if (!partial)
        line_start = clock_type::now();
      buf.append(chunk, static_cast<size_t>(n));
    }
  }

  /// After an error reply to an over-long line: says it sends no more, then
  /// reads and drops the rest of the line (bounded), so that closing does
  /// not reset a client that is still writing it.
  void drain_line(int fd) {
    ::shutdown(fd, SHUT_WR);
    auto deadline = clock_type::now() + drain_time;
    size_t dropped = 0;
    char chunk[4096];
    while (dropped < max_drain
           && wait_ready(fd, POLLIN, deadline, stop_read_)) {
      auto n = ::recv(fd, chunk, sizeof(chunk), MSG_DONTWAIT);
      if (n < 0 && (errno == EINTR || errno == EAGAIN))
        continue;
      if (n <= 0)
        return;
      if (std::memchr(chunk, '\n', static_cast<size_t>(n)) != nullptr)
        return;
      dropped += static_cast<size_t>(n);
    }
  }

  /// A request that opens a stream: {"cmd": "subscribe", ...}.
  static bool is_stream(const std::string& line) {
    auto req = json::parse(line, nullptr, false);
    return req.is_object() && req.value("cmd", json{}) == "subscribe"
           && req.count("module") == 0;
  }

  /// Lines from the service's stream, for one client thread.
  struct stream_queue {
    std::mutex mtx;
    std::deque<std::string> lines;
    uint64_t dropped = 0;
    int event_fd = -1;
  };

  /// Serves a stream: its first line is the service's reply; then one line
  /// per value until the client closes, the stream ends or we stop.
  void stream(int fd, const std::string& line) {
    auto q = std::make_shared<stream_queue>();
    fd_guard efd{::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)};
    if (efd.fd < 0) {
      write_all(fd, error_reply("unavailable", "cannot open a stream: "
                                                 + errno_text(errno)) + '\n',
                clock_type::now() + std::chrono::seconds(1));
      return;
    }
    q->event_fd = efd.fd;
    auto writer = sys_.spawn([q](caf::event_based_actor*) -> caf::behavior {
      return {
        [q](std::string& text) {
          {
            std::lock_guard<std::mutex> guard{q->mtx};
            if (q->lines.size() >= max_stream_lines) {
              ++q->dropped;
              return;
            }
            q->lines.push_back(std::move(text));
          }
          uint64_t one = 1;
          [[maybe_unused]] auto r = ::write(q->event_fd, &one, sizeof(one));
        },
      };
    });
    auto first = ask_service(line, writer);
    auto j = json::parse(first, nullptr, false);
    auto ok = control_json::is_ok_reply(j);
    if (!write_all(fd, first + '\n', clock_type::now() + std::chrono::seconds(5))
        || !ok) {
      caf::anon_send_exit(writer, caf::exit_reason::user_shutdown);
      return;
    }
    for (;;) {
      pollfd p[3] = {{fd, POLLIN, 0}, {efd.fd, POLLIN, 0}, {stop_read_, POLLIN, 0}};
      auto n = ::poll(p, 3, -1);
      if (n < 0 && errno == EINTR)
        continue;
      if (n < 0 || p[2].revents != 0)
        break;
      if (p[0].revents != 0) {
        // Anything from the client is ignored; its end ends the stream.
        char chunk[512];
        auto r = ::recv(fd, chunk, sizeof(chunk), MSG_DONTWAIT);
        if (r == 0 || (r < 0 && errno != EINTR && errno != EAGAIN))
          break;
      }
      if (p[1].revents == 0)
        continue;
      uint64_t count = 0;
      [[maybe_unused]] auto r = ::read(efd.fd, &count, sizeof(count));
      std::deque<std::string> lines;
      uint64_t dropped = 0;
      {
        std::lock_guard<std::mutex> guard{q->mtx};
        lines.swap(q->lines);
        std::swap(dropped, q->dropped);
      }
      std::string out;
      if (dropped > 0)
        out = control_json::dump(json{{"dropped", dropped}}) + '\n';
      for (auto& l : lines)
        out += l + '\n';
      if (!write_all(fd, out, clock_type::now() + std::chrono::seconds(5)))
        break;
    }
    caf::anon_send_exit(writer, caf::exit_reason::user_shutdown);
  }

  /// The server's own counters, for the "stats" reply.
  json counters() const {
    return {{"clients", clients_.load()},
            {"max_clients", max_clients},
            {"clients_refused", clients_refused_.load()},
            {"clients_timed_out", clients_timed_out_.load()},
            {"lines_too_long", lines_too_long_.load()}};
  }

  /// One reply line for one request line; never throws.
  std::string answer(const std::string& line) {
    try {
      auto req = json::parse(line, nullptr, false);
      if (req.is_discarded() || !req.is_object())
        return error_reply("invalid_request",
                           "a request is one JSON object with a \"cmd\"");
      auto cmd = req.find("cmd");
      auto here = req.count("module") == 0;
      if (cmd != req.end() && cmd->is_string()) {
        auto local = locals_.find(cmd->get<std::string>());
        if (local != locals_.end() && here) {
          // They may block and were written for one caller at a time.
          std::lock_guard<std::mutex> guard{locals_mtx_};
          return local->second(line);
        }
      }
      auto reply = ask_service(line);
      if (here && cmd != req.end() && *cmd == "stats") {
        // This socket's own counters join the module's.
        auto j = json::parse(reply, nullptr, false);
        if (control_json::is_ok_reply(j)
            && j["result"].is_object()) {
          j["result"]["control_socket"] = counters();
          return control_json::dump(j);
        }
      }
      return reply;
    } catch (const std::exception& e) {
      return error_reply("internal", e.what());
    }
  }

  /// Asks the service through a helper actor and waits for its answer
  /// here, watching the stop pipe: stopping the server ends the helper and
  /// does not wait for a slow request.
  std::string ask_service(const std::string& line, caf::actor writer = {}) {
    auto result = std::make_shared<std::promise<std::string>>();
    auto answer = result->get_future();
    auto helper = sys_.spawn([service = service_, line, result, writer,
                              deadline = control_deadline(line)](
                               caf::event_based_actor* self) {
      auto on_reply = [result](std::string& r) {
        result->set_value(std::move(r));
      };
      auto on_error = [result](caf::error& err) {
        auto timed_out = err == caf::make_error(caf::sec::request_timeout);
        result->set_value(error_reply(
          timed_out ? "timeout" : "unavailable",
          timed_out ? "the control service did not answer in time"
                    : "control service: " + render(err)));
      };
      if (writer)
        self->request(service, deadline, atom::subscribe_v, line, writer)
          .then(on_reply, on_error);
      else
        self->request(service, deadline, line).then(on_reply, on_error);
    });
    while (answer.wait_for(std::chrono::milliseconds(0))
           != std::future_status::ready) {
      pollfd p{stop_read_, POLLIN, 0};
      if (::poll(&p, 1, 50) > 0) {
        caf::anon_send_exit(helper, caf::exit_reason::user_shutdown);
        return error_reply("unavailable", "the control socket is closing");
      }
    }
    try {
      return answer.get();
    } catch (const std::future_error&) {
      // The helper ended without an answer (the actor system stops).
      return error_reply("unavailable", "the control service is stopping");
    }
  }

  caf::actor_system& sys_;
  control_actor service_;
  std::string path_;
  local_commands locals_;
  std::mutex locals_mtx_;
  int listen_fd_;
  int stop_read_;
  int stop_write_;
  ino_t inode_;
  int reaped_fd_;
  std::atomic<size_t> clients_{0};
  std::atomic<uint64_t> clients_refused_{0};
  std::atomic<uint64_t> clients_timed_out_{0};
  std::atomic<uint64_t> lines_too_long_{0};
  std::thread thread_;
};

/// True if something accepts connections at `path`.
bool live_socket(const sockaddr_un& addr) {
  fd_guard fd{::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0)};
  if (fd.fd < 0)
    return false;
  return ::connect(fd.fd, reinterpret_cast<const sockaddr*>(&addr),
                   sizeof(addr))
         == 0;
}

} // namespace

// -- control_server ------------------------------------------------------------------

caf::expected<std::unique_ptr<control_server>>
control_server::start(caf::actor_system& sys, control_actor service,
                      std::string path, local_commands locals) {
  namespace fs = std::filesystem;
  sockaddr_un addr;
  if (!make_address(path, addr))
    return make_error(ec::invalid_parameter,
                      "control socket '" + path + "': "
                        + (path.empty() ? std::string{"empty path"}
                                        : "longer than "
                                            + std::to_string(sizeof(addr.sun_path) - 1)
                                            + " bytes"));
  auto fail = [&](ec code, const std::string& what, int err) {
    return make_error(code, "control socket '" + path + "': " + what + ": "
                              + errno_text(err));
  };
  // Parent directory: created private if missing.
  auto parent = fs::path{path}.parent_path();
  if (!parent.empty()) {
    std::error_code fec;
    if (!fs::exists(parent, fec)) {
      fs::create_directories(parent, fec);
      if (fec)
        return make_error(ec::device_unavailable,
                          "control socket '" + path + "': cannot create "
                            + parent.string() + ": " + fec.message());
      ::chmod(parent.c_str(), 0700);
    }
  }
  // An existing file: a live endpoint is an error; a stale socket goes.
  struct stat sb;
  if (::lstat(path.c_str(), &sb) == 0) {
    if (!S_ISSOCK(sb.st_mode))
      return make_error(ec::already_exists, "control socket '" + path
                                              + "': exists and is not a socket");
    if (live_socket(addr))
      return make_error(ec::already_exists,
                        "control socket '" + path
                          + "': a module is already listening there");
    ::unlink(path.c_str());
  }
  fd_guard fd{::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0)};
  if (fd.fd < 0)
    return fail(ec::device_unavailable, "socket", errno);
  if (::bind(fd.fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0)
    return fail(errno == EADDRINUSE ? ec::already_exists : ec::device_unavailable,
                "bind", errno);
  ::chmod(path.c_str(), 0600);
  if (::lstat(path.c_str(), &sb) != 0 || ::listen(fd.fd, 16) != 0) {
    auto err = errno;
    ::unlink(path.c_str());
    return fail(ec::device_unavailable, "listen", err);
  }
  int pipe_fds[2];
  if (::pipe2(pipe_fds, O_CLOEXEC) != 0) {
    auto err = errno;
    ::unlink(path.c_str());
    return fail(ec::device_unavailable, "pipe", err);
  }
  std::unique_ptr<control_server> result{
    new server_impl(sys, std::move(service), path, std::move(locals),
                    fd.release(), pipe_fds[0], pipe_fds[1], sb.st_ino)};
  return result;
}

control_server::~control_server() = default;

const std::string& control_server::path() const {
  return static_cast<const server_impl*>(this)->socket_path();
}

// -- client --------------------------------------------------------------------------

caf::expected<std::string> control_call(const std::string& path,
                                        const std::string& request,
                                        std::chrono::milliseconds timeout) {
  auto deadline = clock_type::now() + timeout;
  sockaddr_un addr;
  if (!make_address(path, addr))
    return make_error(ec::invalid_parameter,
                      "'" + path + "' is not a usable socket path");
  fd_guard fd{::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0)};
  if (fd.fd < 0)
    return make_error(ec::device_unavailable, "socket: " + errno_text(errno));
  if (::connect(fd.fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr))
      != 0) {
    auto err = errno;
    if (err == ENOENT || err == ECONNREFUSED || err == ENOTDIR)
      return make_error(app_ec::not_found, "no module listening at " + path
                                         + " (is hermd running?)");
    return make_error(ec::device_unavailable,
                      "cannot connect to " + path + ": " + errno_text(err));
  }
  // A raw newline in JSON can only be whitespace: keep the request one line.
  auto line = request;
  for (auto& c : line)
    if (c == '\n' || c == '\r')
      c = ' ';
  line += '\n';
  if (!write_all(fd.fd, line, deadline))
    return make_error(ec::device_failed,
                      "cannot send the request to " + path + ": "
                        + errno_text(errno));
  std::string buf;
  for (;;) {
    auto nl = buf.find('\n');
    if (nl != std::string::npos) {
      buf.resize(nl);
      return buf;
    }
    if (buf.size() > 64 * max_line)
      return make_error(ec::invalid_parameter,
                        "the reply from " + path + " is too long");
    if (!wait_ready(fd.fd, POLLIN, deadline))
      return make_error(ec::timeout, "no reply from " + path + " within "
                                       + std::to_string(timeout.count())
                                       + " ms");
    char chunk[4096];
    auto n = ::recv(fd.fd, chunk, sizeof(chunk), MSG_DONTWAIT);
    if (n < 0 && (errno == EINTR || errno == EAGAIN))
      continue;
    if (n <= 0)
      return make_error(ec::device_failed,
                        path + " closed the connection without a reply");
    buf.append(chunk, static_cast<size_t>(n));
  }
}

} // namespace herm
