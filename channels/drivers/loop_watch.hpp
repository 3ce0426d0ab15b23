#pragma once

// The life cycle the descriptor drivers (udp, serial, SocketCAN) share on
// the module's event loop: opened, then running (one descriptor watched on a
// loop), then stopped. It owns the state, the loop and the lock; the driver
// says what to prepare, what to do once watched and how to close.

#include <atomic>
#include <functional>
#include <mutex>
#include <string>

#include "caf/error.hpp"

#include "channels/error.hpp"
#include "channels/event_loop.hpp"

namespace herm {

/// Threading: start and stop from any thread (they run their part on the
/// loop's thread through run_sync, never holding the lock while they wait
/// for it); stop also from inside a handler call, where it ends delivery at
/// once. stopping() and loop() from any thread.
class loop_watch {
public:
  /// Names the device in errors: the driver's own fail(code, text).
  using fail_fn = std::function<caf::error(ec, const std::string&)>;

  /// On `loop`'s thread, under the lock: refuses unless never started
  /// (ec::device_unavailable, "already started" / "already stopped") and
  /// without a handler (ec::invalid_parameter, "start needs a frame
  /// handler"); runs `prepare` (the driver's own set-up; an error refuses);
  /// watches `fd` for EPOLLIN with `on_ready` (ec::device_unavailable,
  /// "cannot watch the NOUN: ..." when epoll refuses); then `running`
  /// (store the handler, arm what waits). Every error goes through `fail`.
  caf::error start(event_loop& loop, int fd, bool has_handler,
                   const char* noun, const fail_fn& fail,
                   const std::function<caf::error()>& prepare,
                   event_loop::io_callback on_ready,
                   const std::function<void()>& running);

  /// Idempotent. Never started: marks stopped and calls `close` at once.
  /// Running: on the loop's thread, once, marks stopping, unwatches the
  /// descriptor and calls `close` (close it, drop the handler). Returns after
  /// the last handler call. `close` runs under the lock.
  void stop(const std::function<void()>& close);

  /// Whether stop began: a readiness callback checks it after each handler
  /// call and touches the descriptor no more once it is set.
  bool stopping() const {
    return stopping_.load();
  }

  /// The loop while running or stopped after running, else nullptr.
  event_loop* loop() const {
    return loop_.load();
  }

  /// Stops watching the descriptor after a failure (send() may go on until
  /// stop). Loop thread, while running.
  void unwatch() {
    loop_.load()->unwatch(fd_);
  }

private:
  enum class state { opened, running, stopped };

  std::mutex mtx_;
  state state_ = state::opened;
  int fd_ = -1;
  std::atomic<event_loop*> loop_{nullptr};
  std::atomic<bool> stopping_{false};
};

} // namespace herm
