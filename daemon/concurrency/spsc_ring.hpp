// SpscRing<T, N>: a bounded, wait-free single-producer / single-consumer ring.
//
// Why: the 1 kHz haptic thread hands one ToolSample per tick to the sim thread
// and must never block or allocate. When the consumer falls behind the ring is
// full and try_push() refuses the new element (it is counted in drops()):
// dropping the newest sample is harmless (the next one follows 1 ms later),
// blocking the haptic thread is not.
//
// Protocol: the producer owns tail_, the consumer owns head_. Each side
// publishes its index with a release store and reads the other's with an
// acquire load, so an element's bytes are visible before its slot is handed
// over. Indices run freely (64-bit, no wrap in practice) and are masked into
// the power-of-two storage. Storage lives inside the object: no allocation
// after construction. Exactly one thread may push and one thread may pop.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <type_traits>

namespace tissue::concurrency {

// Separate cache lines for the two indices: the producer and consumer write
// them from different cores and must not false-share.
inline constexpr std::size_t kCacheLineBytes = 64;

template <typename T, std::size_t N>
class SpscRing {
  static_assert(N >= 2 && (N & (N - 1)) == 0, "SpscRing capacity must be a power of two >= 2");
  static_assert(std::is_nothrow_copy_assignable_v<T>, "SpscRing elements are copied by value and must not throw");

 public:
  static constexpr std::size_t kCapacity = N;

  SpscRing() = default;
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  // Producer side. Returns false (and counts a drop) when the ring is full.
  bool try_push(const T& value) noexcept {
    const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    if (tail - head_cache_ >= N) {
      head_cache_ = head_.load(std::memory_order_acquire);
      if (tail - head_cache_ >= N) {
        drops_.store(drops_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
        return false;
      }
    }
    slots_[tail & kMask] = value;
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  // Consumer side. Returns false when the ring is empty.
  bool try_pop(T& out) noexcept {
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    if (head == tail_cache_) {
      tail_cache_ = tail_.load(std::memory_order_acquire);
      if (head == tail_cache_) return false;
    }
    out = slots_[head & kMask];
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  // Consumer side: calls fn(const T&) for every element available now and
  // returns how many were consumed. Elements pushed meanwhile wait for the
  // next drain (bounded work per call).
  template <typename Fn>
  std::size_t drain(Fn&& fn) {
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    const std::uint64_t tail = tail_.load(std::memory_order_acquire);
    tail_cache_ = tail;
    for (std::uint64_t i = head; i != tail; ++i) {
      fn(static_cast<const T&>(slots_[i & kMask]));
      // Release each slot as soon as it is consumed so the producer sees room early.
      head_.store(i + 1, std::memory_order_release);
    }
    return static_cast<std::size_t>(tail - head);
  }

  // Approximate (exact when called from either endpoint with the other idle).
  std::size_t size() const noexcept {
    const std::uint64_t tail = tail_.load(std::memory_order_acquire);
    const std::uint64_t head = head_.load(std::memory_order_acquire);
    return tail >= head ? static_cast<std::size_t>(tail - head) : 0;
  }
  // Elements refused because the ring was full; any thread may read it.
  std::uint64_t drops() const noexcept { return drops_.load(std::memory_order_relaxed); }
  // Elements accepted so far; any thread may read it.
  std::uint64_t pushed() const noexcept { return tail_.load(std::memory_order_relaxed); }

 private:
  static constexpr std::uint64_t kMask = N - 1;

  // Producer-owned line.
  alignas(kCacheLineBytes) std::atomic<std::uint64_t> tail_{0};
  std::uint64_t head_cache_ = 0;  // producer's last view of head_ (saves cross-core loads)
  std::atomic<std::uint64_t> drops_{0};
  // Consumer-owned line.
  alignas(kCacheLineBytes) std::atomic<std::uint64_t> head_{0};
  std::uint64_t tail_cache_ = 0;  // consumer's last view of tail_
  alignas(kCacheLineBytes) std::array<T, N> slots_{};
};

}  // namespace tissue::concurrency
