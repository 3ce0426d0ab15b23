#!/usr/bin/env python3
"""Writes the results section of docs/performance.md and the plots in
docs/img/ from the raw JSON that apps/bench/run-all.sh keeps (issue 7).

  generate.py --results DIR [--doc docs/performance.md] [--img-dir docs/img]
              [--no-plots]

Reads from DIR (every file optional: a missing one, or a missing mode of
herm-bench-rtt, becomes a "not in this run" line, never an error):
  manifest.json            run-all.sh: command, date, commit, machine, load
  can_efficiency.json      Google Benchmark JSON (--benchmark_out)
  serial_goodput.json      "
  emu_bandwidth.json       "
  fragmentation.json       "
  routing_convergence.json bench_routing_convergence --json
  rtt.json                 herm-bench-rtt --json
  footprint.json           hermd_footprint.py --json
Writes DIR/results.md always; with --doc, replaces what lies between the
lines <!-- results:begin --> and <!-- results:end --> of that file (and
nothing else); with --img-dir, the PNGs (gnuplot, scripts in plots/). Every
figure is a median over the repetitions with [min..max]; every ratio is to a
limit or peer measured in the same run. Exit status 2 for bad usage or a
document without the markers, 1 when gnuplot fails.

Standard library only.
"""

import argparse
import functools
import json
import math
import os
import statistics
import subprocess
import sys

BEGIN = "<!-- results:begin -->"
END = "<!-- results:end -->"
HERE = os.path.dirname(os.path.abspath(__file__))

# The modes herm-bench-rtt can write, in the order they are shown; a mode
# missing from rtt.json is listed as not run.
RTT_MODES = [
    ("back-to-back", "Round trip, back to back", "ratio_to_udp", "raw UDP"),
    ("gap-10ms", "Round trip, 10 ms gap after each reply", "ratio_to_udp",
     "raw UDP"),
    ("inprocess", "Round trip inside one process", "ratio_to_caf_local",
     "a local CAF actor"),
    ("router", "Round trip through a router module", "ratio_to_direct",
     "the direct path"),
]
# Distinct colours for the transports of the bar charts (Tableau 20).
PALETTE = ["#9467bd", "#1f77b4", "#aec7e8", "#17becf", "#ff7f0e", "#ffbb78",
           "#d62728", "#ff9896", "#2ca02c", "#98df8a", "#8c564b", "#c49c94",
           "#e377c2", "#f7b6d2", "#7f7f7f", "#bcbd22", "#dbdb8d", "#9edae5"]
SHORT_NAMES = {"hermd-alone": "hermd, alone", "hermd-pair": "hermd + neighbour",
               "caf-herm": "CAF as in hermd", "caf": "CAF defaults",
               "dds": "Cyclone DDS"}
FAMILY_NAMES = {"udp": "raw UDP", "herm": "HERM", "caf": "CAF remote actor",
                "caf-local": "CAF local actor", "zmq": "ZeroMQ",
                "dds": "Cyclone DDS"}


# -- numbers ----------------------------------------------------------------------


def num(v, unit=""):
    """Three significant figures, thousands separated: 0.123, 12.3, 1,234."""
    if v is None:
        return "n/a"
    if v == 0:
        return "0" + unit
    a = abs(v)
    if a >= 100:
        s = f"{v:,.0f}"
    elif a >= 10:
        s = f"{v:.1f}"
    elif a >= 1:
        s = f"{v:.2f}"
    else:
        s = f"{v:.3f}"
    return s + unit


def pct(v, digits=1):
    return "n/a" if v is None else f"{v * 100:.{digits}f} %"


def rng(med, lo, hi, f=num):
    """median [min..max], or the median alone when they are equal."""
    if lo is None or hi is None or (f(lo) == f(med) == f(hi)):
        return f(med)
    m, a, b = f(med), f(lo), f(hi)
    if " " in m:  # "87.3 %": the unit once, after the median
        unit = m[m.rindex(" "):]
        a, b = a.removesuffix(unit), b.removesuffix(unit)
    return f"{m} [{a}..{b}]"


def mmm(values):
    values = [v for v in values if v is not None]
    if not values:
        return None, None, None
    return statistics.median(values), min(values), max(values)


def verdict(ok):
    return "n/a" if ok is None else ("**met**" if ok else "**missed**")


def load(path):
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return json.load(f)


# -- Google Benchmark JSON --------------------------------------------------------


def gbench_cases(doc):
    """{run_name: {"reps": [entry, ...], "error": text}} in file order, the
    per-repetition entries only (aggregates are recomputed here)."""
    cases = {}
    for b in doc.get("benchmarks", []):
        if b.get("run_type", "iteration") != "iteration":
            continue
        name = b.get("run_name", b["name"])
        c = cases.setdefault(name, {"reps": [], "error": None})
        if b.get("error_occurred"):
            c["error"] = b.get("error_message", "error")
        else:
            c["reps"].append(b)
    return cases


def counter(case, key, scale=1.0):
    return mmm([r[key] * scale for r in case["reps"] if key in r])


def arg(name, key):
    """Value of KEY:VALUE in a benchmark name (bytes:2000 -> 2000)."""
    for part in name.split("/"):
        if part.startswith(key + ":"):
            return int(part.split(":", 1)[1])
    return None


# -- sections ---------------------------------------------------------------------


def section(title, fname):
    """Makes a Report method `m(self, doc)` the writer of the section `title`
    on the results file `fname`: the decorated method takes no argument,
    writes the heading, then calls `m` with the file's parsed JSON, or writes
    a "not in this run" line instead when the file is absent."""
    def decorate(method):
        @functools.wraps(method)
        def write(self):
            doc = load(f"{self.dir}/{fname}")
            self.out(f"### {title}", "")
            if doc is None:
                self.out(f"Not in this run (no `{fname}` in the results).", "")
                return
            method(self, doc)
        return write
    return decorate


class Report:
    def __init__(self, results):
        self.dir = results
        self.lines = []
        self.targets = []  # rows of the summary table
        self.plots = {}    # name -> data, for plots()

    def out(self, *lines):
        self.lines.extend(lines)

    def target(self, what, measured, against, ratio, goal, ok):
        self.targets.append(f"| {what} | {measured} | {against} | {ratio} | "
                            f"{goal} | {verdict(ok)} |")

    # CAN ------------------------------------------------------------------------
    @section("CAN: payload efficiency and frame rate, emulated 1 Mbit/s bus",
             "can_efficiency.json")
    def can(self, doc):
        self.out("Command: `bench_can_efficiency` (two stations of the `can` "
                 "driver's emulated bus, HERM's port stack). Limit: frames/s of "
                 "8-byte frames at 1 Mbit/s for this identifier format, computed "
                 "in the same run; bus load counts every frame's exact bits "
                 "(1 = the bus never idles, above 1 is impossible).", "",
                 "| identifiers | packet | payload efficiency (≥ 87 %) | "
                 "frames/s | limit | bus load | goodput |",
                 "|---|---|---|---|---|---|---|")
        kinds = {"ext29": "29-bit", "std11": "11-bit",
                 "ext29_stuffed": "29-bit, worst-case stuffing"}
        rows = []
        worst_eff = None
        worst_load = None
        for name, c in gbench_cases(doc).items():
            kind = kinds.get(name.split("/")[1], name.split("/")[1])
            size = arg(name, "bytes")
            if c["error"] or not c["reps"]:
                self.out(f"| {kind} | {size:,} B | failed: {c['error']} | | | | |")
                worst_eff = (0, "failed")
                continue
            eff = counter(c, "payload_eff")
            fps = counter(c, "frames_per_s")
            lim = counter(c, "limit_fps")
            load_ = counter(c, "bus_load")
            good = counter(c, "goodput_Bps", 1e-3)
            self.out(f"| {kind} | {size:,} B | {rng(*eff, f=pct)} | "
                     f"{rng(*fps)} | {num(lim[0])} | {rng(*load_, f=lambda v: f'{v:.4f}')} | "
                     f"{rng(*good)} kB/s |")
            rows.append((f"{kind}, {size} B", eff, load_))
            if worst_eff is None or eff[1] < worst_eff[0]:
                worst_eff = (eff[1], f"{kind}, {size:,} B")
            if worst_load is None or load_[2] > worst_load[0]:
                worst_load = (load_[2], f"{kind}, {size:,} B")
        self.out("")
        self.plots["can"] = rows
        if worst_eff:
            self.target("CAN payload efficiency, long packets (issue 3/7), "
                        f"lowest case: {worst_eff[1]}", pct(worst_eff[0]),
                        "8-byte data field", "", "≥ 87 %",
                        worst_eff[0] >= 0.87)
        if worst_load:
            self.target(f"CAN frame rate within the bus limit, highest: "
                        f"{worst_load[1]}", f"bus load {worst_load[0]:.4f}",
                        "1 Mbit/s, exact frame bits", "", "≤ 1",
                        worst_load[0] <= 1.0)

    # serial -----------------------------------------------------------------------
    @section("Serial: goodput at 19,200 baud", "serial_goodput.json")
    def serial(self, doc):
        self.out("Command: `bench_serial_goodput` (two `serial` drivers on a "
                 "paced pseudo-terminal cable, 8N1, MTU 32). Line rate: baud / "
                 "10 bytes/s, the relay's own pacing in the same run. The "
                 "target applies to packets of a full frame or more; an 8-byte "
                 "packet pays a whole frame's framing.", "",
                 "| packet | goodput | line rate | share of line rate (≥ 80 %) | "
                 "line busy | |",
                 "|---|---|---|---|---|---|")
        rows = []
        worst = None
        for name, c in gbench_cases(doc).items():
            size = arg(name, "packet")
            if c["error"] or not c["reps"]:
                self.out(f"| {size:,} B | failed: {c['error']} | | | | |")
                worst = (None, f"{size:,} B")
                continue
            good = counter(c, "goodput_Bps")
            line = counter(c, "line_Bps")
            ratio = counter(c, "ratio")
            busy = counter(c, "line_busy")
            applies = size >= 31
            self.out(f"| {size:,} B | {rng(*good)} B/s | {num(line[0])} B/s | "
                     f"{rng(*ratio, f=pct)} | {rng(*busy, f=lambda v: f'{v:.4f}')} | "
                     f"{verdict(ratio[1] >= 0.80) if applies else 'n/a'} |")
            rows.append((f"{size} B", ratio, busy))
            if applies and (worst is None or (worst[0] is not None
                                              and ratio[1] < worst[0])):
                worst = (ratio[1], f"{size:,} B")
        self.out("")
        self.plots["serial"] = rows
        if worst:
            self.target(f"Serial goodput at 19,200 baud, lowest: {worst[1]}",
                        "failed" if worst[0] is None else pct(worst[0]),
                        "line rate 1,920 B/s", "", "≥ 80 %",
                        worst[0] is not None and worst[0] >= 0.80)

    # emulated media ---------------------------------------------------------------
    @section("Emulated media: delivered against configured bandwidth",
             "emu_bandwidth.json")
    def emu(self, doc):
        self.out("Command: `bench_emu_bandwidth` (MTU-sized frames back to back "
                 "through the `emu` driver; the ceiling probes show the machine's "
                 "frame rate, not a target).", "",
                 "| profile | configured bit/s | delivered bit/s | ratio "
                 "(within 5 %) | frames / lost |", "|---|---|---|---|---|")
        worst = None
        for name, c in gbench_cases(doc).items():
            prof = name.split("/")[1]
            if c["error"] or not c["reps"]:
                self.out(f"| {prof} | failed: {c['error']} | | | |")
                continue
            conf = counter(c, "configured_bps")
            got = counter(c, "delivered_bps")
            ratio = counter(c, "ratio")
            frames = sum(r.get("frames", 0) for r in c["reps"])
            lost = sum(r.get("lost", 0) for r in c["reps"])
            probe = prof.startswith("ceiling")
            self.out(f"| {prof} | {num(conf[0])} | {rng(*got)} | "
                     f"{rng(*ratio, f=lambda v: f'{v:.3f}')}"
                     f"{' (probe)' if probe else ''} | {frames:,.0f} / {lost:,.0f} |")
            if not probe:
                dev = max(abs(ratio[1] - 1), abs(ratio[2] - 1))
                if worst is None or dev > worst[0]:
                    worst = (dev, prof)
        self.out("")
        if worst:
            self.target(f"Emulated bandwidth, largest deviation: {worst[1]}",
                        f"{worst[0] * 100:.2f} %", "configured bit/s", "",
                        "≤ 5 %", worst[0] <= 0.05)

    # fragmentation ----------------------------------------------------------------
    @section("Fragmentation and reassembly", "fragmentation.json")
    def fragmentation(self, doc):
        self.out("Command: `bench_fragmentation --benchmark_filter="
                 "split_and_reassemble` (one packet split and reassembled, CRC "
                 "included; CPU time per packet).", "",
                 "| packet | MTU | time per packet | throughput | efficiency |",
                 "|---|---|---|---|---|")
        for name, c in gbench_cases(doc).items():
            if not name.startswith("split_and_reassemble"):
                continue
            size, mtu = arg(name, "size"), arg(name, "mtu")
            if c["error"] or not c["reps"]:
                self.out(f"| {size:,} B | {mtu} | failed: {c['error']} | | |")
                continue
            unit = c["reps"][0].get("time_unit", "ns")
            scale = {"ns": 1e-3, "us": 1, "ms": 1e3, "s": 1e6}[unit]
            t = mmm([r["cpu_time"] * scale for r in c["reps"]])
            bps = counter(c, "bytes_per_second", 1e-6)
            eff = counter(c, "efficiency")
            self.out(f"| {size:,} B | {mtu} | {rng(*t)} µs | {rng(*bps)} MB/s | "
                     f"{pct(eff[0]) if eff[0] is not None else 'n/a'} |")
        self.out("")

    # routing ---------------------------------------------------------------------
    @section("Routing: cold-start convergence and repair (simulated time)",
             "routing_convergence.json")
    def routing(self, doc):
        self.out(f"Command: `{doc.get('command', 'bench_routing_convergence')}` "
                 "(deterministic: simulated time, so one run; random meshes with "
                 "a third of the extra links 3-station CAN buses; converged is "
                 "checked every tenth of a hello interval).", "",
                 "| modules | converged after | update packets | update entries "
                 "per module | hellos | wall clock |",
                 "|---|---|---|---|---|---|")
        for r in doc.get("cold_start", []):
            conv = (f"{r['converged_ms']:,} ms" if r.get("converged", True)
                    else f"not after {r['converged_ms']:,} ms")
            self.out(f"| {r['modules']:,} | {conv} | {r['updates']:,} | "
                     f"{num(r['update_entries'] / r['modules'])} | "
                     f"{r['hellos']:,} | {num(r['wall_s'])} s |")
        self.plots["convergence"] = doc.get("cold_start", [])
        self.out("", "Repair after a silent link failure (ring of 10, 8 failure "
                 "moments across one hello interval), in ms and hello intervals:",
                 "", "| hello interval | min | median | max | loops | "
                 "≤ 2 intervals, 0 loops |", "|---|---|---|---|---|---|")
        worst = None
        for r in doc.get("repair", []):
            h = r["hello_ms"]
            cells = []
            for k in ("min_ms", "median_ms", "max_ms"):
                v = r[k]
                cells.append("never" if v is None else
                             f"{v:,} ms ({v / h:.2f})")
            ok = r["max_ms"] is not None and r["max_ms"] <= 2 * h \
                and r["loops"] == 0
            self.out(f"| {h:,} ms | {' | '.join(cells)} | {r['loops']} | "
                     f"{verdict(ok)} |")
            w = float("inf") if r["max_ms"] is None else r["max_ms"] / h
            if worst is None or w > worst[0] or r["loops"] > 0:
                worst = (w, h, r["loops"])
        self.out("")
        if worst:
            self.target(f"Routing repair after a silent failure (issue 4), "
                        f"worst at hello {worst[1]:,} ms",
                        ("never repaired" if worst[0] == float("inf") else
                         f"{worst[0]:.2f} intervals") + f", {worst[2]} loops",
                        "hello interval", "", "≤ 2, 0 loops",
                        worst[0] <= 2 and worst[2] == 0)

    # round trips -------------------------------------------------------------------
    @section("Request round trips next to peers", "rtt.json")
    def rtt(self, doc):
        cases = [c for c in doc.get("cases", [])]
        params = doc.get("parameters", {})
        self.out(f"Command: `{doc.get('command', 'herm-bench-rtt')}` (two fresh "
                 f"processes per case on 127.0.0.1, {params.get('repeat', '?')} "
                 "run(s) with the repetitions outermost). Cells: p50 in µs as the "
                 "median of the runs' p50 [min..max], then the ratio to the "
                 "reference measured in the same run.", "")
        present = {c.get("mode") for c in cases}
        for c in doc.get("skipped", []):
            self.out(f"- skipped: {c if isinstance(c, str) else json.dumps(c)}")
        rtt_plot = []
        for mode, title, ratio_key, ref in RTT_MODES:
            mc = [c for c in cases if c.get("mode") == mode]
            if not mc:
                self.out(f"**{title}** (`{mode}`): not in this run.", "")
                continue
            sizes = sorted({c["size"] for c in mc})
            places = placements_of(mc)
            self.out(f"**{title}** (`{mode}`; ratio to {ref} in the same "
                     "placement):", "",
                     "| transport | placement | "
                     + " | ".join(f"{s:,} B" for s in sizes)
                     + " |", "|---" * (len(sizes) + 2) + "|")
            for pl in places:
                pc = [c for c in mc if c.get("placement") == pl]
                for t in unique(c["transport"] for c in pc):
                    cells = []
                    label = transport_label(next(c for c in pc
                                                 if c["transport"] == t))
                    for s in sizes:
                        c = find(pc, transport=t, size=s)
                        cells.append(rtt_cell(c, ratio_key))
                        if c and c.get("runs") and c.get("p50_us") is not None:
                            rtt_plot.append((mode, placed(label, pl, places), s,
                                             c["p50_us"],
                                             c.get("p50_min_us", c["p50_us"]),
                                             c.get("p50_max_us", c["p50_us"])))
                    bold = "**" if t.startswith("herm") else ""
                    self.out(f"| {bold}{label}{bold} | {pl or '—'} | "
                             + " | ".join(cells) + " |")
            self.out("")
            self.rtt_counts(mode, mc, places)
            for pl in places:
                pc = [c for c in mc if c.get("placement") == pl]
                if mode in ("back-to-back", "gap-10ms"):
                    self.rtt_targets(mode, pc, pl)
                elif mode == "inprocess":
                    self.inprocess_targets(pc)
                elif mode == "router":
                    self.router_targets(pc, pl)
        self.plots["rtt"] = rtt_plot
        self.oneway(cases)
        unknown = sorted(m for m in present
                         if m not in {x[0] for x in RTT_MODES} | {"oneway"})
        if unknown:
            self.out(f"Modes not shown: {', '.join(unknown)}.", "")

    def rtt_counts(self, mode, mc, places):
        """Per round trip and process: wake-ups, syscalls, allocations, and
        the targets of issue 16 for HERM's default policy."""
        counted = [c for c in mc if c.get("per_round_trip")]
        if not counted:
            return
        self.out(f"Per round trip (`{mode}`), each process as client/server"
                 "[/router]: thread wake-ups (schedstat), syscalls (separate "
                 "counting pass), allocations.", "",
                 "| transport | placement | size | wake-ups | syscalls | allocations |",
                 "|---|---|---|---|---|---|")
        for c in counted:
            prt = c["per_round_trip"]
            self.out(f"| {transport_label(c)} | {c.get('placement') or '—'} | "
                     f"{c['size']:,} B | {per_process(prt, 'wakeups')} | "
                     f"{per_process(prt, 'syscalls', c.get('syscalls_per_round_trip'))} | "
                     f"{per_process(prt, 'allocs', c.get('allocs_per_round_trip'))} |")
        self.out("")
        for pl in places:
            for c in default_herm([c for c in counted if c.get("placement") == pl]):
                where = f"{mode}, {c['size']:,} B, {pl or 'unpinned'}"
                for key, what, goal, limit in (
                        ("wakeups_per_round_trip_most",
                         "thread wake-ups per module per round trip", "≤ 2", 2),
                        ("syscalls_per_round_trip", "syscalls per round trip",
                         "≤ 8", 8),
                        ("allocs_per_round_trip", "allocations per round trip",
                         "≤ 12", 12)):
                    v = c.get(key)
                    if v is None:
                        continue
                    shown = num(v)
                    digits = 3
                    while v > limit and shown == num(limit) and digits < 9:
                        # 2.003 is over 2: "2.00" would hide it
                        shown = f"{math.ceil(v * 10**digits) / 10**digits:.{digits}f}"
                        digits += 1
                    self.target(f"HERM {what}, {where}", shown, "—", "—",
                                goal, v <= limit)

    def rtt_targets(self, mode, mc, placement=None):
        """Issue 16: p50 at most 2x raw UDP back to back, 3x with the gap,
        and below Cyclone DDS in both, each in the same placement."""
        herm = default_herm(mc)
        if not herm:
            return
        limit = 3 if mode.startswith("gap") else 2
        mode = f"{mode}, {placement}" if placement else mode
        ratios = [c.get("ratio_to_udp") for c in herm if c.get("runs")]
        ratios = [r for r in ratios if r is not None]
        p50s = [c["p50_us"] for c in herm if c.get("runs")]
        udp = [c["p50_us"] for c in mc if c.get("family") == "udp"
               and c.get("runs")]
        if ratios:
            self.target(f"HERM round trip p50, {mode}, {sizes_of(herm)}, "
                        f"policy {herm[0].get('policy') or 'default'}",
                        span(p50s, " µs"), f"raw UDP {span(udp, ' µs')}",
                        span(ratios, "×"), f"≤ {limit}×", max(ratios) <= limit)
        dds_r = []
        for c in herm:
            d = find(mc, family="dds", size=c["size"])
            if d and d.get("runs") and c.get("runs"):
                dds_r.append(c["p50_us"] / d["p50_us"])
        if dds_r:
            dds = [c["p50_us"] for c in mc if c.get("family") == "dds"
                   and c.get("runs")]
            self.target(f"HERM round trip below Cyclone DDS, {mode}",
                        span(p50s, " µs"), f"DDS {span(dds, ' µs')}",
                        span(dds_r, "×"), "< 1×", max(dds_r) < 1)

    def router_targets(self, mc, placement=None):
        """Issue 16: through a router module at most 1.6x the direct path
        (HERM back to back, same size, policy and placement)."""
        herm = [c for c in default_herm(mc) if c.get("runs")
                and c.get("ratio_to_direct") is not None]
        if not herm:
            return
        ratios = [c["ratio_to_direct"] for c in herm]
        where = f", {placement}" if placement else ""
        self.target(f"HERM round trip through a router module, "
                    f"{sizes_of(herm)}{where}",
                    span([c["p50_us"] for c in herm], " µs"),
                    "the direct path", span(ratios, "×"), "≤ 1.6×",
                    max(ratios) <= 1.6)

    def oneway(self, cases):
        mc = [c for c in cases if c.get("mode") == "oneway"]
        if not mc:
            self.out("**One-way throughput** (`oneway`): not in this run.", "")
            return
        sizes = sorted({c["size"] for c in mc})
        self.out("**One-way throughput** (`oneway`): messages/s as the median "
                 "of the runs [min..max], ratio to raw UDP and to Cyclone DDS "
                 "in the same run, messages lost.", "",
                 "| transport | " + " | ".join(f"{s:,} B" for s in sizes) + " |",
                 "|---" * (len(sizes) + 1) + "|")
        plot = []
        places = placements_of(mc)
        for pl, t in [(pl, t) for pl in places for t in unique(
                c["transport"] for c in mc if c.get("placement") == pl)]:
            pc = [c for c in mc if c.get("placement") == pl]
            label = placed(transport_label(next(c for c in pc if c["transport"] == t)),
                           pl, places)
            cells = []
            for s in sizes:
                c = find(pc, transport=t, size=s)
                if c is None or not c.get("runs") or c.get("msgs_per_s") is None:
                    cells.append(incomplete(c))
                    continue
                cell = rng(c["msgs_per_s"], c.get("msgs_per_s_min"),
                           c.get("msgs_per_s_max"))
                extra = []
                if c.get("ratio_to_udp") is not None:
                    extra.append(f"{c['ratio_to_udp']:.2f}× UDP")
                if c.get("ratio_to_dds") is not None and c.get("family") != "dds":
                    extra.append(f"{c['ratio_to_dds']:.2f}× DDS")
                if c.get("lost"):
                    extra.append(f"{c['lost']:,} lost")
                cells.append(cell + (", " + ", ".join(extra) if extra else ""))
                plot.append((label, s, c["msgs_per_s"],
                             c.get("msgs_per_s_min", c["msgs_per_s"]),
                             c.get("msgs_per_s_max", c["msgs_per_s"])))
            bold = "**" if t.startswith("herm") else ""
            self.out(f"| {bold}{label}{bold} | " + " | ".join(cells) + " |")
        self.out("")
        self.plots["oneway"] = plot
        herm = [c for c in default_herm(mc) if c.get("transport") == "herm"
                or c.get("transport", "").startswith("herm/")]
        # Issue 16: at 64 B at least 3x Cyclone DDS and 60 % of ZeroMQ, each
        # in the same run and placement.
        for c in herm:
            if not (c.get("runs") and c.get("msgs_per_s")) or c["size"] != 64:
                continue
            what = (f"{c['size']:,} B, policy {c.get('policy') or 'default'}"
                    + (f", {c['placement']}" if c.get("placement") else ""))
            for family, name, label, goal, limit in (
                    ("dds", "Cyclone DDS", "DDS", "≥ 3×", 3.0),
                    ("zmq", "ZeroMQ", "ZeroMQ", "≥ 0.6×", 0.6)):
                d = find(mc, family=family, size=c["size"],
                         placement=c.get("placement"))
                if not (d and d.get("runs") and d.get("msgs_per_s")):
                    continue
                r = c["msgs_per_s"] / d["msgs_per_s"]
                self.target(f"HERM one-way throughput against {name}, {what}",
                            f"{c['msgs_per_s']:,.0f} msg/s",
                            f"{label} {d['msgs_per_s']:,.0f} msg/s", f"{r:.2f}×",
                            goal, r >= limit)

    def inprocess_targets(self, mc):
        """APO-to-APO through a real proxy (herm-rebind) against plain CAF."""
        proxied = [c for c in mc if c.get("transport", "").startswith("herm-rebind")
                   and c.get("policy", "") == "sharing:1" and c.get("runs")]
        ratios = [c["ratio_to_caf_local"] for c in proxied
                  if c.get("ratio_to_caf_local") is not None]
        if ratios:
            caf = [c["p50_us"] for c in mc if c.get("transport", "").startswith("caf-local")
                   and c.get("policy", "") == "sharing:1" and c.get("runs")]
            self.target(f"APO-to-APO in one process through a proxy, "
                        f"{sizes_of(proxied)}, policy sharing:1",
                        span([c["p50_us"] for c in proxied], " µs"),
                        f"plain CAF request {span(caf, ' µs')}",
                        span(ratios, "×"), "≤ 2×", max(ratios) <= 2)

    # footprint ------------------------------------------------------------------
    @section("hermd's idle footprint", "footprint.json")
    def footprint(self, doc):
        p = doc.get("parameters", {})
        t = {"cpu_pct": 0.5, "rss_mb": 20.0, "wakeups_per_s": 20.0,
             **doc.get("targets", {})}
        self.out(f"Command: `{doc.get('command', 'hermd_footprint.py')}`: every "
                 f"process started at once, {num(p.get('settle_s'))} s to "
                 f"settle, then sampled over {num(p.get('window_s'))} s; "
                 f"{p.get('runs', '?')} run(s). CPU: utime + stime over the "
                 "window, % of one core; RSS: VmRSS at the end, peak: VmHWM; "
                 "wake-ups: context switches of all threads per second.", "",
                 f"| process | CPU (< {num(t['cpu_pct'])} %) | RSS (< "
                 f"{num(t['rss_mb'])} MiB) | peak RSS | threads | wake-ups/s (≤ "
                 f"{num(t['wakeups_per_s'])}) | |",
                 "|---|---|---|---|---|---|---|")
        plot = []
        for c in doc.get("cases", []):
            hermd = c.get("process") == "hermd"
            ok = (c["cpu_pct"] < t["cpu_pct"] and c["rss_mb"] < t["rss_mb"]
                  and c.get("wakeups_per_s", 0) <= t["wakeups_per_s"]) \
                if hermd else None
            cpu = rng(c["cpu_pct"], c["cpu_pct_min"], c["cpu_pct_max"],
                      f=lambda v: f"{v:.2f} %")
            rss = rng(c["rss_mb"], c["rss_mb_min"], c["rss_mb_max"],
                      f=lambda v: f"{v:.1f}")
            name = f"**{c['label']}**" if hermd else c["label"]
            self.out(f"| {name} | {cpu} | {rss} MiB | {c['hwm_mb']:.1f} MiB | "
                     f"{c['threads_count']:.0f} | {num(c['wakeups_per_s'])} | "
                     f"{verdict(ok) if hermd else 'reference'} |")
            plot.append((SHORT_NAMES.get(c["name"], c["name"]), c["cpu_pct"], c["cpu_pct_min"],
                         c["cpu_pct_max"], c["rss_mb"], c["rss_mb_min"],
                         c["rss_mb_max"]))
            if hermd:
                self.target(f"Idle {c['label']}: CPU", f"{c['cpu_pct']:.2f} %",
                            "one core", "", f"< {num(t['cpu_pct'])} %",
                            c["cpu_pct"] < t["cpu_pct"])
                self.target(f"Idle {c['label']}: resident memory",
                            f"{c['rss_mb']:.1f} MiB", "", "",
                            f"< {num(t['rss_mb'])} MiB",
                            c["rss_mb"] < t["rss_mb"])
                if c.get("wakeups_per_s") is not None:
                    self.target(f"Idle {c['label']}: thread wake-ups",
                                f"{num(c['wakeups_per_s'])}/s", "", "",
                                f"≤ {num(t['wakeups_per_s'])}/s",
                                c["wakeups_per_s"] <= t["wakeups_per_s"])
        for s in doc.get("skipped", []):
            self.out(f"", f"Skipped: {s['name']}: {s['reason']}")
        self.out("")
        alone = next((c for c in doc.get("cases", [])
                      if c["name"] == "hermd-alone"), None)
        if alone and alone.get("threads_of_median_sample"):
            self.out("Threads of the idle hermd (alone, the run nearest the "
                     "median), by wake-ups. CAF 0.17.6 names its scheduler "
                     "workers `caf.multiplexer` (`caf/scheduler/worker.hpp`) "
                     "and threads started from a worker inherit the name; "
                     "`caf.clock` delivers every delayed message (timers).",
                     "",
                     "| thread | CPU (schedstat) | wake-ups/s |", "|---|---|---|")
            for th in alone["threads_of_median_sample"]:
                if th["wakeups_per_s"] == 0 and th["cpu_pct"] == 0:
                    continue
                self.out(f"| {th['name']} | {th['cpu_pct']:.3f} % | "
                         f"{num(th['wakeups_per_s'])} |")
            self.out("")
        self.plots["footprint"] = (plot, t)

    # the whole section ----------------------------------------------------------------
    def build(self, images):
        m = load(f"{self.dir}/manifest.json") or {}
        body_start = len(self.lines)
        self.can()
        self.serial()
        self.emu()
        self.fragmentation()
        self.routing()
        self.rtt()
        self.footprint()
        body = self.lines[body_start:]
        self.lines = self.lines[:body_start]
        mach = m.get("machine", {})
        self.out("## Results of the last full run (generated)", "",
                 "Written by `apps/bench/report/generate.py`; do not edit by "
                 "hand, rerun:", "", "```sh",
                 m.get("command", "apps/bench/run-all.sh"), "```", "",
                 f"- date: {m.get('date', 'unknown')}; commit "
                 f"`{m.get('commit', 'unknown')}`"
                 + (" (with uncommitted changes)" if m.get("dirty") else ""),
                 f"- machine: {mach.get('cpu', '?')}, {mach.get('cpus', '?')} "
                 f"cores, {mach.get('memory', '?')}, {mach.get('kernel', '?')}; "
                 f"load average {m.get('loadavg_before', '?')} before, "
                 f"{m.get('loadavg_after', '?')} after",
                 f"- build: {m.get('build_type', '?')}; every figure is the "
                 f"median of {m.get('repeat', '?')} repetition(s) with "
                 "[min..max]; every ratio is to a limit or peer measured in the "
                 "same run", "")
        if m.get("failed"):
            self.out("**Failed in this run** (see their logs in the results "
                     f"directory): {', '.join(m['failed'])}.", "")
        if m.get("quick"):
            self.out("**Quick run** (`--quick`: one short repetition each): "
                     "for testing the pipeline, not for quoting.", "")
        self.out("### Targets", "",
                 "| target | measured | against (same run) | ratio | target | "
                 "|", "|---|---|---|---|---|---|", *self.targets, "")
        for name, alt in images:
            self.out(f"![{alt}](img/{name})")
        if images:
            self.out("")
        self.lines.extend(body)
        return "\n".join(self.lines).rstrip() + "\n"


# -- helpers for the round-trip tables ----------------------------------------------


def unique(items):
    seen = []
    for i in items:
        if i not in seen:
            seen.append(i)
    return seen


def find(cases, **kv):
    for c in cases:
        if all(c.get(k) == v for k, v in kv.items()):
            return c
    return None


def transport_label(c):
    fam = c.get("family") or c.get("transport", "?")
    label = FAMILY_NAMES.get(fam, fam)
    # A variant of a family (udp/sendmmsg, herm-rebind) is named as such.
    transport = c.get("transport", fam)
    variant = transport.split("/", 1)[1] if "/" in transport else ""
    if variant and variant != c.get("policy"):
        label += f" ({variant})"
    if c.get("policy"):
        label += f", {c['policy']}"
    return label


def placements_of(cases):
    """The placements of the cases in run order (None: a run without them)."""
    return unique(c.get("placement") for c in cases)


def placed(label, placement, places):
    return f"{label}, {placement}" if placement and len(places) > 1 else label


def per_process(prt, key, total=None):
    """"c/s[/r]" of one figure per round trip, with the sum when given."""
    vals = []
    for proc in ("client", "server", "router"):
        if proc in prt:
            v = prt[proc].get(key)
            vals.append("—" if v is None else num(v))
    cell = "/".join(vals) if vals else "—"
    return cell + (f" (Σ {num(total)})" if total is not None else "")


def default_herm(mc):
    """HERM's cases with hermd's default policy (the loop scheduler; runs
    from before it: one sharing worker)."""
    herm = [c for c in mc if c.get("family") == "herm"]
    for policy in ("loop", "sharing:1", "sharing", ""):
        chosen = [c for c in herm if c.get("policy", "") == policy]
        if chosen:
            return chosen
    return herm


def sizes_of(cases):
    s = sorted({c["size"] for c in cases})
    return f"{s[0]:,} B" if len(s) == 1 else f"{s[0]:,}..{s[-1]:,} B"


def span(values, unit=""):
    values = [v for v in values if v is not None]
    if not values:
        return "n/a"
    lo, hi = min(values), max(values)
    return num(lo, unit) if num(lo) == num(hi) else f"{num(lo)}..{num(hi, unit)}"


def incomplete(c):
    if c is None:
        return "—"
    errs = c.get("errors") or []
    return "failed" + (f": {errs[0]}" if errs else "")


def rtt_cell(c, ratio_key):
    if c is None or not c.get("runs") or c.get("p50_us") is None:
        return incomplete(c)
    cell = rng(c["p50_us"], c.get("p50_min_us"), c.get("p50_max_us"))
    if c.get(ratio_key) is not None:
        cell += f", {num(c[ratio_key])}×"
    if not c.get("complete", True):
        cell += " (incomplete)"
    return cell


# -- plots ---------------------------------------------------------------------------


def write_dat(path, header, rows):
    with open(path, "w") as f:
        f.write(" ".join(f'"{h}"' for h in header) + "\n")
        for r in rows:
            f.write(" ".join(f'"{x}"' if isinstance(x, str) else
                             ("NaN" if x is None else f"{x:.6g}") for x in r)
                    + "\n")


def gnuplot(script, data_dir, out, extra=""):
    cmd = ["gnuplot", "-e", f"datadir='{data_dir}'; out='{out}'; {extra}",
           os.path.join(HERE, "plots", script)]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"gnuplot {script}: {res.stderr.strip()}")


def make_plots(report, img_dir, data_dir):
    """Returns [(png name, alt text)] of the plots written."""
    os.makedirs(img_dir, exist_ok=True)
    os.makedirs(data_dir, exist_ok=True)
    made = []
    p = report.plots
    rtt = p.get("rtt") or []
    ow = p.get("oneway") or []
    # A transport has the same colour in every chart.
    colour = {l: PALETTE[i % len(PALETTE)] for i, l in
              enumerate(unique([r[1] for r in rtt] + [r[0] for r in ow]))}
    if rtt:
        # One panel per mode with that mode's transports only; a transport
        # keeps its colour in every panel.
        modes = unique(r[0] for r in rtt)
        sizes = sorted({r[2] for r in rtt})
        meta = []
        for i, mode in enumerate(modes):
            labels = unique(r[1] for r in rtt if r[0] == mode)
            rows = []
            for s in sizes:
                row = [f"{s:,} B"]
                for label in labels:
                    r = next((x for x in rtt if x[0] == mode and x[1] == label
                              and x[2] == s), None)
                    row += [None] * 3 if r is None else [r[3], r[4], r[5]]
                rows.append(row)
            hdr = ["size"] + [x for label in labels
                              for x in (label, "lo", "hi")]
            write_dat(f"{data_dir}/rtt{i}.dat", hdr, rows)
            meta.append(" ".join([mode, str(len(labels))]
                                 + [colour[l] for l in labels]))
        with open(f"{data_dir}/rtt.modes", "w") as f:
            f.write("\n".join(meta) + "\n")
        gnuplot("rtt.gp", data_dir, f"{img_dir}/rtt.png",
                f"nmodes={len(modes)}; nsizes={len(sizes)}")
        made.append(("rtt.png", "Request round trip per transport and size"))
    if ow:
        labels = unique(r[0] for r in ow)
        sizes = sorted({r[1] for r in ow})
        rows = []
        for s in sizes:
            row = [f"{s:,} B"]
            for label in labels:
                r = next((x for x in ow if x[0] == label and x[1] == s), None)
                row += [None] * 3 if r is None else [r[2], r[3], r[4]]
            rows.append(row)
        write_dat(f"{data_dir}/oneway.dat",
                  ["size"] + [x for l in labels for x in (l, "lo", "hi")], rows)
        colours = " ".join(colour[l] for l in labels)
        gnuplot("oneway.gp", data_dir, f"{img_dir}/oneway.png",
                f"nseries={len(labels)}; nsizes={len(sizes)}; "
                f"colours='{colours}'")
        made.append(("oneway.png", "One-way throughput per transport and size"))
    if p.get("can") or p.get("serial"):
        rows = [[name, *eff, *load] for name, eff, load in p.get("can", [])]
        write_dat(f"{data_dir}/can.dat", ["case", "eff", "lo", "hi", "load",
                                          "llo", "lhi"], rows)
        rows = [[name, *ratio, *busy] for name, ratio, busy in
                p.get("serial", [])]
        write_dat(f"{data_dir}/serial.dat", ["case", "ratio", "lo", "hi",
                                             "busy", "blo", "bhi"], rows)
        gnuplot("links.gp", data_dir, f"{img_dir}/links.png",
                f"ncan={len(p.get('can', []))}; "
                f"nserial={len(p.get('serial', []))}")
        made.append(("links.png", "CAN and serial goodput against their limits"))
    conv = p.get("convergence") or []
    if conv:
        write_dat(f"{data_dir}/convergence.dat",
                  ["modules", "converged_ms", "updates_per_module",
                   "entries_per_module", "wall_s"],
                  [[r["modules"], r["converged_ms"], r["updates"] / r["modules"],
                    r["update_entries"] / r["modules"], r["wall_s"]]
                   for r in conv])
        gnuplot("convergence.gp", data_dir, f"{img_dir}/convergence.png")
        made.append(("convergence.png",
                     "Routing convergence against module count"))
    if p.get("footprint"):
        rows, t = p["footprint"]
        write_dat(f"{data_dir}/footprint.dat",
                  ["process", "cpu", "clo", "chi", "rss", "rlo", "rhi"], rows)
        cpu_max = max([r[3] for r in rows] + [t["cpu_pct"]]) * 1.25
        rss_max = max([r[6] for r in rows] + [t["rss_mb"]]) * 1.25
        gnuplot("footprint.gp", data_dir, f"{img_dir}/footprint.png",
                f"cpu_target={t['cpu_pct']}; rss_target={t['rss_mb']}; "
                f"cpu_max={cpu_max}; rss_max={rss_max}; nproc={len(rows)}")
        made.append(("footprint.png", "hermd's idle CPU and memory"))
    return made


# -- main ----------------------------------------------------------------------------


def splice(doc_path, section):
    with open(doc_path) as f:
        text = f.read()
    if text.count(BEGIN) != 1 or text.count(END) != 1 \
            or text.index(BEGIN) > text.index(END):
        raise ValueError(f"{doc_path}: needs exactly one line '{BEGIN}' "
                         f"followed by one line '{END}'")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    new = f"{head}{BEGIN}\n{section}{END}{tail}"
    if new != text:
        with open(doc_path, "w") as f:
            f.write(new)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", required=True, help="run-all.sh's DIR")
    ap.add_argument("--doc", help="replace the results section of this file")
    ap.add_argument("--img-dir", help="write the PNGs here")
    ap.add_argument("--no-plots", action="store_true")
    args = ap.parse_args()
    if not os.path.isdir(args.results):
        print(f"generate.py: {args.results}: not a directory", file=sys.stderr)
        return 2
    report = Report(args.results)
    # A first pass fills report.plots; the images are listed in the second.
    report.build([])
    images = []
    if args.img_dir and not args.no_plots:
        try:
            images = make_plots(report, args.img_dir,
                                os.path.join(args.results, "plots"))
        except (RuntimeError, FileNotFoundError) as e:
            print(f"generate.py: {e}", file=sys.stderr)
            return 1
    report = Report(args.results)
    section = report.build(images)
    with open(os.path.join(args.results, "results.md"), "w") as f:
        f.write(section)
    if args.doc:
        try:
            splice(args.doc, section)
        except ValueError as e:
            print(f"generate.py: {e}", file=sys.stderr)
            return 2
    print(f"generate.py: wrote {os.path.join(args.results, 'results.md')}"
          + (f", {args.doc}" if args.doc else "")
          + (f", {len(images)} plots in {args.img_dir}" if images else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
