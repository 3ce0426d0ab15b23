/* hermc_can.h: the CAN option of the HERM C client (hermc).
 *
 * For boards with a CAN 2.0 controller: HERM frames travel as classic data
 * frames (0..8 bytes) whose identifier carries priority, destination and
 * source node (docs/protocol.md, "CAN identifier layout": 29-bit extended
 * identifiers, or the 11-bit option). The data bytes are frames of the
 * fragment layer of hermc_link.h at MTU 8, reassembled per (source, lane).
 * CAN FD is not supported: received FD frames must not be fed (the
 * application's driver drops them, as a HERM node with fd=false does).
 *
 * Same model as hermc_link.h: no I/O, no clock, no heap, the application
 * owns the struct; it feeds each received frame, pops frames to hand to its
 * controller, and ticks. Bad frames are dropped and counted.
 */
#ifndef HERMC_CAN_H
#define HERMC_CAN_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "hermc_config.h"
#include "hermc_link.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Destination "every node", in this API for both identifier formats (the
 *  11-bit identifier carries it as 0xF). */
#define HERMC_CAN_BROADCAST 0xFFu

/** Identifier formats. */
#define HERMC_CAN_29BIT 0   /* extended identifiers with protocol tag 0x25 */
#define HERMC_CAN_11BIT 1   /* standard identifiers, nodes 1..14 */

/** Largest priority; larger values travel as 7. 0 is the most urgent. */
#define HERMC_CAN_MAX_PRIORITY 7u

/** HERM's protocol tag, bits 9..4 of a 29-bit identifier. */
#define HERMC_CAN_TAG 0x25u

/** Largest node id of format `fmt`: 254 (29-bit) or 14 (11-bit). */
uint8_t hermc_can_max_node(uint8_t fmt);

/** One classic CAN data frame as the application's controller sees it. */
typedef struct hermc_can_frame {
  uint32_t id;       /* 29 or 11 identifier bits, no flags */
  uint8_t extended;  /* 1: 29-bit (IDE set), 0: 11-bit */
  uint8_t rtr;       /* 1: remote frame (never sent; received ones dropped) */
  uint8_t dlc;       /* data bytes, 0..8 */
  uint8_t data[8];
} hermc_can_frame;

/** The fields of a HERM identifier. */
typedef struct hermc_can_fields {
  uint8_t priority;  /* 0..7 */
  uint8_t dst;       /* node or HERMC_CAN_BROADCAST */
  uint8_t src;       /* node */
} hermc_can_fields;

/** Verdicts on a received identifier (the names of can::id_status). */
#define HERMC_CAN_ID_OK 0
#define HERMC_CAN_ID_REMOTE_FRAME 1    /* RTR */
#define HERMC_CAN_ID_STANDARD_ID 2     /* 11-bit id where 29-bit ids are used */
#define HERMC_CAN_ID_EXTENDED_ID 3     /* 29-bit id where 11-bit ids are used */
#define HERMC_CAN_ID_FOREIGN 4         /* protocol tag is not 0x25 */
#define HERMC_CAN_ID_BAD_SOURCE 5      /* source 0, broadcast or above max */
#define HERMC_CAN_ID_BAD_DESTINATION 6 /* destination 0 or above max */
#define HERMC_CAN_ID_BAD_LENGTH 7      /* dlc above 8 */
#define HERMC_CAN_ID_BAD_PADDING 8     /* padding bits set in a classic frame */
#define HERMC_CAN_ID_STATUSES 9

/** The identifier (no flags) for `x` in format `fmt`: a priority above 7
 *  travels as 7; dst HERMC_CAN_BROADCAST becomes the format's broadcast
 *  field. @pre src and dst (unless broadcast) are 1..hermc_can_max_node. */
uint32_t hermc_can_encode_id(uint8_t fmt, const hermc_can_fields* x);

/** Checks a received frame's identifier, flags and length for format `fmt`
 *  and fills `out` (dst broadcast as HERMC_CAN_BROADCAST) on
 *  HERMC_CAN_ID_OK; returns the verdict otherwise. Pure. */
int hermc_can_decode_frame(uint8_t fmt, const hermc_can_frame* f,
                           hermc_can_fields* out);

/** The lane of a frame: 2 * min(priority, 7), plus 1 for a broadcast. */
uint8_t hermc_can_lane(uint8_t priority, uint8_t dst);

/** Counters of a CAN node (the fragment layer's are in can->reasm.stats). */
typedef struct hermc_can_stats {
  hermc_count_t rx_frames;      /* frames taken (for this node or broadcast) */
  hermc_count_t rx_filtered;    /* valid HERM frames for other nodes */
  hermc_count_t rx_malformed;   /* frames refused: bad identifier (one counter
                              per verdict in rx_by_status) or own source */
  hermc_count_t rx_by_status[HERMC_CAN_ID_STATUSES];
  hermc_count_t tx_frames;      /* frames popped */
  hermc_count_t tx_packets;     /* packets accepted */
  hermc_count_t tx_refused;     /* packets refused */
  hermc_count_t tag_evictions;  /* tag sequences forgotten (HERMC_CAN_TX_SEQS) */
} hermc_can_stats;

/** A node on one CAN bus. */
typedef struct hermc_can {
  hermc_reasm reasm;
  hermc_reasm_slot slots[HERMC_CAN_RX_SLOTS];
  hermc_can_stats stats;
  hermc_frag frag;         /* the packet being sent */
  uint32_t tx_id;          /* its identifier */
  uint8_t fmt, node;
  uint8_t tx_busy;         /* 1 while frames of tx_pkt remain */
  uint8_t seq_used;        /* entries of seqs in use, most recent first */
  struct {
    uint8_t dst, lane, tag;
  } seqs[HERMC_CAN_TX_SEQS];
  uint8_t tx_pkt[HERMC_MAX_PACKET];
} hermc_can;

/** Resets `can` for node id `node` (1..hermc_can_max_node(fmt)) in format
 *  `fmt`. Returns HERMC_ERR_ARG (and leaves `can` unusable) when out of
 *  range. */
int hermc_can_init(hermc_can* can, uint8_t fmt, uint8_t node);

/** Takes one received frame. Frames for other nodes are counted
 *  (rx_filtered) and ignored; invalid ones are counted (rx_malformed);
 *  frames from this node's own id are malformed. The rest go to the
 *  reassembler in the frame's (source, lane); `on_packet` (may be NULL) gets
 *  each complete packet with the source node id. O(dlc), O(packet) on
 *  completion. */
void hermc_can_rx_frame(hermc_can* can, const hermc_can_frame* f,
                        hermc_packet_fn on_packet, void* ctx);

/** Queues one packet to node `dst` (or HERMC_CAN_BROADCAST) at `priority`
 *  (0..7; above travels as 7): copies it into the node's packet buffer and
 *  takes the next tag of (dst, lane). One packet at a time: HERMC_ERR_FULL
 *  while the previous one still has frames to pop; HERMC_ERR_TOO_BIG above
 *  HERMC_MAX_PACKET; HERMC_ERR_ARG for a bad destination. O(len). */
int hermc_can_tx_packet(hermc_can* can, uint8_t dst, uint8_t priority,
                        const uint8_t* pkt, size_t len);

/** Writes the next frame to send into `out` and returns true, or returns
 *  false when nothing is queued. Frames of one packet come in order with
 *  one identifier; hand them to the controller in that order (one mailbox
 *  or a FIFO). */
bool hermc_can_tx_pop(hermc_can* can, hermc_can_frame* out);

/** The reassembly clock: see hermc_reasm_tick. */
void hermc_can_tick(hermc_can* can, uint32_t now_ms);

#ifdef __cplusplus
}
#endif

#endif /* HERMC_CAN_H */
