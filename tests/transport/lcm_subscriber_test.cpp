// The LCM mesh subscriber (daemon/transport/lcm_subscriber): the layout check
// that stands between a datagram and LCM's trusting decoder, reason by
// reason, and how on_message() files each kind of bad message. Fed bytes
// directly over LCM's in-process provider (memq://): no network.
// (mesh_subscriber_test.cpp throws random and damaged bytes at it and checks
// the totals and the queue.)
#include "transport/lcm_subscriber.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "transport/lcm_messages.hpp"
#include "transport/transport_test_support.hpp"

namespace tissue::transport {
namespace {

// 10 vertices, 8 triangles, as the daemon encodes them.
service::MeshSnapshot strip() {
  service::MeshSnapshot s;
  s.sim_time_s = 0.5;
  for (std::uint32_t i = 0; i <= 4; ++i) {
    s.vertices_m.push_back({0.01 * i, 0.0, 0.0});
    s.vertices_m.push_back({0.01 * i, 0.01, 0.0});
  }
  for (std::uint32_t i = 0; i < 4; ++i) {
    s.triangles.push_back({2 * i, 2 * i + 2, 2 * i + 3});
    s.triangles.push_back({2 * i, 2 * i + 3, 2 * i + 1});
  }
  return s;
}

using testing::lcm_encoded;
using testing::put_be32;

// Byte offsets of the length fields of an encoded surface_mesh.
constexpr std::size_t kVertexCountAt = 8 + 8 + 8;  // after fingerprint, time_s, sequence_number
constexpr std::size_t kCoordinateCountAt = kVertexCountAt + 4;
std::size_t triangle_count_at(std::size_t vertices) { return kCoordinateCountAt + 4 + 12 * vertices + vertices; }

std::string layout_error(const std::vector<std::uint8_t>& b) { return lcm_mesh_layout_error(b.data(), b.size()); }

// Waiting on an LCM whose TCP provider could not connect aborted the client
// (FD_SET of descriptor -1 inside lcm_handle_timeout): refused at the start
// instead, with exit 3 in the clients.
TEST(LcmSubscriber, AProviderThatCouldNotConnectIsAStartError) {
  const std::string url = testing::refused_tcpq_url();
  try {
    LcmMeshSubscriber subscriber(url);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(url), std::string::npos) << e.what();
  }
}

TEST(LcmSubscriber, LayoutErrorsNameTheFieldAndTheReason) {
  const std::vector<std::uint8_t> good = lcm_encoded(strip());
  const std::size_t n = good.size();
  ASSERT_EQ(layout_error(good), "");
  const std::size_t tc = triangle_count_at(10);

  std::vector<std::uint8_t> b(good.begin(), good.begin() + 5);
  EXPECT_EQ(layout_error(b), "message of 5 bytes is shorter than an LCM fingerprint");
  b = good;
  b[7] ^= 1;
  EXPECT_EQ(layout_error(b), "fingerprint is not surface_mesh's (another type, or another schema revision)");
  b.assign(good.begin(), good.begin() + 30);
  EXPECT_EQ(layout_error(b), "message of 30 bytes ends inside the vertex counts");

  b = good;
  put_be32(b, kCoordinateCountAt, 29);
  EXPECT_EQ(layout_error(b),
            "vertex_count 10 with vertex_coordinate_count 29 (must be 3 · vertex_count, vertex_count ≥ 0)");
  b = good;
  put_be32(b, kVertexCountAt, -1);
  put_be32(b, kCoordinateCountAt, -3);
  EXPECT_EQ(layout_error(b),
            "vertex_count -1 with vertex_coordinate_count -3 (must be 3 · vertex_count, vertex_count ≥ 0)");
  b = good;  // consistent, but far more than the message holds: never allocated
  put_be32(b, kVertexCountAt, 0x20000000);
  put_be32(b, kCoordinateCountAt, 0x60000000);
  EXPECT_EQ(layout_error(b), "message of " + std::to_string(n) + " bytes is too short for 536870912 vertices");

  b = good;
  put_be32(b, tc + 4, 25);
  EXPECT_EQ(layout_error(b),
            "triangle_count 8 with triangle_index_count 25 (must be 3 · triangle_count, triangle_count ≥ 0)");
  b = good;
  put_be32(b, tc, -2);
  put_be32(b, tc + 4, -6);
  EXPECT_EQ(layout_error(b),
            "triangle_count -2 with triangle_index_count -6 (must be 3 · triangle_count, triangle_count ≥ 0)");
  b = good;  // consistent counts, one triangle more than the bytes hold
  put_be32(b, tc, 9);
  put_be32(b, tc + 4, 27);
  EXPECT_EQ(layout_error(b),
            "message of " + std::to_string(n) +
                " bytes does not match its counts (10 vertices, 9 triangles: " + std::to_string(n + 16) + " bytes)");
  b = good;
  b.push_back(0);
  EXPECT_EQ(layout_error(b), "message of " + std::to_string(n + 1) +
                                 " bytes does not match its counts (10 vertices, 8 triangles: " + std::to_string(n) +
                                 " bytes)");
  b.assign(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(tc + 2));  // cut inside the triangle counts
  EXPECT_EQ(layout_error(b), "message of " + std::to_string(tc + 2) + " bytes is too short for 10 vertices");
  // The largest counts an int32 holds: no overflow in the size arithmetic.
  b = good;
  put_be32(b, tc, std::numeric_limits<std::int32_t>::max() / 3);
  put_be32(b, tc + 4, std::numeric_limits<std::int32_t>::max() / 3 * 3);
  EXPECT_NE(layout_error(b).find("does not match its counts"), std::string::npos) << layout_error(b);
}

// Each bad message is counted under its reason, with the full text kept;
// none reaches the queue.
TEST(LcmSubscriber, OnMessageFilesEachBadMessageUnderItsReason) {
  LcmMeshSubscriber sub("memq://");
  EXPECT_EQ(sub.name(), std::string("LCM channel TISSUE_SURFACE_MESH on memq://"));

  std::vector<std::uint8_t> b = lcm_encoded(strip());
  put_be32(b, kCoordinateCountAt, 29);
  sub.on_message(b.data(), b.size());
  EXPECT_EQ(sub.counts().rejected_by_reason.at("size"), 1u);
  EXPECT_EQ(sub.counts().last_rejection, layout_error(b));

  service::MeshSnapshot s = strip();
  s.vertices_m[3][1] = std::numeric_limits<double>::quiet_NaN();  // an exploded simulation
  b = lcm_encoded(s);
  ASSERT_EQ(layout_error(b), "") << "the layout is fine: the values are not";
  sub.on_message(b.data(), b.size());
  EXPECT_EQ(sub.counts().rejected_by_reason.at("non_finite"), 1u);
  EXPECT_EQ(sub.counts().last_rejection, "vertex 3 has a non-finite coordinate");

  s = strip();
  s.triangles[5][2] = 10;  // one past the last vertex
  b = lcm_encoded(s);
  sub.on_message(b.data(), b.size());
  EXPECT_EQ(sub.counts().rejected_by_reason.at("index"), 1u);
  EXPECT_EQ(sub.counts().last_rejection, "triangle 5 uses vertex 10 of 10");

  EXPECT_EQ(sub.counts().received, 3u);
  EXPECT_EQ(sub.counts().rejected, 3u);
  EXPECT_EQ(sub.counts().accepted, 0u);
  EXPECT_FALSE(sub.next_frame(0.0).has_value());

  b = lcm_encoded(strip());
  sub.on_message(b.data(), b.size());
  EXPECT_EQ(sub.counts().accepted, 1u);
  EXPECT_EQ(sub.counts().rejected, 3u);
  const auto f = sub.next_frame(0.0);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->vertices_m.size(), 10u);
}

}  // namespace
}  // namespace tissue::transport
