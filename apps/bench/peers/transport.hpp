#pragma once

// herm-bench-rtt: the client and server side of every transport measured.
// Each runs in a process of its own (herm-bench-rtt --role client|server),
// started by the orchestrator in rtt.cpp. Everything stays on 127.0.0.1.

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "apps/bench/peers/probes.hpp"

namespace herm::bench {

/// Splits "POLICY[:THREADS]" into the policy and the worker count (0: none
/// given).
inline std::pair<std::string, size_t> split_policy(const std::string& x) {
  auto colon = x.find(':');
  if (colon == std::string::npos)
    return {x, 0};
  return {x.substr(0, colon),
          static_cast<size_t>(std::stoul(x.substr(colon + 1)))};
}

/// What one client or server process does.
struct endpoint_params {
  /// Transport family: udp, herm, caf, zmq, dds (caf-local: inprocess only).
  std::string transport;
  /// What is measured: "rtt" (request round trips, back to back or with a
  /// gap), "oneway" (one-way throughput with a credit window), "inprocess"
  /// (round trips inside one process), "router" (round trips across a
  /// router module; herm only).
  std::string mode = "rtt";
  /// Scheduler for herm and caf: "loop" (HERM's loop scheduler), or CAF's
  /// "sharing" or "stealing", optionally with a worker count after a colon
  /// ("sharing:1"; none: one per core); for "loop" the number after the
  /// colon is its busy-poll in microseconds ("loop:50").
  std::string policy = "loop";
  /// udp, caf, zmq: the server's port (0: the server picks and prints it).
  /// herm: the server module's UDP port. dds: the DDS domain id.
  uint16_t port = 0;
  /// herm only: the client module's UDP port.
  uint16_t port2 = 0;
  /// herm router mode only: the router module's UDP ports facing the client
  /// module (port3) and the server module (port4).
  uint16_t port3 = 0;
  uint16_t port4 = 0;
  /// herm only: the routing hello interval of both modules.
  std::chrono::milliseconds hello{1000};
  /// Client: payload bytes per request (the reply has the same size).
  size_t size = 16;
  /// Client: measured round trips, and unmeasured ones before them.
  uint32_t count = 1000;
  uint32_t warmup = 100;
  /// Client: pause after each reply before the next request (0: none).
  std::chrono::microseconds gap{0};
  /// Client: one round trip slower than this fails the run.
  std::chrono::milliseconds timeout{2000};
  /// oneway: the receiver acknowledges every `ack_every` messages (and the
  /// last one); the sender never has more than `window` unacknowledged. A
  /// window that stays full for `stall` (a lost message or acknowledgement)
  /// is counted as a stall and reopened.
  uint32_t window = 128;
  uint32_t ack_every = 16;
  std::chrono::milliseconds stall{100};
  /// udp oneway only: send in batches with sendmmsg instead of one send each.
  bool batch = false;
  /// dds only: a tag that keeps this run's topics apart from others'.
  std::string tag = "0";
  /// The case's shared counter page (an inherited memfd, see probes.hpp;
  /// -1: none, allocations are then not reported).
  int counter_fd = -1;
  /// Client: the case's server and router processes (0: none), whose
  /// wake-ups and allocations it reads around its timed part.
  int server_pid = 0;
  int router_pid = 0;
  /// Client: count syscalls too (the separate counting pass only).
  bool count_syscalls = false;
};

/// A client's outcome: `count` round-trip times in nanoseconds (rtt,
/// inprocess, router), or the oneway figures, or an error.
struct client_result {
  std::vector<int64_t> rtt_ns;
  std::string error;
  /// oneway: measured messages sent (after the warm-up), messages the
  /// receiver got of them, its time from the first to the last of them, the
  /// window stalls, and operator-new calls per measured message in the
  /// client and in the server (-1: not counted).
  uint64_t sent = 0;
  uint64_t received = 0;
  int64_t elapsed_ns = 0;
  uint64_t stalls = 0;
  double client_allocs = -1;
  double server_allocs = -1;
  /// rtt, inprocess, router: each process's counts over the timed part
  /// (probes.hpp), totals over the `count` measured round trips.
  case_counts counts;
};

// -- the oneway protocol -------------------------------------------------------------
// Data messages carry their sequence number in their first four bytes
// (fill_payload); warm-up messages come first, then `count` measured ones.
// Control values (in the first four bytes of a control message where the
// transport has no message types of its own):
constexpr uint32_t oneway_done = 0xFFFFFFFFu;   // sender -> receiver: report
constexpr uint32_t oneway_ack = 0xFFFFFFFEu;    // receiver -> sender: u32 acked
constexpr uint32_t oneway_result = 0xFFFFFFFDu; // receiver -> sender: figures

/// The receiver's side of the oneway protocol, transport-independent: feed
/// it every data message's sequence number; it says when to acknowledge.
struct oneway_counter {
  uint32_t warmup = 0;
  uint32_t total = 0; // warm-up + measured
  uint32_t ack_every = 32;
  uint64_t received = 0; // measured ones
  uint64_t seen = 0;     // all
  uint32_t next = 0;     // highest sequence number seen + 1
  int64_t first_ns = 0, last_ns = 0;
  uint64_t first_allocs = 0, last_allocs = 0;

  /// Returns true when an acknowledgement of `next` is due.
  bool on_message(uint32_t seq, int64_t now);
  int64_t elapsed() const {
    return received > 1 ? last_ns - first_ns : 0;
  }
  /// operator-new calls per measured message between the first and the
  /// last (-1: fewer than two).
  double allocs_per_message() const {
    return received > 1 ? static_cast<double>(last_allocs - first_allocs)
                            / static_cast<double>(received - 1)
                        : -1;
  }
};

/// Where a transport has no message types of its own: an acknowledgement
/// and the receiver's figures, as they travel (same host, same layout).
struct oneway_ack_msg {
  uint32_t tag = oneway_ack;
  uint32_t acked = 0;
};

struct oneway_result_msg {
  uint32_t tag = oneway_result;
  uint32_t pad = 0;
  uint64_t received = 0;
  int64_t elapsed_ns = 0;
  double allocs = -1;
};

/// Heap allocations of this process so far, counted while counting is on
/// (`alloc_counting(true)`; `attach_counter_page` turns it on too). What is
/// counted: probes.hpp.
uint64_t alloc_count();
void alloc_counting(bool on);

/// Serves until killed. Prints "ready PORT" (flushed) on stdout once clients
/// may connect; returns non-zero after printing "error ..." when it cannot.
using server_fn = int (*)(const endpoint_params&);
using client_fn = client_result (*)(const endpoint_params&);

/// herm router mode: a module with two udp devices (port3 toward the
/// client's module, port4 toward the server's) that forwards between them.
int herm_router(const endpoint_params& p);
/// inprocess mode: one process, one module; transport "herm" requests
/// through a proxy bound by name, "caf-local" the echo actor directly.
client_result inprocess_client(const endpoint_params& p);

int udp_server(const endpoint_params& p);
client_result udp_client(const endpoint_params& p);
int herm_server(const endpoint_params& p);
client_result herm_client(const endpoint_params& p);
int caf_server(const endpoint_params& p);
client_result caf_client(const endpoint_params& p);
// Built only when CMake found their library (HERM_BENCH_HAVE_ZMQ,
// HERM_BENCH_HAVE_DDS); transports() says when they are not.
int zmq_server(const endpoint_params& p);
client_result zmq_client(const endpoint_params& p);
int dds_server(const endpoint_params& p);
client_result dds_client(const endpoint_params& p);

/// One transport measured: its name (as --only and the report spell it) and
/// its two sides, or, when it was not built in, why not (`unavailable`;
/// server and client are then null).
struct transport {
  std::string name;
  server_fn server = nullptr;
  client_fn client = nullptr;
  std::string unavailable;
};

/// Transport `name` as it stands when CMake did not find `library` (the
/// Debian package `package` provides it).
inline transport missing_transport(const std::string& name,
                                   const std::string& library,
                                   const std::string& package) {
  return {name, nullptr, nullptr,
          library + " was not found when herm-bench-rtt was built (apt-get "
            "install " + package + ", then reconfigure)"};
}

/// Every transport, in the report's order: udp, herm, caf, zmq, dds.
const std::vector<transport>& transports();
/// nullptr when `name` is none of them.
const transport* find_transport(const std::string& name);

/// Fills `buf` (already sized) with a pattern that starts with `seq`, so a
/// stale reply is recognised.
void fill_payload(std::vector<uint8_t>& buf, uint32_t seq);
/// The sequence number `fill_payload` wrote (0 if the buffer is too short).
uint32_t payload_seq(const uint8_t* data, size_t size);

/// Monotonic time in nanoseconds.
inline int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
           std::chrono::steady_clock::now().time_since_epoch())
    .count();
}

/// A oneway receiver's counter for a run with `p`.
inline oneway_counter oneway_counter_for(const endpoint_params& p) {
  oneway_counter c;
  c.warmup = p.warmup;
  c.total = p.warmup + p.count;
  c.ack_every = p.ack_every;
  return c;
}

/// A oneway receiver's handling of one received payload of `n` bytes, for
/// transports without message types of their own (udp, zmq): under 4
/// bytes it is ignored; the done marker is answered with the figures
/// through `send_result(const oneway_result_msg&)`; any other payload goes
/// to `c`, and an acknowledgement that falls due out through
/// `send_ack(const oneway_ack_msg&)`. O(1).
template <class SendResult, class SendAck>
void count_payload(oneway_counter& c, const uint8_t* data, int64_t n,
                   SendResult send_result, SendAck send_ack) {
  if (n < 4)
    return;
  auto seq = payload_seq(data, static_cast<size_t>(n));
  if (seq == oneway_done) {
    oneway_result_msg r;
    r.received = c.received;
    r.elapsed_ns = c.elapsed();
    r.allocs = c.allocs_per_message();
    send_result(r);
    return;
  }
  if (c.on_message(seq, now_ns())) {
    oneway_ack_msg a;
    a.acked = c.next;
    send_ack(a);
  }
}

/// The oneway sender's loop for blocking transports that send in batches.
/// `send_some(first, room, n)` sends data messages `first`, `first + 1`, ...
/// (at least one, at most `room`, never across the end of the warm-up),
/// sets `n` to how many and returns an error text or empty;
/// `read_acks(block, acked)` raises `acked` from the acknowledgements that
/// arrived, waiting up to `p.stall` for the first when `block`;
/// `get_result(res)` asks the receiver for its figures (error text or empty).
template <class SendSome, class ReadAcks, class GetResult>
client_result run_oneway_batch_sender(const endpoint_params& p, SendSome send_some,
                                      ReadAcks read_acks, GetResult get_result) {
  client_result res;
  uint32_t total = p.warmup + p.count, sent = 0, acked = 0;
  uint64_t allocs_start = 0, allocs_end = 0;
  while (sent < total) {
    if (sent - acked >= p.window) {
      auto before = acked;
      read_acks(true, acked);
      if (acked == before) {
        ++res.stalls; // a message or an acknowledgement was lost
        acked = sent;
      }
      continue;
    }
    if (sent == p.warmup)
      allocs_start = alloc_count();
    // Never across the warm-up boundary, so the allocation count starts there.
    uint32_t room = std::min(p.window - (sent - acked), total - sent);
    if (sent < p.warmup)
      room = std::min(room, p.warmup - sent);
    uint32_t n = 0;
    if (auto err = send_some(sent, room, n); !err.empty()) {
      res.error = err;
      return res;
    }
    sent += n;
  }
  allocs_end = alloc_count();
  while (acked < total) {
    auto before = acked;
    read_acks(true, acked);
    if (acked == before) {
      ++res.stalls;
      break;
    }
  }
  if (auto err = get_result(res); !err.empty()) {
    res.error = err;
    return res;
  }
  res.sent = p.count;
  if (p.count > 0)
    res.client_allocs = static_cast<double>(allocs_end - allocs_start)
                        / static_cast<double>(p.count);
  return res;
}

/// What one exchange of the round-trip loop came to.
enum class round_trip {
  /// The reply to this request arrived.
  replied,
  /// A warm-up reply was lost: the same request goes again, unmeasured.
  resend,
  /// The run ends; the exchange has set `res.error`.
  failed,
};

/// The client's round-trip loop for blocking transports (udp, zmq, dds):
/// `p.warmup` unmeasured round trips, then `p.count` measured ones whose
/// times go to `res.rtt_ns`, with `p.gap` after each reply and the timed part
/// (probes.hpp) around the measured ones. Before each request `payload` is
/// filled by fill_payload with the request's sequence number;
/// `exchange(seq)` sends it, waits for the reply with `seq` and says how that
/// went (round_trip). The time between the calls' start and end is the round
/// trip's. Memory: `p.count` times in `res.rtt_ns`, reserved up front.
template <class Exchange>
void run_round_trips(const endpoint_params& p, std::vector<uint8_t>& payload,
                     client_result& res, Exchange exchange) {
  res.rtt_ns.reserve(p.count);
  for (uint32_t i = 0; i < p.warmup + p.count;) {
    if (i == p.warmup)
      timed_part_begins(); // once: a warm-up resend never reaches here at warmup
    fill_payload(payload, i);
    auto t0 = now_ns();
    auto outcome = exchange(i);
    auto t1 = now_ns();
    if (outcome == round_trip::failed)
      break;
    if (outcome == round_trip::resend)
      continue;
    if (i >= p.warmup)
      res.rtt_ns.push_back(t1 - t0);
    ++i;
    if (p.gap.count() > 0)
      std::this_thread::sleep_for(p.gap);
  }
  timed_part_ends();
}

/// run_oneway_batch_sender with one message per send: `send_one(seq)` sends
/// data message `seq` and returns an error text or empty.
template <class Send, class ReadAcks, class GetResult>
client_result run_oneway_sender(const endpoint_params& p, Send send_one,
                                ReadAcks read_acks, GetResult get_result) {
  return run_oneway_batch_sender(
    p,
    [&send_one](uint32_t first, uint32_t, uint32_t& n) {
      n = 1;
      return send_one(first);
    },
    std::move(read_acks), std::move(get_result));
}

} // namespace herm::bench
