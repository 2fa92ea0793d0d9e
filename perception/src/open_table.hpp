#pragma once
// Private: a hash table of 64-bit keys for the lookups made by the million (the resampling's
// cells, the free-space test's bins): open addressing with linear probing, each slot's key and
// value side by side in one array. std::unordered_map's node per entry made the free-space
// test's lookups a third of its time.
#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace artisan::detail {

template <typename Value>
class OpenTable {
 public:
  /// Empty, with room for `entries` keys before it grows.
  void reset(size_t entries) {
    size_t capacity = 16;
    while (capacity < 2 * entries) capacity *= 2;
    slots_.assign(capacity, Slot{});
    shift_ = 64 - std::countr_zero(capacity);
    size_ = 0;
  }
  /// The key's value, or null when the key is not in the table.
  const Value* find(uint64_t key) const {
    if (slots_.empty()) return nullptr;
    for (size_t i = slot(key);; i = next(i)) {
      if (!slots_[i].used) return nullptr;
      if (slots_[i].key == key) return &slots_[i].value;
    }
  }
  /// The key's value, `value` put in for a key not in the table yet (second: whether it was).
  std::pair<Value*, bool> insert(uint64_t key, const Value& value) {
    if (2 * (size_ + 1) > slots_.size()) grow();
    size_t i = slot(key);
    for (; slots_[i].used; i = next(i))
      if (slots_[i].key == key) return {&slots_[i].value, false};
    slots_[i] = {key, value, true};
    ++size_;
    return {&slots_[i].value, true};
  }

 private:
  struct Slot {
    uint64_t key = 0;
    Value value{};
    bool used = false;
  };
  size_t slot(uint64_t key) const { return static_cast<size_t>((key * 0x9e3779b97f4a7c15ull) >> shift_); }
  size_t next(size_t i) const { return (i + 1) & (slots_.size() - 1); }
  void grow() {
    std::vector<Slot> old = std::move(slots_);
    reset(std::max(old.size(), size_ + 1));  // twice the slots
    for (const Slot& s : old)
      if (s.used) insert(s.key, s.value);
  }
  std::vector<Slot> slots_;
  int shift_ = 64;
  size_t size_ = 0;
};

}  // namespace artisan::detail
