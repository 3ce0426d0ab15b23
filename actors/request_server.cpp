#include "actors/request_server.hpp"

#include "actors/asl_errors.hpp"
#include "actors/runtime/error.hpp"

namespace herm {

request_server::request_server(config cfg, const apo_registry& apos,
                               reliable_requests& reliable,
                               app_support_stats& stats)
  : cfg_(cfg), apos_(apos), reliable_(reliable), stats_(&stats) {
  // nop
}

void request_server::respond_error(module_id dst, uint64_t rid,
                                   const caf::error& err, bool sign,
                                   asl_outbox& out) {
  if (rid == 0)
    return;
  asl_response r;
  r.request_id = rid;
  r.ok = false;
  r.error = to_wire(err);
  out.push(dst, std::move(r), sign);
}

void request_server::ack(module_id dst, uint64_t rid, asl_outbox& out) {
  ++stats_->acks_sent;
  out.push(dst, asl_ack{rid});
}

bool request_server::admit(module_id src, uint64_t rid, uint32_t apo,
                           bool reliable, bool authenticated, module_id self,
                           asl_outbox& out) {
  if (apos_.signed_only(apo) && !authenticated
      && !cfg_.allow_unsigned_remote) {
    ++stats_->rx_unauthorized;
    auto entry = apos_.table().local(apo);
    respond_error(src, rid,
                  asl_error::unauthorized(entry ? entry->name : "?", self),
                  true, out);
    return false;
  }
  if (reliable)
    if (auto c = reliable_.duplicate(src, rid)) {
      if (c->done && !c->oneway)
        out.push(src, c->response, c->sign);
      else
        ack(src, rid, out);
      return false;
    }
  if (apos_.find(apo) == nullptr) {
    ++stats_->rx_unknown_apo;
    respond_error(src, rid, asl_error::no_such_apo(apo, self), false, out);
    return false;
  }
  return true;
}

void request_server::malformed(module_id src, uint64_t rid, uint32_t apo,
                               const caf::error& err, module_id self,
                               asl_outbox& out) {
  respond_error(src, rid,
                make_herm_error(err.code(), "module " + to_hex(self) + ": "
                                              + context_of(err)),
                apos_.signed_only(apo), out);
}

std::optional<uint64_t>
request_server::accept(module_id src, uint64_t rid, uint32_t apo, bool oneway,
                       bool reliable, time_point now, module_id self,
                       asl_outbox& out) {
  if (oneway) {
    if (reliable) {
      reliable_.remember(src, rid, true, true, now);
      ack(src, rid, out);
    }
    ++stats_->oneway_delivered;
    return 0;
  }
  bool sign = apos_.signed_only(apo);
  if (serving_.size() >= cfg_.max_serving) {
    ++stats_->serving_refused;
    respond_error(src, rid, asl_error::serving_full(self), sign, out);
    return std::nullopt;
  }
  if (reliable)
    reliable_.remember(src, rid, false, false, now).sign = sign;
  auto local = next_++;
  spare_.emplace(serving_, local,
                 served{src, rid, now + cfg_.request_timeout, reliable, sign});
  ++stats_->requests_served;
  return local;
}

void request_server::reply(uint64_t local,
                           std::variant<byte_buffer, caf::error> answer,
                           asl_outbox& out) {
  auto i = serving_.find(local);
  if (i == serving_.end())
    return; // timed out meanwhile
  auto s = i->second;
  spare_.erase(serving_, i);
  asl_response r;
  r.request_id = s.origin_id;
  if (auto err = std::get_if<caf::error>(&answer)) {
    r.ok = false;
    r.error = to_wire(*err);
  } else {
    r.payload = std::move(std::get<byte_buffer>(answer));
  }
  if (s.reliable)
    reliable_.respond(s.origin, s.origin_id, r);
  out.push(s.origin, std::move(r), s.sign);
}

void request_server::expire(time_point now) {
  for (auto i = serving_.begin(); i != serving_.end();)
    i = i->second.deadline <= now ? spare_.erase(serving_, i) : std::next(i);
}

} // namespace herm
