#!/usr/bin/env bash
# The Debian package as a robot would install it: `cpack -G DEB` from a
# finished build into a temporary directory, unpacked with dpkg-deb, then
# checked: hermd and hermctl under /usr/bin without symbol tables or DWARF
# (CPACK_STRIP_FILES), the static libraries without DWARF, the users' one
# header at include/herm/herm/herm.hpp and nowhere else, the systemd unit
# starting /usr/bin/hermd, and the control fields a package needs.
#
#   deb.sh CPACK BUILD_DIR
#
# Writes only below a temporary directory (removed on exit).
set -euo pipefail

cpack=$1 build=$2
for tool in dpkg-deb readelf; do
  command -v $tool > /dev/null || { echo "FAIL: $tool is needed"; exit 1; }
done
tmp=$(mktemp -d "${TMPDIR:-/tmp}/herm-deb-test.XXXXXX")
trap 'rm -rf "$tmp"' EXIT

echo "== cpack -G DEB in $build"
if ! (cd "$build" && "$cpack" -G DEB -B "$tmp/out") > "$tmp/cpack.log" 2>&1; then
  cat "$tmp/cpack.log"
  echo "FAIL: cpack failed (is the build complete?)"
  exit 1
fi
debs=("$tmp"/out/herm_*.deb)
[ -f "${debs[0]}" ] || { echo "FAIL: no herm_*.deb in $tmp/out"; ls "$tmp/out"; exit 1; }
deb=${debs[0]}
echo "   $(basename "$deb"): $(stat -c %s "$deb") bytes"
dpkg-deb -x "$deb" "$tmp/root"

fail=0
check() { # check DESCRIPTION COMMAND...: prints and records a failure
  local what=$1; shift
  if "$@"; then echo "  ok   $what"; else echo "  FAIL $what"; fail=1; fi
}
no_section() { # no_section FILE PATTERN
  ! readelf -S "$1" | grep -Eq "$2"
}
for tool in hermd hermctl; do
  check "usr/bin/$tool present" test -x "$tmp/root/usr/bin/$tool"
  check "usr/bin/$tool stripped (no .symtab, no .debug_*)" \
    no_section "$tmp/root/usr/bin/$tool" '\.(symtab|debug_)'
done
check "libherm_runtime.a without DWARF" \
  no_section "$tmp/root/usr/lib/libherm_runtime.a" '\.debug_info'
headers=$(cd "$tmp/root" && find . -name herm.hpp | sort | tr '\n' ' ')
check "herm.hpp only at usr/include/herm/herm/herm.hpp (found: $headers)" \
  test "$headers" = "./usr/include/herm/herm/herm.hpp "
unit="$tmp/root/usr/lib/systemd/system/hermd@.service"
check "hermd@.service starts /usr/bin/hermd" grep -q '^ExecStart=/usr/bin/hermd ' "$unit"
fields=$(dpkg-deb -f "$deb" Package Architecture Depends)
echo "$fields" | sed 's/^/       /'
check "Package: herm" grep -q '^Package: herm$' <<< "$fields"
check "Depends names CAF's runtime library" grep -q 'libcaf-core' <<< "$fields"
size=$(du -sk "$tmp/root" | cut -f1)
echo "   unpacked: ${size} KiB"
# RelWithDebInfo unstripped is about 140 MB; stripped it is about 25 MB.
check "unpacked below 64 MiB" test "$size" -lt 65536

[ $fail -eq 0 ] || { echo "FAIL: the .deb is not what a robot should install"; exit 1; }
echo "PASS"
