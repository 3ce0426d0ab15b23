#!/usr/bin/env python3
"""CTest bench.report_generator_writes_tables_from_the_fixture: runs
generate.py on the checked-in fixture (fixture/: a run with CAN, serial,
routing, round trips with some modes missing (back to back in two
placements, with counts per round trip), and the footprint; no emulated
media, no fragmentation) and checks the markdown it writes into a copy of a
document with the markers. Never about real figures: the fixture's are made
up. Exit 0 when every check passes, 1 otherwise (each failure printed)."""

import os
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
GENERATE = os.path.join(HERE, "generate.py")
failures = []


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what)
    if not cond:
        failures.append(what)


def run(*args):
    return subprocess.run([sys.executable, GENERATE, *args],
                          capture_output=True, text=True)


def main():
    with tempfile.TemporaryDirectory(prefix="herm-report-test-") as tmp:
        results = os.path.join(tmp, "results")
        shutil.copytree(os.path.join(HERE, "fixture"), results)
        doc = os.path.join(tmp, "performance.md")
        intro = "# HERM performance\n\nIntroduction.\n\n"
        outro = "\n## Hand-written section\n\nKept as it is.\n"
        with open(doc, "w") as f:
            f.write(intro + "<!-- results:begin -->\nold results\n"
                    "<!-- results:end -->" + outro)

        res = run("--results", results, "--doc", doc, "--no-plots")
        check(res.returncode == 0, f"generator exits 0 ({res.stderr.strip()})")
        text = open(doc).read()
        check(text.startswith(intro + "<!-- results:begin -->\n"),
              "text before the markers is unchanged")
        check(text.endswith("<!-- results:end -->" + outro),
              "text after the markers is unchanged")
        check("old results" not in text, "the old section is replaced")
        check(open(os.path.join(results, "results.md")).read() in text,
              "results.md is the section written into the document")

        # Header: command, commit, machine.
        check("apps/bench/run-all.sh --repeat 3" in text, "the command is named")
        check("commit `b593ecd`" in text, "the commit is named")
        check("AMD EPYC, 2 cores" in text, "the machine is named")
        check("**Failed in this run**" in text and ": emu." in text,
              "a failed benchmark is named")

        # A known figure: median [min..max] over the three repetitions, the
        # aggregate entries ignored (their 123.0 would show as 12,300 %).
        check("| 29-bit | 4,000 B | 87.3 % [87.3..87.4] | 7,636 [7,630..7,637]"
              " | 7,634 |" in text, "CAN row: median [min..max] per counter")
        check("12,300" not in text, "aggregate entries are ignored")
        check("| 1,000 B | 1,639 [1,635..1,641] B/s | 1,920 B/s | "
              "85.4 % [85.2..85.5] |" in text, "serial row with its line rate")

        # The met/missed column.
        check(lines_with(text, "CAN payload efficiency", "**met**"),
              "CAN efficiency target met")
        check(lines_with(text, "| 1,000 B |", "**met**"), "serial 1,000 B met")
        check(lines_with(text, "| 8 B |", "| n/a |"),
              "serial 8 B: target does not apply")
        check(lines_with(text, "| 31 B | failed: packets lost", ""),
              "a failed case is shown with its error")
        check(lines_with(text, "Serial goodput at 19,200 baud", "**missed**"),
              "a failed case misses its target")
        check(lines_with(text, "HERM round trip p50, back-to-back", "9.04×",
                         "≤ 2×", "**missed**"),
              "round trip against UDP: missed, with the ratio")
        check(lines_with(text, "HERM round trip below Cyclone DDS", "2.91×",
                         "**missed**"), "round trip against DDS: missed")
        check(lines_with(text, "| 100 ms | 90 ms (0.90)", "**met**"),
              "routing repair met")
        check(lines_with(text, "| 1,000 ms |", "never", "**missed**"),
              "routing repair that never happened: missed")
        check(lines_with(text, "no neighbour: CPU", "0.62 %", "**met**"),
              "footprint CPU met")
        check(lines_with(text, "a neighbour on each: CPU", "1.35 %",
                         "**missed**"), "footprint CPU missed")
        check(lines_with(text, "bare CAF actor_system", "reference"),
              "reference process shown without a verdict")

        # Skipped modes and missing benchmarks: a line each, no failure.
        check(lines_with(text, "(`inprocess`): not in this run."),
              "round-trip mode inprocess listed as not run")
        check("0.16× UDP, 0.41× DDS" in text, "oneway mode with both ratios")

        # Issue 16's targets, each against its peer in the same run: 3x UDP
        # with the gap (2x back to back), 1.6x the direct path through a
        # router, one-way at least 3x DDS and 60 % of ZeroMQ, an idle hermd
        # at most 20 wake-ups/s.
        check(lines_with(text, "HERM round trip p50, gap-10ms, one-cpu",
                         "2.50×", "≤ 3×", "**met**"),
              "round trip with the gap: within 3x UDP, met")
        check(lines_with(text, "HERM round trip below Cyclone DDS, gap-10ms, "
                         "one-cpu", "0.625×", "**met**"),
              "round trip with the gap below DDS: met")
        check(lines_with(text, "HERM round trip through a router module, 16 B, "
                         "one-cpu", "1.50×", "≤ 1.6×", "**met**"),
              "router against the direct path: met")
        check(lines_with(text, "HERM thread wake-ups per module per round trip, "
                         "router, 16 B, one-cpu", "| 2.004 |", "**missed**"),
              "a count just over its limit shows the digits that put it over")
        check(lines_with(text, "HERM one-way throughput against Cyclone DDS, "
                         "64 B", "0.41×", "≥ 3×", "**missed**"),
              "one-way against DDS: missed below 3x")
        check(lines_with(text, "HERM one-way throughput against ZeroMQ, 64 B",
                         "0.68×", "≥ 0.6×", "**met**"),
              "one-way against ZeroMQ: met at 60 %")
        check(not lines_with(text, "HERM one-way throughput against", "256 B"),
              "one-way targets are for 64 B only")
        check(lines_with(text, "no neighbour: thread wake-ups", "12.0/s",
                         "≤ 20.0/s", "**met**"),
              "idle wake-ups met")
        check(lines_with(text, "a neighbour on each: thread wake-ups", "80.0/s",
                         "**missed**"), "idle wake-ups missed")
        check(lines_with(text, "| ZeroMQ | one-cpu | failed: server did not start |"),
              "an incomplete transport shows its error")

        # Placements: every figure names its placement, ratios and targets
        # are taken within it, and the counts per round trip are shown.
        check(lines_with(text, "| **HERM, sharing:1** | per-cpu | 71.0, 2.26× |"),
              "a per-cpu row with its ratio to UDP in the same placement")
        check(lines_with(text, "HERM round trip below Cyclone DDS, back-to-back, "
                         "per-cpu", "DDS 48.8 µs", "1.45×", "**missed**"),
              "the DDS target per placement")
        check(lines_with(text, "| HERM, sharing:1 | one-cpu | 16 B | 3.50/3.00 | "
                         "9.00/8.00 (Σ 17.0) | 22.0/21.0 (Σ 43.0) |"),
              "counts per round trip and process")
        check(lines_with(text, "HERM thread wake-ups per module per round trip, "
                         "back-to-back, 16 B, one-cpu", "3.50", "≤ 2", "**missed**"),
              "wake-up target missed in one placement")
        check(lines_with(text, "HERM allocations per round trip, back-to-back, "
                         "16 B, per-cpu", "11.0", "≤ 12", "**met**"),
              "allocation target met in the other")
        check(lines_with(text, "HERM syscalls per round trip, back-to-back, 16 B, "
                         "per-cpu", "6.00", "≤ 8", "**met**"),
              "syscall target")
        for f in ("emu_bandwidth.json", "fragmentation.json"):
            check(f"Not in this run (no `{f}`" in text,
                  f"missing {f} listed as not run")
        check("Skipped: dds: bench_idle_peer: built without Cyclone DDS"
              in text, "a skipped footprint reference is listed")

        # Idempotent: a second run writes the same document.
        res = run("--results", results, "--doc", doc, "--no-plots")
        check(res.returncode == 0 and open(doc).read() == text,
              "a second run leaves the document unchanged")

        # A document without the markers is refused and left alone.
        bare = os.path.join(tmp, "bare.md")
        with open(bare, "w") as f:
            f.write(intro)
        res = run("--results", results, "--doc", bare, "--no-plots")
        check(res.returncode == 2 and "results:begin" in res.stderr
              and open(bare).read() == intro,
              "a document without markers: exit 2, named, unchanged")
        res = run("--results", os.path.join(tmp, "nowhere"))
        check(res.returncode == 2, "a missing results directory: exit 2")

        # Plots, when gnuplot is there.
        if shutil.which("gnuplot") is None:
            print("skip plots: gnuplot not found (apt-get install gnuplot-nox)")
        else:
            img = os.path.join(tmp, "img")
            res = run("--results", results, "--doc", doc, "--img-dir", img)
            check(res.returncode == 0, f"plots: exit 0 ({res.stderr.strip()})")
            for png in ("rtt.png", "oneway.png", "links.png",
                        "convergence.png", "footprint.png"):
                path = os.path.join(img, png)
                ok = os.path.exists(path) and open(path, "rb").read(8) \
                    == b"\x89PNG\r\n\x1a\n"
                check(ok, f"plot {png} is a PNG")
                check(f"](img/{png})" in open(doc).read(),
                      f"the document links {png}")
    if failures:
        print(f"{len(failures)} check(s) failed", file=sys.stderr)
        return 1
    return 0


def lines_with(text, *parts):
    """True when one line holds every part."""
    return any(all(p in line for p in parts) for line in text.splitlines())


if __name__ == "__main__":
    sys.exit(main())
