// bench_gateway: what the DDS gateway (apps/dds_gateway) costs, next to
// plain DDS (issue 19, item 6). Two processes on one DDS domain on
// loopback: a reader process (this one: DDS only) and a sender process
// (forked) that runs both paths in turn:
//
//   herm   a HERM APO publishes std_msgs/msg/Float64 values on HERM topics;
//          the module's gateway writes them to DDS
//   dds    a plain DDS writer of the same process writes the same values:
//          the reference
//
// Each value is its send time (CLOCK_MONOTONIC in ns, exact in a double),
// so the reader computes each one's latency. Latency: SAMPLES values, one
// per millisecond (nothing queues). Throughput: COUNT values back to back;
// delivered values per second from the first send to the last arrival, and
// how many never came (the reader keeps the last 1000 unread).
//
//   bench_gateway [SAMPLES] [COUNT] [DOMAIN]      (1000, 20000, 199)
//
// Prints one line per path: "<path> latency p50 .. us p90 .. p99 .. max ..
// (n samples) | throughput .. msg/s, lost ..". Exit 1 if a path delivered
// nothing.

#include <stdlib.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/event_based_actor.hpp"
#include "caf/send.hpp"

#include "actors/module.hpp"
#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "apps/dds_gateway/gateway.hpp"

#include "std_msgs/Basic.h"

using namespace herm;
using namespace std::chrono_literals;

namespace {

const char* loopback_only
  = "<CycloneDDS><Domain><General><Interfaces><NetworkInterface name=\"lo\"/>"
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
    "<Peers><Peer address=\"127.0.0.1\"/></Peers><ParticipantIndex>auto"
    "</ParticipantIndex></Discovery></Domain></CycloneDDS>";

constexpr int32_t depth = 1000;

double now_ns() {
  timespec ts;
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<double>(ts.tv_sec) * 1e9 + static_cast<double>(ts.tv_nsec);
}

dds_qos_t* qos() {
  auto* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, depth);
  return q;
}

dds_entity_t topic(dds_entity_t pp, const char* name) {
  return dds_create_topic(pp, &std_msgs_msg_dds__Float64__desc, name, nullptr,
                          nullptr);
}

// -- the sender process ---------------------------------------------------------------

/// Sends `samples` values one per ms, then `count` back to back, each
/// value its send time.
template <class Send>
void send_all(int samples, int count, Send send_lat, Send send_tput) {
  for (int i = 0; i < samples; ++i) {
    send_lat(now_ns());
    std::this_thread::sleep_for(1ms);
  }
  for (int i = 0; i < count; ++i)
    send_tput(now_ns());
}

int sender(int samples, int count, uint32_t domain) {
  caf::actor_system_config cfg;
  configure(cfg);
  cfg.add_message_types<caf::id_block::herm_apos>();
  dds_gateway::add_gateway_types(cfg);
  caf::actor_system sys{cfg};
  module_config mc;
  mc.routing.id = 0x51;
  auto m = run_module(sys, mc);
  if (!m)
    return 1;
  auto gcfg = dds_gateway::parse_gateway_options(
    {{"domain", std::to_string(domain)},
     {"lat.type", "std_msgs/msg/Float64"},
     {"tput.type", "std_msgs/msg/Float64"},
     {"tput.depth", std::to_string(depth)}});
  auto gw = dds_gateway::spawn_dds_gateway(sys, m->handles(), *gcfg);
  if (!gw)
    return 1;
  auto pp = dds_create_participant(domain, nullptr, nullptr);
  auto* q = qos();
  auto w_lat = dds_create_writer(pp, topic(pp, "rt/direct_lat"), q, nullptr);
  auto w_tput = dds_create_writer(pp, topic(pp, "rt/direct_tput"), q, nullptr);
  dds_delete_qos(q);
  // Until the reader process matched (then a second for the gateway's
  // participant, discovered alike).
  for (int i = 0; i < 1000; ++i) {
    dds_publication_matched_status_t a, b;
    if (dds_get_publication_matched_status(w_lat, &a) == 0
        && dds_get_publication_matched_status(w_tput, &b) == 0
        && a.current_count > 0 && b.current_count > 0)
      break;
    std::this_thread::sleep_for(10ms);
  }
  std::this_thread::sleep_for(1s);
  // A HERM APO that publishes what it is told to.
  auto apps = m->handles().apps;
  auto apo = sys.spawn([apps](caf::event_based_actor* self) -> caf::behavior {
    return {[self, apps](std::string& t, double v) {
      self->send(apps, atom::publish_v, std::move(t), caf::make_message(v));
    }};
  });
  auto via = [&](const char* t) {
    return [&apo, t](double v) { caf::anon_send(apo, std::string{t}, v); };
  };
  send_all(samples, count, std::function<void(double)>{via("lat")},
           std::function<void(double)>{via("tput")});
  std::this_thread::sleep_for(2s); // the gateway drains its mailbox
  auto write = [](dds_entity_t w) {
    return [w](double v) {
      std_msgs_msg_dds__Float64_ s{v};
      dds_write(w, &s);
    };
  };
  send_all(samples, count, std::function<void(double)>{write(w_lat)},
           std::function<void(double)>{write(w_tput)});
  std::this_thread::sleep_for(1s);
  caf::anon_send_exit(apo, caf::exit_reason::user_shutdown);
  caf::anon_send_exit(*gw, caf::exit_reason::user_shutdown);
  dds_delete(pp);
  return 0;
}

// -- the reader process --------------------------------------------------------------

struct path {
  dds_entity_t lat = 0;
  dds_entity_t tput = 0;
  std::vector<double> us;
  long got = 0;
  double first_sent = 0;
  double last_arrival = 0;
};

void take(dds_entity_t r, const std::function<void(double, double)>& f) {
  void* samples[64] = {nullptr};
  dds_sample_info_t infos[64];
  auto n = dds_take(r, samples, infos, 64, 64);
  auto t = now_ns();
  for (int i = 0; i < n; ++i)
    if (infos[i].valid_data)
      f(static_cast<std_msgs_msg_dds__Float64_*>(samples[i])->data, t);
  if (n > 0)
    dds_return_loan(r, samples, n);
}

double pct(std::vector<double> v, double p) {
  if (v.empty())
    return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(p * static_cast<double>(v.size() - 1))];
}

} // namespace

int main(int argc, char** argv) {
  int samples = argc > 1 ? std::atoi(argv[1]) : 1000;
  int count = argc > 2 ? std::atoi(argv[2]) : 20000;
  uint32_t domain = argc > 3 ? static_cast<uint32_t>(std::atoi(argv[3])) : 199;
  ::setenv("CYCLONEDDS_URI", loopback_only, 0);
  auto child = ::fork();
  if (child == 0)
    ::_exit(sender(samples, count, domain));
  auto pp = dds_create_participant(domain, nullptr, nullptr);
  auto* q = qos();
  path herm_path, dds_path;
  herm_path.lat = dds_create_reader(pp, topic(pp, "rt/lat"), q, nullptr);
  herm_path.tput = dds_create_reader(pp, topic(pp, "rt/tput"), q, nullptr);
  dds_path.lat = dds_create_reader(pp, topic(pp, "rt/direct_lat"), q, nullptr);
  dds_path.tput = dds_create_reader(pp, topic(pp, "rt/direct_tput"), q,
                                    nullptr);
  dds_delete_qos(q);
  auto ws = dds_create_waitset(pp);
  for (auto* p : {&herm_path, &dds_path})
    for (auto r : {p->lat, p->tput})
      dds_waitset_attach(ws, dds_create_readcondition(r, DDS_ANY_STATE), 0);
  int status = 0;
  bool done = false;
  auto linger = 0.0;
  while (!done || now_ns() < linger) {
    dds_waitset_wait(ws, nullptr, 0, DDS_MSECS(50));
    for (auto* p : {&herm_path, &dds_path}) {
      take(p->lat, [p](double sent, double at) {
        p->us.push_back((at - sent) / 1000.0);
      });
      take(p->tput, [p](double sent, double at) {
        if (p->got++ == 0 || sent < p->first_sent)
          p->first_sent = sent;
        p->last_arrival = at;
      });
    }
    if (!done && ::waitpid(child, &status, WNOHANG) == child) {
      done = true;
      linger = now_ns() + 0.5e9;
    }
  }
  int rc = 0;
  for (auto [name, p] : {std::pair{"herm", &herm_path}, {"dds", &dds_path}}) {
    auto secs = (p->last_arrival - p->first_sent) / 1e9;
    std::printf("%-5s latency p50 %.1f us p90 %.1f p99 %.1f max %.1f (%zu "
                "samples) | throughput %.0f msg/s, lost %ld of %d\n",
                name, pct(p->us, 0.5), pct(p->us, 0.9), pct(p->us, 0.99),
                pct(p->us, 1.0), p->us.size(),
                secs > 0 ? static_cast<double>(p->got) / secs : 0.0,
                count - p->got, count);
    if (p->us.empty() || p->got == 0)
      rc = 1;
  }
  dds_delete(pp);
  return rc;
}
