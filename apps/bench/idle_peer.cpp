// bench_idle_peer: a process that does nothing, as a reference for hermd's
// idle footprint (apps/bench/hermd_footprint.py, issue 7).
//
//   bench_idle_peer caf        a bare caf::actor_system with CAF's defaults
//                              (stealing scheduler, one worker per core)
//   bench_idle_peer caf-herm   a bare caf::actor_system configured as hermd
//                              configures it (herm::configure: the loop
//                              scheduler, HERM's message types)
//   bench_idle_peer dds        one Cyclone DDS domain participant on the
//                              loopback interface (when built with Cyclone
//                              DDS)
//
// Prints "ready" on stdout once set up, then waits for SIGINT or SIGTERM and
// exits 0. Exit status 2 for a bad argument, 77 when the kind is not built in.

#include <signal.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"

#include "actors/runtime/system.hpp"

#ifdef HERM_BENCH_HAVE_DDS
#  include <dds/dds.h>
#endif

namespace {

/// Blocks SIGINT and SIGTERM in every thread started after this call, so
/// that wait_for_stop() receives them.
sigset_t block_stop_signals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  return set;
}

void wait_for_stop(const sigset_t& set) {
  std::printf("ready\n");
  std::fflush(stdout);
  int sig = 0;
  sigwait(&set, &sig);
}

int run_caf(const sigset_t& set, bool herm_config) {
  caf::actor_system_config cfg;
  if (herm_config)
    herm::configure(cfg); // hermd's default: the loop scheduler
  else
    cfg.set("logger.verbosity", caf::atom("quiet"));
  caf::actor_system sys{cfg};
  wait_for_stop(set);
  return 0;
}

int run_dds([[maybe_unused]] const sigset_t& set) {
#ifdef HERM_BENCH_HAVE_DDS
  // Loopback only, no multicast: the same set-up as herm-bench-rtt's dds
  // transport, so the process has its receive threads and its timers.
  ::setenv("CYCLONEDDS_URI",
           "<General><Interfaces><NetworkInterface address=\"127.0.0.1\"/>"
           "</Interfaces><AllowMulticast>false</AllowMulticast></General>"
           "<Discovery><Peers><Peer address=\"127.0.0.1\"/></Peers>"
           "</Discovery>",
           0);
  auto participant = dds_create_participant(DDS_DOMAIN_DEFAULT, nullptr,
                                            nullptr);
  if (participant < 0) {
    std::fprintf(stderr, "bench_idle_peer: dds_create_participant: %s\n",
                 dds_strretcode(-participant));
    return 1;
  }
  wait_for_stop(set);
  dds_delete(participant);
  return 0;
#else
  std::fprintf(stderr, "bench_idle_peer: built without Cyclone DDS "
                       "(cyclonedds-dev)\n");
  return 77;
#endif
}

} // namespace

int main(int argc, char** argv) {
  std::string kind = argc == 2 ? argv[1] : "";
  auto set = block_stop_signals();
  if (kind == "caf")
    return run_caf(set, false);
  if (kind == "caf-herm")
    return run_caf(set, true);
  if (kind == "dds")
    return run_dds(set);
  std::fprintf(stderr, "usage: bench_idle_peer caf|caf-herm|dds\n");
  return 2;
}
