#include "actors/reach_table.hpp"

namespace herm {

void reach_table::up(module_id m) {
  reachable_.insert(m);
  unreachable_since_.erase(m);
}

void reach_table::down(module_id m, time_point now) {
  if (reachable_.erase(m) > 0)
    unreachable_since_.emplace(m, now);
}

std::vector<module_id>
reach_table::lost(time_point now, std::chrono::steady_clock::duration grace) {
  std::vector<module_id> result;
  for (auto i = unreachable_since_.begin(); i != unreachable_since_.end();) {
    if (now - i->second >= grace) {
      result.push_back(i->first);
      i = unreachable_since_.erase(i);
    } else {
      ++i;
    }
  }
  return result;
}

} // namespace herm
