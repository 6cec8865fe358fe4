// Receiving meshes (daemon/transport/mesh_subscriber, lcm_subscriber): the
// shared validation and the LCM byte-level checks, fed directly (no network).
// Every malformed input must be counted and dropped with a reason, never
// decoded into out-of-range indices or huge allocations (the ASan tree runs
// this too).
#include "transport/mesh_subscriber.hpp"

#include <gtest/gtest.h>

#include <limits>
#include <random>
#include <vector>

#include "transport/lcm_messages.hpp"
#include "transport/lcm_subscriber.hpp"
#include "transport/transport_test_support.hpp"

namespace tissue::transport {
namespace {

// Two triangles over four vertices, strain 2 and 6.
struct Arrays {
  std::vector<float> xyz = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
  std::vector<std::uint8_t> level = {0, 1, 2, 3};
  std::vector<std::int32_t> tri = {0, 1, 2, 1, 3, 2};
  std::vector<float> strain = {2.0f, 6.0f};
  x3d::SurfaceFrame frame(double t = 0.5) const { return frame_from_mesh_arrays(t, xyz, level, tri, strain); }
};

std::string category_of(const Arrays& a, double t = 0.5) {
  try {
    a.frame(t);
  } catch (const MeshRejected& e) {
    return e.category() + ": " + e.what();
  }
  return "accepted";
}

TEST(MeshDecode, ValidArraysBecomeAFrameWithPerVertexStrain) {
  const x3d::SurfaceFrame f = Arrays{}.frame();
  EXPECT_EQ(f.time_s, 0.5);
  ASSERT_EQ(f.vertices_m.size(), 4u);
  EXPECT_EQ(f.vertices_m[3], (std::array<double, 3>{1, 1, 0}));
  EXPECT_EQ(f.triangles[1], (std::array<std::uint32_t, 3>{1, 3, 2}));
  EXPECT_EQ(f.vertex_level, (std::vector<std::uint8_t>{0, 1, 2, 3}));
  EXPECT_EQ(f.vertex_strain_energy_Pa, (std::vector<float>{2.0f, 4.0f, 4.0f, 6.0f}));
  EXPECT_EQ(f.triangle_strain_energy_J_per_m3, (std::vector<float>{2.0f, 6.0f}));  // as sent
  x3d::validate_frame(f, true, "decoded");                                         // drawable with strain colours
}

TEST(MeshDecode, MalformedArraysAreRejectedWithAReason) {
  Arrays a;
  a.xyz.pop_back();
  EXPECT_EQ(category_of(a).rfind("size: vertex_m holds 11 values", 0), 0u) << category_of(a);
  a = {};
  a.level.pop_back();
  EXPECT_EQ(category_of(a).rfind("size: vertex_refinement_level", 0), 0u) << category_of(a);
  a = {};
  a.tri.pop_back();
  EXPECT_EQ(category_of(a).rfind("size: triangle_vertex", 0), 0u) << category_of(a);
  a = {};
  a.strain.push_back(1.0f);
  EXPECT_EQ(category_of(a).rfind("size: triangle_strain", 0), 0u) << category_of(a);
  a = {};
  a.tri[4] = 4;
  EXPECT_EQ(category_of(a), "index: triangle 1 uses vertex 4 of 4");
  a.tri[4] = -1;
  EXPECT_EQ(category_of(a), "index: triangle 1 uses vertex -1 of 4");
  a = {};
  a.xyz[5] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(category_of(a), "non_finite: vertex 1 has a non-finite coordinate");
  EXPECT_EQ(category_of(Arrays{}, std::numeric_limits<double>::infinity()), "non_finite: time_s is not finite");
}

TEST(MeshDecode, MissingOrNonFiniteStrainLeavesOnlyTheStrainOut) {
  Arrays a;
  a.strain.clear();
  EXPECT_TRUE(a.frame().vertex_strain_energy_Pa.empty());
  a.strain = {1.0f, std::numeric_limits<float>::infinity()};
  const x3d::SurfaceFrame f = a.frame();
  EXPECT_TRUE(f.vertex_strain_energy_Pa.empty());
  EXPECT_TRUE(f.triangle_strain_energy_J_per_m3.empty());
  EXPECT_EQ(f.triangles.size(), 2u);
  a.strain = {1.0f, -2.0f};  // a density is never negative
  EXPECT_TRUE(a.frame().triangle_strain_energy_J_per_m3.empty());
  EXPECT_TRUE(a.frame().vertex_strain_energy_Pa.empty());
  a = {};
  a.level.clear();  // "all level 0"
  EXPECT_TRUE(a.frame().vertex_level.empty());
}

// Gaps in the publisher's sequence numbers are the messages that never
// arrived; a sequence that does not increase starts a new run.
TEST(MeshReceiveCounts, SequenceGapsCountTheMessagesThatNeverArrived) {
  MeshReceiveCounts c;
  for (const std::int64_t s : {5, 6, 9, 10}) count_sequence(c, s);  // 7 and 8 lost
  EXPECT_EQ(c.missed, 2u);
  count_sequence(c, 1);  // the publisher restarted
  count_sequence(c, 2);
  count_sequence(c, 2);  // a duplicate
  EXPECT_EQ(c.missed, 2u);
  count_sequence(c, 4);
  EXPECT_EQ(c.missed, 3u);
  // Hostile extremes give a defined count (unsigned arithmetic), never UB.
  MeshReceiveCounts e;
  count_sequence(e, std::numeric_limits<std::int64_t>::min());
  count_sequence(e, std::numeric_limits<std::int64_t>::max());
  EXPECT_EQ(e.missed, std::numeric_limits<std::uint64_t>::max() - 1);
}

// LCM does not say who sent a message: two publishers on one channel at
// once are one run, and every switch up counts the distance between them
// (what docs/replay-and-live.md says an LCM reader counts).
TEST(MeshReceiveCounts, WithoutPublisherIdentityInterleavedPublishersCountAsGaps) {
  MeshReceiveCounts c;
  for (const std::int64_t s : {10000, 1, 10001, 2}) count_sequence(c, s);
  EXPECT_EQ(c.missed, 9999u);  // 2 .. 10000 between 1 and 10001; each switch down restarts
}

PublisherSequences::PublisherId publisher(int k) {
  PublisherSequences::PublisherId id{};
  id[0] = 0x01;  // as a GUID prefix would
  id[15] = static_cast<std::uint8_t>(k);
  return id;
}

// DDS names each sample's writer: the daemon (at 10000, ...) and a replay
// (1, 2, ...) interleaved on one topic count no gaps between each other,
// and each one's own gaps and restarts count as for a lone publisher.
TEST(MeshReceiveCounts, EachPublishersGapsAreCountedInItsOwnRun) {
  const PublisherSequences::PublisherId daemon = publisher(1), replay = publisher(2);
  MeshReceiveCounts c;
  PublisherSequences runs;
  for (std::int64_t k = 0; k < 5; ++k) {
    runs.count(c, daemon, 10000 + k);
    runs.count(c, replay, 1 + k);
  }
  EXPECT_EQ(c.missed, 0u);
  EXPECT_EQ(c.last_sequence, 5);
  runs.count(c, daemon, 10007);  // 10005 and 10006 lost
  runs.count(c, replay, 6);
  EXPECT_EQ(c.missed, 2u);
  runs.count(c, replay, 1);  // the replay looped: a new run
  runs.count(c, daemon, 10008);
  runs.count(c, replay, 3);  // 2 lost
  EXPECT_EQ(c.missed, 3u);
  // Hostile extremes in one publisher's run: a defined count, never UB.
  runs.count(c, publisher(3), std::numeric_limits<std::int64_t>::min());
  runs.count(c, publisher(3), std::numeric_limits<std::int64_t>::max());
  EXPECT_EQ(c.missed, 3u + (std::numeric_limits<std::uint64_t>::max() - 1));
}

// At most kMaxPublishers runs are kept: one more publisher forgets the one
// heard longest ago, whose return starts a new run (its gap is not
// counted); the others keep theirs.
TEST(MeshReceiveCounts, BeyondTheTrackedPublishersTheOneHeardLongestAgoIsForgotten) {
  constexpr int kMax = static_cast<int>(PublisherSequences::kMaxPublishers);
  MeshReceiveCounts c;
  PublisherSequences runs;
  for (int k = 0; k < kMax; ++k) runs.count(c, publisher(k), 100 * k);
  runs.count(c, publisher(0), 1);     // heard again (restarted): now publisher 1 is the oldest
  runs.count(c, publisher(kMax), 5);  // one too many: publisher 1 is forgotten
  EXPECT_EQ(c.missed, 0u);
  runs.count(c, publisher(1), 110);  // back: a new run, 101 .. 109 not counted (forgets publisher 2)
  EXPECT_EQ(c.missed, 0u);
  runs.count(c, publisher(3), 303);  // still tracked: 301 and 302 lost
  runs.count(c, publisher(kMax), 6);
  runs.count(c, publisher(0), 2);
  EXPECT_EQ(c.missed, 2u);
}

// An encoded surface_mesh from the daemon's own encoder.
std::vector<std::uint8_t> encoded_mesh(int quads, double time_s = 1.25, std::int64_t sequence = 1) {
  service::MeshSnapshot s;
  s.sequence = 1;
  s.sim_time_s = time_s;
  for (int i = 0; i <= quads; ++i) {
    s.vertices_m.push_back({0.01 * i, 0.0, 0.0});
    s.vertices_m.push_back({0.01 * i, 0.01, 0.0});
    s.vertex_level.push_back(1);
    s.vertex_level.push_back(2);
  }
  for (std::uint32_t i = 0; i < static_cast<std::uint32_t>(quads); ++i) {
    s.triangles.push_back({2 * i, 2 * i + 2, 2 * i + 3});
    s.triangles.push_back({2 * i, 2 * i + 3, 2 * i + 1});
  }
  return testing::lcm_encoded(s, sequence);
}

using testing::put_be32;

TEST(LcmMeshSubscriber, DecodesGoodMessagesAndCountsEveryMalformedOne) {
  LcmMeshSubscriber sub("memq://");                        // in-process provider: nothing on the network
  const std::vector<std::uint8_t> good = encoded_mesh(5);  // 12 vertices, 10 triangles
  EXPECT_EQ(lcm_mesh_layout_error(good.data(), good.size()), "");
  sub.on_message(good.data(), good.size());

  std::vector<std::vector<std::uint8_t>> bad;
  bad.push_back({});                                                       // empty
  bad.push_back(std::vector<std::uint8_t>(good.begin(), good.end() - 1));  // truncated
  bad.push_back(std::vector<std::uint8_t>(good.begin(), good.begin() + 30));
  std::vector<std::uint8_t> b = good;
  b.push_back(0);  // trailing byte
  bad.push_back(b);
  b = good;
  b[0] ^= 0xff;  // another type's fingerprint
  bad.push_back(b);
  b = good;
  put_be32(b, 24, 0x7fffffff);  // vertex_count: a 2^31 allocation if trusted
  put_be32(b, 28, 0x7ffffffd);
  bad.push_back(b);
  b = good;
  put_be32(b, 24, -4);  // negative count
  put_be32(b, 28, -12);
  bad.push_back(b);
  b = good;
  put_be32(b, 28, 35);  // coordinate count != 3 * vertex_count
  bad.push_back(b);
  b = good;
  // The first triangle index (after header 32, coords 144, levels 12, counts 8) points past the vertices.
  put_be32(b, 8 + 8 + 8 + 8 + 4 * 36 + 12 + 8, 12);
  bad.push_back(b);
  std::mt19937 rng(3);
  for (int k = 0; k < 50; ++k) {  // random bytes, and random damage to a good message
    std::vector<std::uint8_t> noise(rng() % 600);
    for (auto& x : noise) x = static_cast<std::uint8_t>(rng());
    bad.push_back(noise);
    b = good;
    for (int d = 0; d < 4; ++d) b[rng() % b.size()] = static_cast<std::uint8_t>(rng());
    bad.push_back(b);
  }
  std::uint64_t accepted_damaged = 0;
  for (const auto& m : bad) {
    const std::uint64_t before = sub.counts().accepted;
    sub.on_message(m.data(), m.size());
    accepted_damaged += sub.counts().accepted - before;
  }
  const MeshReceiveCounts& c = sub.counts();
  EXPECT_EQ(c.received, 1 + bad.size());
  EXPECT_EQ(c.accepted + c.rejected, c.received);
  // Damage to coordinates or levels can leave a valid mesh; everything up to
  // the random cases must be rejected.
  EXPECT_GE(c.rejected, 9u);
  EXPECT_GE(c.rejected_by_reason.at("size"), 7u);
  EXPECT_GE(c.rejected_by_reason.at("index"), 1u);
  EXPECT_FALSE(c.last_rejection.empty());
  std::optional<x3d::SurfaceFrame> f = sub.next_frame(0.0);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->time_s, 1.25);
  EXPECT_EQ(f->vertices_m.size(), 12u);
  EXPECT_EQ(f->triangles.size(), 10u);
  for (std::uint64_t k = 0; k < accepted_damaged; ++k) {
    f = sub.next_frame(0.0);
    ASSERT_TRUE(f.has_value());
    x3d::validate_frame(*f, false, "damaged but accepted");  // whatever got through is drawable-safe
  }
  EXPECT_FALSE(sub.next_frame(0.05).has_value());
}

TEST(LcmMeshSubscriber, KeepsTheNewestFramesWhenTheReaderFallsBehind) {
  LcmMeshSubscriber sub("memq://");
  // Frame i at time i: the reader must get the newest kMaxPending in order
  // (the 5 oldest are the ones dropped, not the 5 newest).
  for (std::size_t i = 0; i < LcmMeshSubscriber::kMaxPending + 5; ++i) {
    const std::vector<std::uint8_t> frame = encoded_mesh(2, static_cast<double>(i));
    sub.on_message(frame.data(), frame.size());
  }
  EXPECT_EQ(sub.counts().overflow, 5u);
  std::vector<double> times;
  while (const auto f = sub.next_frame(0.0)) times.push_back(f->time_s);
  ASSERT_EQ(times.size(), LcmMeshSubscriber::kMaxPending);
  for (std::size_t k = 0; k < times.size(); ++k) EXPECT_EQ(times[k], static_cast<double>(k + 5)) << k;
}

// The LCM subscriber counts the gaps of every decoded message, the ones
// whose content it then refuses included (they did arrive).
TEST(LcmMeshSubscriber, CountsTheMessagesThatNeverArrived) {
  LcmMeshSubscriber sub("memq://");
  for (const std::int64_t s : {1, 2, 6, 7}) {
    const std::vector<std::uint8_t> m = encoded_mesh(2, static_cast<double>(s), s);
    sub.on_message(m.data(), m.size());
  }
  EXPECT_EQ(sub.counts().missed, 3u);
  std::vector<std::uint8_t> bad = encoded_mesh(2, 8.0, 8);
  put_be32(bad, 8 + 8 + 8 + 8 + 4 * 18 + 6 + 8, 99);  // the first triangle index: past the 6 vertices
  sub.on_message(bad.data(), bad.size());
  const std::vector<std::uint8_t> next = encoded_mesh(2, 9.0, 9);
  sub.on_message(next.data(), next.size());
  EXPECT_EQ(sub.counts().rejected, 1u);
  EXPECT_EQ(sub.counts().missed, 3u) << "a refused message arrived: it is not missed";
}

TEST(LcmMeshSubscriber, ABadUrlIsAnErrorNamingIt) {
  try {
    LcmMeshSubscriber sub("nosuchprovider://x");
    FAIL() << "accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("nosuchprovider://x"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tissue::transport
