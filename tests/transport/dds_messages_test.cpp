// The daemon's state as Fast DDS messages (daemon/transport/dds_messages):
// every value of the mesh back through the subscriber's decoding, bounds on
// every axis, the gaps of a short snapshot, storage reuse, and the haptic
// state's every axis. Pure conversions: no participant, no network.
// (dds_publisher_test.cpp checks serialization, the zeros sent for missing
// strain, the empty mesh and the stats fields.)
#include "transport/dds_messages.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <vector>

#include "support/process_support.hpp"
#include "transport/mesh_subscriber.hpp"
#include "transport/transport_test_support.hpp"

namespace tissue::transport {
namespace {

using testing::bent_strip;

// The message's sequences back as a frame, as DdsMeshSubscriber decodes them.
x3d::SurfaceFrame as_frame(const ::tissue::surface_mesh& m) {
  return frame_from_mesh_arrays(m.time_s(), m.vertex_m(), m.vertex_refinement_level(), m.triangle_vertex(),
                                m.triangle_strain_energy_density_J_per_m3());
}

// Library -> wire -> library: every coordinate, index, level and strain
// value arrives where it was.
TEST(DdsMessages, EveryValueOfTheMeshArrivesInItsPlace) {
  const service::MeshSnapshot s = bent_strip(25);
  ::tissue::surface_mesh m;
  to_dds(s, 77, &m);
  EXPECT_EQ(m.sequence_number(), 77);
  testing::expect_frame_is_snapshot(as_frame(m), s);
}

TEST(DdsMessages, BoundsAreTheExtentOfTheVerticesOnEveryAxis) {
  service::MeshSnapshot s;
  s.vertices_m = {{0.5, -2.0, 3.0}, {-1.5, 4.0, -0.25}, {2.5, 1.0, 7.5}, {0.0, -3.0, 0.0}};
  s.triangles = {{0, 1, 2}, {1, 2, 3}};
  ::tissue::surface_mesh m;
  to_dds(s, 1, &m);
  EXPECT_EQ(m.bounds_min_m(), (std::array<double, 3>{-1.5, -3.0, -0.25}));
  EXPECT_EQ(m.bounds_max_m(), (std::array<double, 3>{2.5, 4.0, 7.5}));
  // Bounds are of the double positions, before the float rounding of vertex_m.
  s.vertices_m = {{0.1, 0.2, 0.3}};
  to_dds(s, 2, &m);
  EXPECT_EQ(m.bounds_min_m(), (std::array<double, 3>{0.1, 0.2, 0.3}));
  EXPECT_EQ(m.bounds_max_m(), (std::array<double, 3>{0.1, 0.2, 0.3}));
  // A reused message for an empty mesh: zeros, nothing of the old bounds.
  to_dds(service::MeshSnapshot{}, 3, &m);
  EXPECT_EQ(m.bounds_min_m(), (std::array<double, 3>{0, 0, 0}));
  EXPECT_EQ(m.bounds_max_m(), (std::array<double, 3>{0, 0, 0}));
}

// A snapshot whose level array is short (a producer bug) sends level 0 for
// the vertices it lacks, never bytes from past its end.
TEST(DdsMessages, MissingVertexLevelsAreSentAsZero) {
  service::MeshSnapshot s = bent_strip(4);  // 10 vertices
  s.vertex_level = {5, 6, 7};
  ::tissue::surface_mesh m;
  to_dds(s, 1, &m);
  ASSERT_EQ(m.vertex_refinement_level().size(), 10u);
  for (std::size_t i = 0; i < 10; ++i) EXPECT_EQ(m.vertex_refinement_level()[i], i < 3 ? 5 + i : 0u) << "vertex " << i;
  s.vertex_level.clear();
  to_dds(s, 2, &m);
  EXPECT_EQ(m.vertex_refinement_level(), std::vector<std::uint8_t>(10, 0));
}

// dds_messages.hpp: "a steady-size mesh does not allocate". The publisher
// converts every snapshot into one message; its sequences keep their storage
// and take the new values.
TEST(DdsMessages, ASteadySizeMeshReusesTheMessagesStorage) {
  ::tissue::surface_mesh m;
  to_dds(bent_strip(30, 1.0f), 1, &m);
  const float* xyz = m.vertex_m().data();
  const std::uint8_t* level = m.vertex_refinement_level().data();
  const std::int32_t* tri = m.triangle_vertex().data();
  const float* strain = m.triangle_strain_energy_density_J_per_m3().data();
  service::MeshSnapshot next = bent_strip(30, 100.0f);
  for (auto& v : next.vertices_m) v[2] += 0.25;  // the object moved
  to_dds(next, 2, &m);
  EXPECT_EQ(m.vertex_m().data(), xyz);
  EXPECT_EQ(m.vertex_refinement_level().data(), level);
  EXPECT_EQ(m.triangle_vertex().data(), tri);
  EXPECT_EQ(m.triangle_strain_energy_density_J_per_m3().data(), strain);
  // ...and the new values, not the old.
  const x3d::SurfaceFrame f = as_frame(m);
  EXPECT_EQ(f.vertices_m, next.vertices_m);
  EXPECT_EQ(f.triangle_strain_energy_J_per_m3, next.triangle_strain_energy_J_per_m3);
  EXPECT_EQ(m.sequence_number(), 2);
}

TEST(DdsMessages, HapticStateCarriesEveryAxisAndTheContactFlagBothWays) {
  service::SimStatus st;
  st.sim_time_s = 3.125;
  st.device_position_m = {0.011, -0.012, 0.013};
  st.proxy_position_m = {0.021, -0.022, 0.023};
  st.force_on_device_N = {-0.31, 0.32, -0.33};
  st.tool_contact = false;
  st.model_version = (std::uint64_t{1} << 40) + 9;  // the sim's newest: not what the loop rendered
  st.tick_model_version = (std::uint64_t{1} << 40) + 3;
  const ::tissue::haptic_state m = to_dds_haptic(st, 13);
  EXPECT_EQ(m.time_s(), 3.125);
  EXPECT_EQ(m.sequence_number(), 13);
  EXPECT_EQ(m.device_position_m(), st.device_position_m);
  EXPECT_EQ(m.proxy_position_m(), st.proxy_position_m);
  EXPECT_EQ(m.force_N(), st.force_on_device_N);
  EXPECT_FALSE(m.in_contact());
  EXPECT_EQ(m.local_model_version(), (std::int64_t{1} << 40) + 3);
  st.tool_contact = true;
  EXPECT_TRUE(to_dds_haptic(st, 14).in_contact());
}

// proto/README.md's table of topics and channels is what subscribers go by.
TEST(DdsMessages, TopicNamesAreTheDocumentedOnes) {
  const std::string readme = tissue::testing::slurp(std::string(TISSUE_SOURCE_DIR) + "/proto/README.md");
  ASSERT_FALSE(readme.empty());
  for (const auto& [message, topic] : {std::pair<std::string, std::string>{"surface_mesh", kSurfaceMeshTopic},
                                       {"haptic_state", kHapticStateTopic},
                                       {"sim_stats", kSimStatsTopic}}) {
    EXPECT_EQ(topic, message) << "topics are named after their message";
    const std::string row = "| `" + message + "` | `" + kDdsTopicPrefix + topic + "` |";
    EXPECT_NE(readme.find(row), std::string::npos) << "proto/README.md has no row " << row;
  }
}

}  // namespace
}  // namespace tissue::transport
