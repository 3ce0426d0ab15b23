/* hermc_config.h: every compile-time bound of the HERM C client (hermc).
 *
 * Each macro has a default here and can be overridden on the compiler's
 * command line (-DHERMC_MTU=64 ...). The library allocates nothing at run
 * time: every buffer below is an array inside a struct the application
 * owns, sized by these macros. Whatever would exceed a bound is dropped or
 * refused and counted (see the counters of each module's header).
 *
 * RAM per object, with the defaults (AVR, 2-byte size_t):
 *   hermc_link_rx   ~ (HERMC_MTU + 2) + HERMC_RX_SLOTS * (HERMC_MAX_PACKET + 14) + 60
 *   hermc_link_tx   ~ HERMC_TX_RING + 8
 *   hermc_can       ~ HERMC_CAN_RX_SLOTS * (HERMC_MAX_PACKET + 14) + HERMC_MAX_PACKET
 *                     + 4 * HERMC_CAN_TX_SEQS + 80
 */
#ifndef HERMC_CONFIG_H
#define HERMC_CONFIG_H

#include <stdint.h>

/* -- features a board may leave out ------------------------------------------ */

/* Each is 1 (built) by default: the default build is a full leaf module. A
 * board that has no use for a feature sets it to 0 (-DHERMC_TOPICS=0) and
 * saves its flash and RAM; what the feature would have handled is then
 * dropped and counted as described. The sonar firmware's choice is
 * HERM_SRF04_HERMC_DEFINES in apps/mcu/client/CMakeLists.txt, and the host
 * tests run the module specifications against that build too
 * (hermc_module_sonar_test). */

/* Topics: hermc_topic, hermc_publish, advertisements, subscriber leases.
 * 0: those functions do not exist; subscribe and unsubscribe messages are
 * counted in rx_asl_ignored. */
#ifndef HERMC_TOPICS
#define HERMC_TOPICS 1
#endif

/* Escaped (XON/XOFF) serial framing (hermc_config.escaped). 0: plain
 * framing only; hermc_init refuses escaped = 1 (HERMC_ERR_ARG), and
 * hermc_link_rx_init / hermc_link_tx_init ignore their `escaped` argument. */
#ifndef HERMC_ESCAPED
#define HERMC_ESCAPED 1
#endif

/* Serving reliable requests (APO message kind 13, answered or acknowledged).
 * 0: they are counted in rx_asl_ignored and not answered (the requester
 * retries and times out), so a board without it serves plain requests only. */
#ifndef HERMC_RELIABLE
#define HERMC_RELIABLE 1
#endif

/* Authentication (docs/protocol.md, "Authentication"; hermc_auth.h): the
 * module signs what a keyed network must sign and checks every packet it
 * receives, once the application gives it the network's key
 * (hermc_set_key). 0 (default): hermc_set_key does not exist, nothing is
 * signed, data packets with flag A are counted in rx_auth_unsupported; the
 * library is smaller by the SHA-256 and authentication code (docs/mcu.md).
 * With 1 and no key set the module behaves as with 0. RAM: a struct
 * hermc_auth and a struct hermc_auth_out in the module (about 330 bytes on
 * AVR with hermc_auth.h's default bounds). */
#ifndef HERMC_AUTH
#define HERMC_AUTH 0
#endif

/* Width of every counter (module, link, reassembler): 32 bits by default;
 * 16 halves their RAM and their arithmetic on an 8-bit core, and they wrap
 * at 65535 (read them as differences). */
#ifndef HERMC_COUNTER_BITS
#define HERMC_COUNTER_BITS 32
#endif
#if HERMC_COUNTER_BITS == 32
typedef uint32_t hermc_count_t;
#elif HERMC_COUNTER_BITS == 16
typedef uint16_t hermc_count_t;
#else
#error "HERMC_COUNTER_BITS must be 16 or 32"
#endif

/* -- link layer (hermc_link.h) ---------------------------------------------- */

/* Serial link MTU, bytes of one frame (fragment header included) before
 * CRC-16 and COBS. Both ends must agree; HERM's profile `rs232c` uses 32.
 * 8..255 (docs/protocol.md, "Serial framing"). */
#ifndef HERMC_MTU
#define HERMC_MTU 32
#endif

/* Largest packet (network packet, before fragmentation) the client receives,
 * bytes. A first fragment announcing more, or a single frame carrying more,
 * is dropped as malformed before anything is stored. One reassembly slot
 * holds HERMC_MAX_PACKET + 4 bytes (the CRC-32). 1..65000. */
#ifndef HERMC_MAX_PACKET
#define HERMC_MAX_PACKET 160
#endif

/* Concurrent reassemblies on the serial line. A serial line has one sender
 * and one lane, so one slot is enough: frames arrive in order, and a new
 * first frame means the packet under way lost its tail. 1..255. */
#ifndef HERMC_RX_SLOTS
#define HERMC_RX_SLOTS 1
#endif

/* An incomplete packet older than this is dropped (counter timed_out),
 * milliseconds; measured with the application's tick (hermc_*_tick), so the
 * resolution is the tick period. 2000 as HERM's C++ reassembler. */
#ifndef HERMC_REASSEMBLY_TIMEOUT_MS
#define HERMC_REASSEMBLY_TIMEOUT_MS 2000u
#endif

/* Transmit ring of the serial link, bytes on the wire (COBS-encoded frames
 * with delimiters) waiting for the UART. A packet is queued whole or not at
 * all: hermc_link_tx_wire_bound(len) bytes must be free. The default takes
 * one packet of HERMC_MAX_PACKET bytes at MTU 32 (at most 217 bytes).
 * 16..65535. */
#ifndef HERMC_TX_RING
#define HERMC_TX_RING 256
#endif

/* -- CAN option (hermc_can.h) ------------------------------------------------ */

/* Concurrent reassemblies on a CAN bus, one per (source node, lane) under
 * way. When all are busy, a new packet of a sender that has one under way
 * evicts that sender's oldest; another sender's new packet is refused
 * (counter over_limit). 1..255. */
#ifndef HERMC_CAN_RX_SLOTS
#define HERMC_CAN_RX_SLOTS 2
#endif

/* Packet tag sequences the CAN sender keeps, one per (destination, lane) it
 * sends to; beyond that the least recently used one starts over at tag 0
 * (counter tag_evictions), as HERM's C++ fragmenter does past 4096. A leaf
 * node talks to its neighbour and to broadcast: 4 covers two priorities
 * each. 1..255. */
#ifndef HERMC_CAN_TX_SEQS
#define HERMC_CAN_TX_SEQS 4
#endif

/* -- the module (hermc.h): APOs, discovery, requests, topics, floods ------------ */

/* Local APOs (hermc_register_apo). 0..255; 0 builds a module that serves
 * no APO (a board that only sends requests): queries are never answered,
 * every request gets the typed error apo_gone, hermc_register_apo returns
 * HERMC_ERR_NO_ROOM, and the answer and request-serving code is left out. */
#ifndef HERMC_MAX_APOS
#define HERMC_MAX_APOS 4
#endif

/* Remote APOs this module sends requests to (hermc_remote). 1..255. */
#ifndef HERMC_MAX_REMOTES
#define HERMC_MAX_REMOTES 2
#endif

/* Requests awaiting a response (hermc_request with a callback); one more is
 * refused (HERMC_ERR_NO_ROOM, counter requests_refused). 1..255. */
#ifndef HERMC_MAX_PENDING
#define HERMC_MAX_PENDING 4
#endif

/* Topics this module publishes (hermc_topic). 1..255. */
#ifndef HERMC_MAX_TOPICS
#define HERMC_MAX_TOPICS 2
#endif

/* Subscriptions of other modules held, over all topics; a new one past it
 * is refused (counter subscribers_refused) until a lease ends. 1..255. */
#ifndef HERMC_MAX_SUBSCRIBERS
#define HERMC_MAX_SUBSCRIBERS 4
#endif

/* Floods (src, flood_id) remembered to drop their copies; when full, the
 * oldest is replaced (counter flood_evictions when it was still younger
 * than HERMC_FLOOD_MEMORY_MS). 1..255. */
#ifndef HERMC_FLOOD_CACHE
#define HERMC_FLOOD_CACHE 8
#endif

/* How long a flood is remembered, ms (HERM's flood_memory). */
#ifndef HERMC_FLOOD_MEMORY_MS
#define HERMC_FLOOD_MEMORY_MS 30000u
#endif

/* -- code generation ---------------------------------------------------------- */

/* Marks a small static helper that the library keeps out of line. Called
 * from several places, it is otherwise inlined into each of its callers:
 * under avr-gcc 5.4 -Os -flto that cost the sonar firmware about 450 bytes
 * of flash (hermc.c: rediscover, bytes_equal, on_answer; hermc_link.c:
 * rx_restart, tx_put, drop). No effect on behaviour; empty for compilers
 * without GNU attributes. */
#if defined(__GNUC__)
#define HERMC_NOINLINE __attribute__((noinline))
#else
#define HERMC_NOINLINE
#endif

/* -- checks ------------------------------------------------------------------- */

#if HERMC_MTU < 8 || HERMC_MTU > 255
#error "HERMC_MTU must be 8..255 (docs/protocol.md, Serial framing)"
#endif
#if HERMC_MAX_PACKET < 1 || HERMC_MAX_PACKET > 65000
#error "HERMC_MAX_PACKET must be 1..65000"
#endif
#if HERMC_RX_SLOTS < 1 || HERMC_RX_SLOTS > 255
#error "HERMC_RX_SLOTS must be 1..255"
#endif
#if HERMC_CAN_RX_SLOTS < 1 || HERMC_CAN_RX_SLOTS > 255
#error "HERMC_CAN_RX_SLOTS must be 1..255"
#endif
#if HERMC_CAN_TX_SEQS < 1 || HERMC_CAN_TX_SEQS > 255
#error "HERMC_CAN_TX_SEQS must be 1..255"
#endif
#if HERMC_TX_RING < 16 || HERMC_TX_RING > 65535
#error "HERMC_TX_RING must be 16..65535"
#endif

#if HERMC_MAX_APOS < 0 || HERMC_MAX_APOS > 255 || HERMC_MAX_REMOTES < 1 \
  || HERMC_MAX_REMOTES > 255 || HERMC_MAX_PENDING < 1 || HERMC_MAX_PENDING > 255 \
  || HERMC_MAX_TOPICS < 1 || HERMC_MAX_TOPICS > 255 || HERMC_MAX_SUBSCRIBERS < 1 \
  || HERMC_MAX_SUBSCRIBERS > 255 || HERMC_FLOOD_CACHE < 1 || HERMC_FLOOD_CACHE > 255
#error "HERMC_MAX_APOS must be 0..255; _REMOTES, _PENDING, _TOPICS, _SUBSCRIBERS and HERMC_FLOOD_CACHE 1..255"
#endif
#if (HERMC_TOPICS != 0 && HERMC_TOPICS != 1) || (HERMC_ESCAPED != 0 && HERMC_ESCAPED != 1) \
  || (HERMC_RELIABLE != 0 && HERMC_RELIABLE != 1) || (HERMC_AUTH != 0 && HERMC_AUTH != 1)
#error "HERMC_TOPICS, HERMC_ESCAPED, HERMC_RELIABLE and HERMC_AUTH must be 0 or 1"
#endif
#if HERMC_MAX_PACKET < 64
#error "the module needs HERMC_MAX_PACKET of at least 64 (a hello, an update, a discovery answer)"
#endif

#endif /* HERMC_CONFIG_H */
