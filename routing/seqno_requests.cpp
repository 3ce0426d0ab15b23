#include "routing/seqno_requests.hpp"

#include <iterator>

namespace herm {

seqno_requests::seqno_requests() : seqno_requests(limits{}) {
}

seqno_requests::seqno_requests(limits lim) : limits_(lim) {
}

seqno_requests::decision seqno_requests::request(module_id dst,
                                                 time_point now) {
  auto i = sent_.find(dst);
  if (i != sent_.end() && now - i->second < limits_.interval)
    return decision::duplicate;
  if (i == sent_.end()) {
    if (sent_.size() >= limits_.per_interval) {
      ++over_limit_;
      return decision::over_limit;
    }
    i = sent_.emplace(dst, now).first;
  }
  i->second = now;
  return decision::send;
}

void seqno_requests::expire(time_point now) {
  for (auto i = sent_.begin(); i != sent_.end();)
    i = now - i->second >= limits_.interval ? sent_.erase(i) : std::next(i);
}

std::optional<seqno_requests::time_point> seqno_requests::next_expiry() const {
  std::optional<time_point> first;
  for (auto& [dst, sent] : sent_)
    if (!first || sent + limits_.interval < *first)
      first = sent + limits_.interval;
  return first;
}

} // namespace herm
