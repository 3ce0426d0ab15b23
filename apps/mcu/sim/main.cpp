// herm-avr-sim: runs the sonar board's firmware (an ATmega128 ELF) in simavr,
// in real time, with UART0 on a pseudo-terminal and an SRF04 on PB0 (trigger)
// and PD4/ICP1 (echo). docs/mcu.md, "The SRF04 board" and "Testing a board".
//
//   herm-avr-sim --firmware herm-srf04-firmware.elf [--distance-mm N]
//                [--script FILE] [--pty-link PATH | --device PATH]
//                [--eeprom FILE] [--max-seconds S] [--report-stack]
//
// UART0 goes to a new pty (its path printed, and --pty-link made to point at
// it), or with --device to an existing serial line (one end of a paced pty
// cable, a real tty). --eeprom FILE loads the board's EEPROM from FILE at
// start (missing: erased) and writes it back at every exit after start, so
// a board run again is the same board rebooted (the sonar firmware's boot
// counter, its instance, goes on counting).
//
// Prints `pty PATH` (or `line PATH` with --device) first, then `ready ...`;
// at the end `stopped reason=...`, `realtime ...`, `uart ...`, `srf04 ...`,
// with --eeprom `eeprom saved FILE bytes=N` (or `eeprom error ...`) and, with
// --report-stack, `stack used=N ...`. Exit status: 0 after --max-seconds or
// SIGTERM/SIGINT, 2 when it could not start (or could not save --eeprom), 3
// when the firmware stopped (returned from main, slept with interrupts off)
// or crashed.
//
// Time: simavr runs as fast as the host allows; the harness runs 1 ms of
// board time at a time and sleeps until the wall clock catches up, so the
// board's millisecond tick and its 19,200 baud line match real time (the
// largest lag behind the wall clock is reported as max_lag_ms).
#include <signal.h>
#include <time.h>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cinttypes>
#include <cstdarg>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>

#include "apps/mcu/sim/distance_script.hpp"
#include "apps/mcu/sim/eeprom_file.hpp"
#include "apps/mcu/sim/simavr.hpp"
#include "apps/mcu/sim/srf04_part.hpp"
#include "apps/mcu/sim/stack_report.hpp"
#include "apps/mcu/sim/uart_bridge.hpp"

// LeakSanitizer (the AddressSanitizer suite): simavr 1.6's
// elf_read_firmware mallocs the firmware's flash, EEPROM and symbol images
// and sim_elf.h has no function that frees them (avr_load_firmware copies
// what it needs); one set per run. LeakSanitizer asks this hook for its
// suppressions; nothing of HERM's own is suppressed.
extern "C" const char* __lsan_default_suppressions() {
  return "leak:elf_read_firmware\n";
}

namespace {

volatile sig_atomic_t stop_signal = 0;

void on_signal(int sig) {
  stop_signal = sig;
}

/// The board's clock frequency and part (the paper's board).
constexpr uint32_t f_cpu = 16000000;
constexpr const char* mcu = "atmega128";

int64_t now_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

void sleep_until_ns(int64_t t) {
  timespec ts{static_cast<time_t>(t / 1000000000), static_cast<long>(t % 1000000000)};
  while (::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR
         && stop_signal == 0) {
  }
}

/// The data-space address where the firmware's painted area starts: `_end`
/// (avr-libc's end of .data and .bss), else `__heap_start`; 0 if neither.
uint32_t painted_from(const elf_firmware_t& f) {
  for (const char* name : {"_end", "__heap_start"})
    for (uint32_t i = 0; i < f.symbolcount; ++i)
      if (std::strcmp(f.symbol[i]->symbol, name) == 0)
        return f.symbol[i]->addr & 0xFFFFu; // data lives at 0x800000 in the ELF
  return 0;
}

/// simavr's messages go to stderr (stdout carries the harness's lines), its
/// errors and warnings only (an overrun, a crash, a bad opcode).
void log_to_stderr(avr_t*, const int level, const char* format, va_list ap) {
  if (level > LOG_WARNING)
    return;
  std::fputs("simavr: ", stderr);
  std::vfprintf(stderr, format, ap);
}

/// simavr's idle callback would usleep on its own; the pacing loop sleeps.
void no_sleep(avr_t*, avr_cycle_count_t) {
}

} // namespace

int main(int argc, char** argv) {
  CLI::App app{"herm-avr-sim: the sonar board's ATmega128 firmware in simavr, "
               "in real time, UART0 on a pty, an SRF04 on PB0/PD4"};
  std::string firmware;
  uint32_t distance_mm = 1000;
  std::string script_file;
  std::string pty_link;
  std::string device;
  std::string eeprom_path;
  double max_seconds = 0;
  bool report_stack = false;
  app.add_option("--firmware", firmware, "the firmware (ELF for the ATmega128)")
    ->required();
  app.add_option("--distance-mm", distance_mm,
                 "the obstacle's distance when no script says otherwise (mm)");
  app.add_option("--script", script_file,
                 "a file of `t_ms distance_mm` lines: the obstacle from board "
                 "time t_ms on");
  auto* link_opt = app.add_option("--pty-link", pty_link,
                                  "make this symlink point at the board's serial line");
  app.add_option("--device", device,
                 "connect UART0 to this existing serial line instead of a new pty")
    ->excludes(link_opt);
  app.add_option("--eeprom", eeprom_path,
                 "keep the board's EEPROM in this file across runs "
                 "(missing: erased; written back at exit)");
  app.add_option("--max-seconds", max_seconds,
                 "stop after this much board time (0: run until SIGTERM)")
    ->check(CLI::NonNegativeNumber);
  app.add_flag("--report-stack", report_stack,
               "at exit, print the stack high-water mark (painted stack)");
  CLI11_PARSE(app, argc, argv);

  herm::avr_sim::distance_script script;
  if (!script_file.empty()) {
    std::ifstream in{script_file};
    if (!in) {
      std::cout << "error cannot read --script " << script_file << std::endl;
      return 2;
    }
    std::ostringstream text;
    text << in.rdbuf();
    script = herm::avr_sim::parse_distance_script(text.str());
    if (!script.error.empty()) {
      std::cout << "error " << script_file << ": " << script.error << std::endl;
      return 2;
    }
  }

  avr_global_logger_set(log_to_stderr);
  elf_firmware_t f{};
  if (elf_read_firmware(firmware.c_str(), &f) != 0) {
    std::cout << "error cannot load the ELF " << firmware << std::endl;
    return 2;
  }
  avr_t* avr = avr_make_mcu_by_name(mcu);
  if (avr == nullptr) {
    std::cout << "error simavr has no core " << mcu << std::endl;
    return 2;
  }
  avr_init(avr);
  f.frequency = f_cpu;
  avr->frequency = f_cpu;
  avr_load_firmware(avr, &f);
  avr->sleep = no_sleep;
  avr->log = LOG_WARNING;

  // The EEPROM after the ELF's .eeprom section: the file is the board's
  // memory of earlier runs, so it wins.
  avr_eeprom_desc_t ee{};
  if (!eeprom_path.empty()) {
    ee.size = avr->e2end + 1u; // the whole EEPROM
    avr_ioctl(avr, AVR_IOCTL_EEPROM_GET, &ee);
    if (ee.ee == nullptr || ee.size == 0) {
      std::cout << "error the core has no EEPROM for --eeprom" << std::endl;
      return 2;
    }
    auto img = herm::avr_sim::load_eeprom(eeprom_path, ee.size);
    if (!img.error.empty()) {
      std::cout << "error " << img.error << std::endl;
      return 2;
    }
    std::copy(img.bytes.begin(), img.bytes.end(), ee.ee);
  }

  std::string error;
  auto uart = device.empty()
                ? herm::avr_sim::uart_bridge::open(avr, '0', pty_link, error)
                : herm::avr_sim::uart_bridge::attach(avr, '0', device, error);
  if (!uart) {
    std::cout << "error " << error << std::endl;
    return 2;
  }
  herm::avr_sim::srf04_part sonar{
    avr, 'B', 0, 'D', 4, [&](uint32_t t_ms) {
      return herm::avr_sim::distance_at(script.points, t_ms, distance_mm);
    }};
  if (!sonar.attached()) {
    std::cout << "error the core has no PB0 or PD4" << std::endl;
    return 2;
  }

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  ::sigaction(SIGTERM, &sa, nullptr);
  ::sigaction(SIGINT, &sa, nullptr);

  std::cout << (device.empty() ? "pty " : "line ") << uart->pty_path() << "\n"
            << "ready firmware=" << firmware << " mcu=" << mcu
            << " f_cpu=" << f_cpu << " uart=0 trigger=PB0 echo=PD4" << std::endl;

  const avr_cycle_count_t slice = f_cpu / 1000; // 1 ms of board time
  const auto max_cycles = static_cast<avr_cycle_count_t>(max_seconds * f_cpu);
  const int64_t start = now_ns();
  int64_t max_lag_ns = 0;
  std::string reason = "signal";
  int status = 0;
  for (;;) {
    if (stop_signal != 0)
      break;
    if (max_cycles != 0 && avr->cycle >= max_cycles) {
      reason = "max-seconds";
      break;
    }
    avr_cycle_count_t target = avr->cycle + slice;
    int state = cpu_Running;
    while (avr->cycle < target) {
      state = avr_run(avr);
      if (state == cpu_Done || state == cpu_Crashed)
        break;
    }
    uart->pump();
    if (state == cpu_Done || state == cpu_Crashed) {
      reason = state == cpu_Done ? "firmware-done" : "firmware-crashed";
      status = 3;
      break;
    }
    int64_t board_ns = static_cast<int64_t>(avr->cycle * 1000u / (f_cpu / 1000000u));
    int64_t wall_ns = now_ns() - start;
    if (board_ns > wall_ns)
      sleep_until_ns(start + board_ns);
    else if (wall_ns - board_ns > max_lag_ns)
      max_lag_ns = wall_ns - board_ns;
  }
  uart->pump();

  auto board_ms = avr->cycle / (f_cpu / 1000u);
  auto wall_ms = (now_ns() - start) / 1000000;
  const auto& u = uart->counters();
  const auto& s = sonar.counters();
  std::cout << "stopped reason=" << reason << " board_ms=" << board_ms << "\n"
            << "realtime board_ms=" << board_ms << " wall_ms=" << wall_ms
            << " max_lag_ms=" << max_lag_ns / 1000000 << "\n"
            << "uart to_board=" << u.to_board << " to_host=" << u.to_host
            << " held=" << u.held << " lost_rx_off=" << u.lost_rx_off
            << " dropped_to_host=" << u.dropped_to_host
            << " frame_cycles=" << uart->frame_cycles() << "\n"
            << "srf04 measurements=" << s.measurements
            << " short_triggers=" << s.short_triggers
            << " busy_triggers=" << s.busy_triggers << "\n";
  if (report_stack) {
    auto from = painted_from(f);
    if (from == 0) {
      std::cout << "stack unknown: the ELF has no _end or __heap_start symbol\n";
    } else {
      auto use = herm::avr_sim::measure_stack(avr->data, from, avr->ramend);
      char line[160];
      std::snprintf(line, sizeof(line),
                    "stack used=%" PRIu32 " headroom=%" PRIu32
                    " from=0x%04" PRIx32 " ramend=0x%04x painted=%s\n",
                    use.used, use.headroom, from, static_cast<unsigned>(avr->ramend),
                    use.painted ? "yes" : "no");
      std::cout << line;
    }
  }
  if (!eeprom_path.empty()) {
    auto err = herm::avr_sim::save_eeprom(eeprom_path, ee.ee, ee.size);
    if (err.empty()) {
      std::cout << "eeprom saved " << eeprom_path << " bytes=" << ee.size << "\n";
    } else {
      std::cout << "eeprom error " << err << "\n";
      if (status == 0)
        status = 2;
    }
  }
  std::cout.flush();
  uart.reset();
  avr_terminate(avr);
  return status;
}
