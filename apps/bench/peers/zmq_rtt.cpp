// ZeroMQ REQ/REP over tcp://127.0.0.1 (libzmq's C API): the message-queue
// library a robot builder picks for simple request/reply between processes.
// oneway: PUSH/PULL for the data, a second PUSH/PULL pair back for the
// acknowledgements.
// Built only when CMake found libzmq (HERM_BENCH_HAVE_ZMQ).

#include "apps/bench/peers/transport.hpp"

#ifdef HERM_BENCH_HAVE_ZMQ

#include <zmq.h>

#include <algorithm>
#include <cstring>
#include <iostream>
#include <thread>

namespace herm::bench {

namespace {

std::string zmq_text(const char* what) {
  return std::string{what} + ": " + zmq_strerror(zmq_errno());
}

std::string last_port(void* sock) {
  char last[256] = {};
  size_t len = sizeof(last);
  zmq_getsockopt(sock, ZMQ_LAST_ENDPOINT, last, &len);
  std::string bound{last};
  return bound.substr(bound.rfind(':') + 1);
}

/// oneway receiver: PULL on the printed port for data, PUSH on a second one
/// for acknowledgements and the figures.
int zmq_count(const endpoint_params& p) {
  void* ctx = zmq_ctx_new();
  void* pull = zmq_socket(ctx, ZMQ_PULL);
  void* push = zmq_socket(ctx, ZMQ_PUSH);
  if (zmq_bind(pull, "tcp://127.0.0.1:*") != 0 || zmq_bind(push, "tcp://127.0.0.1:*") != 0) {
    std::cout << "error " << zmq_text("zmq_bind") << std::endl;
    return 1;
  }
  std::cout << "ready " << last_port(pull) << " " << last_port(push) << std::endl;
  auto c = oneway_counter_for(p);
  std::vector<uint8_t> buf(65536);
  for (;;) {
    int n = zmq_recv(pull, buf.data(), buf.size(), 0);
    count_payload(
      c, buf.data(), n,
      [push](const oneway_result_msg& r) { zmq_send(push, &r, sizeof(r), 0); },
      [push](const oneway_ack_msg& a) {
        // Never blocks: before the client's PULL connected an ack is
        // dropped (the sender's stall timer reopens its window).
        zmq_send(push, &a, sizeof(a), ZMQ_DONTWAIT);
      });
  }
}

client_result zmq_oneway_client(const endpoint_params& p) {
  void* ctx = zmq_ctx_new();
  void* push = zmq_socket(ctx, ZMQ_PUSH);
  void* pull = zmq_socket(ctx, ZMQ_PULL);
  int stall = static_cast<int>(p.stall.count());
  int linger = 0;
  zmq_setsockopt(pull, ZMQ_RCVTIMEO, &stall, sizeof(stall));
  zmq_setsockopt(push, ZMQ_LINGER, &linger, sizeof(linger));
  zmq_setsockopt(pull, ZMQ_LINGER, &linger, sizeof(linger));
  auto data = "tcp://127.0.0.1:" + std::to_string(p.port);
  auto acks = "tcp://127.0.0.1:" + std::to_string(p.port2);
  if (zmq_connect(push, data.c_str()) != 0 || zmq_connect(pull, acks.c_str()) != 0)
    return {{}, zmq_text("zmq_connect")};
  std::vector<uint8_t> out(p.size);
  uint8_t in[64];
  auto res = run_oneway_sender(
    p,
    [&](uint32_t seq) {
      fill_payload(out, seq);
      return zmq_send(push, out.data(), out.size(), 0) < 0 ? zmq_text("zmq_send")
                                                           : std::string{};
    },
    [&](bool block, uint32_t& acked) {
      for (;;) {
        int n = zmq_recv(pull, in, sizeof(in), block ? 0 : ZMQ_DONTWAIT);
        if (n < 0)
          return;
        block = false;
        oneway_ack_msg a;
        if (n == sizeof(a) && payload_seq(in, 4) == oneway_ack) {
          std::memcpy(&a, in, sizeof(a));
          acked = std::max(acked, a.acked);
        }
      }
    },
    [&](client_result& r) {
      uint32_t done = oneway_done;
      for (int tries = 0; tries < 20; ++tries) {
        zmq_send(push, &done, sizeof(done), 0);
        int n;
        while ((n = zmq_recv(pull, in, sizeof(in), 0)) >= 0)
          if (n == sizeof(oneway_result_msg) && payload_seq(in, 4) == oneway_result) {
            oneway_result_msg m;
            std::memcpy(&m, in, sizeof(m));
            r.received = m.received;
            r.elapsed_ns = m.elapsed_ns;
            r.server_allocs = m.allocs;
            return std::string{};
          }
      }
      return std::string{"zmq: no result from the receiver"};
    });
  zmq_close(push);
  zmq_close(pull);
  zmq_ctx_term(ctx);
  return res;
}

} // namespace

int zmq_server(const endpoint_params& p) {
  if (p.mode == "oneway")
    return zmq_count(p);
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
  if (p.mode == "oneway")
    return zmq_oneway_client(p);
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
  run_round_trips(p, out, res, [&](uint32_t seq) {
    if (zmq_send(sock, out.data(), out.size(), 0) < 0) {
      res.error = zmq_text("zmq_send");
      return round_trip::failed;
    }
    int n = zmq_recv(sock, in.data(), in.size(), 0);
    if (n != static_cast<int>(out.size()) || payload_seq(in.data(), out.size()) != seq) {
      res.error = n < 0 ? zmq_text("zmq_recv")
                        : "zmq reply " + std::to_string(seq) + " does not match";
      return round_trip::failed;
    }
    return round_trip::replied;
  });
  zmq_close(sock);
  zmq_ctx_term(ctx);
  return res;
}

} // namespace herm::bench

#endif // HERM_BENCH_HAVE_ZMQ
