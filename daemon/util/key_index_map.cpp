#include "util/key_index_map.hpp"

#include <algorithm>
#include <stdexcept>

namespace tissue::util {

namespace {
// Grow when the table would pass 7/8 full: linear probing stays short at this
// load with a well-mixed hash, and the memory budget per tet is tight.
constexpr std::size_t kMaxLoadNum = 7;
constexpr std::size_t kMaxLoadDen = 8;
constexpr std::size_t kMinSlots = 16;

std::size_t slots_for(std::size_t entries) {
  std::size_t slots = kMinSlots;
  while (slots * kMaxLoadNum < entries * kMaxLoadDen) slots *= 2;
  return slots;
}
}  // namespace

bool KeyIndexMap::insert(std::uint64_t key, std::uint32_t value) {
  if (key == kEmptyKey) throw std::invalid_argument("KeyIndexMap: key ~0 is reserved as the empty marker");
  if (keys_.empty() || (size_ + 1) * kMaxLoadDen > keys_.size() * kMaxLoadNum) rehash(slots_for(size_ + 1));
  for (std::size_t slot = home(key);; slot = (slot + 1) & mask_) {
    if (keys_[slot] == key) return false;
    if (keys_[slot] == kEmptyKey) {
      keys_[slot] = key;
      values_[slot] = value;
      ++size_;
      return true;
    }
  }
}

bool KeyIndexMap::erase(std::uint64_t key) {
  if (size_ == 0) return false;
  std::size_t slot = home(key);
  for (;; slot = (slot + 1) & mask_) {
    if (keys_[slot] == key) break;
    if (keys_[slot] == kEmptyKey) return false;
  }
  // Backward-shift: pull later members of the probe run into the hole so that
  // no lookup ever stops early at it.
  std::size_t hole = slot;
  for (std::size_t next = (hole + 1) & mask_; keys_[next] != kEmptyKey; next = (next + 1) & mask_) {
    const std::size_t want = home(keys_[next]);
    // Move `next` into `hole` unless its home lies cyclically in (hole, next].
    const bool home_after_hole = ((next - want) & mask_) < ((next - hole) & mask_);
    if (!home_after_hole) {
      keys_[hole] = keys_[next];
      values_[hole] = values_[next];
      hole = next;
    }
  }
  keys_[hole] = kEmptyKey;
  --size_;
  return true;
}

void KeyIndexMap::reserve(std::size_t entries) {
  const std::size_t slots = slots_for(entries);
  if (slots > keys_.size()) rehash(slots);
}

void KeyIndexMap::clear() {
  std::fill(keys_.begin(), keys_.end(), kEmptyKey);
  size_ = 0;
}

void KeyIndexMap::rehash(std::size_t new_slot_count) {
  std::vector<std::uint64_t> old_keys(new_slot_count, kEmptyKey);
  std::vector<std::uint32_t> old_values(new_slot_count, 0);
  old_keys.swap(keys_);
  old_values.swap(values_);
  mask_ = new_slot_count - 1;
  size_ = 0;
  for (std::size_t i = 0; i < old_keys.size(); ++i) {
    if (old_keys[i] == kEmptyKey) continue;
    for (std::size_t slot = home(old_keys[i]);; slot = (slot + 1) & mask_) {
      if (keys_[slot] == kEmptyKey) {
        keys_[slot] = old_keys[i];
        values_[slot] = old_values[i];
        ++size_;
        break;
      }
    }
  }
}

}  // namespace tissue::util
