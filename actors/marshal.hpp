#pragma once

// The APO payload wire format, version 1: how an application object's
// message travels to a remote one. Specified in docs/protocol.md (APO payloads)
// ("## APO payloads") well enough for a peer without CAF to speak it.
//
// A user type needs nothing beyond what every HERM message type has: an
// `inspect` overload and an entry in actors/runtime/type_ids.hpp. The codec
// walks values with CAF's inspection API and writes HERM's own encoding
// (fixed-width little-endian integers, LEB128 lengths), so the bytes do not
// depend on the host's byte order, word size or compiler. The bytes are
// read and written through channels/le_codec.hpp.
//
// Bounds per call: marshal is O(n) in the encoded size n and allocates the
// result (plus what CAF's inspection of the values allocates). unmarshal
// is O(n) in `size`: one decoding pass and one re-encoding pass (the
// canonical-form check); it allocates the decoded values, each bounded by
// `limits` and by the bytes present, plus one per-thread buffer of n bytes
// for the re-encoding (kept, at most 64 KiB of capacity, for the next call).

#include <cstddef>
#include <cstdint>

#include "caf/expected.hpp"
#include "caf/fwd.hpp"
#include "caf/message.hpp"

#include "channels/messages.hpp"

namespace herm {

/// The version byte every APO payload starts with.
constexpr uint8_t apo_format_version = 1;

/// Upper bounds the decoder enforces before it allocates anything. A payload
/// that exceeds one is refused with `ec::invalid_parameter`; the defaults
/// suit HERM's packet sizes. Units: elements, bytes, counts, levels, bytes.
struct unmarshal_limits {
  /// Most top-level elements in one message.
  size_t max_elements = 16;
  /// Longest string in bytes (UTF-8, UTF-16LE or UTF-32LE code units).
  size_t max_string = 64 * 1024;
  /// Largest element count of one sequence or map (bytes for byte buffers).
  size_t max_sequence = 1 << 20;
  /// Deepest nesting of sequences and maps.
  size_t max_depth = 16;
  /// Largest payload in bytes, version byte included.
  size_t max_total = 1 << 20;
};

/// Encodes `msg` as an APO payload (version 1).
///
/// Fails with `ec::invalid_parameter` and a context naming the element if an
/// element's type has no portable name in the system, holds an actor handle
/// or a group (references into this process: APO payloads carry data only),
/// or holds a `long double` (no portable representation). CAF 0.17.6 skips
/// a `caf::message` nested in a value: a `caf::error` travels as code and
/// category without its context.
/// Thread-safe: reads only the system's type registry. Allocates the result.
caf::expected<byte_buffer> marshal(caf::actor_system& sys,
                                   const caf::message& msg);

/// Decodes an APO payload of `size` bytes at `data` (not retained).
///
/// Total and bounded: every length and count is checked against the bytes
/// left and `limits` before anything is allocated; any input, however
/// malformed, yields either a message or `ec::invalid_parameter` with a
/// context such as "element 1 (herm::write_packet): truncated in value 1
/// (needs 8 bytes at offset 28, 2 left)". Only canonical encodings are
/// accepted: a decoded message re-encodes to exactly the input bytes.
/// Values are created by name through the system's type registry; actor
/// handles are refused, never resolved. A type name the registry does not
/// know yields `app_ec::unknown_type` instead (the sender speaks a type this
/// module was not built with).
caf::expected<caf::message> unmarshal(caf::actor_system& sys,
                                      const uint8_t* data, size_t size,
                                      const unmarshal_limits& limits = {});

} // namespace herm
