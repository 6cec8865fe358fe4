// LatestValue<T>: single-writer / single-reader "newest complete value wins"
// triple buffer.
//
// Why: the sim thread publishes a LocalModel (~10 KB) after every step and the
// 1 kHz haptic thread wants the newest complete one. Neither may wait for the
// other. Three slots make that possible: the writer fills its private back
// slot, then swaps it with the shared middle slot in one atomic exchange; the
// reader, when the middle slot carries the "fresh" bit, swaps it with its
// private front slot. The reader's front slot is never touched by the writer,
// so the value the reader holds is stable until its next read() (no tearing,
// no copy on the reader side); the writer never waits, it overwrites an
// unread middle value (newest wins).
//
// Memory ordering: the exchange is acq_rel on both sides, so the writer's
// stores to a slot happen-before the reader's loads from it after the swap.
// Storage lives inside the object: no allocation after construction.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <utility>

namespace tissue::concurrency {

template <typename T>
class LatestValue {
 public:
  struct Read {
    const T* value;  // stable until the reader's next read(); never null
    bool is_new;     // a value was published since the previous read()
  };

  LatestValue() = default;
  explicit LatestValue(const T& initial) { slots_.fill(initial); }
  LatestValue(const LatestValue&) = delete;
  LatestValue& operator=(const LatestValue&) = delete;

  // Writer side: fill the returned slot in place (no copy of a large T is
  // needed), then publish(). The slot may hold any older value: overwrite
  // every field that matters.
  T& write_buffer() noexcept { return slots_[back_]; }
  void publish() noexcept {
    const std::uint8_t old = middle_.exchange(static_cast<std::uint8_t>(back_ | kFresh), std::memory_order_acq_rel);
    back_ = static_cast<std::uint8_t>(old & kIndexMask);
    published_.store(published_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  }
  // Writer side convenience: copy then publish.
  void write(const T& value) noexcept(noexcept(std::declval<T&>() = value)) {
    write_buffer() = value;
    publish();
  }

  // Reader side: takes the newest published value if there is one, otherwise
  // keeps the one it holds. Before anything was published it returns the
  // initial (default-constructed) value with is_new == false.
  Read read() noexcept {
    if ((middle_.load(std::memory_order_relaxed) & kFresh) == 0) return {&slots_[front_], false};
    const std::uint8_t old = middle_.exchange(front_, std::memory_order_acq_rel);
    front_ = static_cast<std::uint8_t>(old & kIndexMask);
    return {&slots_[front_], true};
  }

  // Number of publish() calls; any thread may read it.
  std::uint64_t published() const noexcept { return published_.load(std::memory_order_relaxed); }

 private:
  static constexpr std::uint8_t kIndexMask = 0x3;
  static constexpr std::uint8_t kFresh = 0x4;

  std::array<T, 3> slots_{};
  alignas(64) std::atomic<std::uint8_t> middle_{1};  // index of the shared slot | kFresh when unread
  alignas(64) std::uint8_t back_ = 2;                // writer-private slot
  std::atomic<std::uint64_t> published_{0};
  alignas(64) std::uint8_t front_ = 0;  // reader-private slot
};

}  // namespace tissue::concurrency
