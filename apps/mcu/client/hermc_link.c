/* hermc_link.c: serial framing and the fragment layer (contracts in
 * hermc_link.h; wire formats in docs/protocol.md). */
#include "hermc_link.h"

#include <string.h>

/* The CRC-32 nibble table lives in flash on AVR (const data is copied to RAM
 * there otherwise); elsewhere const data already is in flash. */
#if defined(__AVR__)
#include <avr/pgmspace.h>
#define HERMC_ROM PROGMEM
#define HERMC_ROM_U32(p) pgm_read_dword(p)
#else
#define HERMC_ROM
#define HERMC_ROM_U32(p) (*(p))
#endif

/* -- checksums and codecs --------------------------------------------------------- */

uint16_t hermc_crc16(uint16_t crc, const uint8_t* data, size_t n) {
  while (n-- > 0) {
    uint8_t bit;
    crc = (uint16_t)(crc ^ (uint16_t)((uint16_t)*data++ << 8));
    for (bit = 0; bit < 8; ++bit)
      crc = (crc & 0x8000u) != 0 ? (uint16_t)((uint16_t)(crc << 1) ^ 0x1021u)
                                 : (uint16_t)(crc << 1);
  }
  return crc;
}

static const uint32_t crc32_nibbles[16] HERMC_ROM = {
  0x00000000ul, 0x1DB71064ul, 0x3B6E20C8ul, 0x26D930ACul,
  0x76DC4190ul, 0x6B6B51F4ul, 0x4DB26158ul, 0x5005713Cul,
  0xEDB88320ul, 0xF00F9344ul, 0xD6D6A3E8ul, 0xCB61B38Cul,
  0x9B64C2B0ul, 0x86D3D2D4ul, 0xA00AE278ul, 0xBDBDF21Cul,
};

uint32_t hermc_crc32_update(uint32_t state, const uint8_t* data, size_t n) {
  while (n-- > 0) {
    uint8_t b = *data++;
    state = HERMC_ROM_U32(&crc32_nibbles[(state ^ b) & 0x0Fu]) ^ (state >> 4);
    state = HERMC_ROM_U32(&crc32_nibbles[(state ^ (uint32_t)(b >> 4)) & 0x0Fu])
            ^ (state >> 4);
  }
  return state;
}

uint32_t hermc_crc32(const uint8_t* data, size_t n) {
  return hermc_crc32_update(HERMC_CRC32_INIT, data, n) ^ 0xFFFFFFFFul;
}

size_t hermc_cobs_encode(const uint8_t* in, size_t n, uint8_t* out) {
  size_t code_pos = 0;
  size_t pos = 1;
  uint8_t code = 1;
  size_t i;
  for (i = 0; i < n; ++i) {
    if (in[i] != 0) {
      out[pos++] = in[i];
      ++code;
    }
    if (in[i] == 0 || code == 0xFF) {
      out[code_pos] = code;
      code = 1;
      code_pos = pos;
      /* A full piece at the very end of the input needs no empty piece. */
      if (in[i] == 0 || i + 1 < n)
        ++pos;
    }
  }
  if (code_pos < pos)
    out[code_pos] = code;
  return pos;
}

size_t hermc_leb128_size(uint32_t v) {
  size_t k = 1;
  while (v >= 0x80u) {
    v >>= 7;
    ++k;
  }
  return k;
}

/* -- fragmenter -------------------------------------------------------------------- */

#define FRAG_CRC 4u
#define WIDE_MTU 64u

int hermc_frag_begin(hermc_frag* f, const uint8_t* pkt, size_t len,
                     uint16_t mtu, uint8_t tag) {
  if (mtu < 8)
    return HERMC_ERR_ARG;
#if SIZE_MAX > 2097151u /* a 16-bit size_t cannot exceed the bound */
  if (len > HERMC_MAX_ANNOUNCED)
    return HERMC_ERR_TOO_BIG;
#else /* but its stream (packet and CRC-32) must stay countable */
  if (len > SIZE_MAX - FRAG_CRC)
    return HERMC_ERR_TOO_BIG;
#endif
  f->pkt = pkt;
  f->len = len;
  f->off = 0;
  f->mtu = mtu;
  f->index = 0;
  f->tag = (uint8_t)(tag & 0x03u);
  f->done = 0;
  f->crc = len + 1u <= mtu ? 0u : hermc_crc32(pkt, len);
  return HERMC_OK;
}

/* Lengths and offsets are size_t throughout (16 bits on an 8-bit core):
 * the only 32-bit value is the CRC. */
size_t hermc_frag_next(hermc_frag* f, uint8_t* out) {
  size_t total = f->len + FRAG_CRC;
  size_t take;
  size_t pos = 1;
  uint8_t head = (uint8_t)(f->tag << 4);
  if (f->done)
    return 0;
  if (f->len + 1u <= f->mtu) {
    out[0] = head;
    if (f->len > 0)
      memcpy(out + 1, f->pkt, f->len);
    f->done = 1;
    return f->len + 1u;
  }
  if (f->index == 0) {
    size_t v = f->len;
    out[0] = (uint8_t)(0x40u | head | (f->mtu >= WIDE_MTU ? 0x08u : 0u));
    do {
      uint8_t b = (uint8_t)(v & 0x7Fu);
      v >>= 7;
      out[pos++] = (uint8_t)(v != 0 ? b | 0x80u : b);
    } while (v != 0);
  } else if (f->mtu >= WIDE_MTU) {
    out[0] = (uint8_t)(0xC0u | head | (uint8_t)(f->index >> 8 & 0x0Fu));
    out[pos++] = (uint8_t)(f->index & 0xFFu);
  } else {
    out[0] = (uint8_t)(0x80u | head | (uint8_t)(f->index & 0x0Fu));
  }
  take = f->mtu - pos;
  if (total - f->off < take)
    take = total - f->off;
  /* Packet bytes, then the CRC-32 little endian. */
  while (take-- > 0) {
    size_t at = f->off++;
    out[pos++] = at < f->len ? f->pkt[at]
                             : (uint8_t)(f->crc >> (8u * (uint8_t)(at - f->len)));
  }
  ++f->index;
  if (f->off == total)
    f->done = 1;
  return pos;
}

uint32_t hermc_frag_count(size_t len, uint16_t mtu) {
  uint32_t n = (uint32_t)len;
  uint32_t first;
  uint32_t chunk;
  if (mtu < 8 || n > HERMC_MAX_ANNOUNCED)
    return 0;
  if (n + 1u <= mtu)
    return 1;
  first = (uint32_t)mtu - 1u - (uint32_t)hermc_leb128_size(n);
  chunk = (uint32_t)mtu - (mtu >= WIDE_MTU ? 2u : 1u);
  return 1u + (n + FRAG_CRC - first + chunk - 1u) / chunk;
}

/* -- reassembler -------------------------------------------------------------------- */

void hermc_reasm_init(hermc_reasm* r, hermc_reasm_slot* slots, uint8_t nslots) {
  uint8_t i;
  r->slots = slots;
  r->nslots = nslots;
  r->now_ms = 0;
  memset(&r->stats, 0, sizeof r->stats);
  for (i = 0; i < nslots; ++i)
    slots[i].used = 0;
}

static hermc_reasm_slot* find_slot(hermc_reasm* r, uint8_t src, uint8_t lane) {
  uint8_t i;
  for (i = 0; i < r->nslots; ++i) {
    hermc_reasm_slot* s = &r->slots[i];
    if (s->used && s->src == src && s->lane == lane)
      return s;
  }
  return NULL;
}

/* A slot for a new packet of `src`: a free one, else the oldest of the same
 * sender's (evicted, over_limit), else none. */
static hermc_reasm_slot* take_slot(hermc_reasm* r, uint8_t src) {
  hermc_reasm_slot* oldest = NULL;
  uint8_t i;
  for (i = 0; i < r->nslots; ++i) {
    hermc_reasm_slot* s = &r->slots[i];
    if (!s->used)
      return s;
    if (s->src == src
        && (oldest == NULL
            || (uint32_t)(r->now_ms - s->started_ms)
                 > (uint32_t)(r->now_ms - oldest->started_ms)))
      oldest = s;
  }
  if (oldest != NULL) {
    ++r->stats.over_limit;
    oldest->used = 0;
  }
  return oldest;
}

static int complete(hermc_reasm* r, hermc_reasm_slot* s,
                    hermc_packet_fn on_packet, void* ctx) {
  const uint8_t* t = s->stream + s->length;
  uint32_t want = (uint32_t)t[0] | (uint32_t)t[1] << 8 | (uint32_t)t[2] << 16
                  | (uint32_t)t[3] << 24;
  s->used = 0;
  if (hermc_crc32(s->stream, s->length) != want) {
    ++r->stats.bad_checksum;
    return HERMC_REASM_DROPPED;
  }
  ++r->stats.packets;
  if (on_packet != NULL)
    on_packet(ctx, s->src, s->stream, s->length);
  return HERMC_REASM_COMPLETE;
}

HERMC_NOINLINE
static int drop(hermc_count_t* counter) {
  ++*counter;
  return HERMC_REASM_DROPPED;
}

/* Lengths, offsets and frame indices are 16-bit (HERMC_MAX_PACKET <= 65000,
 * so a stream is at most 65004 bytes): cheap on an 8-bit core. */
static int push_first(hermc_reasm* r, uint8_t src, uint8_t lane,
                      const uint8_t* frame, size_t n, hermc_packet_fn on_packet,
                      void* ctx) {
  uint8_t tag = (uint8_t)(frame[0] >> 4 & 0x03u);
  uint8_t wide = (frame[0] & 0x08u) != 0;
  uint16_t length = 0;
  uint8_t pos = 1;
  uint8_t shift = 0;
  uint16_t data;
  hermc_reasm_slot* s;
  for (;;) {
    uint8_t b;
    if (pos >= n || pos > 3)
      return drop(&r->stats.malformed);
    b = frame[pos++];
    /* A third length byte above HERMC_MAX_PACKET >> 14 announces more than
     * HERMC_MAX_PACKET (and would not fit 16 bits). */
    if (shift == 14u && b > (uint8_t)(HERMC_MAX_PACKET >> 14))
      return drop(&r->stats.malformed);
    length = (uint16_t)(length | (uint16_t)((uint16_t)(b & 0x7Fu) << shift));
    shift = (uint8_t)(shift + 7u);
    if ((b & 0x80u) == 0)
      break;
  }
  data = (uint16_t)(n - pos);
  if (length > HERMC_MAX_PACKET || data == 0 || data > length + FRAG_CRC)
    return drop(&r->stats.malformed);
  s = find_slot(r, src, lane);
  if (s != NULL) {
    if (s->tag == tag && s->wide == wide && s->length == length
        && s->first_data == data && memcmp(s->stream, frame + pos, data) == 0)
      return drop(&r->stats.duplicates);
    ++r->stats.superseded;
  } else {
    s = take_slot(r, src);
    if (s == NULL)
      return drop(&r->stats.over_limit);
  }
  s->used = 1;
  s->src = src;
  s->lane = lane;
  s->tag = tag;
  s->wide = wide;
  s->started_ms = r->now_ms;
  s->length = length;
  s->first_data = data;
  s->have = data;
  s->chunk = (uint16_t)(n - (wide ? 2u : 1u));
  s->next = 1;
  memcpy(s->stream, frame + pos, data);
  if (data == length + FRAG_CRC)
    return complete(r, s, on_packet, ctx);
  return HERMC_REASM_PENDING;
}

static int push_consecutive(hermc_reasm* r, uint8_t src, uint8_t lane,
                            const uint8_t* frame, size_t n,
                            hermc_packet_fn on_packet, void* ctx) {
  uint8_t tag = (uint8_t)(frame[0] >> 4 & 0x03u);
  uint8_t wide = (frame[0] & 0x40u) != 0;
  uint8_t h = wide ? 2u : 1u;
  uint16_t modulus = wide ? 4096u : 16u;
  uint16_t seq;
  uint16_t left;
  uint16_t d;
  uint16_t data;
  hermc_reasm_slot* s;
  if (n <= h)
    return drop(&r->stats.malformed);
  seq = wide ? (uint16_t)((uint16_t)(frame[0] & 0x0Fu) << 8 | frame[1])
             : (uint16_t)(frame[0] & 0x0Fu);
  data = (uint16_t)(n - h);
  s = find_slot(r, src, lane);
  if (s == NULL || s->tag != tag)
    return drop(&r->stats.orphans);
  if (s->wide != wide)
    return drop(&r->stats.malformed);
  /* While a packet is under way, have = first_data + (next - 1) * chunk. */
  left = (uint16_t)(s->length + FRAG_CRC - s->have);
  d = (uint16_t)((uint16_t)(seq - s->next) & (modulus - 1u));
  if (d == 0) {
    if (data != (left < s->chunk ? left : s->chunk))
      return drop(&r->stats.orphans);
    memcpy(s->stream + s->have, frame + h, data);
    s->have = (uint16_t)(s->have + data);
    ++s->next;
    if (data == left)
      return complete(r, s, on_packet, ctx);
    return HERMC_REASM_PENDING;
  }
  /* Index next + d - modulus, when at least 1, already holds a frame: equal
   * bytes make this a late copy of it (its stream bytes start at
   * first_data + (next + d - modulus - 1) * chunk, below have). */
  if (s->next > modulus - d) {
    uint16_t off = (uint16_t)(s->first_data
                              + (uint16_t)(s->next - 1u - (modulus - d)) * s->chunk);
    if (data == s->chunk && memcmp(s->stream + off, frame + h, data) == 0)
      return drop(&r->stats.duplicates);
  }
  /* Index next + d lies past the packet's end (its bytes would start at
   * have + d * chunk): not this packet's frame. */
  if ((uint32_t)d * s->chunk >= left)
    return drop(&r->stats.orphans);
  /* A frame of this packet was skipped: on an in-order link it is lost. */
  s->used = 0;
  ++r->stats.lost;
  return drop(&r->stats.orphans);
}

int hermc_reasm_push(hermc_reasm* r, uint8_t src, uint8_t lane,
                     const uint8_t* frame, size_t n, hermc_packet_fn on_packet,
                     void* ctx) {
  uint8_t hdr;
  if (n == 0)
    return drop(&r->stats.malformed);
  hdr = frame[0];
  switch (hdr >> 6) {
    case 0:
      if ((hdr & 0x0Fu) != 0 || n - 1u > HERMC_MAX_PACKET)
        return drop(&r->stats.malformed);
      ++r->stats.packets;
      if (on_packet != NULL)
        on_packet(ctx, src, frame + 1, n - 1u);
      return HERMC_REASM_COMPLETE;
    case 1:
      if ((hdr & 0x07u) != 0)
        return drop(&r->stats.malformed);
      return push_first(r, src, lane, frame, n, on_packet, ctx);
    default:
      return push_consecutive(r, src, lane, frame, n, on_packet, ctx);
  }
}

void hermc_reasm_tick(hermc_reasm* r, uint32_t now_ms) {
  uint8_t i;
  r->now_ms = now_ms;
  for (i = 0; i < r->nslots; ++i) {
    hermc_reasm_slot* s = &r->slots[i];
    if (s->used && (uint32_t)(now_ms - s->started_ms) > HERMC_REASSEMBLY_TIMEOUT_MS) {
      s->used = 0;
      ++r->stats.timed_out;
    }
  }
}

uint8_t hermc_reasm_pending(const hermc_reasm* r) {
  uint8_t i;
  uint8_t k = 0;
  for (i = 0; i < r->nslots; ++i)
    k = (uint8_t)(k + (r->slots[i].used ? 1u : 0u));
  return k;
}

/* -- serial link: receiving ------------------------------------------------------------ */

#define DELIMITER 0x00u
#define ESCAPE 0x7Du
#define ESCAPE_XOR 0x20u
#define RX_ESCAPED 0x01u
#define RX_ESCAPE_PENDING 0x02u
#define RX_SKIPPING 0x04u

static uint8_t needs_escape(uint8_t x) {
  return x == 0x11u || x == 0x13u || x == ESCAPE;
}

void hermc_link_rx_init(hermc_link_rx* rx, bool escaped) {
  hermc_reasm_init(&rx->reasm, rx->slots, (uint8_t)HERMC_RX_SLOTS);
  memset(&rx->frame_stats, 0, sizeof rx->frame_stats);
  rx->run = 0;
  rx->dec = 0;
  rx->left = 0;
  rx->code = 0;
  rx->flags = HERMC_ESCAPED && escaped ? RX_ESCAPED : 0u;
}

HERMC_NOINLINE
static void rx_restart(hermc_link_rx* rx, uint8_t skipping) {
  rx->run = 0;
  rx->dec = 0;
  rx->left = 0;
  rx->code = 0;
  rx->flags = (uint8_t)((rx->flags & RX_ESCAPED) | skipping);
}

static void rx_put(hermc_link_rx* rx, uint8_t b) {
  if (rx->dec < HERMC_MTU + 2u)
    rx->buf[rx->dec] = b;
  ++rx->dec; /* at most run <= HERMC_RUN_MAX: counted even past buf */
}

static void rx_end_of_run(hermc_link_rx* rx, hermc_packet_fn on_packet,
                          void* ctx) {
  hermc_frame_stats* st = &rx->frame_stats;
  uint16_t m = rx->dec;
  if (rx->flags & RX_SKIPPING) {
    rx_restart(rx, 0);
    return;
  }
  if (rx->flags & RX_ESCAPE_PENDING)
    ++st->bad_escape;
  else if (rx->run == 0)
    ++st->idle;
  else if (rx->left != 0)
    ++st->bad_cobs;
  else if (m < 3)
    ++st->too_short;
  else if (m > HERMC_MTU + 2u)
    ++st->oversized;
  else if (hermc_crc16(HERMC_CRC16_INIT, rx->buf, (size_t)(m - 2u))
           != (uint16_t)((uint16_t)rx->buf[m - 2] << 8 | rx->buf[m - 1]))
    ++st->bad_crc;
  else {
    ++st->frames;
    rx_restart(rx, 0);
    hermc_reasm_push(&rx->reasm, 1, 0, rx->buf, (size_t)(m - 2u), on_packet, ctx);
    return;
  }
  rx_restart(rx, 0);
}

void hermc_link_rx_feed(hermc_link_rx* rx, const uint8_t* bytes, size_t n,
                        hermc_packet_fn on_packet, void* ctx) {
  size_t i;
  for (i = 0; i < n; ++i) {
    uint8_t x = bytes[i];
    if (x == DELIMITER) {
      rx_end_of_run(rx, on_packet, ctx);
      continue;
    }
    if (rx->flags & RX_SKIPPING)
      continue;
#if HERMC_ESCAPED
    if (rx->flags & RX_ESCAPED) {
      if (rx->flags & RX_ESCAPE_PENDING) {
        rx->flags = (uint8_t)(rx->flags & ~RX_ESCAPE_PENDING);
        x = (uint8_t)(x ^ ESCAPE_XOR);
        if (!needs_escape(x)) {
          ++rx->frame_stats.bad_escape;
          rx_restart(rx, RX_SKIPPING);
          continue;
        }
      } else if (x == ESCAPE) {
        rx->flags |= RX_ESCAPE_PENDING;
        continue;
      }
    }
#endif
    if (rx->run == HERMC_RUN_MAX) {
      ++rx->frame_stats.oversized;
      rx_restart(rx, RX_SKIPPING);
      continue;
    }
    ++rx->run;
    if (rx->left == 0) {
      /* A code byte: the previous piece, unless full (0xFF), ended in 0. */
      if (rx->code != 0 && rx->code != 0xFFu)
        rx_put(rx, 0);
      rx->code = x;
      rx->left = (uint8_t)(x - 1u);
    } else {
      rx_put(rx, x);
      --rx->left;
    }
  }
}

void hermc_link_rx_tick(hermc_link_rx* rx, uint32_t now_ms) {
  hermc_reasm_tick(&rx->reasm, now_ms);
}

/* -- serial link: sending ------------------------------------------------------------ */

size_t hermc_link_tx_wire_bound(size_t len, bool escaped) {
  uint32_t frames = hermc_frag_count(len, HERMC_MTU);
  uint32_t per_frame = (uint32_t)HERMC_COBS_MAX(HERMC_MTU + 2u) * (escaped ? 2u : 1u) + 1u;
  uint32_t bound;
  if (frames == 0 || frames > 0xFFFFFFFFul / per_frame)
    return 0;
  bound = frames * per_frame + 1u;
  return bound > (uint32_t)(size_t)-1 ? 0 : (size_t)bound;
}

void hermc_link_tx_init(hermc_link_tx* tx, bool escaped) {
  tx->head = 0;
  tx->count = 0;
  tx->tag = 0;
  tx->escaped = HERMC_ESCAPED && escaped ? 1u : 0u;
  tx->packets = 0;
  tx->refused = 0;
}

HERMC_NOINLINE
static void tx_put(hermc_link_tx* tx, uint8_t b) {
  uint32_t at = (uint32_t)tx->head + tx->count;
  if (at >= HERMC_TX_RING)
    at -= HERMC_TX_RING;
  tx->ring[at] = b;
  ++tx->count;
}

static void tx_put_encoded(hermc_link_tx* tx, uint8_t b) {
  if (HERMC_ESCAPED && tx->escaped && needs_escape(b)) {
    tx_put(tx, ESCAPE);
    b = (uint8_t)(b ^ ESCAPE_XOR);
  }
  tx_put(tx, b);
}

/* Frames the packet cut by `f` and counts its wire bytes; writes them too
 * when `write` (the caller checked that they fit). Counting stops past
 * HERMC_TX_RING: such a packet cannot fit. */
static size_t tx_frames(hermc_link_tx* tx, const hermc_frag* start,
                        bool write) {
  hermc_frag f = *start;
  uint8_t raw[HERMC_MTU + 2];
  uint8_t enc[HERMC_COBS_MAX(HERMC_MTU + 2u)];
  size_t n;
  size_t total = 0;
  if (tx->count == 0) {
    if (write)
      tx_put(tx, DELIMITER);
    ++total;
  }
  while ((n = hermc_frag_next(&f, raw)) != 0) {
    uint16_t crc = hermc_crc16(HERMC_CRC16_INIT, raw, n);
    size_t k;
    size_t i;
    raw[n] = (uint8_t)(crc >> 8);
    raw[n + 1] = (uint8_t)(crc & 0xFFu);
    k = hermc_cobs_encode(raw, n + 2u, enc);
    for (i = 0; i < k; ++i) {
      total += HERMC_ESCAPED && tx->escaped && needs_escape(enc[i]) ? 2u : 1u;
      if (write)
        tx_put_encoded(tx, enc[i]);
    }
    if (write)
      tx_put(tx, DELIMITER);
    ++total;
    if (total > HERMC_TX_RING)
      return total;
  }
  return total;
}

int hermc_link_tx_packet(hermc_link_tx* tx, const uint8_t* pkt, size_t len) {
  hermc_frag f;
  size_t need;
  /* One fragmenter state (and one CRC-32) serves both passes. */
  if (hermc_frag_begin(&f, pkt, len, HERMC_MTU, tx->tag) != HERMC_OK) {
    ++tx->refused;
    return HERMC_ERR_TOO_BIG;
  }
  need = tx_frames(tx, &f, false);
  if (need > hermc_link_tx_free(tx)) {
    ++tx->refused;
    /* Into an empty ring it also takes the leading delimiter. */
    return need + (tx->count != 0 ? 1u : 0u) > HERMC_TX_RING ? HERMC_ERR_TOO_BIG
                                                             : HERMC_ERR_FULL;
  }
  (void)tx_frames(tx, &f, true);
  tx->tag = (uint8_t)((tx->tag + 1u) & 0x03u);
  ++tx->packets;
  return HERMC_OK;
}

size_t hermc_link_tx_pop(hermc_link_tx* tx, uint8_t* out, size_t cap) {
  size_t k = 0;
  while (k < cap && tx->count > 0) {
    out[k++] = tx->ring[tx->head];
    tx->head = (uint16_t)(tx->head + 1u == HERMC_TX_RING ? 0u : tx->head + 1u);
    --tx->count;
  }
  return k;
}

size_t hermc_link_tx_pending(const hermc_link_tx* tx) {
  return tx->count;
}

size_t hermc_link_tx_free(const hermc_link_tx* tx) {
  return (size_t)(HERMC_TX_RING - tx->count);
}
