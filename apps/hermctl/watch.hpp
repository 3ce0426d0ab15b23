#pragma once

// `hermctl watch`: a dashboard of one module, redrawn every interval
// (docs/user-guide.md, "watch"): the modules it routes to, its links with
// rates and drops, the routes that changed since the last frame, and the
// network's topics with their publish rates.
//
// The core is pure: parse_snapshot turns the module's replies into a
// snapshot, carry_gone keeps links that disappeared visible as "down", and
// render_frame draws a frame from the previous and the current snapshot
// (rates are counter deltas over the time between them). run_watch is the
// loop around it: it polls through a control_fn, sleeps, and writes frames.

#include <chrono>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "apps/hermctl/format.hpp"
#include "routing/module_id.hpp"

namespace hermctl {

/// Rows a frame shows per section at most; the rest is counted
/// ("... 12 more"). Also bounds what snapshots keep.
constexpr size_t max_watch_rows = 256;

/// One channel of the watched module.
struct watch_channel {
  uint64_t id = 0;
  std::string device;
  std::string kind;
  /// "up", "retrying", "closed", or "down" for a channel that was listed
  /// before and is gone now (carry_gone).
  std::string state;
  /// Whether the counters below are known (the channel is up).
  bool has_stats = false;
  uint64_t tx_bytes = 0;
  uint64_t rx_bytes = 0;
  uint64_t tx_frames = 0;
  uint64_t rx_frames = 0;
  /// tx_dropped + rx_malformed + rx_reassembly_dropped + rx_kernel_dropped
  /// + rx_queue_dropped.
  uint64_t drops = 0;
};

/// The selected class-0 route to one destination.
struct watch_route {
  herm::module_id destination = 0;
  /// nullopt: infinite (a retracted route).
  std::optional<uint64_t> cost;
  uint64_t hops = 0;
  /// The next hop's module id ("0x31"), or "-" when unknown.
  std::string via;

  friend bool operator==(const watch_route& a, const watch_route& b) {
    return a.destination == b.destination && a.cost == b.cost && a.hops == b.hops
           && a.via == b.via;
  }
};

/// One topic of the network, as the watched module's merged list shows it
/// (its "topics" reply with "all": every module that answered).
struct watch_topic {
  std::string topic;
  /// The type of the last value seen ("" if none).
  std::string type;
  /// Each publishing module that answered, with its last sequence number:
  /// the publish rate is their increase, modulo 2^32, over time.
  std::map<std::string, uint32_t> seqs;
  /// Modules publishing it ("0x31"), at most 4 kept; how many in all.
  std::vector<std::string> publishers;
  uint64_t publisher_count = 0;
  /// Modules subscribed to it, at most 4 kept; how many in all.
  std::vector<std::string> subscribers;
  uint64_t subscriber_count = 0;
};

/// What one poll saw.
struct watch_snapshot {
  /// When it was taken, ms on a steady clock: rates divide by differences.
  uint64_t at_ms = 0;
  herm::module_id self = 0;
  std::string name;
  /// By destination; at most max_watch_rows.
  std::vector<watch_route> routes;
  /// By id; at most max_watch_rows.
  std::vector<watch_channel> channels;
  /// Module names known so far (the watched module's own included).
  std::map<herm::module_id, std::string> names;
  /// Requests that failed this time, "routes: TEXT"; their sections show
  /// what the previous snapshot had.
  std::vector<std::string> errors;
  /// From the "topics" command with "all" (every module's, merged), by
  /// name; nullopt when the module does not answer it (an older module):
  /// `topics_note` then says why.
  std::optional<std::vector<watch_topic>> topics;
  std::string topics_note;
  /// How many modules answered for `topics`; those that did not ("0x33").
  uint64_t topic_modules = 0;
  std::vector<std::string> topics_unanswered;
};

/// The selected class-0 routes of a "routes" reply (all or not), by
/// destination. Rows that are not objects or lack a destination are skipped.
std::vector<watch_route> parse_routes(const json& routes);

/// The rows of a "channels" reply, by id.
std::vector<watch_channel> parse_channels(const json& channels);

/// The rows of a "topics" reply with "all" (its "topics" list), by topic;
/// nullopt when it is not a list. Rows of the wrong shape are skipped.
std::optional<std::vector<watch_topic>> parse_topics(const json& topics);

/// Channels in `prev` whose device has no channel in `cur` are added to
/// `cur` with state "down" and no counters (a link taken down stays on the
/// dashboard), up to max_watch_rows channels in all.
void carry_gone(const watch_snapshot& prev, watch_snapshot& cur);

/// How a frame is drawn.
struct frame_style {
  /// Columns a line may use; 0: unlimited.
  size_t width = 0;
  /// With `ansi`: rows of the terminal. A frame longer than height - 1
  /// lines ends with a line that counts the rest. 0: unlimited.
  size_t height = 0;
  /// On a terminal: the frame is drawn over the previous one from the top
  /// left, each line and the rest of the screen erased, and changed routes,
  /// links down or dropping, and errors are in reverse video. Otherwise plain text, no
  /// escape codes, a blank line after each frame.
  bool ansi = false;
  /// Shown in the header: frame number, interval and wall-clock time.
  uint64_t number = 1;
  uint64_t interval_ms = 1000;
  std::string clock;
};

/// One frame: header, modules, links with rates (from `prev`; "-" without
/// one or for a channel not in it), route changes since `prev`, topics
/// with the rate this module publishes each at.
/// O(rows log rows).
std::string render_frame(const watch_snapshot* prev, const watch_snapshot& cur,
                         const frame_style& style);

/// "0 B/s", "950 B/s", "1.2 kB/s", "12 MB/s" (powers of 1000).
std::string byte_rate_text(double bytes_per_s);

/// What a control request gave.
struct watch_reply {
  bool ok = false;
  json result;
  /// The error, one line, when not ok.
  std::string error;
};

/// Sends `request` to module `at` (herm::no_module: the local one). Returns
/// the result or the module's error; throws (any exception, which ends the
/// watch) when there is no module to talk to.
using control_fn = std::function<watch_reply(json request, herm::module_id at)>;

struct watch_options {
  /// The module watched (herm::no_module: the local one).
  herm::module_id module = herm::no_module;
  std::chrono::milliseconds interval{1000};
  /// Frames to draw; 0: until killed.
  uint64_t count = 0;
  bool ansi = false;
  /// Used when the terminal's width is unknown; 0: unlimited.
  size_t width = 0;
};

/// Polls and draws frames to `out` until `count` are drawn. A request that
/// fails shows in the frame; a missing module ends the watch with the
/// control_fn's exception. On a terminal the width is read before every
/// frame. Each frame polls "echo", "routes", "channels", "topics" and
/// "echo" of at most 8 modules whose name is not known yet (one that did
/// not answer is asked again 5 frames later).
void run_watch(const control_fn& call, const watch_options& o, std::ostream& out);

} // namespace hermctl
