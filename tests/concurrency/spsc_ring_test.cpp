#include "concurrency/spsc_ring.hpp"

#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <thread>

namespace tissue::concurrency {
namespace {

// Every field carries the same sequence number: a torn copy shows up as a mismatch.
struct Stamped {
  std::uint64_t seq = 0;
  std::array<std::uint64_t, 7> copy{};
};

TEST(SpscRing, FifoDropsWhenFullAndDrains) {
  SpscRing<int, 4> ring;
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(ring.try_push(i));
  EXPECT_FALSE(ring.try_push(99));
  EXPECT_EQ(ring.drops(), 1u);
  int v = -1;
  ASSERT_TRUE(ring.try_pop(v));
  EXPECT_EQ(v, 0);
  EXPECT_TRUE(ring.try_push(4));
  int expected = 1;
  EXPECT_EQ(ring.drain([&](const int& x) { EXPECT_EQ(x, expected++); }), 4u);
  EXPECT_FALSE(ring.try_pop(v));
  EXPECT_EQ(ring.size(), 0u);
  EXPECT_EQ(ring.pushed(), 5u);
}

TEST(SpscRing, ProducerConsumerStressKeepsOrderAndNeverTears) {
  auto ring = std::make_unique<SpscRing<Stamped, 64>>();
  std::atomic<bool> stop{false};
  std::uint64_t attempts = 0;
  std::thread producer([&] {
    std::uint64_t seq = 0;
    while (!stop.load(std::memory_order_acquire)) {
      for (int k = 0; k < 64; ++k) {
        Stamped s;
        s.seq = ++seq;
        s.copy.fill(seq);
        ring->try_push(s);  // never blocks; a full ring drops
        ++attempts;
      }
    }
  });
  std::uint64_t received = 0, last_seq = 0, torn = 0, backwards = 0;
  auto check = [&](const Stamped& s) {
    for (std::uint64_t c : s.copy) torn += (c != s.seq);
    backwards += (s.seq <= last_seq);
    last_seq = s.seq;
    ++received;
  };
  Stamped s;
  // Enough traffic, or a deadline on a machine too loaded to deliver it.
  const auto start = std::chrono::steady_clock::now();
  for (;;) {
    const auto elapsed = std::chrono::steady_clock::now() - start;
    if ((received >= 200000 && elapsed > std::chrono::milliseconds(200)) || elapsed > std::chrono::milliseconds(1500))
      break;
    if (received % 3 == 0)
      ring->drain(check);
    else if (ring->try_pop(s))
      check(s);
  }
  stop.store(true, std::memory_order_release);
  producer.join();
  ring->drain(check);
  EXPECT_EQ(torn, 0u);
  EXPECT_EQ(backwards, 0u);
  EXPECT_GT(received, 1000u);
  EXPECT_EQ(received + ring->drops(), attempts);  // every push either arrived or was counted
}

}  // namespace
}  // namespace tissue::concurrency
