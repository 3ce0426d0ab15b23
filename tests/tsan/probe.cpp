// Checks that a ThreadSanitizer build means something (tests/tsan/run.sh):
//
//   tsan_probe handoff   two detached actors (threads of their own) and the
//                        caller pass a vector around by message; each
//                        writes it in turn. With
//                        CAF instrumented, TSan sees the mailbox's
//                        synchronisation: no report, exit 0. (With Debian's
//                        uninstrumented CAF this reports a race.)
//   tsan_probe race      the same two actors count up one global at the
//                        same time, without synchronisation: TSan must
//                        report a data race (exit 66).
//
// tests/tsan/CMakeLists.txt registers both; a TSan setup that hides real
// races or reports message passing as one fails them.

#include <atomic>
#include <cstdio>
#include <cstring>
#include <thread>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/scoped_actor.hpp"

#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "channels/messages.hpp"

namespace {

long unsynchronised = 0;

// Both workers wait here until both have arrived, so that their writes
// overlap in time. Relaxed operations give TSan no happens-before edge (a
// mutex here would order the writes and hide the race).
std::atomic<int> arrived{0};

caf::behavior worker(caf::event_based_actor*) {
  return {
    // handoff: the frame is this actor's until it answers; write it all.
    [](herm::frame_received& f, int32_t left)
      -> caf::result<herm::frame_received, int32_t> {
      for (auto& x : f.bytes)
        ++x;
      return {std::move(f), left - 1};
    },
    // race: count up a global that the other worker counts up as well.
    [](int32_t n) {
      arrived.fetch_add(1, std::memory_order_relaxed);
      while (arrived.load(std::memory_order_relaxed) < 2)
        std::this_thread::yield();
      for (int i = 0; i < n; ++i)
        ++unsynchronised;
      return n;
    },
  };
}

} // namespace

int main(int argc, char** argv) {
  bool race = argc == 2 && std::strcmp(argv[1], "race") == 0;
  if (argc != 2 || (!race && std::strcmp(argv[1], "handoff") != 0)) {
    std::fprintf(stderr, "usage: %s handoff|race\n", argv[0]);
    return 2;
  }
  caf::actor_system_config cfg;
  herm::configure(cfg);
  caf::actor_system sys{cfg};
  // Detached: each worker has its own thread, as do the caller's requests.
  auto a = sys.spawn<caf::detached>(worker);
  auto b = sys.spawn<caf::detached>(worker);
  caf::scoped_actor self{sys};
  bool ok = true;
  if (race) {
    constexpr int32_t n = 100000;
    self->send(a, n);
    self->send(b, n);
    for (int i = 0; i < 2; ++i)
      self->receive([](int32_t) {}, [&](caf::error&) { ok = false; });
    std::printf("race: counted to %ld\n", unsynchronised);
  } else {
    constexpr int32_t rounds = 200; // xs[i] is a byte
    herm::frame_received f;
    f.bytes.assign(64, 0);
    for (int32_t left = rounds; ok && left > 0;) {
      self->request(left % 2 == 0 ? a : b, caf::infinite, std::move(f), left)
        .receive(
          [&](herm::frame_received& back, int32_t next) {
            f = std::move(back);
            left = next;
          },
          [&](caf::error&) { ok = false; });
    }
    ok = ok && f.bytes.size() == 64 && f.bytes[0] == rounds;
    std::printf("handoff: %d rounds, data[0] = %d\n", rounds,
                f.bytes.empty() ? -1 : f.bytes[0]);
  }
  self->send_exit(a, caf::exit_reason::user_shutdown);
  self->send_exit(b, caf::exit_reason::user_shutdown);
  return ok ? 0 : 1;
}
