#!/usr/bin/env bash
# Plots herm-bench-rtt's JSON as a grouped bar chart: one panel per mode
# (back to back, with a gap), one group per payload size, one bar per
# transport at its p50 (median over runs), an error bar from p50 up to p99.
# Logarithmic axis: the transports span two orders of magnitude.
#
#   apps/bench/peers/plot.sh rtt.json docs/img/rtt.png
#
# Needs gnuplot (Debian: gnuplot-nox) and python3.
set -euo pipefail
if [ $# -ne 2 ]; then
  echo "usage: $0 RESULTS.json OUT.png" >&2
  exit 2
fi
json=$1
png=$2
command -v gnuplot >/dev/null || { echo "plot.sh: gnuplot not found (apt-get install gnuplot-nox)" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# One data file per mode: a row per size; per transport p50, p50, p99
# (gnuplot's errorbars histogram takes y, ylow, yhigh).
python3 - "$json" "$tmp" <<'PY'
import json, sys
doc = json.load(open(sys.argv[1]))
out = sys.argv[2]
cases = [c for c in doc["cases"] if c["runs"]]
transports = []
for c in cases:
    if c["transport"] not in transports:
        transports.append(c["transport"])
modes = []
for c in cases:
    if c["mode"] not in modes:
        modes.append(c["mode"])
sizes = sorted({c["size"] for c in cases})
by = {(c["mode"], c["size"], c["transport"]): c for c in cases}
for i, m in enumerate(modes):
    with open(f"{out}/mode{i}.dat", "w") as f:
        f.write("size " + " ".join(f"{t} {t}_lo {t}_hi" for t in transports) + "\n")
        for s in sizes:
            row = [f'"{s} B"']
            for t in transports:
                c = by.get((m, s, t))
                row += ["NaN"] * 3 if c is None else \
                       [f'{c["p50_us"]:.2f}', f'{c["p50_us"]:.2f}', f'{c["p99_us"]:.2f}']
            f.write(" ".join(row) + "\n")
with open(f"{out}/meta", "w") as f:
    f.write(f"{len(modes)}\n{len(transports)}\n")
    f.write("\n".join(modes) + "\n")
    f.write("\n".join(transports) + "\n")
    f.write(doc.get("command", "") + "\n")
    f.write(str(doc.get("machine", {}).get("cpus", "?")) + "\n")
PY

nmodes=$(sed -n 1p "$tmp/meta")
ntrans=$(sed -n 2p "$tmp/meta")
mapfile -t modes < <(sed -n "3,$((2 + nmodes))p" "$tmp/meta")
command_line=$(sed -n "$((3 + nmodes + ntrans))p" "$tmp/meta")
cpus=$(sed -n "$((4 + nmodes + ntrans))p" "$tmp/meta")

{
  echo "set terminal pngcairo size 1400,$((420 * nmodes + 60)) font 'sans,11'"
  echo "set output '$png'"
  echo "set multiplot layout $nmodes,1 title \"Request round trip on 127.0.0.1 ($cpus cores): bar = p50 (median of runs), whisker = p99\\n$command_line\" font 'sans,12'"
  echo "set style data histograms"
  echo "set style histogram errorbars gap 2 lw 1"
  echo "set style fill solid 0.85 border -1"
  echo "set boxwidth 0.9"
  echo "set logscale y"
  echo "set yrange [5:*]"
  echo "set ylabel 'microseconds (log)'"
  echo "set grid ytics mytics"
  echo "set key outside right top vertical"
  for i in $(seq 0 $((nmodes - 1))); do
    echo "set title '${modes[$i]}'"
    plot="plot"
    for t in $(seq 0 $((ntrans - 1))); do
      col=$((2 + 3 * t))
      [ "$t" -gt 0 ] && plot+=","
      plot+=" '$tmp/mode$i.dat' using $col:$((col + 1)):$((col + 2)):xtic(1) title columnheader($col)"
    done
    echo "$plot"
  done
  echo "unset multiplot"
} > "$tmp/plot.gp"
gnuplot "$tmp/plot.gp"
echo "wrote $png"
