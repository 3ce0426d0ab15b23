/* hermc_can.c: HERM frames on CAN 2.0 (contracts in hermc_can.h; layout in
 * docs/protocol.md, "CAN identifier layout"). */
#include "hermc_can.h"

#include <string.h>

#define CAN_MTU 8u
#define BCAST_11 0x0Fu

uint8_t hermc_can_max_node(uint8_t fmt) {
  return fmt == HERMC_CAN_11BIT ? 14u : 254u;
}

static uint8_t clamp_priority(uint8_t p) {
  return p < HERMC_CAN_MAX_PRIORITY ? p : (uint8_t)HERMC_CAN_MAX_PRIORITY;
}

uint32_t hermc_can_encode_id(uint8_t fmt, const hermc_can_fields* x) {
  uint32_t prio = clamp_priority(x->priority);
  if (fmt == HERMC_CAN_11BIT) {
    uint32_t dst = x->dst == HERMC_CAN_BROADCAST ? BCAST_11 : (x->dst & 0x0Fu);
    return prio << 8 | dst << 4 | (uint32_t)(x->src & 0x0Fu);
  }
  return prio << 26 | (uint32_t)x->dst << 18 | (uint32_t)x->src << 10
         | (uint32_t)HERMC_CAN_TAG << 4;
}

int hermc_can_decode_frame(uint8_t fmt, const hermc_can_frame* f,
                           hermc_can_fields* out) {
  hermc_can_fields x;
  uint8_t pad = 0;
  uint8_t max = hermc_can_max_node(fmt);
  if (f->rtr)
    return HERMC_CAN_ID_REMOTE_FRAME;
  if (fmt == HERMC_CAN_11BIT) {
    uint32_t id = f->id & 0x7FFu;
    if (f->extended)
      return HERMC_CAN_ID_EXTENDED_ID;
    x.priority = (uint8_t)(id >> 8);
    x.dst = (uint8_t)(id >> 4 & 0x0Fu);
    x.src = (uint8_t)(id & 0x0Fu);
    if (x.dst == BCAST_11)
      x.dst = HERMC_CAN_BROADCAST;
  } else {
    uint32_t id = f->id & 0x1FFFFFFFul;
    if (!f->extended)
      return HERMC_CAN_ID_STANDARD_ID;
    if ((id >> 4 & 0x3Fu) != HERMC_CAN_TAG)
      return HERMC_CAN_ID_FOREIGN;
    x.priority = (uint8_t)(id >> 26);
    x.dst = (uint8_t)(id >> 18);
    x.src = (uint8_t)(id >> 10);
    pad = (uint8_t)(id & 0x0Fu);
  }
  if (x.src < 1 || x.src > max)
    return HERMC_CAN_ID_BAD_SOURCE;
  if (x.dst < 1 || (x.dst > max && x.dst != HERMC_CAN_BROADCAST))
    return HERMC_CAN_ID_BAD_DESTINATION;
  if (f->dlc > CAN_MTU)
    return HERMC_CAN_ID_BAD_LENGTH;
  if (pad != 0)
    return HERMC_CAN_ID_BAD_PADDING;
  *out = x;
  return HERMC_CAN_ID_OK;
}

uint8_t hermc_can_lane(uint8_t priority, uint8_t dst) {
  uint8_t lane = (uint8_t)(clamp_priority(priority) * 2u);
  return dst == HERMC_CAN_BROADCAST ? (uint8_t)(lane + 1u) : lane;
}

int hermc_can_init(hermc_can* can, uint8_t fmt, uint8_t node) {
  if ((fmt != HERMC_CAN_29BIT && fmt != HERMC_CAN_11BIT) || node < 1
      || node > hermc_can_max_node(fmt))
    return HERMC_ERR_ARG;
  hermc_reasm_init(&can->reasm, can->slots, (uint8_t)HERMC_CAN_RX_SLOTS);
  memset(&can->stats, 0, sizeof can->stats);
  can->fmt = fmt;
  can->node = node;
  can->tx_busy = 0;
  can->tx_id = 0;
  can->seq_used = 0;
  return HERMC_OK;
}

void hermc_can_rx_frame(hermc_can* can, const hermc_can_frame* f,
                        hermc_packet_fn on_packet, void* ctx) {
  hermc_can_fields x;
  int st = hermc_can_decode_frame(can->fmt, f, &x);
  if (st != HERMC_CAN_ID_OK) {
    ++can->stats.rx_malformed;
    ++can->stats.rx_by_status[st];
    return;
  }
  if (x.dst != can->node && x.dst != HERMC_CAN_BROADCAST) {
    ++can->stats.rx_filtered;
    return;
  }
  if (x.src == can->node) {
    ++can->stats.rx_malformed;
    return;
  }
  ++can->stats.rx_frames;
  hermc_reasm_push(&can->reasm, x.src, hermc_can_lane(x.priority, x.dst),
                   f->data, f->dlc, on_packet, ctx);
}

/* The next tag of (dst, lane); the table is kept most recent first. */
static uint8_t next_tag(hermc_can* can, uint8_t dst, uint8_t lane) {
  uint8_t i = 0;
  uint8_t tag = 0;
  while (i < can->seq_used
         && !(can->seqs[i].dst == dst && can->seqs[i].lane == lane))
    ++i;
  if (i < can->seq_used) {
    tag = can->seqs[i].tag;
  } else if (can->seq_used < HERMC_CAN_TX_SEQS) {
    i = can->seq_used++;
  } else {
    i = (uint8_t)(HERMC_CAN_TX_SEQS - 1);
    ++can->stats.tag_evictions;
  }
  for (; i > 0; --i)
    can->seqs[i] = can->seqs[i - 1];
  can->seqs[0].dst = dst;
  can->seqs[0].lane = lane;
  can->seqs[0].tag = (uint8_t)((tag + 1u) & 0x03u);
  return tag;
}

int hermc_can_tx_packet(hermc_can* can, uint8_t dst, uint8_t priority,
                        const uint8_t* pkt, size_t len) {
  hermc_can_fields x;
  uint8_t lane;
  if (can->tx_busy) {
    ++can->stats.tx_refused;
    return HERMC_ERR_FULL;
  }
  if (len > HERMC_MAX_PACKET) {
    ++can->stats.tx_refused;
    return HERMC_ERR_TOO_BIG;
  }
  if (dst != HERMC_CAN_BROADCAST
      && (dst < 1 || dst > hermc_can_max_node(can->fmt) || dst == can->node)) {
    ++can->stats.tx_refused;
    return HERMC_ERR_ARG;
  }
  x.priority = clamp_priority(priority);
  x.dst = dst;
  x.src = can->node;
  lane = hermc_can_lane(x.priority, dst);
  if (len > 0)
    memcpy(can->tx_pkt, pkt, len);
  hermc_frag_begin(&can->frag, can->tx_pkt, len, CAN_MTU, next_tag(can, dst, lane));
  can->tx_id = hermc_can_encode_id(can->fmt, &x);
  can->tx_busy = 1;
  ++can->stats.tx_packets;
  return HERMC_OK;
}

bool hermc_can_tx_pop(hermc_can* can, hermc_can_frame* out) {
  size_t n;
  if (!can->tx_busy)
    return false;
  memset(out, 0, sizeof *out);
  n = hermc_frag_next(&can->frag, out->data);
  out->id = can->tx_id;
  out->extended = can->fmt == HERMC_CAN_29BIT ? 1u : 0u;
  out->dlc = (uint8_t)n;
  if (can->frag.done)
    can->tx_busy = 0;
  ++can->stats.tx_frames;
  return true;
}

void hermc_can_tick(hermc_can* can, uint32_t now_ms) {
  hermc_reasm_tick(&can->reasm, now_ms);
}
