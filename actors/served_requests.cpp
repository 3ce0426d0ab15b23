#include "actors/served_requests.hpp"

namespace herm {

uint64_t served_requests::add(served s) {
  auto local = next_++;
  requests_.emplace(local, s);
  return local;
}

std::optional<served> served_requests::take(uint64_t local) {
  auto i = requests_.find(local);
  if (i == requests_.end())
    return std::nullopt;
  auto result = i->second;
  requests_.erase(i);
  return result;
}

void served_requests::expire(time_point now) {
  for (auto i = requests_.begin(); i != requests_.end();)
    i = i->second.deadline <= now ? requests_.erase(i) : std::next(i);
}

} // namespace herm
