#include "concurrency/latest_value.hpp"

#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <thread>

#include "haptics/local_model.hpp"

namespace tissue::concurrency {
namespace {

TEST(LatestValue, NewestWinsAndReadsAreStableUntilTheNextRead) {
  LatestValue<int> v;
  auto r = v.read();
  EXPECT_FALSE(r.is_new);
  v.write(1);
  v.write(2);  // overwrites the unread 1
  r = v.read();
  EXPECT_TRUE(r.is_new);
  EXPECT_EQ(*r.value, 2);
  const int* held = r.value;
  v.write(3);
  v.write(4);
  EXPECT_EQ(*held, 2);  // the writer never touches the reader's slot
  r = v.read();
  EXPECT_TRUE(r.is_new);
  EXPECT_EQ(*r.value, 4);
  r = v.read();
  EXPECT_FALSE(r.is_new);
  EXPECT_EQ(*r.value, 4);
  EXPECT_EQ(v.published(), 4u);
}

// Writer fills a LocalModel (the real ~10 KB payload) whose every vertex
// coordinate equals the version; the reader checks the copy it holds while
// the writer keeps going.
TEST(LatestValue, LocalModelStressNeverTearsNorGoesBackwards) {
  using haptics::LocalModel;
  auto buffer = std::make_unique<LatestValue<LocalModel>>();
  std::atomic<bool> stop{false};
  std::thread writer([&] {
    std::uint64_t version = 0;
    while (!stop.load(std::memory_order_acquire)) {
      LocalModel& m = buffer->write_buffer();
      ++version;
      const double x = static_cast<double>(version);
      m.version = version;
      m.vertex_count = LocalModel::kMaxPatchVertices;
      for (auto& p : m.vertex_m) p = haptics::Vec3(x, x, x);
      m.force_ref_N = haptics::Vec3(x, x, x);
      buffer->publish();
    }
  });
  std::uint64_t reads = 0, fresh = 0, torn = 0, backwards = 0, last_version = 0;
  // Enough fresh values, or a deadline on a machine too loaded to deliver them.
  const auto start = std::chrono::steady_clock::now();
  for (;;) {
    const auto elapsed = std::chrono::steady_clock::now() - start;
    if ((fresh >= 5000 && elapsed > std::chrono::milliseconds(200)) || elapsed > std::chrono::milliseconds(1500)) break;
    const auto r = buffer->read();
    ++reads;
    if (!r.is_new) continue;
    ++fresh;
    const LocalModel& m = *r.value;
    const double x = static_cast<double>(m.version);
    for (const auto& p : m.vertex_m) torn += (p.x() != x || p.y() != x || p.z() != x);
    torn += (m.force_ref_N.x() != x);
    backwards += (m.version <= last_version);
    last_version = m.version;
  }
  stop.store(true, std::memory_order_release);
  writer.join();
  EXPECT_EQ(torn, 0u);
  EXPECT_EQ(backwards, 0u);
  EXPECT_GT(fresh, 10u);
  EXPECT_GT(reads, fresh / 2);
}

}  // namespace
}  // namespace tissue::concurrency
