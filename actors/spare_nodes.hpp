#pragma once

// Spare nodes for a std::map whose entries come and go with every message
// (the requests application support waits for, those it serves): a node
// taken out is kept, its value reset, for the next insertion, so that a map
// holding a handful of entries at a time stops allocating once warmed up.
// At most N nodes are kept; the rest are freed as usual. O(1) besides the
// map's own O(log n). Not thread-safe (one owner, like its map).

#include <cstddef>
#include <iterator>
#include <utility>
#include <vector>

namespace herm {

template <class Map, size_t N = 16>
class spare_nodes {
public:
  using iterator = typename Map::iterator;
  using key_type = typename Map::key_type;
  using mapped_type = typename Map::mapped_type;

  spare_nodes() {
    spare_.reserve(N);
  }

  /// Inserts `value` under `key` (not in `m` yet) into `m`, in a spare node
  /// when there is one. Returns where it went.
  template <class V>
  iterator emplace(Map& m, const key_type& key, V&& value) {
    if (spare_.empty())
      return m.emplace(key, std::forward<V>(value)).first;
    auto node = std::move(spare_.back());
    spare_.pop_back();
    node.key() = key;
    node.mapped() = std::forward<V>(value);
    return m.insert(std::move(node)).position;
  }

  /// Erases `i` from `m`, keeping its node when there is room. Returns the
  /// iterator after it.
  iterator erase(Map& m, iterator i) {
    auto next = std::next(i);
    auto node = m.extract(i);
    if (spare_.size() < N) {
      node.mapped() = mapped_type{}; // drops what the value held
      spare_.push_back(std::move(node));
    }
    return next;
  }

  /// Erases the entry under `key`, if any; true if there was one.
  bool erase(Map& m, const key_type& key) {
    auto i = m.find(key);
    if (i == m.end())
      return false;
    erase(m, i);
    return true;
  }

  size_t size() const {
    return spare_.size();
  }

private:
  std::vector<typename Map::node_type> spare_;
};

} // namespace herm
