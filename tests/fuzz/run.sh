#!/usr/bin/env bash
# Runs every libFuzzer target of a HERM_FUZZ build for a bounded time.
#
#   tests/fuzz/run.sh BUILD_DIR SECONDS_PER_TARGET [TARGET...]
#
# BUILD_DIR is a build configured with -DHERM_FUZZ=ON (tests/fuzz/README.md);
# every BUILD_DIR/bin/fuzz_* runs for SECONDS_PER_TARGET seconds (only the
# named targets, e.g. "marshal", when some are given), one after the other,
# on a temporary copy of its seed corpus tests/fuzz/corpus/NAME (the
# repository's corpus is never written), with tests/fuzz/NAME.dict when there
# is one. Prints one line per target: executions, coverage (cov: edges,
# ft: features), corpus size and "no crash"; exits non-zero if any target
# crashed, leaked, timed out or violated a property, leaving its input and
# log in the work directory it names (HERM_FUZZ_KEEP=1 keeps that directory
# after a clean run too).
set -euo pipefail

if [[ $# -lt 2 ]]; then
  echo "usage: $0 BUILD_DIR SECONDS_PER_TARGET [TARGET...]" >&2
  exit 2
fi
build=$1
seconds=$2
shift 2
here=$(cd "$(dirname "$0")" && pwd)
bin=$build/bin

# Largest input per target, bytes: room for the largest valid message of
# each format without wasting executions on huge inputs.
max_len_of() {
  case $1 in
    srf04) echo 16 ;;          # exactly 8 bytes is valid
    can_id) echo 64 ;;         # 18 bytes of fields
    emu_wire) echo 128 ;;      # 11 bytes of setup + 16 + a canfd_frame (72)
    serial_framing) echo 2048 ;;
    *) echo 4096 ;;            # packets, payloads, scripts, config files
  esac
}

shopt -s nullglob
targets=()
if [[ $# -gt 0 ]]; then
  for name in "$@"; do
    targets+=("$bin/fuzz_${name#fuzz_}")
  done
else
  targets=("$bin"/fuzz_*)
fi
if [[ ${#targets[@]} -eq 0 ]]; then
  echo "$0: no fuzz_* binaries in $bin (cmake --build $build --target fuzzers)" >&2
  exit 2
fi

work=$(mktemp -d "${TMPDIR:-/tmp}/herm-fuzz.XXXXXX")
# UBSan is recoverable in HERM builds (tests/ubsan.supp); here every finding
# stops the run, like ASan's, except the reported, unfixed findings listed in
# tests/fuzz/known-findings.supp.
cat "$here/../ubsan.supp" "$here/known-findings.supp" >"$work/ubsan.supp"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1:suppressions=$work/ubsan.supp"
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1}"

failed=0
printf '%-22s %6s %12s %8s %8s %8s %7s  %s\n' target seconds runs cov ft corpus rss_mb \
  result
for exe in "${targets[@]}"; do
  name=$(basename "$exe")
  name=${name#fuzz_}
  if [[ ! -x $exe ]]; then
    echo "$0: $exe is missing" >&2
    failed=1
    continue
  fi
  corpus=$work/$name/corpus
  mkdir -p "$corpus" "$work/$name/artifacts"
  if [[ -d $here/corpus/$name ]]; then
    cp -r "$here/corpus/$name/." "$corpus/"
  fi
  args=(-max_total_time="$seconds" -max_len="$(max_len_of "$name")"
        -timeout=30 -rss_limit_mb=2048 -print_final_stats=1
        -artifact_prefix="$work/$name/artifacts/")
  if [[ -f $here/$name.dict ]]; then
    args+=(-dict="$here/$name.dict")
  fi
  log=$work/$name/log
  start=$(date +%s)
  status=0
  # The outer bound catches a fuzzer that hangs while reporting (ASan's
  # memory profile after an out-of-memory can take very long).
  timeout -s KILL $((seconds + 300)) "$exe" "${args[@]}" "$corpus" \
    >"$log" 2>&1 || status=$?
  elapsed=$(( $(date +%s) - start ))
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  last=$(grep -E '^#[0-9]+.* cov: ' "$log" | tail -1 || true)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
  rss=$(sed -n 's/^stat::peak_rss_mb: *//p' "$log" | tail -1)
  files=$(find "$corpus" -type f | wc -l)
  if [[ $status -eq 0 ]]; then
    result="no crash"
  else
    result="CRASH (exit $status): $log"
    failed=1
  fi
  printf '%-22s %6s %12s %8s %8s %8s %7s  %s\n' "fuzz_$name" "$elapsed" \
    "${runs:-?}" "${cov:-?}" "${ft:-?}" "$files" "${rss:-?}" "$result"
  if [[ $status -ne 0 ]]; then
    grep -E 'ERROR|SUMMARY|property violated|Test unit written' "$log" \
      | head -20 | sed 's/^/    /' || true
    for a in "$work/$name/artifacts"/*; do
      echo "    input: $a"
    done
  fi
done

if [[ $failed -ne 0 ]]; then
  echo "fuzzing found problems; logs and inputs in $work" >&2
  exit 1
fi
if [[ ${HERM_FUZZ_KEEP:-0} == 1 ]]; then
  echo "logs and grown corpora kept in $work"
else
  rm -rf "$work"
fi
echo "every fuzz target ran ${seconds} s without a crash"
