#pragma once

// A medium as a directory, shared by the emulated link kinds (emu, the can
// kind's emulated bus): every station is an AF_UNIX datagram socket named
// "N.sock" in the medium's directory.

#include <sys/un.h>

#include <cstdint>
#include <string>
#include <vector>

namespace herm::medium_dir {

/// "N.sock".
std::string station_file(uint64_t station);

/// Parses "N.sock" with N in [min, max] (no leading zeros, at most 3
/// digits); 0 for anything else.
uint64_t parse_station_file(const char* name, uint64_t min, uint64_t max);

/// Parses an address as people write it: 1 to 3 decimal digits (leading
/// zeros allowed) naming a number in [min, max]; 0 for anything else.
uint64_t parse_number(const std::string& str, uint64_t min, uint64_t max);

/// The socket address of a path (truncated to sun_path).
sockaddr_un unix_addr(const std::string& path);

enum class probe_result { live, stale, absent };

/// Whether a process is bound to the datagram socket at `path`: live, stale
/// (a file nobody listens on) or absent. Unknown errors count as live.
probe_result probe_socket(const std::string& path);

/// Station numbers in [min, max] with a socket file in `dir`, ascending.
std::vector<uint64_t> list_stations(const std::string& dir, uint64_t min,
                                    uint64_t max);

/// mkdir -p; 0 or an errno value (ENOTDIR when a component is a file).
int make_dirs(const std::string& path);

/// "1, 2, 5".
std::string join_numbers(const std::vector<uint64_t>& xs);

} // namespace herm::medium_dir
