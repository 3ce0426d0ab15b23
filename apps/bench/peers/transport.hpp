#pragma once

// herm-bench-rtt: the client and server side of every transport measured.
// Each runs in a process of its own (herm-bench-rtt --role client|server),
// started by the orchestrator in rtt.cpp. Everything stays on 127.0.0.1.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace herm::bench {

/// What one client or server process does.
struct endpoint_params {
  /// Transport family: udp, herm, caf, zmq, dds.
  std::string transport;
  /// CAF scheduler policy for herm and caf: "sharing" or "stealing".
  std::string policy = "sharing";
  /// udp, caf, zmq: the server's port (0: the server picks and prints it).
  /// herm: the server module's UDP port. dds: the DDS domain id.
  uint16_t port = 0;
  /// herm only: the client module's UDP port.
  uint16_t port2 = 0;
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
  /// dds only: a tag that keeps this run's topics apart from others'.
  std::string tag = "0";
};

/// A client's outcome: `count` round-trip times in nanoseconds, or an error.
struct client_result {
  std::vector<int64_t> rtt_ns;
  std::string error;
};

/// Serves until killed. Prints "ready PORT" (flushed) on stdout once clients
/// may connect; returns non-zero after printing "error ..." when it cannot.
using server_fn = int (*)(const endpoint_params&);
using client_fn = client_result (*)(const endpoint_params&);

int udp_server(const endpoint_params& p);
client_result udp_client(const endpoint_params& p);
int herm_server(const endpoint_params& p);
client_result herm_client(const endpoint_params& p);
int caf_server(const endpoint_params& p);
client_result caf_client(const endpoint_params& p);
int zmq_server(const endpoint_params& p);
client_result zmq_client(const endpoint_params& p);
int dds_server(const endpoint_params& p);
client_result dds_client(const endpoint_params& p);

/// Empty when the transport was built in; otherwise why it was not.
std::string zmq_unavailable();
std::string dds_unavailable();

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

} // namespace herm::bench
