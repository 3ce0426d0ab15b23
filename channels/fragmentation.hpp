#pragma once

// Fragmentation and reassembly for small-MTU links (the paper's decorator
// channel, channels/port.hpp), one job per header:
//   channels/fragment_wire.hpp   the fragment header codec (wire format)
//   channels/fragmenter.hpp      splitting packets into frames
//   channels/reassembler.hpp     reassembling them, bounded, time passed in
//   channels/bundle_codec.hpp    several small packets in one frame
// This header includes the three public ones, for code that uses them all.

#include "channels/bundle_codec.hpp"
#include "channels/fragmenter.hpp"
#include "channels/reassembler.hpp"
