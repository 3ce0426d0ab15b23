// herm-demo: two modules, each its own process, joined by two different
// links: Ethernet (UDP on loopback) and a CAN 2.0 bus (emulated: 1 Mbit/s,
// 8-byte frames). The sensor module sends a reading over each link; the
// controller module prints what arrived, how many frames it took, and
// answers over the same link.
//
//   herm-demo                  run both modules and print their trace
//   herm-demo --role sensor|controller ...   (started by the above)

#include <sys/socket.h>
#include <sys/wait.h>
#include <netinet/in.h>
#include <arpa/inet.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <string>

#include <CLI/CLI.hpp>

#include "caf/actor_system.hpp"
#include "caf/actor_system_config.hpp"
#include "caf/scoped_actor.hpp"

#include "actors/runtime/error.hpp"
#include "actors/runtime/system.hpp"
#include "actors/runtime/type_ids.hpp"
#include "channels/drivers/udp_addr.hpp"
#include "channels/io_manager.hpp"

using namespace herm;

namespace {

struct role_args {
  std::string role;
  uint16_t udp_port = 0;
  uint16_t peer_port = 0;
  std::string bus;
};

/// Asks the kernel for a free UDP port on loopback.
uint16_t free_udp_port() {
  int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr));
  socklen_t len = sizeof(addr);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  ::close(fd);
  return ntohs(addr.sin_port);
}

std::string peer_name(const std::string& kind, link_addr addr) {
  if (kind == "udp")
    return udp::format_addr(addr);
  return std::to_string(addr);
}

std::string preview(const byte_buffer& buf) {
  std::string s(buf.begin(), buf.begin() + std::min<size_t>(buf.size(), 48));
  for (auto& c : s)
    if (c < 32 || c > 126)
      c = '.';
  return s + (buf.size() > 48 ? "..." : "");
}

int run_module(const role_args& a) {
  bool sensor = a.role == "sensor";
  auto tag = sensor ? "[sensor]     " : "[controller] ";
  auto say = [&](const std::string& line) {
    std::cout << tag << line << std::endl;
  };
  caf::actor_system_config cfg;
  configure(cfg);
  caf::actor_system sys{cfg};
  caf::scoped_actor self{sys};
  auto io = spawn_io_manager(sys);
  auto t = std::chrono::seconds(5);
  auto fail = [&](const caf::error& err) {
    say("error: " + render(err));
    self->send_exit(io, caf::exit_reason::user_shutdown);
    return 1;
  };
  // -- devices: one UDP socket, one station on the emulated CAN bus --------
  device_config eth{"eth0", "udp", "127.0.0.1:" + std::to_string(a.udp_port),
                    {{"peers", "127.0.0.1:" + std::to_string(a.peer_port)}}};
  device_config can{"can0", "emu", a.bus,
                    {{"profile", "can2.0"}, {"station", sensor ? "1" : "2"}}};
  caf::error err;
  for (auto& dev : {eth, can}) {
    self->request(io, t, atom::add_v, dev)
      .receive([](device_info&) {}, [&](caf::error& e) { err = e; });
    if (err)
      return fail(err);
  }
  // -- channels ---------------------------------------------------------------
  std::map<channel_id, channel_info> infos;
  std::map<std::string, channel_actor> chans;
  for (auto name : {"eth0", "can0"}) {
    self->request(io, t, atom::open_v, channel_request{name, "*"})
      .receive(
        [&](channel_actor& ch, channel_info& info) {
          self->request(ch, t, atom::subscribe_v,
                        caf::actor_cast<channel_reader_actor>(self))
            .receive([](channel_info&) {}, [&](caf::error& e) { err = e; });
          say("opened channel " + std::to_string(info.id) + " on " + name + " ("
              + info.kind + ", profile " + info.profile.name + ": "
              + std::to_string(info.profile.bandwidth_bps) + " bit/s, MTU "
              + std::to_string(info.profile.mtu) + " bytes, cost "
              + std::to_string(link_cost(info.profile)) + "), local address "
              + info.local);
          infos[info.id] = info;
          chans[name] = ch;
        },
        [&](caf::error& e) { err = e; });
    if (err)
      return fail(err);
  }
  auto report = [&](const std::string& name) {
    channel_stats st;
    self->request(chans[name], t, atom::get_v, atom::stats_v)
      .receive([&](channel_stats& s) { st = s; }, [](caf::error&) {});
    std::ostringstream os;
    os << name << " counters: tx " << st.tx_packets << " packets in "
       << st.tx_frames << " frames, rx " << st.rx_packets << " packets from "
       << st.rx_frames << " frames, dropped " << st.tx_dropped << " tx / "
       << st.rx_malformed + st.rx_reassembly_dropped << " rx";
    say(os.str());
  };
  // The controller starts first and waits; the sensor sends when ready.
  auto expect = sensor ? 2 : 2;
  if (sensor) {
    std::string reading = "ultrasonic range 1.42 m (SRF04, t=0 s)";
    say("sending \"" + reading + "\" over Ethernet (udp)");
    self->send(chans["eth0"], write_packet{broadcast_addr, prio_normal,
                                           byte_buffer(reading.begin(), reading.end())});
    std::string batch = "ten readings:";
    for (int i = 0; i < 10; ++i)
      batch += " " + std::to_string(140 + i * 3) + "cm";
    batch += " | calibrated against the AVR Atmega128 reference clock";
    while (batch.size() < 300)
      batch += '.';
    say("sending a " + std::to_string(batch.size())
        + "-byte batch over CAN 2.0 (8-byte frames: fragmented)");
    self->send(chans["can0"], write_packet{broadcast_addr, prio_high,
                                           byte_buffer(batch.begin(), batch.end())});
  }
  int got = 0;
  bool ok = true;
  while (got < expect) {
    bool timed_out = false;
    self->receive(
      [&](packet_received& pkt) {
        ++got;
        auto& info = infos[pkt.channel];
        say("received " + std::to_string(pkt.bytes.size()) + " bytes on "
            + info.device + " (" + info.profile.name + ") from " + info.kind
            + " address " + peer_name(info.kind, pkt.src) + ": \"" + preview(pkt.bytes)
            + "\"");
        if (!sensor) {
          std::string ack = "ack " + std::to_string(pkt.bytes.size()) + " bytes";
          self->send(chans[info.device],
                     write_packet{pkt.src, prio_normal,
                                  byte_buffer(ack.begin(), ack.end())});
        }
      },
      [&](link_event&) {},
      [&](caf::down_msg& msg) {
        say("channel down: " + render(msg.reason));
        ok = false;
        timed_out = true;
      },
      caf::after(std::chrono::seconds(10)) >> [&] { timed_out = true; });
    if (timed_out) {
      say("timed out waiting for packets");
      ok = false;
      break;
    }
  }
  report("eth0");
  report("can0");
  // Give the last acknowledgement time to leave before closing.
  std::this_thread::sleep_for(std::chrono::milliseconds(sensor ? 0 : 300));
  self->send_exit(io, caf::exit_reason::user_shutdown);
  return ok ? 0 : 1;
}

int run_demo(const std::string& self_path) {
  auto dir = std::filesystem::temp_directory_path()
             / ("herm-demo-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  auto bus = (dir / "can-bus").string();
  auto p_sensor = free_udp_port();
  auto p_ctrl = free_udp_port();
  std::cout << "HERM two-module demo: a sensor module and a controller module,\n"
               "each its own process, joined by Ethernet (UDP on loopback)\n"
               "and a CAN 2.0 bus (emulated at 1 Mbit/s with 8-byte frames)."
            << std::endl;
  auto spawn = [&](const char* role, uint16_t mine, uint16_t peer) {
    auto pid = ::fork();
    if (pid == 0) {
      auto port = std::to_string(mine);
      auto peer_port = std::to_string(peer);
      ::execl(self_path.c_str(), self_path.c_str(), "--role", role,
              "--udp-port", port.c_str(), "--peer-port", peer_port.c_str(),
              "--bus", bus.c_str(), static_cast<char*>(nullptr));
      std::_Exit(127);
    }
    return pid;
  };
  auto ctrl = spawn("controller", p_ctrl, p_sensor);
  // Let the controller open its links before the sensor talks.
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  auto sens = spawn("sensor", p_sensor, p_ctrl);
  int st_sens = 0, st_ctrl = 0;
  ::waitpid(sens, &st_sens, 0);
  ::waitpid(ctrl, &st_ctrl, 0);
  std::filesystem::remove_all(dir);
  bool ok = WIFEXITED(st_sens) && WEXITSTATUS(st_sens) == 0
            && WIFEXITED(st_ctrl) && WEXITSTATUS(st_ctrl) == 0;
  std::cout << (ok ? "demo finished: every message arrived intact"
                   : "demo FAILED")
            << std::endl;
  return ok ? 0 : 1;
}

} // namespace

int main(int argc, char** argv) {
  role_args a;
  CLI::App app{"herm-demo: two HERM modules over two link kinds"};
  app.add_option("--role", a.role, "internal: run one module")
    ->check(CLI::IsMember({"sensor", "controller"}));
  app.add_option("--udp-port", a.udp_port, "internal");
  app.add_option("--peer-port", a.peer_port, "internal");
  app.add_option("--bus", a.bus, "internal");
  CLI11_PARSE(app, argc, argv);
  if (!a.role.empty())
    return run_module(a);
  return run_demo(std::filesystem::read_symlink("/proc/self/exe").string());
}
