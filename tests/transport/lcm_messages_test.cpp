// The daemon's state as LCM messages (daemon/transport/lcm_messages): every
// field of every message, the length fields LCM's encoder trusts, bounds on
// every axis, and the gaps of a short snapshot. Pure conversions: no network.
// (lcm_publisher_test.cpp checks the first encode/decode round trip and the
// zeros sent for missing strain; these go field by field.)
#include "transport/lcm_messages.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "support/process_support.hpp"
#include "transport/lcm_subscriber.hpp"
#include "transport/mesh_subscriber.hpp"
#include "transport/transport_test_support.hpp"

namespace tissue::transport {
namespace {

using tissue_lcm::tissue::surface_mesh;

using testing::bent_strip;

std::vector<std::uint8_t> encode(const surface_mesh& m) {
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(bytes.data(), 0, static_cast<int>(bytes.size())), static_cast<int>(bytes.size()));
  return bytes;
}

// The message's arrays back as a frame, as LcmMeshSubscriber decodes them.
x3d::SurfaceFrame as_frame(const surface_mesh& m) {
  return frame_from_mesh_arrays(
      m.time_s, m.vertex_m,
      {reinterpret_cast<const std::uint8_t*>(m.vertex_refinement_level.data()), m.vertex_refinement_level.size()},
      m.triangle_vertex, m.triangle_strain_energy_density_J_per_m3);
}

void expect_counts_match_arrays(const surface_mesh& m, std::size_t vertices, std::size_t triangles) {
  EXPECT_EQ(m.vertex_count, static_cast<std::int32_t>(vertices));
  EXPECT_EQ(m.vertex_coordinate_count, static_cast<std::int32_t>(3 * vertices));
  EXPECT_EQ(m.vertex_m.size(), 3 * vertices);
  EXPECT_EQ(m.vertex_refinement_level.size(), vertices);
  EXPECT_EQ(m.triangle_count, static_cast<std::int32_t>(triangles));
  EXPECT_EQ(m.triangle_index_count, static_cast<std::int32_t>(3 * triangles));
  EXPECT_EQ(m.triangle_vertex.size(), 3 * triangles);
  EXPECT_EQ(m.triangle_strain_energy_density_J_per_m3.size(), triangles);
  // The receiving side's check of exactly these length fields.
  const std::vector<std::uint8_t> bytes = encode(m);
  EXPECT_EQ(lcm_mesh_layout_error(bytes.data(), bytes.size()), "");
}

TEST(LcmMessages, LengthFieldsFollowTheMeshThroughReuseAndPassTheLayoutCheck) {
  surface_mesh m;
  for (const int quads : {40, 3, 0, 1, 7}) {  // grow, shrink, empty, grow again: one message reused
    SCOPED_TRACE(quads);
    service::MeshSnapshot s = bent_strip(quads);
    if (quads == 0) s = service::MeshSnapshot{};
    to_message(s, quads, &m);
    expect_counts_match_arrays(m, s.vertices_m.size(), s.triangles.size());
    EXPECT_EQ(m.sequence_number, quads);
  }
}

// Library -> wire -> library: every coordinate, index, level and strain
// value arrives where it was, as the subscriber decodes it.
TEST(LcmMessages, EveryValueOfTheMeshArrivesInItsPlace) {
  const service::MeshSnapshot s = bent_strip(25);
  surface_mesh m;
  to_message(s, 77, &m);
  const std::vector<std::uint8_t> bytes = encode(m);
  surface_mesh back;
  ASSERT_EQ(back.decode(bytes.data(), 0, static_cast<int>(bytes.size())), static_cast<int>(bytes.size()));
  EXPECT_EQ(back.sequence_number, 77);
  testing::expect_frame_is_snapshot(as_frame(back), s);
}

TEST(LcmMessages, BoundsAreTheExtentOfTheVerticesOnEveryAxis) {
  service::MeshSnapshot s;
  s.vertices_m = {{0.5, -2.0, 3.0}, {-1.5, 4.0, -0.25}, {2.5, 1.0, 7.5}, {0.0, -3.0, 0.0}};
  s.triangles = {{0, 1, 2}, {1, 2, 3}};
  surface_mesh m;
  to_message(s, 1, &m);
  EXPECT_EQ((std::vector<double>(m.bounds_min_m, m.bounds_min_m + 3)), (std::vector<double>{-1.5, -3.0, -0.25}));
  EXPECT_EQ((std::vector<double>(m.bounds_max_m, m.bounds_max_m + 3)), (std::vector<double>{2.5, 4.0, 7.5}));
  // Bounds are of the double positions, before the float rounding of vertex_m.
  s.vertices_m = {{0.1, 0.2, 0.3}};
  to_message(s, 2, &m);
  EXPECT_EQ(m.bounds_min_m[0], 0.1);
  EXPECT_EQ(m.bounds_max_m[2], 0.3);
  // No vertices: zeros, not +-infinity (a reused message keeps none of the old).
  to_message(service::MeshSnapshot{}, 3, &m);
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(m.bounds_min_m[a], 0.0) << a;
    EXPECT_EQ(m.bounds_max_m[a], 0.0) << a;
  }
}

// A snapshot whose level array is short (a producer bug) sends level 0 for
// the vertices it lacks, never bytes from past its end.
TEST(LcmMessages, MissingVertexLevelsAreSentAsZero) {
  service::MeshSnapshot s = bent_strip(4);  // 10 vertices
  s.vertex_level = {5, 6, 7};
  surface_mesh m;
  to_message(s, 1, &m);
  ASSERT_EQ(m.vertex_refinement_level.size(), 10u);
  for (std::size_t i = 0; i < 10; ++i)
    EXPECT_EQ(m.vertex_refinement_level[i], i < 3 ? static_cast<std::int8_t>(5 + i) : 0) << "vertex " << i;
  s.vertex_level.clear();
  to_message(s, 2, &m);
  ASSERT_EQ(m.vertex_refinement_level.size(), 10u);
  for (const std::int8_t level : m.vertex_refinement_level) EXPECT_EQ(level, 0);
}

service::SimStatus distinct_status() {
  service::SimStatus st;
  st.sim_time_s = 3.125;
  st.nodes = 1001;
  st.tets = 4002;
  st.springs = 6003;
  st.refines = 104;
  st.merges = 55;
  st.kinetic_energy_J = 1.5e-4;
  st.elastic_energy_J = 2.5e-3;
  st.real_time_factor = 0.875;
  st.step_ms_last = 0.625;
  st.step_ms_max_window = 9.0;  // not on the wire: must not leak into step_ms
  st.device_position_m = {0.011, -0.012, 0.013};
  st.proxy_position_m = {0.021, -0.022, 0.023};
  st.force_on_device_N = {-0.31, 0.32, -0.33};
  st.tool_contact = false;
  st.model_version = (std::uint64_t{1} << 40) + 9;  // the sim's newest: not what the loop rendered
  st.tick_model_version = (std::uint64_t{1} << 40) + 3;
  return st;
}

TEST(LcmMessages, SimStatsCarryEveryField) {
  const auto m = to_message(distinct_status(), 12);
  EXPECT_EQ(m.time_s, 3.125);
  EXPECT_EQ(m.sequence_number, 12);
  EXPECT_EQ(m.real_time_factor, 0.875);
  EXPECT_EQ(m.step_ms, 0.625);
  EXPECT_EQ(m.node_count, 1001);
  EXPECT_EQ(m.tet_count, 4002);
  EXPECT_EQ(m.spring_count, 6003);
  EXPECT_EQ(m.refine_count, 104);
  EXPECT_EQ(m.merge_count, 55);
  EXPECT_EQ(m.kinetic_energy_J, 1.5e-4);
  EXPECT_EQ(m.elastic_energy_J, 2.5e-3);
}

TEST(LcmMessages, HapticStateCarriesEveryAxisAndTheContactFlagBothWays) {
  service::SimStatus st = distinct_status();
  auto m = haptic_message(st, 13);
  EXPECT_EQ(m.time_s, 3.125);
  EXPECT_EQ(m.sequence_number, 13);
  for (int a = 0; a < 3; ++a) {
    SCOPED_TRACE(a);
    EXPECT_EQ(m.device_position_m[a], st.device_position_m[a]);
    EXPECT_EQ(m.proxy_position_m[a], st.proxy_position_m[a]);
    EXPECT_EQ(m.force_N[a], st.force_on_device_N[a]);
  }
  EXPECT_FALSE(m.in_contact);
  EXPECT_EQ(m.local_model_version, (std::int64_t{1} << 40) + 3);
  st.tool_contact = true;
  EXPECT_TRUE(haptic_message(st, 14).in_contact);
}

// proto/README.md's table of topics and channels is what subscribers go by.
TEST(LcmMessages, ChannelNamesAreTheDocumentedOnes) {
  const std::string readme = tissue::testing::slurp(std::string(TISSUE_SOURCE_DIR) + "/proto/README.md");
  ASSERT_FALSE(readme.empty());
  for (const auto& [message, channel] : {std::pair<std::string, std::string>{"surface_mesh", kSurfaceMeshChannel},
                                         {"haptic_state", kHapticStateChannel},
                                         {"sim_stats", kSimStatsChannel}}) {
    const std::string row = "| `" + message + "` | `tissue/" + message + "` | `" + channel + "` |";
    EXPECT_NE(readme.find(row), std::string::npos) << "proto/README.md has no row " << row;
  }
}

}  // namespace
}  // namespace tissue::transport
