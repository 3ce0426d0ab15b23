#!/usr/bin/env bash
# Builds and runs every HERM benchmark, keeps the raw JSON, and writes the
# results section of docs/performance.md and the plots in docs/img/ (issue 7).
#
#   apps/bench/run-all.sh                 the full suite (about 20 minutes),
#                                         3 repetitions, updates the docs
#   apps/bench/run-all.sh --quick         everything once, short (about 3
#                                         minutes): tests the pipeline and
#                                         writes to DIR only
#
# Options:
#   --out DIR         raw JSON, logs, results.md (and img/ when the docs are
#                     not updated); default bench-results/ (never committed:
#                     the directory gets a .gitignore of its own)
#   --repeat N        repetitions of every benchmark (default 3; --quick: 1)
#   --quick           one short repetition of everything
#   --update-docs     write docs/performance.md and docs/img/ (the default
#                     without --quick)
#   --no-docs         write DIR only (the default with --quick)
#   --build-dir DIR   build directory (default build-bench)
#   --jobs N          parallel build jobs (default 2)
#   --only LIST       run only these, comma-separated: can, serial, emu,
#                     fragmentation, routing, rtt, footprint, mcu (the
#                     report uses whatever DIR holds; mcu's figures go to
#                     docs/performance.md by hand, see its issue-17 section)
#   --no-build        use the binaries already in the build directory
#
# Every benchmark runs even when another fails; the exit status is 1 when
# any failed (the report says which), 2 for bad usage. Run it on an idle
# machine: every figure is a median over the repetitions with [min..max],
# and every ratio is against a limit or peer measured in the same run, but
# absolute figures move with load. Needs cmake, ninja, gnuplot
# (gnuplot-nox), socat and python3 (standard library only).
set -uo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
cd "$root" || exit 2
invocation="apps/bench/run-all.sh${*:+ $*}"

out=bench-results
repeat=
quick=0
docs=
build=build-bench
jobs=2
only=can,serial,emu,fragmentation,routing,rtt,footprint,mcu
do_build=1
usage() { sed -n '2,/^set -uo/p' "$0" | sed '$d; s/^# \{0,1\}//'; }
while [ $# -gt 0 ]; do
  case $1 in
    --out) out=${2:?--out needs a directory}; shift 2 ;;
    --repeat) repeat=${2:?--repeat needs a number}; shift 2 ;;
    --quick) quick=1; shift ;;
    --update-docs) docs=1; shift ;;
    --no-docs) docs=0; shift ;;
    --build-dir) build=${2:?--build-dir needs a directory}; shift 2 ;;
    --jobs) jobs=${2:?--jobs needs a number}; shift 2 ;;
    --only) only=${2:?--only needs a list}; shift 2 ;;
    --no-build) do_build=0; shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "run-all.sh: unknown option '$1' (--help)" >&2; exit 2 ;;
  esac
done
[ -n "$repeat" ] || { [ $quick = 1 ] && repeat=1 || repeat=3; }
[ -n "$docs" ] || { [ $quick = 1 ] && docs=0 || docs=1; }
case $repeat in ''|*[!0-9]*|0) echo "run-all.sh: --repeat expects a positive integer, got '$repeat'" >&2; exit 2 ;; esac
for tool in cmake python3 gnuplot; do
  command -v $tool >/dev/null || { echo "run-all.sh: $tool not found (.ci/setup installs it; gnuplot: apt-get install gnuplot-nox)" >&2; exit 2; }
done
mkdir -p "$out" || exit 2
out=$(cd "$out" && pwd)
# Raw results are never committed: the directory ignores itself.
[ -e "$out/.gitignore" ] || echo '*' >"$out/.gitignore"
bin=$root/$build/bin
wants() { [[ ",$only," == *",$1,"* ]]; }
log() { printf '%s run-all: %s\n' "$(date +%H:%M:%S)" "$*"; }
started=$(date +%s)

# -- build ------------------------------------------------------------------------
if [ $do_build = 1 ]; then
  cfg=(-S "$root" -B "$root/$build" -G Ninja -DHERM_BUILD_BENCHMARKS=ON)
  if [ ! -f "$root/$build/CMakeCache.txt" ]; then
    cfg+=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DHERM_BUILD_TESTS=OFF)
    command -v ccache >/dev/null && cfg+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  fi
  log "configuring and building in $build (-j$jobs)"
  cmake "${cfg[@]}" >"$out/build.log" 2>&1 \
    && cmake --build "$root/$build" -j"$jobs" --target bench_can_efficiency \
         bench_serial_goodput bench_emu_bandwidth bench_fragmentation \
         bench_routing_convergence herm-bench-rtt hermd bench_idle_peer \
         bench_mcu_board \
         >>"$out/build.log" 2>&1 \
    || { echo "run-all.sh: build failed, see $out/build.log" >&2; tail -20 "$out/build.log" >&2; exit 1; }
fi
build_type=$(sed -n 's/^CMAKE_BUILD_TYPE:STRING=//p' "$root/$build/CMakeCache.txt" 2>/dev/null)

# -- run --------------------------------------------------------------------------
loadavg_before=$(cut -d' ' -f1-3 /proc/loadavg)
failed=()
durations=()
# run NAME OUTPUT.json COMMAND...: logs to NAME.log, keeps the JSON only
# when the command succeeded and wrote a well-formed file.
run() {
  local name=$1 json=$2
  shift 2
  wants "$name" || return 0
  log "$name: $*"
  local t0=$(date +%s)
  rm -f "$out/$json"
  if "$@" >"$out/$name.log" 2>&1 \
     && python3 -c 'import json,sys; json.load(open(sys.argv[1]))' "$out/$json" 2>/dev/null; then
    log "$name: done in $(( $(date +%s) - t0 )) s"
  else
    log "$name: FAILED (see $out/$name.log)"
    tail -5 "$out/$name.log" | sed 's/^/    /'
    failed+=("$name")
    rm -f "$out/$json"
  fi
  durations+=("$name=$(( $(date +%s) - t0 ))")
}
gbench=(--benchmark_repetitions="$repeat" --benchmark_out_format=json)
if [ $quick = 1 ]; then
  min_time=0.01; sizes=10,30; rtt_args=(--quick); fp_args=(--quick)
else
  min_time=0.2; sizes=10,30,100,300,1000; rtt_args=(--repeat "$repeat"); fp_args=(--runs "$repeat")
fi
# Round trips in both placements (every process on vCPU 0; server and router
# on vCPU 0, client on vCPU 1), each transport in each, with wake-ups,
# syscalls (a separate perf counting pass) and allocations per round trip.
rtt_args+=(--placements one-cpu,per-cpu)
run can can_efficiency.json "$bin/bench_can_efficiency" "${gbench[@]}" \
  --benchmark_out="$out/can_efficiency.json"
run serial serial_goodput.json "$bin/bench_serial_goodput" "${gbench[@]}" \
  --benchmark_out="$out/serial_goodput.json"
# The C client (herm-mcu-board) on a 19,200 baud cable next to a C++ module:
# fixed counts, about 45 s per repetition (--quick: one).
run mcu mcu_board.json "$bin/bench_mcu_board" "${gbench[@]}" \
  --benchmark_out="$out/mcu_board.json"
run emu emu_bandwidth.json "$bin/bench_emu_bandwidth" "${gbench[@]}" \
  --benchmark_out="$out/emu_bandwidth.json"
run fragmentation fragmentation.json "$bin/bench_fragmentation" "${gbench[@]}" \
  --benchmark_filter=split_and_reassemble --benchmark_min_time=$min_time \
  --benchmark_out="$out/fragmentation.json"
run routing routing_convergence.json "$bin/bench_routing_convergence" \
  --sizes $sizes --json "$out/routing_convergence.json"
# herm-bench-rtt counts syscalls through tracefs' raw_syscalls:sys_enter;
# a fresh machine may not have it mounted yet (root can mount it).
if [ ! -e /sys/kernel/tracing/events/raw_syscalls ] && [ "$(id -u)" -eq 0 ]; then
  mount -t tracefs none /sys/kernel/tracing 2>/dev/null \
    || echo "run-all: tracefs not mounted: rtt reports no syscall counts" >&2
fi
run rtt rtt.json "$bin/herm-bench-rtt" "${rtt_args[@]}" --json "$out/rtt.json"
run footprint footprint.json python3 "$root/apps/bench/hermd_footprint.py" \
  --hermd "$bin/hermd" --peer "$bin/bench_idle_peer" "${fp_args[@]}" \
  --json "$out/footprint.json"
loadavg_after=$(cut -d' ' -f1-3 /proc/loadavg)

# -- manifest and report ---------------------------------------------------------------
commit=$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)
dirty=false
[ -n "$(git -C "$root" status --porcelain --untracked-files=no 2>/dev/null)" ] && dirty=true
MANIFEST_COMMAND=$invocation MANIFEST_COMMIT=$commit MANIFEST_DIRTY=$dirty \
MANIFEST_QUICK=$quick MANIFEST_REPEAT=$repeat MANIFEST_BUILD_TYPE=$build_type \
MANIFEST_LOAD_BEFORE=$loadavg_before MANIFEST_LOAD_AFTER=$loadavg_after \
MANIFEST_FAILED="${failed[*]}" MANIFEST_DURATIONS="${durations[*]}" \
MANIFEST_SECONDS=$(( $(date +%s) - started )) \
python3 - "$out/manifest.json" <<'PY'
import datetime, json, os, platform, sys
e = os.environ
cpu = "unknown"
with open("/proc/cpuinfo") as f:
    for line in f:
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
with open("/proc/meminfo") as f:
    mem_kib = int(f.readline().split()[1])
doc = {
    "command": e["MANIFEST_COMMAND"],
    "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    "commit": e["MANIFEST_COMMIT"],
    "dirty": e["MANIFEST_DIRTY"] == "true",
    "quick": e["MANIFEST_QUICK"] == "1",
    "repeat": int(e["MANIFEST_REPEAT"]),
    "build_type": e["MANIFEST_BUILD_TYPE"] or "unknown",
    "machine": {"cpu": cpu, "cpus": os.cpu_count(),
                "memory": f"{mem_kib / 1048576:.0f} GiB",
                "kernel": f"{platform.system()} {platform.release()}"},
    "loadavg_before": e["MANIFEST_LOAD_BEFORE"],
    "loadavg_after": e["MANIFEST_LOAD_AFTER"],
    "failed": e["MANIFEST_FAILED"].split(),
    "durations_s": {k: int(v) for k, v in
                    (d.split("=") for d in e["MANIFEST_DURATIONS"].split())},
    "seconds": int(e["MANIFEST_SECONDS"]),
}
with open(sys.argv[1], "w") as f:
    json.dump(doc, f, indent=2)
    f.write("\n")
PY
gen=(python3 "$root/apps/bench/report/generate.py" --results "$out")
if [ $docs = 1 ]; then
  gen+=(--doc "$root/docs/performance.md" --img-dir "$root/docs/img")
else
  gen+=(--img-dir "$out/img")
fi
log "report: ${gen[*]}"
"${gen[@]}" || { echo "run-all.sh: the report generator failed" >&2; exit 1; }
log "finished in $(( $(date +%s) - started )) s; raw results in $out"
if [ ${#failed[@]} -gt 0 ]; then
  echo "run-all.sh: failed: ${failed[*]}" >&2
  exit 1
fi
exit 0
