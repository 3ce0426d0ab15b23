#!/bin/bash
# Runs the SocketCAN tests of can_driver_test against a real Linux kernel.
#
#   tests/qemu/run-can-kernel-test.sh TEST_BINARY BUILD_DIR [GTEST_FILTER]
#
# Where the host kernel has vcan (root can `ip link add dev vcan0 type
# vcan`), the tests run directly on the host, on a vcan0 this script creates
# and removes. Otherwise (containers, kernels without CAN) it boots Debian's
# stock kernel under qemu in software emulation (TCG) with an initramfs that
# holds busybox, the CAN modules, the test binary and the libraries ldd lists;
# /init loads can, can-raw, can-dev and vcan, creates vcan0, runs the tests
# and prints a marker line with their exit code on the serial console.
#
# Downloads (the kernel package resolved through linux-image-amd64, and
# busybox-static) go through apt-get and are cached under
# BUILD_DIR/qemu-can-cache, so reruns boot right away.
#
# Exit status: the test binary's; 77 (CTest's SKIP_RETURN_CODE) only when
# neither a vcan-capable host kernel nor qemu plus a Debian kernel can be
# had, with the reason on stderr; 1 when the VM did not report a result.
#
# Environment: HERM_QEMU_TIMEOUT (seconds for the whole VM run, default 300),
# HERM_QEMU_FORCE=1 boots qemu even where the host has vcan.

set -u -o pipefail

if [ $# -lt 2 ]; then
  echo "usage: $0 TEST_BINARY BUILD_DIR [GTEST_FILTER]" >&2
  exit 2
fi
test_bin=$(readlink -f "$1")
build_dir=$(readlink -f "$2")
filter=${3:-socketcan*}
timeout_s=${HERM_QEMU_TIMEOUT:-300}
cache=$build_dir/qemu-can-cache

if [ ! -x "$test_bin" ]; then
  echo "error: test binary '$1' not found or not executable" >&2
  exit 2
fi

skip() {
  echo "SKIP: $*" >&2
  exit 77
}

# -- the host kernel, if it has vcan ------------------------------------------------

if [ "${HERM_QEMU_FORCE:-0}" != 1 ] && command -v ip >/dev/null 2>&1 \
   && ip link add dev hermprobe0 type vcan 2>/dev/null; then
  ip link del dev hermprobe0
  created=""
  if ! ip link show dev vcan0 >/dev/null 2>&1; then
    ip link add dev vcan0 type vcan && created=vcan0
  fi
  trap '[ -n "$created" ] && ip link del dev "$created"' EXIT
  ip link set dev vcan0 up || exit 1
  echo "host kernel $(uname -r) has vcan: running the tests directly"
  "$test_bin" --gtest_filter="$filter"
  exit $?
fi

# -- qemu and the Debian kernel -----------------------------------------------------

qemu=$(command -v qemu-system-x86_64) \
  || skip "the host kernel has no vcan and qemu-system-x86_64 is not installed (apt-get install --no-install-recommends qemu-system-x86 cpio)"
command -v cpio >/dev/null || skip "cpio is not installed (apt-get install cpio)"
[ "$(uname -m)" = x86_64 ] || skip "the qemu harness boots an amd64 kernel; this host is $(uname -m)"

mkdir -p "$cache" || exit 1
kernel_dir=$cache/kernel
busybox=$cache/busybox/bin/busybox

# Downloads into $cache/dl and unpacks only what the VM needs.
fetch() {
  local dl=$cache/dl
  rm -rf "$dl" && mkdir -p "$dl" || return 1
  local pkg
  pkg=$(apt-cache depends linux-image-amd64 2>/dev/null \
          | awk '/Depends: linux-image-[0-9]/ { print $2; exit }')
  if [ -z "$pkg" ]; then
    echo "cannot resolve linux-image-amd64 to a kernel package (apt-get update?)" >&2
    return 1
  fi
  echo "downloading $pkg and busybox-static into $dl"
  # apt-get download runs as _apt when it can; let it write into $dl.
  chmod 777 "$dl" 2>/dev/null
  (cd "$dl" && apt-get download -q "$pkg" busybox-static) >&2 || {
    echo "apt-get download $pkg busybox-static failed" >&2
    return 1
  }
  rm -rf "$kernel_dir.new" && mkdir -p "$kernel_dir.new" || return 1
  dpkg-deb --fsys-tarfile "$dl"/linux-image-*.deb \
    | tar -x -C "$kernel_dir.new" --wildcards './boot/vmlinuz-*' \
        '*/kernel/net/can/can.ko*' '*/kernel/net/can/can-raw.ko*' \
        '*/kernel/drivers/net/can/dev/can-dev.ko*' \
        '*/kernel/drivers/net/can/vcan.ko*' || {
    echo "cannot unpack $pkg" >&2
    return 1
  }
  rm -rf "$cache/busybox" && mkdir -p "$cache/busybox" || return 1
  dpkg-deb -x "$dl"/busybox-static_*.deb "$cache/busybox.tmp" \
    && mkdir -p "$cache/busybox/bin" \
    && cp "$cache/busybox.tmp/bin/busybox" "$busybox" || {
    echo "cannot unpack busybox-static" >&2
    return 1
  }
  rm -rf "$cache/busybox.tmp" "$kernel_dir" "$dl"
  mv "$kernel_dir.new" "$kernel_dir"
  echo "$pkg" > "$kernel_dir/package"
}

vmlinuz=$(ls "$kernel_dir"/boot/vmlinuz-* 2>/dev/null | head -n 1)
if [ -z "$vmlinuz" ] || [ ! -x "$busybox" ]; then
  command -v apt-get >/dev/null && command -v dpkg-deb >/dev/null \
    || skip "no cached kernel in $cache and no apt-get/dpkg-deb to fetch one"
  fetch || skip "cannot get a Debian kernel and busybox (see above)"
  vmlinuz=$(ls "$kernel_dir"/boot/vmlinuz-* 2>/dev/null | head -n 1)
  [ -n "$vmlinuz" ] || skip "the kernel package holds no /boot/vmlinuz-*"
fi

module() {
  local path
  path=$(find "$kernel_dir" -name "$1.ko*" | head -n 1)
  [ -n "$path" ] || { echo "module $1 missing in $kernel_dir" >&2; return 1; }
  echo "$path"
}

# -- the initramfs --------------------------------------------------------------------

work=$(mktemp -d "$build_dir/qemu-can-run.XXXXXX") || exit 1
trap 'rm -rf "$work"' EXIT
root=$work/root
mkdir -p "$root"/{bin,dev,proc,sys,tmp,herm,modules} || exit 1
cp "$busybox" "$root/bin/busybox" || exit 1
for m in can can-raw can-dev vcan; do
  src=$(module "$m") || exit 1
  case $src in
    *.ko) cp "$src" "$root/modules/$m.ko" ;;
    *.ko.xz) xz -dc "$src" > "$root/modules/$m.ko" ;;
    *.ko.zst) zstd -qdc "$src" > "$root/modules/$m.ko" ;;
    *.ko.gz) gzip -dc "$src" > "$root/modules/$m.ko" ;;
    *) echo "cannot handle module file $src" >&2; exit 1 ;;
  esac || { echo "cannot unpack $src" >&2; exit 1; }
done
# Without debug info: a smaller initramfs loads faster under TCG.
strip --strip-debug -o "$root/herm/can_driver_test" "$test_bin" 2>/dev/null \
  || cp "$test_bin" "$root/herm/can_driver_test" || exit 1
# Every library the binary needs, at the same path, and the loader.
ldd "$test_bin" | awk '/=> \// { print $3 } /^[[:space:]]*\// { print $1 }' \
  | while read -r lib; do
      mkdir -p "$root$(dirname "$lib")" && cp -L "$lib" "$root$lib" || exit 1
    done || exit 1

cat > "$root/init" <<EOF
#!/bin/busybox sh
/bin/busybox mount -t devtmpfs devtmpfs /dev
exec >/dev/console 2>&1 </dev/null
/bin/busybox --install -s /bin
export PATH=/bin
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t tmpfs tmpfs /tmp
for m in can can-raw can-dev vcan; do
  insmod /modules/\$m.ko || echo "HERM-CAN-INIT: insmod \$m failed"
done
ip link set dev lo up
ip link add dev vcan0 type vcan && ip link set dev vcan0 up \
  || echo "HERM-CAN-INIT: cannot create vcan0"
echo "HERM-CAN-KERNEL: \$(uname -r), up \$(cut -d' ' -f1 /proc/uptime) s"
/herm/can_driver_test --gtest_filter='$filter' --gtest_color=no
echo "HERM-CAN-RESULT: \$?"
poweroff -f
EOF
chmod +x "$root/init"
(cd "$root" && find . | cpio -o -H newc --quiet) > "$work/initrd.cpio" \
  || { echo "cannot build the initramfs" >&2; exit 1; }

# -- boot -----------------------------------------------------------------------------

echo "booting $(basename "$vmlinuz") ($(cat "$kernel_dir/package" 2>/dev/null)) under qemu (TCG), timeout ${timeout_s} s"
start=$(date +%s%N)
timeout --kill-after=10 "$timeout_s" "$qemu" -accel tcg -cpu qemu64 -smp 1 \
  -m 512M -nographic -no-reboot -monitor none -nic none \
  -kernel "$vmlinuz" -initrd "$work/initrd.cpio" \
  -append "console=ttyS0 panic=-1 quiet" </dev/null > "$work/console.raw" 2>&1
qemu_rc=$?
end=$(date +%s%N)
tr -d '\r' < "$work/console.raw" > "$work/console.log"
cat "$work/console.log"
elapsed_ms=$(( (end - start) / 1000000 ))
printf 'qemu ran %d.%03d s (exit %d)\n' $((elapsed_ms / 1000)) $((elapsed_ms % 1000)) "$qemu_rc"

result=$(sed -n 's/^HERM-CAN-RESULT: \([0-9]*\)$/\1/p' "$work/console.log" | tail -n 1)
if [ -z "$result" ]; then
  if [ "$qemu_rc" = 124 ] || [ "$qemu_rc" = 137 ]; then
    echo "error: the VM did not finish within ${timeout_s} s" >&2
  else
    echo "error: the VM reported no result (boot or init failed)" >&2
  fi
  exit 1
fi
exit "$result"
