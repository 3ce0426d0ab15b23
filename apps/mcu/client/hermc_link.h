/* hermc_link.h: the link layer of the HERM C client (hermc).
 *
 * What a board on a serial line (RS232C, USB CDC-ACM) needs below the
 * network packets, exactly as docs/protocol.md specifies it:
 *   - "Serial framing": every frame is protected by a CRC-16/CCITT-FALSE,
 *     COBS-encoded and ended by a 0x00 delimiter (optionally escaped for
 *     XON/XOFF lines);
 *   - "Fragment header": a packet travels as one single frame or as a first
 *     frame and consecutive frames with a CRC-32 over the packet; the
 *     receiver reassembles it in a bounded slot.
 * hermc_can.h reuses the fragment layer (hermc_frag, hermc_reasm) at MTU 8.
 *
 * Model (as libcanard): the library does no I/O and reads no clock. The
 * application owns every object (static or on its stack), feeds received
 * bytes in, pops bytes to send out, and calls a tick with a millisecond
 * clock. Nothing allocates; every buffer is a fixed array sized by
 * hermc_config.h. Bad input of any kind is dropped and counted in the
 * object's counters, never undefined behaviour. No function blocks, none
 * recurses, none is reentrant for one object: one object is used from one
 * context (main loop, or an ISR with interrupts of that object masked).
 * Time is O(bytes handled) per call unless stated.
 *
 * Simplification against HERM's C++ reassembler (channels/reassembler.hpp),
 * allowed because both links this client serves keep frame order (a serial
 * line; one sender's lane on CAN): consecutive frames are placed in order
 * only, nothing is stashed. A frame that shows a gap (a frame was lost) drops
 * its packet at once (counter `lost`) instead of waiting for the timeout; a
 * copy of an already placed frame is a duplicate. Late copies of a completed
 * packet's first frame start a reassembly that times out or is superseded;
 * they are never delivered (the CRC-32 and the length stand in the way).
 */
#ifndef HERMC_LINK_H
#define HERMC_LINK_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "hermc_config.h"

#ifdef __cplusplus
extern "C" {
#endif

/* -- results -------------------------------------------------------------------- */

#define HERMC_OK 0
/** Not enough room now (transmit ring full, previous packet still sending):
 *  try again after draining; nothing was queued. */
#define HERMC_ERR_FULL (-1)
/** Can never fit (larger than the ring or the packet buffer, or than the
 *  fragment header can announce); nothing was queued. */
#define HERMC_ERR_TOO_BIG (-2)
/** An argument out of its documented range (node id, destination). */
#define HERMC_ERR_ARG (-3)

/** Receives one complete packet. `pkt` points into the receiver's own
 *  buffer and is valid only during the call (copy what you keep); `src` is
 *  the link address of the sender: 1 (the peer) on a serial line, the node
 *  id on CAN. The callback must not feed the same receiver again. */
typedef void (*hermc_packet_fn)(void* ctx, uint8_t src, const uint8_t* pkt,
                                size_t len);

/* -- checksums and codecs (pure functions) ---------------------------------------- */

#define HERMC_CRC16_INIT 0xFFFFu

/** CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, not reflected, no final
 *  XOR; "123456789" gives 0x29B1), continued from `crc` (start with
 *  HERMC_CRC16_INIT). Bitwise: no table in flash. */
uint16_t hermc_crc16(uint16_t crc, const uint8_t* data, size_t n);

#define HERMC_CRC32_INIT 0xFFFFFFFFul

/** CRC-32/ISO-HDLC (zlib's crc32; "123456789" gives 0xCBF43926) of
 *  `data[0..n)`. For a running CRC: state = hermc_crc32_update(
 *  HERMC_CRC32_INIT, ...), ..., result = state ^ 0xFFFFFFFF. 16-entry
 *  nibble table (64 bytes of flash). */
uint32_t hermc_crc32_update(uint32_t state, const uint8_t* data, size_t n);
uint32_t hermc_crc32(const uint8_t* data, size_t n);

/** Largest COBS encoding of n bytes. */
#define HERMC_COBS_MAX(n) ((n) + (n) / 254u + 1u)

/** COBS-encodes `in[0..n)` (canonical form, docs/protocol.md "COBS") into
 *  `out`, which holds HERMC_COBS_MAX(n) bytes and does not overlap `in`.
 *  Returns the encoded size; the output contains no 0x00. */
size_t hermc_cobs_encode(const uint8_t* in, size_t n, uint8_t* out);

/** Bytes of the minimal unsigned LEB128 form of `v` (1..5). */
size_t hermc_leb128_size(uint32_t v);

/* -- fragmenter (sender rules) -------------------------------------------------------- */

/** Largest packet the fragment header can announce (3-byte LEB128). */
#define HERMC_MAX_ANNOUNCED 2097151ul

/** Cuts one packet into frames of at most `mtu` bytes (docs/protocol.md,
 *  "Fragment header", sender rules: single frame when len + 1 <= mtu, else
 *  first + consecutive frames with the CRC-32 trailer, wide sequence numbers
 *  from MTU 64). Does not copy the packet: it reads `pkt` until the last
 *  frame was produced, so the caller keeps it unchanged until then. */
typedef struct hermc_frag {
  const uint8_t* pkt;
  size_t len;        /* packet bytes */
  size_t off;        /* next stream byte to send (stream = packet || CRC) */
  uint32_t crc;      /* CRC-32 of the packet, appended little endian */
  uint16_t mtu;
  uint16_t index;    /* next frame index */
  uint8_t tag;       /* 0..3 */
  uint8_t done;      /* 1 once the last frame was produced */
} hermc_frag;

/** Starts cutting `pkt[0..len)` with packet tag `tag` (0..3; the caller
 *  advances its tag by one, mod 4, per packet: hermc_link_tx and hermc_can
 *  do). Returns HERMC_ERR_TOO_BIG (and produces no frame) when len >
 *  HERMC_MAX_ANNOUNCED, or where size_t is 16 bits (AVR) when len >
 *  SIZE_MAX - 4 (the stream, packet and CRC-32, is counted in size_t);
 *  HERMC_ERR_ARG when mtu < 8. O(len) for the CRC. */
int hermc_frag_begin(hermc_frag* f, const uint8_t* pkt, size_t len,
                     uint16_t mtu, uint8_t tag);

/** Writes the next frame into `out` (at least `mtu` bytes) and returns its
 *  size (1..mtu), or 0 when every frame was produced. O(frame size). */
size_t hermc_frag_next(hermc_frag* f, uint8_t* out);

/** Frames a packet of `len` bytes takes at `mtu` (protocol.md, sender rule
 *  4); 0 above HERMC_MAX_ANNOUNCED. */
uint32_t hermc_frag_count(size_t len, uint16_t mtu);

/* -- reassembler (receiver rules) ------------------------------------------------------ */

/** Counters of a reassembler; each dropped frame or packet counts once,
 *  under the names of docs/protocol.md's receiver rules (plus `lost`). */
typedef struct hermc_reasm_stats {
  hermc_count_t packets;      /* packets delivered */
  hermc_count_t malformed;    /* frames that did not decode (reserved bits, bad
                            length field, announced length or single payload
                            above HERMC_MAX_PACKET, wrong width, no stream
                            byte, more than n + 4 stream bytes) */
  hermc_count_t duplicates;   /* copies of a frame already placed */
  hermc_count_t orphans;      /* consecutive frames that belong to no packet under
                            way (first frame missed, tag or size mismatch) */
  hermc_count_t timed_out;    /* incomplete packets older than the timeout */
  hermc_count_t over_limit;   /* packets refused or evicted for want of a slot */
  hermc_count_t bad_checksum; /* packets whose CRC-32 did not match */
  hermc_count_t superseded;   /* incomplete packets replaced by a new first frame
                            in their (source, lane) */
  hermc_count_t lost;         /* incomplete packets dropped at once because a
                            frame was missing (a gap on an in-order link) */
} hermc_reasm_stats;

/** One reassembly under way. Storage only: the application declares arrays
 *  of them through hermc_link_rx / hermc_can, or hands its own array to
 *  hermc_reasm_init. */
typedef struct hermc_reasm_slot {
  uint32_t started_ms;   /* tick time of its first frame */
  uint16_t length;       /* announced packet length n */
  uint16_t have;         /* stream bytes placed */
  uint16_t first_data;   /* stream bytes of the first frame */
  uint16_t chunk;        /* stream bytes of every full consecutive frame */
  uint16_t next;         /* next frame index expected */
  uint8_t used, src, lane, tag, wide;
  uint8_t stream[HERMC_MAX_PACKET + 4];
} hermc_reasm_slot;

typedef struct hermc_reasm {
  hermc_reasm_slot* slots;
  uint8_t nslots;
  uint32_t now_ms;       /* latest tick */
  hermc_reasm_stats stats;
} hermc_reasm;

/** Resets `r` to use `slots[0..nslots)` (owned by the caller, outliving
 *  `r`), all free, counters zero, time 0. */
void hermc_reasm_init(hermc_reasm* r, hermc_reasm_slot* slots, uint8_t nslots);

#define HERMC_REASM_DROPPED 0  /* the frame was dropped and counted */
#define HERMC_REASM_PENDING 1  /* accepted, its packet is not complete yet */
#define HERMC_REASM_COMPLETE 2 /* a packet was delivered to `on_packet` */

/** Feeds one frame `frame[0..n)` from link address `src` in `lane` (0 on a
 *  serial line; hermc_can_lane on CAN). Single frames are delivered from
 *  `frame` itself; reassembled packets from the slot. Never reads past n,
 *  never writes past a slot. O(n) plus O(nslots); O(packet) on completion
 *  for the CRC. `on_packet` may be NULL (packets are then only counted). */
int hermc_reasm_push(hermc_reasm* r, uint8_t src, uint8_t lane,
                     const uint8_t* frame, size_t n, hermc_packet_fn on_packet,
                     void* ctx);

/** Advances the clock to `now_ms` (wrapping millisecond counter; it must
 *  be called at least every 2^31 ms) and drops incomplete packets older
 *  than HERMC_REASSEMBLY_TIMEOUT_MS (timed_out). O(nslots). */
void hermc_reasm_tick(hermc_reasm* r, uint32_t now_ms);

/** Incomplete packets held now. */
uint8_t hermc_reasm_pending(const hermc_reasm* r);

/* -- serial link: receiving ---------------------------------------------------------- */

/** Counters of the serial frame decoder; every run of bytes between two
 *  delimiters counts once: as a frame, as idle or under one error
 *  (protocol.md "Serial framing", receiver rules). */
typedef struct hermc_frame_stats {
  hermc_count_t frames;      /* good frames handed to the reassembler */
  hermc_count_t idle;        /* empty runs (delimiter after delimiter) */
  hermc_count_t bad_cobs;    /* not valid COBS */
  hermc_count_t too_short;   /* decoded to fewer than 3 bytes */
  hermc_count_t oversized;   /* more than the MTU allows (counted once per run) */
  hermc_count_t bad_crc;     /* CRC-16 mismatch */
  hermc_count_t bad_escape;  /* escaped mode: 0x7D not followed by 31, 33 or 5D */
} hermc_frame_stats;

/** Largest run of (unescaped) bytes between delimiters that can be valid. */
#define HERMC_RUN_MAX HERMC_COBS_MAX(HERMC_MTU + 2u)

/** Receive state of one serial line: a streaming COBS/CRC-16 decoder
 *  (decodes as bytes arrive into a buffer of HERMC_MTU + 2 bytes), then the
 *  reassembler with HERMC_RX_SLOTS slots. Packets come from src 1, lane 0. */
typedef struct hermc_link_rx {
  hermc_reasm reasm;
  hermc_reasm_slot slots[HERMC_RX_SLOTS];
  hermc_frame_stats frame_stats;
  uint16_t run;          /* unescaped bytes of the current run */
  uint16_t dec;          /* decoded bytes of the current run */
  uint8_t left;          /* data bytes left in the current COBS piece */
  uint8_t code;          /* the current piece's code byte, 0 at run start */
  uint8_t flags;         /* internal: escaped mode, escape pending, skipping */
  uint8_t buf[HERMC_MTU + 2];
} hermc_link_rx;

/** Resets `rx`: no run under way, no packet, counters zero, time 0.
 *  `escaped`: XON/XOFF mode (protocol.md "Escaped mode"); both ends must
 *  agree. Ignored (plain framing) in a build without HERMC_ESCAPED. */
void hermc_link_rx_init(hermc_link_rx* rx, bool escaped);

/** Consumes received bytes `bytes[0..n)` (any chunking, one byte at a time
 *  is fine, e.g. from a UART ISR's ring). Calls `on_packet` (may be NULL)
 *  once per complete packet, in order. Every malformed run or frame is
 *  dropped and counted in rx->frame_stats / rx->reasm.stats; the decoder
 *  resynchronises at the next 0x00. O(n) plus O(packet) per completed
 *  packet (CRC-32). */
void hermc_link_rx_feed(hermc_link_rx* rx, const uint8_t* bytes, size_t n,
                        hermc_packet_fn on_packet, void* ctx);

/** The reassembly clock: see hermc_reasm_tick. */
void hermc_link_rx_tick(hermc_link_rx* rx, uint32_t now_ms);

/* -- serial link: sending ------------------------------------------------------------ */

/** Upper bound of the wire bytes of a packet of `len` bytes at HERMC_MTU,
 *  leading delimiter included, whatever its bytes (for sizing HERMC_TX_RING:
 *  in escaped mode every byte may double). 0 when len >
 *  HERMC_MAX_ANNOUNCED. */
size_t hermc_link_tx_wire_bound(size_t len, bool escaped);

/** Transmit state of one serial line: the packet tag and a ring of
 *  HERMC_TX_RING bytes ready for the UART. */
typedef struct hermc_link_tx {
  uint16_t head;         /* index of the next byte to pop */
  uint16_t count;        /* bytes in the ring */
  uint8_t tag;           /* tag of the next packet */
  uint8_t escaped;
  hermc_count_t packets;      /* packets queued */
  hermc_count_t refused;      /* packets refused (HERMC_ERR_FULL or _TOO_BIG) */
  uint8_t ring[HERMC_TX_RING];
} hermc_link_tx;

/** Resets `tx`: empty ring, tag 0. `escaped` as for hermc_link_rx_init. */
void hermc_link_tx_init(hermc_link_tx* tx, bool escaped);

/** Fragments `pkt[0..len)` at HERMC_MTU, frames each (CRC-16, COBS, escapes)
 *  and appends the wire bytes to the ring; the packet buffer is free again
 *  on return. A leading 0x00 goes first when the ring was empty (the line
 *  idle, as far as the client knows). All or nothing: a first pass counts
 *  the exact wire bytes, then returns HERMC_OK after queueing them, or
 *  HERMC_ERR_FULL when they exceed hermc_link_tx_free (drain and retry),
 *  HERMC_ERR_TOO_BIG when they exceed HERMC_TX_RING even with the ring
 *  empty, or the packet exceeds HERMC_MAX_ANNOUNCED (never fits). Refusals
 *  are counted (`refused`) and do not advance the tag. len 0 sends the
 *  empty packet. O(len), twice (count, then write); stack: about
 *  2 * HERMC_MTU + 30 bytes. */
int hermc_link_tx_packet(hermc_link_tx* tx, const uint8_t* pkt, size_t len);

/** Moves up to `cap` queued wire bytes into `out`, oldest first; returns
 *  how many (0 when nothing is queued). cap 1 suits a UART data-register-
 *  empty interrupt. */
size_t hermc_link_tx_pop(hermc_link_tx* tx, uint8_t* out, size_t cap);

/** Bytes queued for the UART. */
size_t hermc_link_tx_pending(const hermc_link_tx* tx);

/** Bytes free in the ring. */
size_t hermc_link_tx_free(const hermc_link_tx* tx);

#ifdef __cplusplus
}
#endif

#endif /* HERMC_LINK_H */
