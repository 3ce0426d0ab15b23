#include "channels/drivers/loop_watch.hpp"

#include <sys/epoll.h>

namespace herm {

caf::error loop_watch::start(event_loop& loop, int fd, bool has_handler,
                             const char* noun, const fail_fn& fail,
                             const std::function<caf::error()>& prepare,
                             event_loop::io_callback on_ready,
                             const std::function<void()>& running) {
  caf::error result;
  loop.run_sync([&] {
    std::lock_guard<std::mutex> guard{mtx_};
    if (state_ != state::opened) {
      result = fail(ec::device_unavailable, state_ == state::running
                                              ? "already started"
                                              : "already stopped");
      return;
    }
    if (!has_handler) {
      result = fail(ec::invalid_parameter, "start needs a frame handler");
      return;
    }
    if (prepare && (result = prepare()))
      return;
    if (auto err = loop.watch(fd, EPOLLIN, std::move(on_ready))) {
      result = fail(ec::device_unavailable,
                    std::string{"cannot watch the "} + noun + ": "
                      + render(err));
      return;
    }
    fd_ = fd;
    loop_ = &loop;
    state_ = state::running;
    running();
  });
  return result;
}

void loop_watch::stop(const std::function<void()>& close) {
  event_loop* loop;
  {
    std::lock_guard<std::mutex> guard{mtx_};
    if (state_ == state::stopped)
      return;
    if (state_ == state::opened) { // never started: nothing is watched
      stopping_ = true;
      state_ = state::stopped;
      close();
      return;
    }
    loop = loop_;
  }
  loop->run_sync([&] {
    std::lock_guard<std::mutex> guard{mtx_};
    if (state_ != state::running)
      return; // another stop came first
    stopping_ = true;
    state_ = state::stopped;
    loop->unwatch(fd_);
    close();
  });
}

} // namespace herm
