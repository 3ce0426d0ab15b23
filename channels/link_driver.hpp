#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "caf/error.hpp"
#include "caf/expected.hpp"

#include "channels/link_profile.hpp"
#include "channels/messages.hpp"

namespace herm {

class event_loop;

/// Lanes: the order a link keeps between one sender's frames. Frames of one
/// sender in one lane arrive in the order they were sent; frames in
/// different lanes may overtake each other. On CAN a lane is what the
/// identifier says about order (priority, and whether the frame is a
/// broadcast): a controller's transmit queue sends the most urgent
/// identifier first, so a control frame overtakes bulk frames queued
/// before it, while frames with one identifier stay in order (as ISO-TP
/// also needs). Links that keep every frame in order use lane 0 only.
/// The fragment layer keeps one tag sequence and one reassembly per
/// (sender, lane), so packets in different lanes never collide
/// (docs/protocol.md, "Fragment header").
constexpr uint8_t max_lanes = 16;

/// One frame of a link_driver::send_batch call: what send() takes, as data.
/// `data` is borrowed for the call only.
struct tx_frame {
  link_addr dst = 0;
  const uint8_t* data = nullptr;
  size_t size = 0;
  uint8_t priority = 0;
};

/// Receives what a driver hears.
///
/// Threading: a driver calls these on the thread of the event loop it was
/// started on (descriptor-based kinds: from its readiness callbacks and
/// timers; docs/architecture.md, "Threads"), or on the thread of the actor
/// that sent the frame (the in-process kind). Implementations must be
/// thread-safe and must not block: under the loop scheduler that thread
/// runs every actor of the module.
class frame_handler {
public:
  virtual ~frame_handler();

  /// One frame of at most MTU bytes from `src`. `data` is valid only during
  /// the call.
  virtual void on_frame(link_addr src, const uint8_t* data, size_t size) = 0;

  /// One frame of at most MTU bytes from `src` that travelled in `lane`
  /// (< max_lanes; see above). Drivers of links with lanes call this one.
  /// Default: on_frame(src, data, size), for handlers that ignore lanes.
  virtual void on_frame_in_lane(link_addr src, uint8_t lane,
                                const uint8_t* data, size_t size);

  /// A frame the driver itself could not accept (oversized, truncated, bad
  /// medium header). It is dropped; the handler counts it.
  virtual void on_malformed(link_addr src, const char* why) = 0;

  /// The kernel dropped `count` frames for this device because its receive
  /// buffer was full (SO_RXQ_OVFL), since the previous call. Default:
  /// nothing, for handlers that do not count them.
  virtual void on_kernel_drops(uint64_t count);

  /// Something else happened on the link (error frame, bus-off, ...).
  virtual void on_event(link_event_kind kind, link_addr peer,
                        std::string detail) = 0;

  /// The device failed for good. Called at most once; no call follows it.
  virtual void on_failure(caf::error reason) = 0;
};

/// The narrow interface between a channel and a physical (or emulated)
/// interface: it moves frames of at most MTU bytes and does nothing else. One
/// driver per device; all channels on that device share it.
///
/// Lifetime: created by a link kind's `open`, then `start`ed once, then
/// `stop`ped once (also from the destructor).
class link_driver {
public:
  virtual ~link_driver();

  /// Starts delivering received frames to `handler`, from callbacks on
  /// `loop` (the module's event loop: channels/event_loop.hpp). The driver
  /// registers its descriptors there and owns no receive thread; `loop`
  /// must outlive the driver's stop().
  virtual caf::error start(std::shared_ptr<frame_handler> handler,
                           event_loop& loop)
    = 0;

  /// start(handler, shared_io_loop()): for driver tests and benchmarks.
  caf::error start(std::shared_ptr<frame_handler> handler);

  /// Stops receiving and joins any thread of the driver. Idempotent. No
  /// handler call happens after it returns.
  virtual void stop() = 0;

  /// Sends one frame of at most `profile().mtu` bytes to `dst`, or to every
  /// peer for `broadcast_addr`. Thread-safe. Never blocks longer than one
  /// system call on a non-blocking descriptor. Errors: ec::packet_too_large,
  /// ec::queue_full, ec::invalid_address, ec::device_failed.
  virtual caf::error send(link_addr dst, const uint8_t* data, size_t size,
                          uint8_t priority)
    = 0;

  /// Sends `frames[0 .. n)` in order, each as send() would, and returns how
  /// many were taken: a prefix of `frames`, which the driver sent (or
  /// queued) exactly as n send() calls that succeeded would have.
  ///
  /// Returns n with `err` cleared when every frame was taken. Otherwise it
  /// stops at the first frame it did not take, returns that frame's index
  /// k (< n) and sets `err` to what send() would have returned for it:
  /// - ec::queue_full: frames[k] and every frame after it were not sent;
  ///   retry them (from frames[k]) when the driver's queue has room again.
  /// - any other error (ec::packet_too_large, ec::invalid_parameter,
  ///   ec::invalid_address, ec::device_failed): frames[k] is refused for
  ///   good; nothing after it was tried. A caller drops frames[k] and calls
  ///   again with frames[k + 1 ..].
  /// So frames before a refused frame leave, the refused one does not, and
  /// the ones after it wait for the next call: the order on the link is the
  /// order of `frames` whatever fails.
  ///
  /// Thread-safety and blocking as send(): any thread; never blocks longer
  /// than one system call per (driver-chosen, bounded) chunk of frames on a
  /// non-blocking descriptor. Counters count each taken frame as send()
  /// does. Default: one send() per frame, stopping as described above;
  /// kinds override it when their medium takes several frames per system
  /// call (udp: one sendmmsg per chunk of unicast frames).
  virtual size_t send_batch(const tx_frame* frames, size_t n, caf::error& err);

  /// The lane (< max_lanes) in which frames sent to `dst` with `priority`
  /// travel: the one receivers see in frame_handler::on_frame_in_lane.
  /// Default: 0, for links that keep every frame in order.
  virtual uint8_t lane(link_addr dst, uint8_t priority) const;

  /// The link's characteristics (bandwidth, MTU, multi-access, cost).
  virtual const link_profile& profile() const = 0;

  /// This station's own address on the link.
  virtual link_addr local_addr() const = 0;

  /// Formats a link address in the kind's notation ("10.0.0.2:47000").
  virtual std::string format_addr(link_addr addr) const = 0;

  /// Parses a link address in the kind's notation; ec::invalid_address with
  /// the offending text on failure.
  virtual caf::expected<link_addr> parse_addr(const std::string& str) const
    = 0;

  /// Changes a link parameter at run time (the paper's "control"). Default:
  /// ec::invalid_parameter naming the key.
  virtual caf::error set_param(const std::string& key,
                               const std::string& value);

  /// Reads a link parameter. Default: "bandwidth", "mtu", "delay_coef" from
  /// the profile, ec::invalid_parameter otherwise.
  virtual caf::expected<std::string> get_param(const std::string& key) const;
};

using link_driver_ptr = std::shared_ptr<link_driver>;

/// A link kind: the factory that opens drivers for devices of that kind (the
/// paper's abstract factory). The library's own kinds live in one file each
/// under channels/drivers/ and are listed by one line in link_kinds.def; a
/// program (or a test) adds kinds of its own with add_link_kind.
struct link_kind {
  /// Name used in device_config::kind, e.g. "udp".
  const char* name;
  /// One line for people.
  const char* description;
  /// Opens the device. Errors name the device and what was wrong.
  caf::expected<link_driver_ptr> (*open)(const device_config& cfg);
  /// Validates the device's interface and options exactly as `open` reads
  /// them, touching no device, file or socket (open runs the same parser
  /// first): none, or the error open would return for them
  /// (ec::invalid_parameter, ec::invalid_address) naming the device and the
  /// option. A configuration loader calls it so that a misspelled option is
  /// a configuration error, not a start-up failure. Null: the kind checks
  /// nothing before open (kinds added by programs may leave it out).
  caf::error (*check)(const device_config& cfg) = nullptr;
};

/// Makes `kind` known to find_link_kind and link_kinds, for devices of a kind
/// the library does not compile in (docs/architecture.md, "Adding a link
/// kind"). The entry is copied; `name` and `description` must outlive the
/// program's use of it (string literals do). Thread-safe; call it before any
/// device of that kind is added (from main, or from a namespace-scope
/// initializer of a file the program links). Errors: ec::invalid_parameter
/// for a null name or open, ec::already_exists when a kind of that name is
/// known (built in or added before); the known kind stays.
caf::error add_link_kind(const link_kind& kind);

/// Returns the link kind with that name, or nullptr. The pointer stays valid
/// for the life of the program. Thread-safe; O(number of kinds).
const link_kind* find_link_kind(const std::string& name);

/// Every known link kind: the compiled-in ones in link_kinds.def order, then
/// the added ones in the order they were added. Thread-safe.
std::vector<const link_kind*> link_kinds();

} // namespace herm
