// ZeroMQ REQ/REP over tcp://127.0.0.1 (libzmq's C API): the message-queue
// library a robot builder picks for simple request/reply between processes.
// Built only when CMake found libzmq (HERM_BENCH_HAVE_ZMQ).

#include "apps/bench/peers/transport.hpp"

#ifdef HERM_BENCH_HAVE_ZMQ

#include <zmq.h>

#include <cstring>
#include <iostream>
#include <thread>

namespace herm::bench {

namespace {

std::string zmq_text(const char* what) {
  return std::string{what} + ": " + zmq_strerror(zmq_errno());
}

} // namespace

std::string zmq_unavailable() {
  return {};
}

int zmq_server(const endpoint_params& p) {
  void* ctx = zmq_ctx_new();
  void* sock = zmq_socket(ctx, ZMQ_REP);
  auto endpoint = "tcp://127.0.0.1:" + (p.port == 0 ? std::string{"*"}
                                                     : std::to_string(p.port));
  if (zmq_bind(sock, endpoint.c_str()) != 0) {
    std::cout << "error " << zmq_text("zmq_bind") << std::endl;
    return 1;
  }
  char last[256] = {};
  size_t len = sizeof(last);
  zmq_getsockopt(sock, ZMQ_LAST_ENDPOINT, last, &len);
  std::string bound{last};
  std::cout << "ready " << bound.substr(bound.rfind(':') + 1) << std::endl;
  zmq_msg_t msg;
  zmq_msg_init(&msg);
  for (;;) {
    if (zmq_msg_recv(&msg, sock, 0) < 0)
      continue;
    zmq_msg_send(&msg, sock, 0); // hands the bytes back without copying
  }
}

client_result zmq_client(const endpoint_params& p) {
  client_result res;
  void* ctx = zmq_ctx_new();
  void* sock = zmq_socket(ctx, ZMQ_REQ);
  int timeout = static_cast<int>(p.timeout.count());
  int linger = 0;
  zmq_setsockopt(sock, ZMQ_RCVTIMEO, &timeout, sizeof(timeout));
  zmq_setsockopt(sock, ZMQ_LINGER, &linger, sizeof(linger));
  auto endpoint = "tcp://127.0.0.1:" + std::to_string(p.port);
  if (zmq_connect(sock, endpoint.c_str()) != 0) {
    res.error = zmq_text("zmq_connect");
    return res;
  }
  std::vector<uint8_t> out(p.size), in(p.size + 64);
  res.rtt_ns.reserve(p.count);
  for (uint32_t i = 0; i < p.warmup + p.count; ++i) {
    fill_payload(out, i);
    auto t0 = now_ns();
    if (zmq_send(sock, out.data(), out.size(), 0) < 0) {
      res.error = zmq_text("zmq_send");
      break;
    }
    int n = zmq_recv(sock, in.data(), in.size(), 0);
    auto t1 = now_ns();
    if (n != static_cast<int>(out.size()) || payload_seq(in.data(), out.size()) != i) {
      res.error = n < 0 ? zmq_text("zmq_recv")
                        : "zmq reply " + std::to_string(i) + " does not match";
      break;
    }
    if (i >= p.warmup)
      res.rtt_ns.push_back(t1 - t0);
    if (p.gap.count() > 0)
      std::this_thread::sleep_for(p.gap);
  }
  zmq_close(sock);
  zmq_ctx_term(ctx);
  return res;
}

} // namespace herm::bench

#else // no libzmq

namespace herm::bench {

std::string zmq_unavailable() {
  return "libzmq was not found when herm-bench-rtt was built (apt-get install "
         "libzmq3-dev, then reconfigure)";
}

int zmq_server(const endpoint_params&) {
  return 1;
}

client_result zmq_client(const endpoint_params&) {
  return {{}, zmq_unavailable()};
}

} // namespace herm::bench

#endif
