#include "util/key_index_map.hpp"

#include <gtest/gtest.h>

#include <random>
#include <stdexcept>
#include <unordered_map>

namespace tissue::util {
namespace {

TEST(KeyIndexMap, MatchesAReferenceMapUnderRandomInsertAndErase) {
  KeyIndexMap map;
  std::unordered_map<std::uint64_t, std::uint32_t> ref;
  std::mt19937_64 rng(42);
  for (int i = 0; i < 200000; ++i) {
    // A small key range forces collisions, long probe runs and wrap-around.
    const std::uint64_t key = rng() % 5000;
    if (rng() % 3 == 0) {
      EXPECT_EQ(map.erase(key), ref.erase(key) == 1);
    } else {
      const auto value = static_cast<std::uint32_t>(rng());
      const bool inserted = ref.emplace(key, value).second;
      EXPECT_EQ(map.insert(key, value), inserted);
    }
    if (i % 997 == 0) {
      ASSERT_EQ(map.size(), ref.size());
      for (const auto& [k, v] : ref) ASSERT_EQ(map.find(k), v);
    }
  }
  for (std::uint64_t k = 0; k < 5000; ++k) {
    auto it = ref.find(k);
    EXPECT_EQ(map.find(k), it == ref.end() ? KeyIndexMap::kNotFound : it->second);
  }
  std::size_t visited = 0;
  map.for_each([&](std::uint64_t k, std::uint32_t v) {
    ++visited;
    EXPECT_EQ(ref.at(k), v);
  });
  EXPECT_EQ(visited, ref.size());
}

TEST(KeyIndexMap, RejectsTheReservedKeyAndHandlesEmpty) {
  KeyIndexMap map;
  EXPECT_EQ(map.find(7), KeyIndexMap::kNotFound);
  EXPECT_FALSE(map.erase(7));
  EXPECT_THROW(map.insert(KeyIndexMap::kEmptyKey, 1), std::invalid_argument);
  EXPECT_TRUE(map.insert(0, 5));
  EXPECT_EQ(map.find(0), 5u);
  map.clear();
  EXPECT_EQ(map.size(), 0u);
  EXPECT_FALSE(map.contains(0));
}

// The empty marker is no key: find and erase on a map with entries (so
// with empty slots) must not take an empty slot for it. find returned the
// slot's stale value and erase counted an entry gone.
TEST(KeyIndexMap, TheEmptyMarkerIsNeverFoundNorErased) {
  KeyIndexMap map;
  for (std::uint64_t k = 0; k < 10; ++k) ASSERT_TRUE(map.insert(k, static_cast<std::uint32_t>(k)));
  ASSERT_GT(map.slot_count(), map.size());
  EXPECT_EQ(map.find(KeyIndexMap::kEmptyKey), KeyIndexMap::kNotFound);
  EXPECT_FALSE(map.contains(KeyIndexMap::kEmptyKey));
  EXPECT_FALSE(map.erase(KeyIndexMap::kEmptyKey));
  EXPECT_EQ(map.size(), 10u);
  for (std::uint64_t k = 0; k < 10; ++k) EXPECT_EQ(map.find(k), k);
}

TEST(KeyIndexMap, StaysUnderThreeQuartersLoad) {
  KeyIndexMap map;
  for (std::uint32_t i = 0; i < 100000; ++i) map.insert(std::uint64_t{i} * 2654435761u, i);
  EXPECT_LE(map.size() * 4, map.slot_count() * 3);
  EXPECT_EQ(map.memory_bytes(), 16 * map.slot_count());
}

}  // namespace
}  // namespace tissue::util
