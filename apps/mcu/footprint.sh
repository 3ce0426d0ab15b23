#!/bin/sh
# footprint.sh BUILD_DIR: the microcontroller footprint table of issue 17
# (docs/performance.md, "Microcontroller footprint (issue 17)").
#
# Prints, for the sonar firmware BUILD_DIR/bin/herm-srf04-firmware.elf (as
# built by apps/mcu/firmware/CMakeLists.txt) and for the hermc library alone:
#   - avr-size of the firmware: flash (text + data) and static RAM (data + bss);
#   - the library's objects (apps/mcu/client/hermc*.c, each -Os -c) for the
#     ATmega128, in the default (full) configuration and in the firmware's
#     (HERM_SRF04_HERMC_DEFINES, read from BUILD_DIR/CMakeCache.txt);
#   - the same objects for a Cortex-M0 (arm-none-eabi-gcc -Os -mcpu=cortex-m0
#     -mthumb), when that compiler is installed;
#   - sizeof(struct hermc_module) on each;
#   - the stack high-water mark of the firmware in simavr (herm-avr-sim
#     --max-seconds 5 --report-stack: painted stack; the board runs alone, so
#     this is its idle loop with SRF04 readings and hellos, no neighbour).
# and checks the targets: firmware flash <= 12288 B, static RAM <= 1024 B,
# stack < 512 B.
#
# Exit status: 0 every target met, 1 one missed (the table says which),
# 77 skipped (no avr-gcc/avr-size, no firmware or no herm-avr-sim in
# BUILD_DIR; the reason is printed), 2 bad usage.
set -eu

FLASH_TARGET=12288
RAM_TARGET=1024
STACK_TARGET=512

if [ $# -ne 1 ]; then
  echo "usage: $0 BUILD_DIR" >&2
  exit 2
fi
build=$(cd "$1" && pwd)
here=$(cd "$(dirname "$0")" && pwd)
client="$here/client"
fw="$build/bin/herm-srf04-firmware.elf"
sim="$build/bin/herm-avr-sim"

skip() {
  echo "footprint: skipped: $*"
  exit 77
}
command -v avr-gcc >/dev/null 2>&1 || skip "avr-gcc not installed (gcc-avr, avr-libc)"
command -v avr-size >/dev/null 2>&1 || skip "avr-size not installed (binutils-avr)"
[ -f "$fw" ] || skip "$fw not built (target herm-srf04-firmware)"
[ -x "$sim" ] || skip "$sim not built (target herm-avr-sim; needs libsimavr)"

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT INT TERM

# The firmware's hermc definitions, as CMake passed them (a;b;c list).
defs=$(sed -n 's/^HERM_SRF04_HERMC_DEFINES:INTERNAL=//p' "$build/CMakeCache.txt" | tr ';' ' ')
sonar_flags=""
for d in $defs; do sonar_flags="$sonar_flags -D$d"; done

# text data bss of the objects of the library built by compiler $1 with
# size tool $2, flags $3 (prints "text data bss").
lib_size() {
  dir="$tmp/$(echo "$1 $3" | md5sum | cut -c1-8)"
  mkdir -p "$dir"
  for c in "$client"/hermc*.c; do
    # shellcheck disable=SC2086
    "$1" -std=c99 -Os $3 -ffunction-sections -fdata-sections -I"$client" \
      -c "$c" -o "$dir/$(basename "$c" .c).o"
  done
  "$2" -t "$dir"/*.o | awk 'END { print $1, $2, $3 }'
}

# sizeof(struct hermc_module) with compiler $1, size tool's nm $2, flags $3.
module_size() {
  printf '#include "hermc.h"\nchar hermc_module_size[sizeof(struct hermc_module)];\n' \
    > "$tmp/probe.c"
  # shellcheck disable=SC2086
  "$1" -std=c99 $3 -I"$client" -c "$tmp/probe.c" -o "$tmp/probe.o"
  "$2" -S -t d "$tmp/probe.o" | awk '/hermc_module_size/ { print $2 + 0 }'
}

avr="-mmcu=atmega128"
set -- $(avr-size --format=berkeley "$fw" | awk 'NR == 2 { print $1, $2, $3 }')
fw_text=$1 fw_data=$2 fw_bss=$3
fw_flash=$((fw_text + fw_data))
fw_ram=$((fw_data + fw_bss))

stack=$("$sim" --firmware "$fw" --max-seconds 5 --report-stack 2>&1 \
        | sed -n 's/^stack used=\([0-9]*\).*/\1/p')
[ -n "$stack" ] || { echo "footprint: herm-avr-sim reported no stack figure" >&2; exit 1; }

verdict() { # value limit strict(1: below, 0: at most)
  if [ "$3" = 1 ]; then [ "$1" -lt "$2" ]; else [ "$1" -le "$2" ]; fi \
    && echo "met" || echo "NOT MET"
}

echo "Microcontroller footprint (bytes)"
echo
echo "| what | text | data | bss | flash (text+data) | static RAM (data+bss) |"
echo "|---|---:|---:|---:|---:|---:|"
echo "| sonar firmware, ATmega128 (herm-srf04-firmware.elf) | $fw_text | $fw_data | $fw_bss | $fw_flash | $fw_ram |"
set -- $(lib_size avr-gcc avr-size "$avr")
echo "| hermc library alone, ATmega128, full (default macros) | $1 | $2 | $3 | $(($1 + $2)) | $(($2 + $3)) |"
set -- $(lib_size avr-gcc avr-size "$avr $sonar_flags")
echo "| hermc library alone, ATmega128, the firmware's macros | $1 | $2 | $3 | $(($1 + $2)) | $(($2 + $3)) |"
arm_module=""
if command -v arm-none-eabi-gcc >/dev/null 2>&1; then
  arm="-mcpu=cortex-m0 -mthumb"
  set -- $(lib_size arm-none-eabi-gcc arm-none-eabi-size "$arm")
  echo "| hermc library alone, Cortex-M0, full (default macros) | $1 | $2 | $3 | $(($1 + $2)) | $(($2 + $3)) |"
  set -- $(lib_size arm-none-eabi-gcc arm-none-eabi-size "$arm $sonar_flags")
  echo "| hermc library alone, Cortex-M0, the firmware's macros | $1 | $2 | $3 | $(($1 + $2)) | $(($2 + $3)) |"
  arm_module=$(module_size arm-none-eabi-gcc arm-none-eabi-nm "$arm")
fi
echo
arm_note="Cortex-M0 not measured (no arm-none-eabi-gcc)"
[ -z "$arm_module" ] || arm_note="Cortex-M0 full $arm_module"
echo "sizeof(struct hermc_module): ATmega128 full $(module_size avr-gcc avr-nm "$avr"), ATmega128 firmware's macros $(module_size avr-gcc avr-nm "$avr $sonar_flags"), $arm_note"
echo "firmware's hermc macros: ${defs:-none}"
echo
echo "| target (issue 17) | measured | limit | verdict |"
echo "|---|---:|---:|---|"
echo "| firmware flash (text+data) | $fw_flash | <= $FLASH_TARGET | $(verdict "$fw_flash" $FLASH_TARGET 0) |"
echo "| firmware static RAM (data+bss) | $fw_ram | <= $RAM_TARGET | $(verdict "$fw_ram" $RAM_TARGET 0) |"
echo "| stack high-water mark in simavr | $stack | < $STACK_TARGET | $(verdict "$stack" $STACK_TARGET 1) |"

[ "$fw_flash" -le $FLASH_TARGET ] && [ "$fw_ram" -le $RAM_TARGET ] && [ "$stack" -lt $STACK_TARGET ]
