#pragma once

// Messages an actor does not handle. CAF's default handler prints each one
// with its content to stdout: an APO reachable from the network would print
// whatever anybody sends it, as fast as it is sent. HERM's APOs use
// `log_unexpected` instead (`self->set_default_handler(log_unexpected)`):
// it counts every such message (process-wide, `unexpected_messages()`, shown
// as `unexpected_messages` in `hermctl stats`), logs at most `burst` lines
// and then one per second (a token bucket; the next line says how many were
// not logged), naming the actor and the element types, never the content,
// and drops the message. A request gets CAF's unexpected_message error back.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <mutex>
#include <string>
#include <utility>

#include "caf/actor_system.hpp"
#include "caf/message_view.hpp"
#include "caf/uniform_type_info_map.hpp"
#include "caf/result.hpp"
#include "caf/scheduled_actor.hpp"
#include "caf/sec.hpp"

namespace herm {

/// Where log_unexpected writes its lines (hermd: its logger at warn level).
using unexpected_sink = std::function<void(const std::string&)>;

namespace detail {

/// The process-wide state behind log_unexpected. Thread-safe.
struct unexpected_log {
  static constexpr uint32_t burst = 10;
  static constexpr std::chrono::milliseconds refill{1000};

  std::atomic<uint64_t> count{0};
  std::mutex mtx;
  /// Tokens left; one comes back per `refill`, up to `burst`.
  uint32_t tokens = burst;
  std::chrono::steady_clock::time_point last_refill
    = std::chrono::steady_clock::now();
  uint64_t suppressed = 0;
  unexpected_sink sink;

  static unexpected_log& instance() {
    static unexpected_log x;
    return x;
  }

  /// Returns the line to log, or empty if over the rate (counted as
  /// suppressed). `now` is passed in for tests.
  std::string admit(const std::string& line,
                    std::chrono::steady_clock::time_point now) {
    std::lock_guard<std::mutex> guard{mtx};
    auto earned = (now - last_refill) / refill;
    if (earned > 0) {
      tokens = static_cast<uint32_t>(
        std::min<int64_t>(burst, tokens + static_cast<int64_t>(earned)));
      last_refill += earned * refill;
    }
    if (tokens == 0) {
      ++suppressed;
      return {};
    }
    --tokens;
    if (suppressed == 0)
      return line;
    auto result = line + " (" + std::to_string(suppressed)
                  + " more not logged)";
    suppressed = 0;
    return result;
  }
};

} // namespace detail

/// Messages dropped by log_unexpected in this process so far.
inline uint64_t unexpected_messages() {
  return detail::unexpected_log::instance().count.load();
}

/// Sets where log_unexpected writes (default: stderr).
inline void set_unexpected_sink(unexpected_sink f) {
  auto& x = detail::unexpected_log::instance();
  std::lock_guard<std::mutex> guard{x.mtx};
  x.sink = std::move(f);
}

/// The type names of a message's elements, "(int32_t, std::string)".
inline std::string type_names_of(caf::actor_system& sys,
                                 const caf::message_view& x) {
  auto& content = x.content();
  std::string result = "(";
  for (size_t i = 0; i < content.size(); ++i) {
    if (i > 0)
      result += ", ";
    result += sys.types().portable_name(content.type(i));
  }
  return result + ")";
}

/// A default handler for scheduled actors; see the file comment.
inline caf::result<caf::message> log_unexpected(caf::scheduled_actor* self,
                                                caf::message_view& x) {
  auto& log = detail::unexpected_log::instance();
  ++log.count;
  auto line = log.admit(std::string{"unexpected message at "} + self->name()
                          + " (actor " + std::to_string(self->id())
                          + "): " + type_names_of(self->system(), x)
                          + ", dropped",
                        std::chrono::steady_clock::now());
  if (!line.empty()) {
    unexpected_sink sink;
    {
      std::lock_guard<std::mutex> guard{log.mtx};
      sink = log.sink;
    }
    if (sink)
      sink(line);
    else
      std::fprintf(stderr, "%s\n", line.c_str());
  }
  return caf::sec::unexpected_message;
}

} // namespace herm
