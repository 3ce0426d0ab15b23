#!/bin/bash
# Builds CAF 0.17.6 with ThreadSanitizer, so that TSan sees the hand-offs
# inside CAF (mailboxes, scheduler queues, reference counts) and its reports
# on HERM's actor code mean something. Debian's libcaf-core0.17 is not
# instrumented, and TSan reports every message passed between threads as a
# race when it cannot see the library's atomics.
#
#   tests/tsan/build-caf.sh [PREFIX]      (default PREFIX: ./build-caf-tsan)
#
# The source is Debian's own: actor-framework_0.17.6.orig.tar.gz from the
# Debian archive (the upstream release tarball Debian builds its packages
# from), checked against the SHA-256 that bookworm's actor-framework
# 0.17.6-2.1 source package lists. Nothing of it enters the repository: it is
# downloaded into PREFIX/src, built there and installed into PREFIX (headers,
# libcaf_core.so, libcaf_io.so). Then:
#
#   cmake -S . -B build-tsan -G Ninja -DHERM_TSAN=ON \
#         -DHERM_CAF_ROOT=$PWD/build-caf-tsan -DHERM_BUILD_BENCHMARKS=OFF
#
# Same configuration as Debian's package (log level QUIET, exceptions and
# memory management on) but without OpenSSL, examples, tools and CAF's own
# tests. Takes about 3 minutes on 2 cores (3 min 8 s here); reruns reuse
# the build.

set -euo pipefail

repo=$(cd "$(dirname "$0")/../.." && pwd)
prefix=${1:-$repo/build-caf-tsan}
mkdir -p "$prefix"
prefix=$(cd "$prefix" && pwd)
jobs=${HERM_JOBS:-$(nproc)}

tarball=actor-framework_0.17.6.orig.tar.gz
sha256=e2bf5bd243f08bb7d8adde197cfe3e6d71314ed3378fe0692f8932f4c3b3928c
url=${HERM_CAF_URL:-http://deb.debian.org/debian/pool/main/a/actor-framework/$tarball}

if [ -f "$prefix/lib/libcaf_core.so" ] && [ -f "$prefix/.herm-tsan-g1-$sha256" ]; then
  echo "build-caf.sh: $prefix already holds CAF 0.17.6 built with TSan"
  exit 0
fi

mkdir -p "$prefix/src"
cd "$prefix/src"
if ! echo "$sha256  $tarball" | sha256sum -c --status 2>/dev/null; then
  echo "build-caf.sh: downloading $url"
  curl -fsSL -o "$tarball.part" "$url" || {
    echo "build-caf.sh: cannot download $url (Debian's archive must be reachable)" >&2
    exit 1
  }
  mv "$tarball.part" "$tarball"
  if ! echo "$sha256  $tarball" | sha256sum -c --status; then
    echo "build-caf.sh: $tarball does not have the SHA-256 Debian lists ($sha256)" >&2
    exit 1
  fi
fi
if [ ! -f actor-framework-0.17.6/.herm-patched ]; then
  rm -rf actor-framework-0.17.6 build
  tar xzf "$tarball"
  # The one change Debian's package makes to the sources (0.17.6-2.1: a
  # missing include that newer compilers need; the installed header
  # /usr/include/caf/io/network/receive_buffer.hpp has it).
  sed -i 's|^#include <cstring>$|#include <cstring>\n#include <limits>|' \
    actor-framework-0.17.6/libcaf_io/caf/io/network/receive_buffer.hpp
  grep -q '^#include <limits>$' \
    actor-framework-0.17.6/libcaf_io/caf/io/network/receive_buffer.hpp
  touch actor-framework-0.17.6/.herm-patched
fi

# -O2 with line tables only (-g1), as HERM's instrumented builds
# (CMakeLists.txt): a report names file and line of every frame, inlined
# ones too, and the build is faster than with full debug info.
flags="-fsanitize=thread -fno-omit-frame-pointer"
cmake -S actor-framework-0.17.6 -B build -G Ninja \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG" \
  -DCMAKE_CXX_FLAGS="-std=c++11 -Wall -Wextra $flags" \
  -DCMAKE_EXE_LINKER_FLAGS=-fsanitize=thread \
  -DCMAKE_SHARED_LINKER_FLAGS=-fsanitize=thread \
  -DCMAKE_INSTALL_PREFIX="$prefix" -DCMAKE_INSTALL_LIBDIR=lib \
  -DCAF_LOG_LEVEL=QUIET -DCAF_NO_EXAMPLES=yes -DCAF_NO_UNIT_TESTS=yes \
  -DCAF_NO_TOOLS=yes -DCAF_NO_OPENSSL=yes -DCAF_NO_PYTHON=yes \
  -DCAF_NO_OPENCL=yes -DCAF_NO_SUMMARY=yes -DCAF_NO_COMPILER_CHECK=yes \
  > "$prefix/cmake.log"
cmake --build build -j"$jobs"
cmake --install build > /dev/null
touch "$prefix/.herm-tsan-g1-$sha256"
echo "build-caf.sh: CAF 0.17.6 with TSan installed in $prefix"
