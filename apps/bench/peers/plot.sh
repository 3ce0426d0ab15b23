#!/usr/bin/env bash
# Plots herm-bench-rtt's JSON: one panel per mode, one group per payload
# size, one bar per transport at its p50 (median over runs), whiskers from
# the runs' lowest to highest p50; logarithmic axis. The chart is the one
# apps/bench/run-all.sh puts into docs/img/rtt.png (apps/bench/report/).
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
[ -r "$json" ] || { echo "plot.sh: $json: cannot read" >&2; exit 2; }
command -v gnuplot >/dev/null || { echo "plot.sh: gnuplot not found (apt-get install gnuplot-nox)" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir "$tmp/results"
cp "$json" "$tmp/results/rtt.json"
python3 "$(dirname "${BASH_SOURCE[0]}")/../report/generate.py" \
  --results "$tmp/results" --img-dir "$tmp/img" >/dev/null
[ -f "$tmp/img/rtt.png" ] || { echo "plot.sh: $json holds no complete round-trip case" >&2; exit 1; }
cp "$tmp/img/rtt.png" "$png"
echo "wrote $png"
