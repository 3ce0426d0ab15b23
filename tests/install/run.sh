#!/usr/bin/env bash
# Installs HERM from a finished build into a temporary prefix, then builds and
# runs tests/install/consumer/ (an outside project: find_package(herm),
# herm::herm) against that prefix only, and checks what it prints.
#
#   run.sh CMAKE BUILD_DIR CONSUMER_SOURCE_DIR GENERATOR CXX_COMPILER [FLAGS [CAF_ROOT]]
#
# FLAGS: compile and link flags the consumer needs to link HERM's libraries
# (the sanitizer flags of a -DHERM_SANITIZE=ON or -DHERM_TSAN=ON build).
# CAF_ROOT: the HERM_CAF_ROOT the build used (a CAF outside the system's,
# e.g. the one tests/tsan/build-caf.sh builds); the consumer must link it too.
#
# Writes only below a temporary directory (removed on exit). `cmake --install`
# also writes BUILD_DIR/install_manifest.txt; that file is put back as it was.
set -euo pipefail

cmake=$1 build=$2 consumer=$3 generator=$4 cxx=$5 flags=${6:-} caf_root=${7:-}

tmp=$(mktemp -d "${TMPDIR:-/tmp}/herm-install-test.XXXXXX")
manifest="$build/install_manifest.txt"
had_manifest=0
if [ -e "$manifest" ]; then
  cp -p "$manifest" "$tmp/install_manifest.saved"
  had_manifest=1
fi
cleanup() {
  if [ $had_manifest -eq 1 ]; then
    cp -p "$tmp/install_manifest.saved" "$manifest"
  else
    rm -f "$manifest"
  fi
  rm -rf "$tmp"
}
trap cleanup EXIT

prefix="$tmp/prefix"
echo "== cmake --install $build --prefix $prefix"
if ! "$cmake" --install "$build" --prefix "$prefix" > "$tmp/install.log" 2>&1; then
  cat "$tmp/install.log"
  echo "FAIL: cmake --install failed (is the build complete? run cmake --build first)"
  exit 1
fi

fail=0
expect_file() {
  if [ -e "$prefix/$1" ]; then echo "  ok   $1"; else echo "  MISSING $1"; fail=1; fi
}
echo "== installed files"
for f in lib/libherm_runtime.a lib/libherm_asl.a lib/libherm_module.a \
         lib/libherm_channels.a lib/libherm_routing.a \
         lib/cmake/herm/hermConfig.cmake lib/cmake/herm/hermConfigVersion.cmake \
         lib/cmake/herm/hermTargets.cmake lib/cmake/herm/HermFindCAF.cmake \
         include/herm/actors/module.hpp include/herm/actors/runtime/type_ids.hpp \
         include/herm/channels/link_kinds.def include/herm/channels/drivers/udp_addr.hpp \
         include/herm/routing/routing_agent.hpp include/herm/herm/herm.hpp; do
  expect_file "$f"
done
if [ -e "$prefix/bin/hermd" ]; then
  expect_file lib/systemd/system/hermd@.service
  if ! grep -q "^ExecStart=$prefix/bin/hermd " "$prefix/lib/systemd/system/hermd@.service"; then
    echo "  unit does not start this prefix's hermd:"
    grep ExecStart "$prefix/lib/systemd/system/hermd@.service" || true
    fail=1
  fi
fi
command -v readelf > /dev/null || { echo "FAIL: readelf (binutils) is needed to check stripping"; exit 1; }
# Stripped by default (HERM_INSTALL_STRIP): programs without a symbol table
# or DWARF, static libraries without DWARF (their symbols stay for linking).
for tool in hermd hermctl; do
  if [ -e "$prefix/bin/$tool" ] && readelf -S "$prefix/bin/$tool" | grep -Eq '\.(symtab|debug_info)'; then
    echo "  bin/$tool is installed with symbols or debug info (not stripped)"; fail=1
  fi
done
if readelf -S "$prefix/lib/libherm_runtime.a" | grep -q '\.debug_info'; then
  echo "  lib/libherm_runtime.a is installed with debug info"; fail=1
fi
if grep -rq -- "-Wshadow" "$prefix/lib/cmake/herm"; then
  echo "  HERM's warning flags leak into the package"; fail=1
fi
[ $fail -eq 0 ] || { echo "FAIL: install tree incomplete"; exit 1; }

echo "== configure and build the consumer"
# Only the temporary prefix may provide herm (not a system-wide install).
if ! "$cmake" -S "$consumer" -B "$tmp/consumer" -G "$generator" \
      -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_PREFIX_PATH="$prefix" \
      -DCMAKE_FIND_PACKAGE_NO_PACKAGE_REGISTRY=ON \
      -DCMAKE_CXX_FLAGS="$flags" -DCMAKE_EXE_LINKER_FLAGS="$flags" \
      ${caf_root:+-DHERM_CAF_ROOT="$caf_root"} \
      > "$tmp/configure.log" 2>&1; then
  cat "$tmp/configure.log"; echo "FAIL: configuring the consumer failed"; exit 1
fi
grep "herm_DIR=" "$tmp/configure.log" || true
if ! grep -q "herm_DIR=$prefix/lib/cmake/herm " "$tmp/configure.log"; then
  echo "FAIL: find_package(herm) did not find the package in $prefix"; exit 1
fi
if ! "$cmake" --build "$tmp/consumer" -j2 > "$tmp/build.log" 2>&1; then
  cat "$tmp/build.log"; echo "FAIL: building the consumer failed"; exit 1
fi

echo "== run the consumer"
out=$("$tmp/consumer/herm_consumer" 2>&1) || { echo "$out"; echo "FAIL: consumer exited with an error"; exit 1; }
echo "$out"
if ! grep -q "^herm consumer: registered 'echo' (consumer.echo) as APO [0-9]*; link_cost(can2.0) = [1-9][0-9]*; reading has 2 described fields" <<<"$out"; then
  echo "FAIL: unexpected output"; exit 1
fi
echo "PASS"
