#pragma once
// The viewer's caches of frames: at most `capacity` entries, the least recently used evicted
// first. Not synchronised: its owner holds a mutex.

#include <cstddef>
#include <list>
#include <map>
#include <utility>

namespace th::viewer {

template <class Key, class Value>
class Recent {
 public:
  explicit Recent(size_t capacity) : capacity_(capacity < 1 ? 1 : capacity) {}

  // The value of `key`, now the most recently used; null when absent.
  Value* find(const Key& key) {
    const auto it = index_.find(key);
    if (it == index_.end()) return nullptr;
    order_.splice(order_.begin(), order_, it->second);
    return &it->second->second;
  }

  // The value of `key` without making it the most recently used; null when absent.
  const Value* peek(const Key& key) const {
    const auto it = index_.find(key);
    return it == index_.end() ? nullptr : &it->second->second;
  }

  // Stores `value` as `key`'s, the most recently used; beyond capacity the least recently used
  // entry goes.
  Value& put(const Key& key, Value value) {
    if (Value* v = find(key)) return *v = std::move(value);
    order_.emplace_front(key, std::move(value));
    index_[key] = order_.begin();
    while (order_.size() > capacity_) {
      index_.erase(order_.back().first);
      order_.pop_back();
    }
    return order_.front().second;
  }

  size_t size() const { return order_.size(); }
  size_t capacity() const { return capacity_; }

 private:
  size_t capacity_;
  std::list<std::pair<Key, Value>> order_;  // most recent first
  std::map<Key, typename std::list<std::pair<Key, Value>>::iterator> index_;
};

}  // namespace th::viewer
