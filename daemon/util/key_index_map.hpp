// Open-addressing hash map from 64-bit lattice keys to 32-bit indices.
//
// Why not std::unordered_map: the mesh holds millions of node and edge keys and
// the benchmark budget is <= 200 bytes per leaf tet. A node-based map spends
// ~40 bytes and one allocation per entry; this one spends 16 bytes per slot
// (key and value side by side, so a lookup costs one cache miss, not two) at
// <= 3/4 load, with no per-entry allocation. Linear probing with backward-shift deletion keeps lookups short
// without tombstones, so long split/merge churn does not degrade it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace tissue::util {

class KeyIndexMap {
 public:
  static constexpr std::uint64_t kEmptyKey = ~std::uint64_t{0};
  static constexpr std::uint32_t kNotFound = ~std::uint32_t{0};

  explicit KeyIndexMap(std::size_t expected_entries = 0) { reserve(expected_entries); }

  // Returns the value stored for `key`, or kNotFound (always for kEmptyKey,
  // which no entry can hold: it would match the first empty slot).
  std::uint32_t find(std::uint64_t key) const {
    if (size_ == 0 || key == kEmptyKey) return kNotFound;
    for (std::size_t slot = home(key);; slot = (slot + 1) & mask_) {
      const Slot& s = slots_[slot];
      if (s.key == key) return s.value;
      if (s.key == kEmptyKey) return kNotFound;
    }
  }

  bool contains(std::uint64_t key) const { return find(key) != kNotFound; }

  // Inserts key → value. Returns false (and changes nothing) if key is present.
  // Throws std::invalid_argument for the reserved key kEmptyKey.
  bool insert(std::uint64_t key, std::uint32_t value);

  // Removes key. Returns false if it was absent (always for kEmptyKey).
  bool erase(std::uint64_t key);

  void reserve(std::size_t entries);
  void clear();

  std::size_t size() const { return size_; }
  std::size_t slot_count() const { return slots_.size(); }
  std::size_t memory_bytes() const { return slots_.capacity() * sizeof(Slot); }

  // Calls f(key, value) for every entry, in slot order (deterministic for a
  // given insertion/erase history, but not sorted).
  template <class F>
  void for_each(F&& f) const {
    for (const Slot& s : slots_)
      if (s.key != kEmptyKey) f(s.key, s.value);
  }

 private:
  static std::uint64_t mix(std::uint64_t x) {
    // splitmix64 finaliser: lattice keys are highly structured (packed
    // coordinates), so a plain multiplicative hash would cluster.
    x ^= x >> 30;
    x *= 0xbf58476d1ce4e5b9ULL;
    x ^= x >> 27;
    x *= 0x94d049bb133111ebULL;
    x ^= x >> 31;
    return x;
  }
  std::size_t home(std::uint64_t key) const { return static_cast<std::size_t>(mix(key)) & mask_; }
  void rehash(std::size_t new_slot_count);

  struct Slot {
    std::uint64_t key;
    std::uint32_t value;
  };
  std::vector<Slot> slots_;
  std::size_t mask_ = 0;
  std::size_t size_ = 0;
};

}  // namespace tissue::util
