// LatencyHistogram: fixed-width buckets preallocated at construction, so the
// real-time thread records without allocating; any thread may read
// percentiles concurrently (single writer, relaxed atomics: a reader may see a
// sample or two in flight, which a percentile does not care about).
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>

namespace tissue::haptics {

class LatencyHistogram {
 public:
  // A bucket's count. The daemon's histograms run for the haptic thread's
  // life: 32 bits would wrap after 49.7 days of 1 kHz ticks in one bucket.
  using Count = std::uint64_t;
  static_assert(std::atomic<Count>::is_always_lock_free, "the real-time writer must not lock");

  LatencyHistogram(std::int64_t bucket_width_ns, std::size_t bucket_count)
      : bucket_width_ns_(std::max<std::int64_t>(1, bucket_width_ns)),
        bucket_count_(std::max<std::size_t>(1, bucket_count)),
        counts_(new std::atomic<Count>[bucket_count_]) {
    reset();
  }

  // Single writer. Negative values (early wake-ups) land in bucket 0; values
  // past the last bucket are counted as overflow and still set max_ns().
  void record(std::int64_t value_ns) noexcept {
    if (value_ns > max_ns_.load(std::memory_order_relaxed)) max_ns_.store(value_ns, std::memory_order_relaxed);
    const std::int64_t b = std::max<std::int64_t>(0, value_ns) / bucket_width_ns_;
    if (b >= static_cast<std::int64_t>(bucket_count_))
      overflow_.store(overflow_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    else
      counts_[b].store(counts_[b].load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    count_.store(count_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  }

  // Not concurrent with record().
  void reset() noexcept {
    for (std::size_t i = 0; i < bucket_count_; ++i) counts_[i].store(0, std::memory_order_relaxed);
    overflow_.store(0, std::memory_order_relaxed);
    count_.store(0, std::memory_order_relaxed);
    max_ns_.store(0, std::memory_order_relaxed);
  }

  std::uint64_t count() const noexcept { return count_.load(std::memory_order_relaxed); }
  std::int64_t max_ns() const noexcept { return max_ns_.load(std::memory_order_relaxed); }
  std::int64_t bucket_width_ns() const noexcept { return bucket_width_ns_; }

  // Samples of at least threshold_ns (counted from whole buckets at or above
  // it, so thresholds on a bucket edge are exact; overflow included).
  std::uint64_t count_at_least(std::int64_t threshold_ns) const noexcept {
    const std::int64_t first = std::max<std::int64_t>(0, threshold_ns + bucket_width_ns_ - 1) / bucket_width_ns_;
    std::uint64_t n = overflow_.load(std::memory_order_relaxed);
    for (std::size_t i = static_cast<std::size_t>(std::min<std::int64_t>(first, bucket_count_)); i < bucket_count_; ++i)
      n += counts_[i].load(std::memory_order_relaxed);
    return n;
  }

  // Upper edge of the bucket holding the q-quantile (0 < q <= 1), so the
  // figure is never optimistic; max_ns() when it falls in the overflow.
  std::int64_t percentile_ns(double q) const noexcept {
    const std::uint64_t n = count();
    if (n == 0) return 0;
    const double rank = std::clamp(q, 0.0, 1.0) * static_cast<double>(n);
    std::uint64_t seen = 0;
    for (std::size_t i = 0; i < bucket_count_; ++i) {
      seen += counts_[i].load(std::memory_order_relaxed);
      if (static_cast<double>(seen) >= rank && seen > 0) return static_cast<std::int64_t>(i + 1) * bucket_width_ns_;
    }
    return max_ns();
  }

 private:
  std::int64_t bucket_width_ns_;
  std::size_t bucket_count_;
  std::unique_ptr<std::atomic<Count>[]> counts_;
  std::atomic<std::uint64_t> overflow_{0};
  std::atomic<std::uint64_t> count_{0};
  std::atomic<std::int64_t> max_ns_{0};
};

}  // namespace tissue::haptics
