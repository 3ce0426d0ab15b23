// herm-link: one module process with one channel, for probing links and for
// multi-process tests.
//
//   herm-link -k udp -i 127.0.0.1:0 echo
//   herm-link -k udp -i 127.0.0.1:0 -a 127.0.0.1:40001 send --count 10 --max-size 5000 --expect-echo
//   herm-link -k emu -i /tmp/bus -o profile=can2.0 -o station=1 recv --count 3
//
// Prints one line per event on stdout: "ready local=... mtu=... max_packet=...",
// "rx src=... size=... seq=...", "done ...". Exit status: 0 success, 1 the
// exchange failed (missing or corrupted echo, timeout), 2 bad arguments or
// the device or channel could not be opened (the typed error is printed).

#include <atomic>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <map>
#include <random>
#include <string>

#include <CLI/CLI.hpp>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/scoped_actor.hpp"

#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "channels/io_manager.hpp"

using namespace herm;

namespace {

// Set by SIGTERM/SIGINT, which may run on any thread (CAF's workers
// included): a lock-free atomic, not a volatile sig_atomic_t, which only
// the interrupted thread may read safely.
std::atomic<bool> stop_requested{false};
static_assert(std::atomic<bool>::is_always_lock_free);

/// Packet payload for sequence number `seq`: 8-byte header (seq, size) and a
/// pattern derived from both, so any corruption or mix-up is detected.
byte_buffer make_payload(uint32_t seq, uint32_t size) {
  byte_buffer buf(size);
  for (uint32_t i = 0; i < size; ++i)
    buf[i] = static_cast<uint8_t>((seq * 131 + i * 7 + (i >> 8)) & 0xFF);
  for (uint32_t i = 0; i < 4 && i < size; ++i)
    buf[i] = static_cast<uint8_t>(seq >> (8 * i));
  for (uint32_t i = 0; i < 4 && i + 4 < size; ++i)
    buf[i + 4] = static_cast<uint8_t>(size >> (8 * i));
  return buf;
}

uint32_t seq_of(const byte_buffer& buf) {
  uint32_t seq = 0;
  for (uint32_t i = 0; i < 4 && i < buf.size(); ++i)
    seq |= uint32_t{buf[i]} << (8 * i);
  return seq;
}

struct options {
  std::string kind;
  std::string interface;
  std::vector<std::string> opts;
  std::string address = "*";
  std::string scheduler = "loop";
  uint32_t count = 0;
  uint32_t min_size = 0;
  uint32_t max_size = 64;
  uint64_t seed = 1;
  double timeout = 10;
  bool expect_echo = false;
  uint32_t window = 4;
};

int fail_open(const caf::error& err) {
  std::cout << "error " << render(err) << std::endl;
  return 2;
}

} // namespace

int main(int argc, char** argv) {
  options o;
  CLI::App app{"herm-link: open one HERM channel and echo, send or receive"};
  app.add_option("-k,--kind", o.kind, "link kind (udp, emu, inproc)")->required();
  app.add_option("-i,--interface", o.interface, "device interface")->required();
  app.add_option("-o,--option", o.opts, "device option KEY=VALUE (repeatable)");
  app.add_option("-a,--address", o.address,
                 "channel address: * for every peer, or one peer's address");
  app.add_option("--scheduler", o.scheduler, "loop, sharing or stealing");
  app.add_option("--timeout", o.timeout, "seconds to wait for traffic");
  auto* echo = app.add_subcommand("echo", "send every packet back to its sender");
  echo->add_option("--count", o.count, "stop after N packets (0: run until SIGTERM)");
  auto* send = app.add_subcommand("send", "send packets of random sizes");
  send->add_option("--count", o.count, "number of packets")->required();
  send->add_option("--min-size", o.min_size, "smallest packet, bytes");
  send->add_option("--max-size", o.max_size, "largest packet, bytes");
  send->add_option("--seed", o.seed, "random seed for the sizes");
  send->add_flag("--expect-echo", o.expect_echo, "wait for and verify echoes");
  send->add_option("--window", o.window, "packets in flight when expecting echoes");
  auto* recv = app.add_subcommand("recv", "print received packets");
  recv->add_option("--count", o.count, "stop after N packets");
  app.require_subcommand(1);
  CLI11_PARSE(app, argc, argv);

  device_config dev{"dev0", o.kind, o.interface, {}};
  for (auto& kv : o.opts) {
    auto eq = kv.find('=');
    if (eq == std::string::npos || eq == 0) {
      std::cout << "error option '" << kv << "' is not KEY=VALUE" << std::endl;
      return 2;
    }
    dev.options[kv.substr(0, eq)] = kv.substr(eq + 1);
  }
  std::signal(SIGTERM, [](int) { stop_requested = true; });
  std::signal(SIGINT, [](int) { stop_requested = true; });

  caf::actor_system_config cfg;
  configure(cfg, o.scheduler);
  caf::actor_system sys{cfg};
  caf::scoped_actor self{sys};
  auto io = spawn_io_manager(sys);
  auto timeout = std::chrono::seconds(5);
  caf::error err;
  self->request(io, timeout, atom::add_v, dev)
    .receive([](const device_info&) {}, [&](caf::error& e) { err = e; });
  if (err)
    return fail_open(err);
  channel_actor ch;
  channel_info info;
  self->request(io, timeout, atom::open_v, channel_request{"dev0", o.address})
    .receive(
      [&](channel_actor& c, channel_info& i) {
        ch = c;
        info = i;
      },
      [&](caf::error& e) { err = e; });
  if (err)
    return fail_open(err);
  self->request(ch, timeout, atom::subscribe_v,
                caf::actor_cast<channel_reader_actor>(self))
    .receive([](const channel_info&) {}, [&](caf::error& e) { err = e; });
  if (err)
    return fail_open(err);
  std::cout << "ready local=" << info.local << " mtu=" << info.profile.mtu
            << " max_packet=" << info.max_packet << std::endl;

  auto idle = std::chrono::milliseconds(static_cast<int64_t>(o.timeout * 1000));
  int status = 0;
  uint32_t received = 0;
  bool running = true;
  auto on_down = [&](caf::down_msg& msg) {
    std::cout << "down " << render(msg.reason) << std::endl;
    running = false;
    status = 1;
  };
  auto on_event = [](link_event&) {};
  if (echo->parsed() || recv->parsed()) {
    while (running && !stop_requested
           && (o.count == 0 || received < o.count)) {
      self->receive(
        [&](packet_received& pkt) {
          ++received;
          std::cout << "rx src=" << pkt.src << " size=" << pkt.bytes.size()
                    << " seq=" << seq_of(pkt.bytes) << std::endl;
          if (echo->parsed())
            self->send(ch, write_packet{pkt.src, prio_normal, std::move(pkt.bytes)});
        },
        on_event, on_down,
        caf::after(std::chrono::milliseconds(200)) >> [&] {});
    }
  } else {
    std::mt19937_64 rng{o.seed};
    std::uniform_int_distribution<uint32_t> dist{o.min_size, o.max_size};
    std::map<uint32_t, byte_buffer> in_flight;
    uint32_t next = 0, echoed = 0, bad = 0;
    auto deadline = std::chrono::steady_clock::now() + idle;
    while (running && !stop_requested) {
      while (next < o.count && (!o.expect_echo || in_flight.size() < o.window)) {
        auto payload = make_payload(next, dist(rng));
        if (o.expect_echo)
          in_flight.emplace(next, payload);
        self->send(ch, write_packet{broadcast_addr, prio_normal, std::move(payload)});
        ++next;
      }
      if (!o.expect_echo || (next == o.count && in_flight.empty()))
        break;
      if (std::chrono::steady_clock::now() > deadline) {
        std::cout << "timeout waiting for " << in_flight.size() << " echoes"
                  << std::endl;
        status = 1;
        break;
      }
      self->receive(
        [&](packet_received& pkt) {
          deadline = std::chrono::steady_clock::now() + idle;
          auto i = in_flight.find(seq_of(pkt.bytes));
          if (i == in_flight.end() || i->second != pkt.bytes) {
            ++bad;
            std::cout << "bad echo size=" << pkt.bytes.size() << std::endl;
            return;
          }
          in_flight.erase(i);
          ++echoed;
        },
        on_event, on_down, caf::after(std::chrono::milliseconds(200)) >> [&] {});
    }
    if (bad > 0)
      status = 1;
    std::cout << "done sent=" << next << " echoed=" << echoed << " bad=" << bad
              << std::endl;
  }
  channel_stats st;
  self->request(ch, timeout, atom::get_v, atom::stats_v)
    .receive([&](channel_stats& s) { st = s; }, [](caf::error&) {});
  std::cout << "stats tx_packets=" << st.tx_packets << " tx_frames=" << st.tx_frames
            << " tx_dropped=" << st.tx_dropped << " rx_packets=" << st.rx_packets
            << " rx_frames=" << st.rx_frames << " rx_malformed=" << st.rx_malformed
            << " rx_reassembly_dropped=" << st.rx_reassembly_dropped << std::endl;
  self->send_exit(io, caf::exit_reason::user_shutdown);
  return status;
}
