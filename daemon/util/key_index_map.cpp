#include "util/key_index_map.hpp"

#include <algorithm>
#include <stdexcept>

namespace tissue::util {

namespace {
// Grow when the table would pass 3/4 full. Misses (every insert is one) cost
// about (1 + 1/(1-a)^2)/2 probes under linear probing: 8.5 at 3/4 but 15+
// above 0.82, which the mesh benchmark showed as split cost growing with size.
constexpr std::size_t kMaxLoadNum = 3;
constexpr std::size_t kMaxLoadDen = 4;
constexpr std::size_t kMinSlots = 16;

std::size_t slots_for(std::size_t entries) {
  std::size_t slots = kMinSlots;
  while (slots * kMaxLoadNum < entries * kMaxLoadDen) slots *= 2;
  return slots;
}
}  // namespace

bool KeyIndexMap::insert(std::uint64_t key, std::uint32_t value) {
  if (key == kEmptyKey) throw std::invalid_argument("KeyIndexMap: key ~0 is reserved as the empty marker");
  if (slots_.empty() || (size_ + 1) * kMaxLoadDen > slots_.size() * kMaxLoadNum) rehash(slots_for(size_ + 1));
  for (std::size_t slot = home(key);; slot = (slot + 1) & mask_) {
    if (slots_[slot].key == key) return false;
    if (slots_[slot].key == kEmptyKey) {
      slots_[slot] = {key, value};
      ++size_;
      return true;
    }
  }
}

bool KeyIndexMap::erase(std::uint64_t key) {
  // kEmptyKey would "find" an empty slot and count an entry gone.
  if (size_ == 0 || key == kEmptyKey) return false;
  std::size_t slot = home(key);
  for (;; slot = (slot + 1) & mask_) {
    if (slots_[slot].key == key) break;
    if (slots_[slot].key == kEmptyKey) return false;
  }
  // Backward-shift: pull later members of the probe run into the hole so that
  // no lookup ever stops early at it.
  std::size_t hole = slot;
  for (std::size_t next = (hole + 1) & mask_; slots_[next].key != kEmptyKey; next = (next + 1) & mask_) {
    const std::size_t want = home(slots_[next].key);
    // Move `next` into `hole` unless its home lies cyclically in (hole, next].
    const bool home_after_hole = ((next - want) & mask_) < ((next - hole) & mask_);
    if (!home_after_hole) {
      slots_[hole] = slots_[next];
      hole = next;
    }
  }
  slots_[hole].key = kEmptyKey;
  --size_;
  return true;
}

void KeyIndexMap::reserve(std::size_t entries) {
  const std::size_t slots = slots_for(entries);
  if (slots > slots_.size()) rehash(slots);
}

void KeyIndexMap::clear() {
  for (Slot& s : slots_) s.key = kEmptyKey;
  size_ = 0;
}

void KeyIndexMap::rehash(std::size_t new_slot_count) {
  std::vector<Slot> old(new_slot_count, Slot{kEmptyKey, 0});
  old.swap(slots_);
  mask_ = new_slot_count - 1;
  size_ = 0;
  for (const Slot& s : old) {
    if (s.key == kEmptyKey) continue;
    for (std::size_t slot = home(s.key);; slot = (slot + 1) & mask_) {
      if (slots_[slot].key == kEmptyKey) {
        slots_[slot] = s;
        ++size_;
        break;
      }
    }
  }
}

}  // namespace tissue::util
