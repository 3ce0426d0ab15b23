// Cyclone DDS (C API): a ping topic and a pong topic of one type, a struct
// holding a sequence<octet> payload; RELIABLE, KEEP_LAST 1, volatile (ROS
// 2's default profile, which keeps 10: one is enough for strict ping-pong).
// The client writes a ping and waits on a read condition for the pong; the
// server takes each ping and writes it back as a pong. Discovery and data
// stay on 127.0.0.1: a CYCLONEDDS_URI configuration selects the loopback
// interface, disables multicast and lists 127.0.0.1 as the only peer.
// oneway: a data topic and an acknowledgement topic, reliable and KEEP_ALL
// (nothing is overwritten; the writer blocks instead), the receiver taking
// up to 64 samples per call.
// Built only when CMake found Cyclone DDS (HERM_BENCH_HAVE_DDS).

#include "apps/bench/peers/transport.hpp"

#ifdef HERM_BENCH_HAVE_DDS

#include <dds/dds.h>

#include <cstddef>
#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <thread>

namespace herm::bench {

namespace {

// -- the topic type, as idlc would generate it from
//    module herm_bench { struct octets { sequence<octet> payload; }; };

struct octets {
  dds_sequence_t payload;
};

const uint32_t octets_ops[] = {
  DDS_OP_ADR | DDS_OP_TYPE_SEQ | DDS_OP_SUBTYPE_1BY,
  static_cast<uint32_t>(offsetof(octets, payload)),
  DDS_OP_RTS,
};

const dds_topic_descriptor_t octets_desc = {
  sizeof(octets),
  alignof(octets),
  DDS_TOPIC_NO_OPTIMIZE,
  0u,
  "herm_bench::octets",
  nullptr,
  2u, // instructions: ADR, RTS
  octets_ops,
  "",
  {nullptr, 0},
  {nullptr, 0},
  0u,
};

constexpr const char* loopback_config =
  "<CycloneDDS><Domain Id=\"any\">"
  "<General><Interfaces><NetworkInterface address=\"127.0.0.1\"/></Interfaces>"
  "<AllowMulticast>false</AllowMulticast></General>"
  "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
  "<MaxAutoParticipantIndex>40</MaxAutoParticipantIndex>"
  "<Peers><Peer Address=\"127.0.0.1\"/></Peers></Discovery>"
  "</Domain></CycloneDDS>";

std::string dds_text(const char* what, dds_return_t rc) {
  return std::string{what} + ": " + dds_strretcode(rc);
}

/// One side's entities: it reads `in` and writes `out`.
struct endpoint {
  dds_entity_t participant = 0;
  dds_entity_t reader = 0;
  dds_entity_t writer = 0;
  dds_entity_t waitset = 0;
  std::string error;

  ~endpoint() {
    if (participant > 0)
      dds_delete(participant);
  }
};

void open(endpoint& e, const endpoint_params& p, const std::string& in,
          const std::string& out, bool keep_all = false) {
  ::setenv("CYCLONEDDS_URI", loopback_config, 1);
  e.participant = dds_create_participant(p.port, nullptr, nullptr);
  if (e.participant < 0) {
    e.error = dds_text("dds_create_participant", e.participant);
    return;
  }
  auto* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  if (keep_all)
    dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
  else
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 1);
  auto topic_in = dds_create_topic(e.participant, &octets_desc,
                                   (in + "_" + p.tag).c_str(), qos, nullptr);
  auto topic_out = dds_create_topic(e.participant, &octets_desc,
                                    (out + "_" + p.tag).c_str(), qos, nullptr);
  if (topic_in < 0 || topic_out < 0) {
    e.error = dds_text("dds_create_topic", topic_in < 0 ? topic_in : topic_out);
    dds_delete_qos(qos);
    return;
  }
  e.reader = dds_create_reader(e.participant, topic_in, qos, nullptr);
  e.writer = dds_create_writer(e.participant, topic_out, qos, nullptr);
  dds_delete_qos(qos);
  if (e.reader < 0 || e.writer < 0) {
    e.error = dds_text("dds_create_reader/writer", e.reader < 0 ? e.reader : e.writer);
    return;
  }
  e.waitset = dds_create_waitset(e.participant);
  auto cond = dds_create_readcondition(e.reader, DDS_ANY_STATE);
  dds_waitset_attach(e.waitset, cond, 0);
}

/// Takes one sample (a loan, returned by the caller) within `timeout`.
/// Returns 1 with `*sample` set, 0 on timeout, < 0 on error.
int take_one(const endpoint& e, dds_duration_t timeout, void** sample) {
  dds_sample_info_t info;
  for (;;) {
    *sample = nullptr;
    auto n = dds_take(e.reader, sample, &info, 1, 1);
    if (n < 0)
      return n;
    if (n == 1 && info.valid_data)
      return 1;
    if (n == 1)
      dds_return_loan(e.reader, sample, 1);
    auto w = dds_waitset_wait(e.waitset, nullptr, 0, timeout);
    if (w <= 0)
      return w;
  }
}

/// Writes `bytes` as one sample.
dds_return_t write_bytes(const endpoint& e, const void* bytes, size_t n) {
  octets s{};
  s.payload._buffer = static_cast<uint8_t*>(const_cast<void*>(bytes));
  s.payload._length = s.payload._maximum = static_cast<uint32_t>(n);
  s.payload._release = false;
  return dds_write(e.writer, &s);
}

/// Waits until both of our endpoints matched the other side's.
std::string wait_for_match(const endpoint& e) {
  auto until = now_ns() + 20'000'000'000;
  for (;;) {
    dds_publication_matched_status_t pm;
    dds_subscription_matched_status_t sm;
    dds_get_publication_matched_status(e.writer, &pm);
    dds_get_subscription_matched_status(e.reader, &sm);
    if (pm.current_count > 0 && sm.current_count > 0)
      return {};
    if (now_ns() > until)
      return "dds discovery: no match within 20 s";
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

/// oneway receiver: takes data samples in batches from a reliable keep-all
/// reader, acknowledges and reports on a keep-all topic back.
int dds_count(const endpoint_params& p) {
  endpoint e;
  open(e, p, "herm_bench_data", "herm_bench_ack", true);
  if (!e.error.empty()) {
    std::cout << "error " << e.error << std::endl;
    return 1;
  }
  std::cout << "ready " << p.port << std::endl;
  auto c = oneway_counter_for(p);
  constexpr int batch = 64;
  void* samples[batch];
  dds_sample_info_t infos[batch];
  for (;;) {
    samples[0] = nullptr;
    auto n = dds_take(e.reader, samples, infos, batch, batch);
    if (n <= 0) {
      dds_waitset_wait(e.waitset, nullptr, 0, DDS_INFINITY);
      continue;
    }
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data)
        continue;
      auto* in = static_cast<octets*>(samples[i]);
      auto seq = payload_seq(in->payload._buffer, in->payload._length);
      if (seq == oneway_done) {
        oneway_result_msg r;
        r.received = c.received;
        r.elapsed_ns = c.elapsed();
        r.allocs = c.allocs_per_message();
        write_bytes(e, &r, sizeof(r));
      } else if (c.on_message(seq, now_ns())) {
        oneway_ack_msg a;
        a.acked = c.next;
        write_bytes(e, &a, sizeof(a));
      }
    }
    dds_return_loan(e.reader, samples, n);
  }
}

client_result dds_oneway_client(const endpoint_params& p) {
  endpoint e;
  open(e, p, "herm_bench_ack", "herm_bench_data", true);
  if (!e.error.empty())
    return {{}, e.error};
  if (auto err = wait_for_match(e); !err.empty())
    return {{}, err};
  std::vector<uint8_t> buf(p.size);
  // Reads every acknowledgement (or result) that arrived; waits up to `wait`
  // for the first.
  auto drain = [&](dds_duration_t wait, uint32_t& acked, oneway_result_msg* result) {
    for (;;) {
      void* sample = nullptr;
      auto n = take_one(e, wait, &sample);
      if (n != 1)
        return;
      wait = 0;
      auto* in = static_cast<octets*>(sample);
      auto tag = payload_seq(in->payload._buffer, in->payload._length);
      if (tag == oneway_ack && in->payload._length == sizeof(oneway_ack_msg)) {
        oneway_ack_msg a;
        std::memcpy(&a, in->payload._buffer, sizeof(a));
        acked = std::max(acked, a.acked);
      } else if (tag == oneway_result && result != nullptr
                 && in->payload._length == sizeof(oneway_result_msg)) {
        std::memcpy(result, in->payload._buffer, sizeof(*result));
        result->pad = 1; // arrived
      }
      dds_return_loan(e.reader, &sample, 1);
    }
  };
  auto stall = DDS_MSECS(p.stall.count());
  return run_oneway_sender(
    p,
    [&](uint32_t seq) {
      fill_payload(buf, seq);
      auto rc = write_bytes(e, buf.data(), buf.size());
      return rc < 0 ? dds_text("dds_write", rc) : std::string{};
    },
    [&](bool block, uint32_t& acked) { drain(block ? stall : 0, acked, nullptr); },
    [&](client_result& r) {
      uint32_t done = oneway_done, acked = 0;
      oneway_result_msg m;
      m.pad = 0;
      for (int tries = 0; tries < 20 && m.pad == 0; ++tries) {
        write_bytes(e, &done, sizeof(done));
        drain(DDS_MSECS(200), acked, &m);
      }
      if (m.pad == 0)
        return std::string{"dds: no result from the receiver"};
      r.received = m.received;
      r.elapsed_ns = m.elapsed_ns;
      r.server_allocs = m.allocs;
      return std::string{};
    });
}

} // namespace

int dds_server(const endpoint_params& p) {
  if (p.mode == "oneway")
    return dds_count(p);
  endpoint e;
  open(e, p, "herm_bench_ping", "herm_bench_pong");
  if (!e.error.empty()) {
    std::cout << "error " << e.error << std::endl;
    return 1;
  }
  std::cout << "ready " << p.port << std::endl;
  for (;;) {
    void* sample = nullptr;
    auto n = take_one(e, DDS_INFINITY, &sample);
    if (n != 1)
      continue;
    dds_write(e.writer, sample);
    dds_return_loan(e.reader, &sample, 1);
  }
}

client_result dds_client(const endpoint_params& p) {
  if (p.mode == "oneway")
    return dds_oneway_client(p);
  client_result res;
  endpoint e;
  open(e, p, "herm_bench_pong", "herm_bench_ping");
  if (!e.error.empty()) {
    res.error = e.error;
    return res;
  }
  // Discovery: both of our endpoints matched with the server's.
  if (auto err = wait_for_match(e); !err.empty()) {
    res.error = err;
    return res;
  }
  std::vector<uint8_t> buf(p.size);
  octets out{};
  out.payload._buffer = buf.data();
  out.payload._length = out.payload._maximum = static_cast<uint32_t>(buf.size());
  out.payload._release = false;
  auto timeout = DDS_MSECS(p.timeout.count());
  run_round_trips(p, buf, res, [&](uint32_t i) {
    auto rc = dds_write(e.writer, &out);
    if (rc < 0) {
      res.error = dds_text("dds_write", rc);
      return round_trip::failed;
    }
    // The server's writer may match our reader a little after ours matched
    // it: a ping answered too early is lost, so the warm-up resends.
    void* sample = nullptr;
    int n;
    uint32_t seq = i + 1;
    do {
      n = take_one(e, i < p.warmup ? DDS_MSECS(200) : timeout, &sample);
      if (n == 1) {
        auto* in = static_cast<octets*>(sample);
        seq = payload_seq(in->payload._buffer, in->payload._length);
        if (in->payload._length != buf.size())
          seq = i + 1;
        dds_return_loan(e.reader, &sample, 1);
      }
    } while (n == 1 && seq != i);
    if (n == 1)
      return round_trip::replied;
    if (n == 0 && i < p.warmup)
      return round_trip::resend;
    res.error = n == 0 ? "dds: no pong " + std::to_string(i) + " in time"
                       : dds_text("dds_take", n);
    return round_trip::failed;
  });
  return res;
}

} // namespace herm::bench

#endif // HERM_BENCH_HAVE_DDS
