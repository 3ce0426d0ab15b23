#pragma once

// The board's EEPROM kept in a file across runs (herm-avr-sim --eeprom FILE),
// so that what the firmware stores there (the sonar firmware's boot counter,
// which makes its instance) survives a reboot, as on a real board. Pure file
// I/O: no simavr here; main.cpp moves the bytes in and out of the core.
//
// The file holds the EEPROM's bytes from address 0, nothing else. A missing
// file is an erased EEPROM (the caller leaves the core's 0xFF). A file
// shorter than the EEPROM fills its first bytes; a longer one is refused
// (it was written for another part).

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace herm::avr_sim {

struct eeprom_image {
  /// False when the file did not exist: the EEPROM stays erased.
  bool found = false;
  /// The file's bytes, at most the EEPROM's size.
  std::vector<uint8_t> bytes;
  /// Empty when the file was read (or did not exist); otherwise why not.
  std::string error;
};

/// Reads `path` for an EEPROM of `size` bytes; reads at most size + 1 bytes
/// (to tell a file that is too long), so a large file costs nothing.
eeprom_image load_eeprom(const std::string& path, size_t size);

/// Writes `size` bytes to `path` atomically (PATH.tmp, then rename), so a
/// run killed while saving leaves the previous image. Returns an empty
/// string, or what failed with the path and errno's text.
std::string save_eeprom(const std::string& path, const uint8_t* data, size_t size);

} // namespace herm::avr_sim
