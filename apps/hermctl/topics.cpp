#include "apps/hermctl/topics.hpp"

#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <deque>
#include <iomanip>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "actors/control.hpp"
#include "actors/text_form.hpp"
#include "apps/hermctl/bag.hpp"
#include "apps/hermctl/format.hpp"
#include "routing/module_id.hpp"

namespace hermctl {

namespace {

using json = nlohmann::ordered_json;
using clock_type = std::chrono::steady_clock;
using namespace std::chrono_literals;

constexpr int exit_ok = 0;
constexpr int exit_failed = 1;
constexpr int exit_usage = 2;
constexpr int exit_unreachable = 3;

/// Set by SIGINT and SIGTERM: a stream ends cleanly (a recording is
/// committed) instead of dying.
std::atomic<bool> interrupted{false};

extern "C" void on_signal(int) {
  interrupted = true;
}

void catch_signals() {
  struct sigaction sa;
  std::memset(&sa, 0, sizeof(sa));
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

/// One connection to a control socket, kept for many lines (a stream, or
/// a publication after another).
class connection {
public:
  explicit connection(const std::string& path) : path_(path) {
    fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr;
    std::memset(&addr, 0, sizeof(addr));
    addr.sun_family = AF_UNIX;
    if (fd_ < 0 || path.size() >= sizeof(addr.sun_path))
      throw topic_failure{exit_unreachable, "cannot use socket " + path};
    std::memcpy(addr.sun_path, path.data(), path.size());
    if (::connect(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0)
      throw topic_failure{exit_unreachable,
                          "no module listening at " + path
                            + " (is hermd running?)"};
  }

  ~connection() {
    if (fd_ >= 0)
      ::close(fd_);
  }

  connection(const connection&) = delete;
  connection& operator=(const connection&) = delete;

  void send(const json& req) {
    auto text = req.dump() + '\n';
    size_t done = 0;
    while (done < text.size()) {
      auto n = ::send(fd_, text.data() + done, text.size() - done, MSG_NOSIGNAL);
      if (n < 0 && errno == EINTR)
        continue;
      if (n <= 0)
        throw topic_failure{exit_unreachable,
                            "the module at " + path_ + " closed the connection"};
      done += static_cast<size_t>(n);
    }
  }

  /// The next line; nullopt when `deadline` passes or we are interrupted;
  /// throws when the module closes the connection.
  std::optional<std::string> line(clock_type::time_point deadline) {
    for (;;) {
      if (auto l = buffered())
        return l;
      if (interrupted)
        return std::nullopt;
      auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - clock_type::now());
      if (left.count() <= 0)
        return std::nullopt;
      pollfd p{fd_, POLLIN, 0};
      auto n = ::poll(&p, 1, static_cast<int>(std::min<int64_t>(left.count(), 100)));
      if (n > 0)
        fill();
    }
  }

  /// A whole line already received, if there is one.
  std::optional<std::string> buffered() {
    auto nl = buf_.find('\n');
    if (nl == std::string::npos)
      return std::nullopt;
    auto l = buf_.substr(0, nl);
    buf_.erase(0, nl + 1);
    return l;
  }

  /// Reads what the socket holds (once poll said it is readable); throws
  /// when the module closed the connection.
  void fill() {
    char chunk[8192];
    auto r = ::recv(fd_, chunk, sizeof(chunk), MSG_DONTWAIT);
    if (r < 0 && (errno == EINTR || errno == EAGAIN))
      return;
    if (r <= 0)
      throw topic_failure{exit_unreachable,
                          "the module at " + path_ + " closed the connection"};
    buf_.append(chunk, static_cast<size_t>(r));
  }

  int fd() const noexcept {
    return fd_;
  }

  /// Sends `req` and returns the reply's result; a failure for an error.
  json call(const json& req, std::chrono::milliseconds timeout) {
    send(req);
    auto l = line(clock_type::now() + timeout);
    if (!l)
      throw topic_failure{interrupted ? exit_failed : exit_unreachable,
                          interrupted ? "interrupted"
                                      : "no reply from " + path_ + " in time"};
    return result_of(*l);
  }

  /// The result of a reply line; a failure for an error reply.
  json result_of(const std::string& reply) {
    auto j = json::parse(reply, nullptr, false);
    if (j.is_discarded() || !j.is_object() || !j.contains("ok"))
      throw topic_failure{exit_failed, "the module at " + path_
                                         + " sent a reply that is not a "
                                           "control reply: "
                                         + reply.substr(0, 200)};
    if (j["ok"] != true) {
      auto err = j.value("error", json::object());
      auto code = err.value("code", std::string{"error"});
      auto msg = err.value("message", std::string{});
      throw topic_failure{exit_failed,
                          msg.empty() ? code : msg + " [" + code + "]"};
    }
    return j.value("result", json{});
  }

private:
  std::string path_;
  int fd_ = -1;
  std::string buf_;
};

/// Opens a stream of `topics`; returns the connection after its first line.
std::unique_ptr<connection> open_stream(const std::string& path,
                                        const std::vector<std::string>& topics,
                                        bool raw,
                                        std::chrono::milliseconds timeout) {
  auto c = std::make_unique<connection>(path);
  c->call({{"cmd", "subscribe"}, {"topics", topics}, {"raw", raw}}, timeout);
  return c;
}

/// A value given on the command line: JSON, or else a plain word taken as
/// a string (`hermctl topic pub greeting hello`).
json parse_value(const std::string& text) {
  auto j = json::parse(text, nullptr, false);
  if (!j.is_discarded())
    return j;
  return json(text);
}

void print_ordered(std::ostream& out, const json& j) {
  out << j.dump(2, ' ', false, json::error_handler_t::replace) << '\n';
}

std::string value_text(const json& v) {
  return v.dump(-1, ' ', false, json::error_handler_t::replace);
}

/// A stream line that is not a value: a note of values dropped, or the
/// stream's end with an error. True if it was one.
bool stream_note(const json& line) {
  if (line.contains("error") && !line.contains("topic"))
    throw topic_failure{exit_failed, line["error"].get<std::string>()};
  if (line.contains("dropped") && !line.contains("topic")) {
    std::cerr << "hermctl: the module dropped " << line["dropped"]
              << " values this client did not read in time\n";
    return true;
  }
  if (line.contains("dropped"))
    std::cerr << "hermctl: " << line["dropped"]
              << " values were dropped before this one\n";
  return false;
}

std::string time_text(int64_t ns) {
  auto secs = static_cast<time_t>(ns / 1000000000);
  std::tm tm{};
  localtime_r(&secs, &tm);
  std::ostringstream out;
  out << std::put_time(&tm, "%Y-%m-%d %H:%M:%S") << '.' << std::setw(3)
      << std::setfill('0') << (ns / 1000000) % 1000;
  return out.str();
}

// -- the commands ----------------------------------------------------------------

int cmd_list(connection& c, std::chrono::milliseconds timeout, bool json_out) {
  auto r = c.call({{"cmd", "topics"}, {"all", true},
                   {"timeout_ms", timeout.count()}},
                  2 * timeout + 2s);
  if (json_out) {
    print_ordered(std::cout, r);
    return exit_ok;
  }
  std::vector<std::vector<std::string>> rows;
  for (auto& t : r.value("topics", json::array())) {
    auto join = [](const json& a) {
      std::string s;
      for (auto& x : a)
        s += (s.empty() ? "" : " ") + x.get<std::string>();
      return s.empty() ? std::string{"-"} : s;
    };
    auto type = t.value("type", std::string{});
    rows.push_back({t.value("topic", std::string{}), type.empty() ? "-" : type,
                    join(t["publishers"]), join(t["subscribers"])});
  }
  if (rows.empty())
    std::cout << "no topics (" << r.value("modules", 0) << " modules asked)\n";
  else
    print_table(std::cout, {"TOPIC", "TYPE", "PUBLISHERS", "SUBSCRIBERS"}, rows);
  auto unanswered = r.value("unanswered", json::array());
  if (!unanswered.empty())
    std::cerr << "hermctl: no answer from " << unanswered.size()
              << " module(s): " << value_text(unanswered) << '\n';
  return exit_ok;
}

int cmd_echo(const std::string& path, const std::string& topic, uint64_t count,
             bool raw, bool json_out, std::chrono::milliseconds timeout) {
  catch_signals();
  auto c = open_stream(path, {topic}, raw, timeout);
  uint64_t seen = 0;
  while (count == 0 || seen < count) {
    auto l = c->line(clock_type::now() + 24h);
    if (!l)
      break;
    auto j = json::parse(*l, nullptr, false);
    if (j.is_discarded() || stream_note(j))
      continue;
    ++seen;
    if (json_out)
      std::cout << value_text(j) << std::endl;
    else if (j.contains("error"))
      std::cout << "(cannot decode: " << j["error"].get<std::string>() << ")"
                << std::endl;
    else
      std::cout << value_text(j["value"]) << std::endl;
  }
  return exit_ok;
}

/// ros2 topic hz: the rate over the last `window` values, printed every
/// second; `reports` of them (0: until interrupted).
int cmd_hz(const std::string& path, const std::string& topic, uint64_t window,
           uint64_t reports, bool json_out, std::chrono::milliseconds timeout) {
  catch_signals();
  auto c = open_stream(path, {topic}, false, timeout);
  std::deque<int64_t> times;
  uint64_t printed = 0;
  auto next = clock_type::now() + 1s;
  bool fresh = false;
  while (reports == 0 || printed < reports) {
    auto l = c->line(next);
    if (interrupted)
      break;
    if (l) {
      auto j = json::parse(*l, nullptr, false);
      if (j.is_discarded() || stream_note(j))
        continue;
      times.push_back(j.value("time_ns", int64_t{0}));
      fresh = true;
      while (times.size() > window + 1)
        times.pop_front();
      continue;
    }
    next += 1s;
    ++printed;
    if (!fresh || times.size() < 2) {
      if (json_out)
        std::cout << json{{"topic", topic}, {"messages", times.size()}}.dump()
                  << std::endl;
      else
        std::cout << "no new messages" << std::endl;
      continue;
    }
    fresh = false;
    double sum = 0, lo = 1e300, hi = 0;
    std::vector<double> periods;
    for (size_t i = 1; i < times.size(); ++i) {
      auto p = static_cast<double>(times[i] - times[i - 1]) / 1e9;
      periods.push_back(p);
      sum += p;
      lo = std::min(lo, p);
      hi = std::max(hi, p);
    }
    auto mean = sum / periods.size();
    double var = 0;
    for (auto p : periods)
      var += (p - mean) * (p - mean);
    auto std_dev = std::sqrt(var / periods.size());
    auto rate = mean > 0 ? 1.0 / mean : 0.0;
    if (json_out) {
      std::cout << json{{"topic", topic},
                        {"rate_hz", rate},
                        {"min_s", lo},
                        {"max_s", hi},
                        {"std_dev_s", std_dev},
                        {"window", periods.size()}}
                     .dump()
                << std::endl;
    } else {
      std::cout << std::fixed << std::setprecision(3) << "average rate: " << rate
                << "\n\tmin: " << lo << "s max: " << hi
                << "s std dev: " << std::setprecision(5) << std_dev
                << "s window: " << periods.size() << std::endl;
    }
  }
  return exit_ok;
}

json publish_request(const std::string& topic, const json& value,
                     const std::string& type) {
  json req{{"cmd", "publish"}, {"topic", topic}, {"value", value}};
  if (!type.empty())
    req["type"] = type;
  return req;
}

int cmd_pub(const std::string& path, const std::string& topic,
            const std::string& text, const std::string& type, double rate,
            uint64_t times, bool json_out, std::chrono::milliseconds timeout) {
  catch_signals();
  if (rate < 0)
    throw topic_failure{exit_usage, "--rate must be positive"};
  connection c{path};
  auto value = parse_value(text);
  auto req = publish_request(topic, value, type);
  if (rate == 0 && times == 0)
    times = 1;
  auto period = rate > 0 ? std::chrono::duration_cast<clock_type::duration>(
                             std::chrono::duration<double>(1.0 / rate))
                         : clock_type::duration::zero();
  auto next = clock_type::now();
  for (uint64_t n = 1; (times == 0 || n <= times) && !interrupted; ++n) {
    auto r = c.call(req, timeout);
    if (json_out)
      std::cout << value_text(r) << std::endl;
    else
      std::cout << "publishing #" << n << " on '" << topic << "' ("
                << r.value("type", std::string{}) << "): " << value_text(value)
                << std::endl;
    next += period;
    while (rate > 0 && !interrupted && clock_type::now() < next)
      std::this_thread::sleep_for(
        std::min<clock_type::duration>(next - clock_type::now(), 100ms));
  }
  return exit_ok;
}

int cmd_call(const std::string& path, const std::string& apo,
             const std::string& text, const std::string& type, bool json_out,
             std::chrono::milliseconds timeout) {
  connection c{path};
  json req{{"cmd", "call"},
           {"apo", apo},
           {"value", parse_value(text)},
           {"timeout_ms", timeout.count()}};
  if (!type.empty())
    req["type"] = type;
  auto r = c.call(req, herm::control_deadline(req.dump()) + 1s);
  if (json_out) {
    print_ordered(std::cout, r);
  } else {
    if (r.contains("error"))
      throw topic_failure{exit_failed, "the reply cannot be shown: "
                                         + r["error"].get<std::string>()};
    std::cout << r["value"].dump(2, ' ', false, json::error_handler_t::replace)
              << std::endl;
  }
  return exit_ok;
}

/// The topics every module knows of now (`topic list`'s request).
json topics_request(std::chrono::milliseconds timeout) {
  return {{"cmd", "topics"}, {"all", true}, {"timeout_ms", timeout.count()}};
}

std::vector<std::string> topic_names(const json& result) {
  std::vector<std::string> names;
  for (auto& t : result.value("topics", json::array()))
    if (t.is_object() && t.contains("topic") && t["topic"].is_string())
      names.push_back(t["topic"].get<std::string>());
  return names;
}

int cmd_record(const std::string& path, const std::string& out,
               std::vector<std::string> topics, uint64_t count,
               double duration_s, size_t max_subscriptions, bool json_out,
               std::chrono::milliseconds timeout) {
  catch_signals();
  if (out.empty())
    throw topic_failure{exit_usage, "record needs -o FILE (or --info FILE)"};
  // Without topics: every topic there is, and (as ros2 bag record -a) every
  // topic that appears while recording, asked for again every few seconds
  // on a connection of its own, so that the recording never waits for it.
  const bool every = topics.empty();
  if (every) {
    connection c{path};
    topics = topic_names(c.call(topics_request(timeout), 2 * timeout + 2s));
  }
  auto b = bag::create(out);
  std::vector<std::unique_ptr<connection>> streams;
  if (!topics.empty())
    streams.push_back(open_stream(path, topics, true, timeout));
  std::set<std::string> recording{topics.begin(), topics.end()};
  // New topics not recorded for want of a subscription (named once).
  std::set<std::string> skipped;
  b.set_metadata("recorded_by", "hermctl record");
  b.set_metadata("control_socket", path);
  std::cerr << "hermctl: recording " << topics.size() << " topic(s)"
            << (every ? " and every new one" : "") << " into " << out << '\n';
  constexpr auto rescan_every = 2s;
  std::unique_ptr<connection> lister;
  auto rescan_at = clock_type::now() + rescan_every;
  uint64_t n = 0;
  auto end = duration_s > 0
               ? clock_type::now()
                   + std::chrono::duration_cast<clock_type::duration>(
                     std::chrono::duration<double>(duration_s))
               : clock_type::time_point::max();
  auto full = [&] { return count != 0 && n >= count; };
  // Lines already read (with a subscription's reply, say) before polling.
  auto drain = [&] {
    for (auto& s : streams)
      while (!full())
        if (auto l = s->buffered())
          n += record_line(b, *l) ? 1 : 0;
        else
          break;
  };
  while (!full() && !interrupted && clock_type::now() < end) {
    drain();
    if (full())
      break;
    auto now = clock_type::now();
    if (every && !lister && now >= rescan_at) {
      lister = std::make_unique<connection>(path);
      lister->send(topics_request(timeout));
    }
    std::vector<pollfd> fds;
    for (auto& s : streams)
      fds.push_back({s->fd(), POLLIN, 0});
    if (lister)
      fds.push_back({lister->fd(), POLLIN, 0});
    auto wait = std::chrono::duration_cast<std::chrono::milliseconds>(
      std::min(end, now + 100ms) - now);
    if (::poll(fds.data(), fds.size(), static_cast<int>(wait.count())) <= 0)
      continue;
    for (size_t i = 0; i < streams.size(); ++i)
      if (fds[i].revents != 0)
        streams[i]->fill();
    drain();
    if (lister && fds.back().revents != 0) {
      lister->fill();
      if (auto l = lister->buffered()) {
        std::vector<std::string> fresh;
        try {
          for (auto& t : topic_names(lister->result_of(*l)))
            if (recording.count(t) == 0 && skipped.count(t) == 0)
              fresh.push_back(t);
        } catch (const topic_failure& e) {
          std::cerr << "hermctl: asking for new topics: " << e.message << '\n';
        }
        lister.reset();
        rescan_at = clock_type::now() + rescan_every;
        // Each batch of new topics is one more control connection (a
        // module serves 16 clients at once): at most max_subscriptions.
        if (!fresh.empty() && streams.size() >= max_subscriptions) {
          std::cerr << "hermctl: not recording " << fresh.size()
                    << " new topic(s), " << streams.size()
                    << " subscriptions open (--max-subscriptions):";
          for (auto& t : fresh)
            std::cerr << ' ' << t;
          std::cerr << '\n';
          if (skipped.size() < 4096)
            skipped.insert(fresh.begin(), fresh.end());
          fresh.clear();
        }
        recording.insert(fresh.begin(), fresh.end());
        if (!fresh.empty()) {
          streams.push_back(open_stream(path, fresh, true, timeout));
          std::cerr << "hermctl: recording " << fresh.size()
                    << " more topic(s):";
          for (auto& t : fresh)
            std::cerr << ' ' << t;
          std::cerr << '\n';
        }
      }
    }
  }
  b.flush();
  std::vector<std::string> names{recording.begin(), recording.end()};
  if (json_out)
    std::cout << json{{"file", out}, {"messages", n}, {"topics", names}}.dump()
              << std::endl;
  else
    std::cout << "recorded " << n << " messages into " << out << std::endl;
  return exit_ok;
}

int cmd_info(const std::string& file, bool json_out) {
  auto b = bag::open(file);
  auto info = b.info();
  auto secs = static_cast<double>(info.end_ns - info.start_ns) / 1e9;
  if (json_out) {
    json topics = json::array();
    for (auto& t : info.topics)
      topics.push_back({{"topic", t.name}, {"type", t.type}, {"count", t.count}});
    print_ordered(std::cout, {{"file", info.path},
                           {"bytes", info.size_bytes},
                           {"messages", info.messages},
                           {"start_ns", info.start_ns},
                           {"end_ns", info.end_ns},
                           {"duration_s", secs},
                           {"topics", topics},
                           {"described_types", info.descriptions.size()}});
    return exit_ok;
  }
  std::cout << "Files:             " << info.path << '\n'
            << "Bag size:          " << info.size_bytes << " B\n"
            << "Storage id:        sqlite3 (herm-apo-1)\n"
            << std::fixed << std::setprecision(3)
            << "Duration:          " << secs << "s\n";
  if (info.messages > 0)
    std::cout << "Start:             " << time_text(info.start_ns) << '\n'
              << "End:               " << time_text(info.end_ns) << '\n';
  std::cout << "Messages:          " << info.messages << '\n'
            << "Topic information: ";
  bool first = true;
  for (auto& t : info.topics) {
    std::cout << (first ? "" : "                   ") << "Topic: " << t.name
              << " | Type: " << (t.type.empty() ? "-" : t.type)
              << " | Count: " << t.count << " | Serialization Format: herm-apo-1"
              << '\n';
    first = false;
  }
  if (first)
    std::cout << '\n';
  std::cout << "Type descriptions: " << info.descriptions.size() << '\n';
  return exit_ok;
}

int cmd_play(const std::string& path, const std::string& file, double rate,
             bool loop, const std::vector<std::string>& only,
             const std::vector<std::string>& remaps, bool json_out,
             std::chrono::milliseconds timeout) {
  catch_signals();
  if (!(rate > 0))
    throw topic_failure{exit_usage, "--rate must be above 0"};
  std::map<std::string, std::string> renamed;
  for (auto& r : remaps) {
    auto sep = r.find(":=");
    if (sep == 0 || sep == std::string::npos || sep + 2 >= r.size())
      throw topic_failure{exit_usage, "--remap takes FROM:=TO, got '" + r + "'"};
    renamed[r.substr(0, sep)] = r.substr(sep + 2);
  }
  auto b = bag::open(file);
  connection c{path};
  uint64_t sent = 0;
  do {
    auto before = sent;
    int64_t first_ns = -1;
    auto start = clock_type::now();
    b.read(only, [&](const bag_message& m) {
      if (interrupted)
        return false;
      if (first_ns < 0)
        first_ns = m.time_ns;
      auto at = start
                + std::chrono::duration_cast<clock_type::duration>(
                  std::chrono::duration<double>(
                    static_cast<double>(m.time_ns - first_ns) / 1e9 / rate));
      while (!interrupted && clock_type::now() < at)
        std::this_thread::sleep_for(
          std::min<clock_type::duration>(at - clock_type::now(), 100ms));
      auto to = renamed.find(m.topic);
      try {
        c.call({{"cmd", "publish"},
                {"topic", to != renamed.end() ? to->second : m.topic},
                {"payload", herm::to_hex_bytes(m.payload.data(), m.payload.size())}},
               timeout);
      } catch (const topic_failure&) {
        // Ctrl-C while a publication waited for its reply: the way to end
        // --loop, not a failure (that one is not counted).
        if (interrupted)
          return false;
        throw;
      }
      ++sent;
      return true;
    });
    // A recording with nothing to play (empty, or nothing of --topics):
    // --loop would only spin.
    if (sent == before)
      break;
  } while (loop && !interrupted);
  if (json_out)
    std::cout << json{{"file", file}, {"published", sent}}.dump() << std::endl;
  else
    std::cout << "played " << sent << " messages from " << file << std::endl;
  return exit_ok;
}

} // namespace

bool record_line(bag& b, const std::string& l) {
  auto j = nlohmann::ordered_json::parse(l, nullptr, false);
  if (j.is_discarded() || !j.is_object() || stream_note(j))
    return false;
  auto text = [&](const char* key) -> const std::string* {
    auto it = j.find(key);
    return it != j.end() && it->is_string() ? &it->get_ref<const std::string&>()
                                            : nullptr;
  };
  auto number = [&](const char* key, auto& out) {
    auto it = j.find(key);
    if (it == j.end() || !it->is_number_integer())
      return false;
    out = it->get<std::decay_t<decltype(out)>>();
    return true;
  };
  auto payload_hex = text("payload");
  auto topic = text("topic");
  auto publisher = text("publisher");
  bag_message m;
  if (!payload_hex || !topic || !publisher || !number("time_ns", m.time_ns)
      || !number("seq", m.seq))
    return false;
  auto payload = herm::from_hex_bytes(*payload_hex);
  auto from = herm::parse_module_id(*publisher);
  if (!payload || !from)
    return false;
  auto types = j.find("types");
  if (types != j.end() && types->is_array() && !types->empty()) {
    if (!(*types)[0].is_string())
      return false;
    m.type = (*types)[0].get<std::string>();
  }
  auto descriptions = j.find("descriptions");
  if (descriptions != j.end() && descriptions->is_array())
    for (auto& d : *descriptions)
      if (d.is_object() && d.contains("name") && d["name"].is_string())
        b.describe(d["name"].get<std::string>(), d.dump());
  m.topic = *topic;
  m.publisher = *from;
  m.payload = std::move(*payload);
  b.add(m);
  return true;
}

topic_commands::topic_commands(CLI::App& app) {
  topic_ = app.add_subcommand("topic", "topics across the network: list, "
                                       "echo, hz, pub");
  topic_->require_subcommand(1);
  list_ = topic_->add_subcommand("list", "every topic with its type, "
                                         "publishers and subscribers");
  echo_ = topic_->add_subcommand("echo", "print each value of a topic as it "
                                         "arrives");
  echo_->add_option("TOPIC", topic, "topic name")->required();
  echo_->add_option("-n,--count", count, "stop after N values");
  echo_->add_flag("--raw", raw, "with --json: the payload bytes too");
  hz_ = topic_->add_subcommand("hz", "the rate of a topic, every second");
  hz_->add_option("TOPIC", topic, "topic name")->required();
  hz_->add_option("-w,--window", window, "values the rate is computed over "
                                         "(default 10000)")
    ->check(CLI::Range(uint64_t{1}, uint64_t{1000000}));
  hz_->add_option("-n,--count", count, "stop after N reports");
  pub_ = topic_->add_subcommand("pub", "publish a value, once or at a rate");
  pub_->add_option("TOPIC", topic, "topic name")->required();
  pub_->add_option("VALUE", value, "the value in the text form (JSON)")
    ->required();
  pub_->add_option("-t,--type", type, "its type (default: from the value: "
                                      "@str, @i64, double, bool)");
  pub_->add_option("-r,--rate", rate, "publish at this rate, Hz");
  pub_->add_option("-n,--times", count, "publish N times (default: once, or "
                                        "until interrupted with --rate)");
  call_ = app.add_subcommand("call", "send a request to an APO by name and "
                                     "print its reply");
  call_->add_option("APO", apo, "APO name")->required();
  call_->add_option("VALUE", value, "the request in the text form (JSON)")
    ->required();
  call_->add_option("-t,--type", type, "its type (default: from the value)");
  record_ = app.add_subcommand("record", "record topics into an SQLite file");
  record_->add_option("TOPIC", topics, "topics (default: every topic, "
                                       "those that appear later too)");
  record_->add_option("-o,--output", output, "the file to create");
  record_->add_option("--info", info_file, "summarise a recording instead");
  record_->add_option("-n,--count", count, "stop after N messages");
  record_->add_option("-d,--duration", duration_s, "stop after S seconds");
  record_->add_option("--max-subscriptions", max_subscriptions,
                      "without topics: most control connections for the "
                      "topics that appear while recording (default 8)")
    ->check(CLI::Range(1, 12));
  play_ = app.add_subcommand("play", "publish a recording again with its "
                                     "timing");
  play_->add_option("FILE", file, "the recording")->required();
  play_->add_option("-r,--rate", play_rate, "speed factor (default 1)");
  play_->add_flag("-l,--loop", loop, "start again at the end");
  play_->add_option("--topics", topics, "only these topics");
  play_->add_option("--remap", remaps, "publish topic FROM as TO (FROM:=TO)");
}

bool topic_commands::parsed() const {
  return topic_->parsed() || call_->parsed() || record_->parsed()
         || play_->parsed();
}

bool topic_commands::needs_module() const {
  return !(record_->parsed() && !info_file.empty());
}

int topic_commands::run(const std::string& path, uint32_t timeout_ms,
                        bool json_out) {
  auto timeout = std::chrono::milliseconds(timeout_ms);
  try {
    if (list_->parsed()) {
      connection c{path};
      return cmd_list(c, timeout, json_out);
    }
    if (echo_->parsed())
      return cmd_echo(path, topic, count, raw, json_out, timeout);
    if (hz_->parsed())
      return cmd_hz(path, topic, window, count, json_out, timeout);
    if (pub_->parsed())
      return cmd_pub(path, topic, value, type, rate, count, json_out, timeout);
    if (call_->parsed())
      return cmd_call(path, apo, value, type, json_out, timeout);
    if (record_->parsed()) {
      if (!info_file.empty())
        return cmd_info(info_file, json_out);
      return cmd_record(path, output, topics, count, duration_s,
                        max_subscriptions, json_out, timeout);
    }
    if (play_->parsed())
      return cmd_play(path, file, play_rate, loop, topics, remaps, json_out,
                      timeout);
  } catch (const bag_error& e) {
    throw topic_failure{exit_failed, e.what()};
  }
  return exit_usage;
}

} // namespace hermctl
