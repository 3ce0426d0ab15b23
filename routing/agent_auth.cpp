#include "routing/agent_state.hpp"

// The routing agent's half of RFC 8967 (docs/protocol.md,
// "Authentication"): checking trailers, challenging unknown senders and
// answering their challenges. The authenticator (routing/auth.hpp) holds
// the keys, counters and nonces; this file sends and counts.

namespace herm::agent_detail {

namespace {

/// Challenges sender `index`, heard at `src` on channel `ch` with a right
/// tag but not known: a fresh nonce it must echo, signed. At most one per
/// index per challenge_interval (the authenticator's rate limit).
void send_challenge(agent_impl self, channel_id ch, link_addr src,
                    uint32_t index) {
  auto& st = self->state;
  challenge_request req;
  if (!st.auth->challenge(index, self->clock().now(), req.nonce))
    return;
  send_on(self, ch, src, encoded(self, req));
  ++st.stats.tx_challenges;
}

/// Answers the challenge request in `pkt` (its body: `t.body_size` bytes)
/// from sender `t.index`, whatever that index and its counter (RFC 8967
/// 4.3: the requester may not know us, and we may not know it), at most
/// once per requesting index per challenge_interval. The reply is followed
/// by our hello to the requester: the requester knows our index once the
/// reply is in, so the hello makes us its neighbour at once instead of at
/// our next hello.
void answer_challenge(agent_impl self, const packet_received& pkt,
                      const auth_trailer& t) {
  auto& st = self->state;
  auto req = decode_challenge_request(pkt.bytes.data(), t.body_size);
  if (!decoded(self, req) || !st.auth->may_reply(t.index, self->clock().now()))
    return;
  send_on(self, pkt.channel, pkt.src, encoded(self, challenge_reply{req->nonce}));
  ++st.stats.tx_challenge_replies;
  if (st.leaving)
    return;
  send_on(self, pkt.channel, pkt.src, make_hello(self, false));
  ++st.stats.tx_hellos;
}

/// A challenge reply from sender `t.index`, not known yet: known from now
/// on if it echoes the live nonce of our challenge to that index.
void on_challenge_reply(agent_impl self, const packet_received& pkt,
                        const auth_trailer& t) {
  auto& st = self->state;
  auto rep = decode_challenge_reply(pkt.bytes.data(), t.body_size);
  if (!decoded(self, rep))
    return;
  switch (st.auth->accept_reply(t, rep->nonce, self->clock().now())) {
    case auth_result::ok:
      break;
    case auth_result::table_full:
      ++st.stats.rx_auth_table_full;
      break;
    default:
      ++st.stats.rx_challenge_failed;
      break;
  }
}

} // namespace

/// In a keyed network: checks the trailer of a received packet and strips
/// it. False (and counted) when the packet must be dropped. Challenge
/// requests and replies are handled here, and never go further.
bool authenticate(agent_impl self, packet_received& pkt, packet_type type) {
  auto& st = self->state;
  auto ci = st.channels.find(pkt.channel);
  if (ci == st.channels.end())
    return false;
  auto& b = pkt.bytes;
  size_t min_body = 1;
  if (type == packet_type::data) {
    auto h = decode_data_header(b.data(), b.size());
    if (!decoded(self, h))
      return false;
    if (!h->authenticated) {
      auto off = header_size(*h);
      if (data_needs_auth(st.auth->config(), h->dst, h->protocol, b.data() + off,
                          b.size() - off)) {
        ++st.stats.rx_unsigned;
        return false;
      }
      return true;
    }
    min_body = header_size(*h);
  }
  auth_trailer t;
  auto res = st.auth->verify(b.data(), b.size(),
                             static_cast<uint8_t>(ci->second.code),
                             self->clock().now(), t, min_body);
  bool right_tag = res == auth_result::ok || res == auth_result::replayed
                   || res == auth_result::table_full
                   || res == auth_result::unknown_index;
  if (res == auth_result::unknown_index
      && type != packet_type::challenge_reply) {
    // Not acted on until its sender has shown that it is alive.
    ++st.stats.rx_auth_challenged;
    // Our challenge goes out before our answer to theirs (below): the
    // sender answers it before it hears our hello, so the full update it
    // sends on meeting us finds its index known here.
    send_challenge(self, pkt.channel, pkt.src, t.index);
  }
  // A challenge request with a right tag is answered before the index and
  // counter checks (RFC 8967 4.3): the requester may be new to us.
  if (right_tag && type == packet_type::challenge_request)
    answer_challenge(self, pkt, t);
  switch (res) {
    case auth_result::ok:
      break;
    case auth_result::unknown_index:
      if (type == packet_type::challenge_reply)
        on_challenge_reply(self, pkt, t);
      return false;
    case auth_result::replayed:
      ++st.stats.rx_replayed;
      return false;
    case auth_result::table_full:
      ++st.stats.rx_auth_table_full;
      return false;
    default:
      ++st.stats.rx_auth_failed;
      return false;
  }
  if (type == packet_type::challenge_request
      || type == packet_type::challenge_reply)
    return false; // answered above; a reply from a known index: nothing to do
  // Data packets keep their authenticated flag: it tells the receiver that
  // the packet was verified (packet_delivered::authenticated) and a
  // forwarder that it must sign it again (must_sign).
  b.resize(t.body_size);
  return true;
}
} // namespace herm::agent_detail
