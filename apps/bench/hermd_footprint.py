#!/usr/bin/env python3
"""hermd's idle footprint (issue 7): CPU and memory of an idle module.

Starts, per run and all at once (so that every process sees the same load):
  hermd-alone  one hermd with four channels: udp on 127.0.0.1, serial on a
               pseudo-terminal (this script drains the other end), can on an
               emulated bus and emu (ieee1394a) on an emulated medium; default
               hellos (1 s), the control socket on
  hermd-pair   two hermd joined by the same four links (udp peers, a socat
               pseudo-terminal cable, one CAN bus, one emulated medium), so
               each has a neighbour on every channel; both are measured
  caf, caf-herm, dds  references from bench_idle_peer (--peer): a bare CAF
               actor_system with CAF's defaults, one configured as hermd
               configures it, and a Cyclone DDS participant (when built in)
waits until every process is up and has settled (--settle), then samples
over --window seconds, from /proc:
  cpu_pct        (utime + stime) of /proc/PID/stat over the window, % of one core
  cpu_pct_sched  the same from every thread's schedstat (ns, more precise)
  rss_mb, hwm_mb VmRSS at the end and VmHWM (peak) from /proc/PID/status, MiB
  wakeups_per_s  context switches of all threads per second, and per thread
Repeated --runs times; every figure is the median with min and max. Targets:
cpu_pct < 1 and rss_mb < 20 for hermd.

  apps/bench/hermd_footprint.py --hermd build/bin/hermd \\
      --peer build/bin/bench_idle_peer --json footprint.json

--quick: one run, 2 s settle, 3 s window. --check: exit 1 unless the JSON is
well formed and every process stopped cleanly (the CTest; never asserts on
the figures). Exit status 2 for bad usage, 1 when a process failed to start.
Standard library only; needs socat for the pair's serial cable (without it
the pair is skipped, with the reason in the JSON).
"""

import argparse
import json
import os
import platform
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time

CLK_TCK = os.sysconf("SC_CLK_TCK")
# Issue 16's targets for an idle hermd with four channels.
TARGET_CPU_PCT = 0.5
TARGET_RSS_MB = 20.0
TARGET_WAKEUPS_PER_S = 20.0


# -- /proc ------------------------------------------------------------------------


def read_stat_ticks(pid):
    """utime + stime of the whole process, clock ticks."""
    with open(f"/proc/{pid}/stat") as f:
        text = f.read()
    fields = text[text.rindex(")") + 2:].split()
    return int(fields[11]) + int(fields[12])  # fields 14 and 15 of stat(5)


def read_status(path):
    result = {}
    with open(path) as f:
        for line in f:
            key, _, value = line.partition(":")
            result[key] = value.strip()
    return result


def kib(value):
    return int(value.split()[0])


def read_threads(pid):
    """Per thread: name, on-CPU ns (schedstat), context switches."""
    threads = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        base = f"/proc/{pid}/task/{tid}"
        try:
            with open(f"{base}/comm") as f:
                name = f.read().strip()
            with open(f"{base}/schedstat") as f:
                run_ns = int(f.read().split()[0])
            st = read_status(f"{base}/status")
            switches = int(st["voluntary_ctxt_switches"]) + int(
                st["nonvoluntary_ctxt_switches"])
        except (FileNotFoundError, ProcessLookupError, KeyError):
            continue  # the thread ended between listdir and open
        threads[int(tid)] = {"name": name, "run_ns": run_ns,
                             "switches": switches}
    return threads


def snapshot(pid):
    return {"t": time.monotonic(), "ticks": read_stat_ticks(pid),
            "threads": read_threads(pid)}


def measure(before, after, rss_samples_kib, hwm_kib):
    seconds = after["t"] - before["t"]
    threads = []
    total_ns = 0
    total_switches = 0
    for tid, a in after["threads"].items():
        b = before["threads"].get(tid, {"run_ns": 0, "switches": 0})
        run_ns = a["run_ns"] - b["run_ns"]
        switches = a["switches"] - b["switches"]
        total_ns += run_ns
        total_switches += switches
        threads.append({"tid": tid, "name": a["name"],
                        "cpu_pct": round(run_ns / 1e9 / seconds * 100, 4),
                        "wakeups_per_s": round(switches / seconds, 2)})
    threads.sort(key=lambda t: (-t["wakeups_per_s"], -t["cpu_pct"]))
    return {
        "window_s": round(seconds, 3),
        "cpu_pct": round((after["ticks"] - before["ticks"]) / CLK_TCK
                         / seconds * 100, 4),
        "cpu_pct_sched": round(total_ns / 1e9 / seconds * 100, 4),
        "rss_mb": round(rss_samples_kib[-1] / 1024, 3),
        "rss_max_mb": round(max(rss_samples_kib) / 1024, 3),
        "hwm_mb": round(hwm_kib / 1024, 3),
        "threads_count": len(after["threads"]),
        "wakeups_per_s": round(total_switches / seconds, 2),
        "threads": threads,
    }


# -- processes --------------------------------------------------------------------


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def hermd_config(name, mid, dirs, tty, udp_port, peers, node, station):
    peers_line = f"    peers: [{', '.join(peers)}]\n" if peers else ""
    return (
        f"module:\n  name: {name}\n  id: {mid}\n"
        f"control: {{ socket: {dirs}/{name}.sock }}\n"
        "channels:\n"
        f"  - name: eth0\n    kind: udp\n    interface: 127.0.0.1:{udp_port}\n"
        + peers_line +
        f"  - name: rs0\n    kind: serial\n    interface: {tty}\n"
        "    baud: 19200\n"
        f"  - name: can0\n    kind: can\n    interface: emu:{dirs}/can0\n"
        f"    node: {node}\n"
        f"  - name: fw0\n    kind: emu\n    interface: {dirs}/fw0\n"
        f"    profile: ieee1394a\n    station: {station}\n")


class Proc:
    """One measured process: started, waited for, stopped with SIGTERM."""

    def __init__(self, case, argv, log, ready_text):
        self.case = case
        self.log_path = log
        self.ready_text = ready_text
        self.log = open(log, "w")
        self.popen = subprocess.Popen(argv, stdout=self.log,
                                      stderr=subprocess.STDOUT,
                                      stdin=subprocess.DEVNULL)
        self.pid = self.popen.pid
        self.exit_status = None

    def wait_ready(self, deadline):
        while time.monotonic() < deadline:
            if self.popen.poll() is not None:
                return False
            with open(self.log_path, errors="replace") as f:
                if self.ready_text in f.read():
                    return True
            time.sleep(0.05)
        return False

    def tail(self):
        with open(self.log_path, errors="replace") as f:
            return f.read()[-800:]

    def stop(self):
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)
            try:
                self.popen.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()
        self.exit_status = self.popen.returncode
        self.log.close()


def drain(fd, stop):
    """Reads and discards what hermd writes to the pseudo-terminal."""
    while not stop.is_set():
        try:
            if not os.read(fd, 4096):
                return
        except OSError:
            return


def one_run(args, run, tmp, skipped):
    """Starts every process, measures them over one window, stops them.
    Returns {case: [sample, ...]}."""
    procs = []
    closers = []
    stop_drain = threading.Event()
    try:
        # hermd alone: the far end of its serial line is drained here.
        d = f"{tmp}/run{run}-alone"
        os.makedirs(d)
        master, slave = os.openpty()
        closers += [lambda: os.close(master), lambda: os.close(slave)]
        threading.Thread(target=drain, args=(master, stop_drain),
                         daemon=True).start()
        cfg = f"{d}/alone.yaml"
        with open(cfg, "w") as f:
            f.write(hermd_config("fp-alone", "0x80", d, os.ttyname(slave),
                                 free_udp_port(), [], 1, 1))
        procs.append(Proc("hermd-alone", [args.hermd, cfg], f"{d}/alone.log",
                          "running as"))

        # Two hermd joined by the same four links.
        socat = shutil.which("socat")
        if socat is None:
            skipped["hermd-pair"] = "socat not found (apt-get install socat)"
        else:
            d = f"{tmp}/run{run}-pair"
            os.makedirs(d)
            cable = subprocess.Popen(
                [socat, f"pty,raw,echo=0,link={d}/ttyA",
                 f"pty,raw,echo=0,link={d}/ttyB"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            closers.append(lambda: (cable.terminate(), cable.wait()))
            deadline = time.monotonic() + 5
            while not (os.path.exists(f"{d}/ttyA")
                       and os.path.exists(f"{d}/ttyB")):
                if time.monotonic() > deadline:
                    raise RuntimeError("socat made no pseudo-terminals")
                time.sleep(0.02)
            pa, pb = free_udp_port(), free_udp_port()
            for name, mid, tty, port, peer, node in (
                    ("fp-pair-a", "0x81", "ttyA", pa, pb, 1),
                    ("fp-pair-b", "0x82", "ttyB", pb, pa, 2)):
                cfg = f"{d}/{name}.yaml"
                with open(cfg, "w") as f:
                    f.write(hermd_config(name, mid, d, f"{d}/{tty}", port,
                                         [f"127.0.0.1:{peer}"], node, node))
                procs.append(Proc("hermd-pair", [args.hermd, cfg],
                                  f"{d}/{name}.log", "running as"))

        # References.
        if args.peer:
            for kind in ("caf", "caf-herm", "dds"):
                if kind in skipped:
                    continue
                procs.append(Proc(kind, [args.peer, kind],
                                  f"{tmp}/run{run}-{kind}.log", "ready"))

        deadline = time.monotonic() + 30
        for p in list(procs):
            if p.wait_ready(deadline):
                continue
            p.stop()
            if p.case in ("caf", "caf-herm", "dds") and p.exit_status == 77:
                skipped[p.case] = p.tail().strip() or "not built in"
                procs.remove(p)
                continue
            raise RuntimeError(f"{p.case} (pid {p.pid}) did not start "
                               f"(exit status {p.exit_status}):\n{p.tail()}")

        time.sleep(args.settle)
        befores = {p.pid: snapshot(p.pid) for p in procs}
        rss = {p.pid: [] for p in procs}
        end = time.monotonic() + args.window
        while True:
            for p in procs:
                st = read_status(f"/proc/{p.pid}/status")
                rss[p.pid].append(kib(st["VmRSS"]))
            left = end - time.monotonic()
            if left <= 0:
                break
            time.sleep(min(1.0, left))
        afters = {p.pid: snapshot(p.pid) for p in procs}
        hwm = {p.pid: kib(read_status(f"/proc/{p.pid}/status")["VmHWM"])
               for p in procs}
        samples = {}
        for p in procs:
            s = measure(befores[p.pid], afters[p.pid], rss[p.pid], hwm[p.pid])
            s["run"] = run
            s["pid"] = p.pid
            samples.setdefault(p.case, []).append(s)
        return samples, procs
    finally:
        for p in procs:
            p.stop()
        stop_drain.set()
        for c in reversed(closers):
            try:
                c()
            except OSError:
                pass


LABELS = {
    "hermd-alone": "hermd, four channels (udp, serial, can, emu), no neighbour",
    "hermd-pair": "hermd, the same four channels, a neighbour on each",
    "caf": "bare CAF actor_system, CAF's defaults (stealing, a worker per core)",
    "caf-herm": "bare CAF actor_system as hermd configures it (sharing, 1 worker)",
    "dds": "Cyclone DDS domain participant, loopback, no topics",
}


def summarize(name, samples):
    case = {"name": name, "label": LABELS[name],
            "process": "hermd" if name.startswith("hermd") else "reference",
            "samples": samples}
    for key in ("cpu_pct", "cpu_pct_sched", "rss_mb", "hwm_mb",
                "wakeups_per_s", "threads_count"):
        values = [s[key] for s in samples]
        case[key] = statistics.median(values)
        case[key + "_min"] = min(values)
        case[key + "_max"] = max(values)
    if case["process"] == "hermd":
        case["cpu_met"] = case["cpu_pct"] < TARGET_CPU_PCT
        case["rss_met"] = case["rss_mb"] < TARGET_RSS_MB
        case["wakeups_met"] = case["wakeups_per_s"] <= TARGET_WAKEUPS_PER_S
    # The threads of the sample closest to the median, busiest first.
    median_sample = min(samples, key=lambda s: abs(s["cpu_pct_sched"]
                                                   - case["cpu_pct_sched"]))
    case["threads_of_median_sample"] = median_sample["threads"]
    return case


def check(doc, procs_exit):
    """The CTest's assertions: structure, not figures."""
    problems = []
    if doc.get("benchmark") != "hermd-footprint":
        problems.append("benchmark is not hermd-footprint")
    names = [c["name"] for c in doc.get("cases", [])]
    if "hermd-alone" not in names:
        problems.append("no hermd-alone case")
    for c in doc.get("cases", []):
        if len(c["samples"]) != doc["parameters"]["runs"] * (
                2 if c["name"] == "hermd-pair" else 1):
            problems.append(f"{c['name']}: wrong number of samples")
        for key in ("cpu_pct", "cpu_pct_sched", "rss_mb", "hwm_mb",
                    "wakeups_per_s"):
            for suffix in ("", "_min", "_max"):
                v = c.get(key + suffix)
                if not isinstance(v, (int, float)) or v < 0:
                    problems.append(f"{c['name']}: {key}{suffix} = {v!r}")
        if c["rss_mb"] <= 0 or c["threads_count"] < 1:
            problems.append(f"{c['name']}: no memory or no threads measured")
    for case, status in procs_exit:
        if status != 0:
            problems.append(f"{case} exited with status {status} after "
                            "SIGTERM")
    return problems


def main():
    ap = argparse.ArgumentParser(
        description="hermd's idle CPU and memory, next to reference processes",
        formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--hermd", required=True, help="the hermd binary")
    ap.add_argument("--peer", help="bench_idle_peer, for the references")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--settle", type=float, default=5.0,
                    help="seconds between start-up and the window")
    ap.add_argument("--window", type=float, default=20.0,
                    help="seconds sampled")
    ap.add_argument("--quick", action="store_true",
                    help="one run, 2 s settle, 3 s window")
    ap.add_argument("--json", help="write the results to this file")
    ap.add_argument("--check", action="store_true",
                    help="exit 1 unless the JSON is well formed and every "
                         "process stopped cleanly")
    args = ap.parse_args()
    if args.quick:
        args.runs, args.settle, args.window = 1, 2.0, 3.0
    if args.runs < 1 or args.window <= 0 or args.settle < 0:
        ap.error("--runs >= 1, --window > 0, --settle >= 0")
    for binary in filter(None, (args.hermd, args.peer)):
        if not os.access(binary, os.X_OK):
            ap.error(f"{binary}: not an executable")

    load_before = open("/proc/loadavg").read().strip()
    skipped = {}
    per_case = {}
    exits = []
    with tempfile.TemporaryDirectory(prefix="herm-footprint-") as tmp:
        for run in range(args.runs):
            try:
                samples, procs = one_run(args, run, tmp, skipped)
            except (RuntimeError, OSError) as e:
                print(f"hermd_footprint: {e}", file=sys.stderr)
                return 1
            exits += [(p.case, p.exit_status) for p in procs]
            for case, s in samples.items():
                per_case.setdefault(case, []).extend(s)
            for case, s in samples.items():
                for x in s:
                    print(f"run {run + 1}/{args.runs} {case:12} pid {x['pid']}: "
                          f"cpu {x['cpu_pct']:.3f} % (sched "
                          f"{x['cpu_pct_sched']:.3f} %), rss {x['rss_mb']:.1f} MiB, "
                          f"hwm {x['hwm_mb']:.1f} MiB, {x['threads_count']} threads, "
                          f"{x['wakeups_per_s']:.1f} wake-ups/s", flush=True)
    order = ["hermd-alone", "hermd-pair", "caf-herm", "caf", "dds"]
    doc = {
        "benchmark": "hermd-footprint",
        "command": " ".join([os.path.basename(sys.argv[0])] + sys.argv[1:]),
        "machine": {"cpus": os.cpu_count(), "kernel": " ".join(
            platform.uname()[i] for i in (0, 2, 4)),
            "loadavg_before": load_before,
            "loadavg_after": open("/proc/loadavg").read().strip()},
        "parameters": {"runs": args.runs, "settle_s": args.settle,
                       "window_s": args.window, "hello_ms": 1000},
        "targets": {"cpu_pct": TARGET_CPU_PCT, "rss_mb": TARGET_RSS_MB,
                    "wakeups_per_s": TARGET_WAKEUPS_PER_S},
        "cases": [summarize(n, per_case[n]) for n in order if n in per_case],
        "skipped": [{"name": n, "reason": r} for n, r in skipped.items()],
    }
    text = json.dumps(doc, indent=2) + "\n"
    if args.json:
        with open(args.json, "w") as f:
            f.write(text)
    for c in doc["cases"]:
        print(f"{c['name']:12} cpu {c['cpu_pct']:.3f} % [{c['cpu_pct_min']:.3f}.."
              f"{c['cpu_pct_max']:.3f}], rss {c['rss_mb']:.1f} MiB "
              f"[{c['rss_mb_min']:.1f}..{c['rss_mb_max']:.1f}], "
              f"{c['wakeups_per_s']:.0f} wake-ups/s")
    for s in doc["skipped"]:
        print(f"skipped {s['name']}: {s['reason']}")
    if args.check:
        problems = check(json.loads(text), exits)
        for p in problems:
            print(f"check: {p}", file=sys.stderr)
        return 1 if problems else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
