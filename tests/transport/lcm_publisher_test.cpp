#include "transport/lcm_publisher.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "transport/lcm_messages.hpp"
#include "transport/lcm_subscriber.hpp"
#include "transport/transport_test_support.hpp"

namespace tissue::transport {
namespace {

using tissue_lcm::tissue::surface_mesh;

// A strip of `quads` x 1 squares at z = 0, two triangles each.
service::MeshSnapshot strip(int quads) {
  service::MeshSnapshot s;
  s.sequence = 1;
  s.sim_time_s = 0.25;
  for (int i = 0; i <= quads; ++i) {
    s.vertices_m.push_back({0.001 * i, 0.0, 0.0});
    s.vertices_m.push_back({0.001 * i, 0.001, 0.0});
    s.vertex_level.push_back(static_cast<std::uint8_t>(i % 7));
    s.vertex_level.push_back(static_cast<std::uint8_t>(i % 5));
  }
  for (std::uint32_t i = 0; i < static_cast<std::uint32_t>(quads); ++i) {
    s.triangles.push_back({2 * i, 2 * i + 2, 2 * i + 3});
    s.triangles.push_back({2 * i, 2 * i + 3, 2 * i + 1});
  }
  // Distinct per triangle, so a dropped, zeroed or shifted value shows.
  for (std::size_t t = 0; t < s.triangles.size(); ++t)
    s.triangle_strain_energy_J_per_m3.push_back(12.5f + 0.25f * static_cast<float>(t));
  return s;
}

void expect_mesh_equals(const surface_mesh& m, const service::MeshSnapshot& s) {
  ASSERT_EQ(m.vertex_count, static_cast<std::int32_t>(s.vertices_m.size()));
  ASSERT_EQ(m.triangle_count, static_cast<std::int32_t>(s.triangles.size()));
  EXPECT_EQ(m.time_s, s.sim_time_s);
  for (std::size_t i = 0; i < s.vertices_m.size(); i += 97) {
    for (int a = 0; a < 3; ++a) EXPECT_EQ(m.vertex_m[3 * i + a], static_cast<float>(s.vertices_m[i][a]));
    EXPECT_EQ(m.vertex_refinement_level[i], static_cast<std::int8_t>(s.vertex_level[i]));
  }
  ASSERT_EQ(m.triangle_strain_energy_density_J_per_m3.size(), s.triangles.size());
  for (std::size_t t = 0; t < s.triangles.size(); ++t)
    EXPECT_EQ(m.triangle_strain_energy_density_J_per_m3[t], s.triangle_strain_energy_J_per_m3[t])
        << "strain of triangle " << t;
  for (std::size_t t = 0; t < s.triangles.size(); t += 89)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(m.triangle_vertex[3 * t + k], static_cast<std::int32_t>(s.triangles[t][k]));
  EXPECT_EQ(m.bounds_min_m[0], 0.0);
  EXPECT_DOUBLE_EQ(m.bounds_max_m[0], s.vertices_m.back()[0]);
  EXPECT_DOUBLE_EQ(m.bounds_max_m[1], 0.001);
}

TEST(LcmMessages, SurfaceMeshEncodesAndDecodesWithItsBounds) {
  const service::MeshSnapshot s = strip(500);
  surface_mesh m;
  to_message(s, 42, &m);
  EXPECT_EQ(m.sequence_number, 42);
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(m.getEncodedSize()));
  ASSERT_EQ(m.encode(bytes.data(), 0, static_cast<int>(bytes.size())), static_cast<int>(bytes.size()));
  surface_mesh back;
  ASSERT_EQ(back.decode(bytes.data(), 0, static_cast<int>(bytes.size())), static_cast<int>(bytes.size()));
  expect_mesh_equals(back, s);
  EXPECT_EQ(back.triangle_strain_energy_density_J_per_m3.size(), s.triangles.size());
}

TEST(LcmMessages, ASnapshotWithoutOrWithShortStrainSendsZerosForTheMissingTriangles) {
  service::MeshSnapshot s = strip(4);
  s.triangle_strain_energy_J_per_m3.resize(3);  // short: a producer bug must not read past the end
  surface_mesh m;
  to_message(s, 1, &m);
  ASSERT_EQ(m.triangle_strain_energy_density_J_per_m3.size(), 8u);
  for (std::size_t t = 0; t < 8; ++t)
    EXPECT_EQ(m.triangle_strain_energy_density_J_per_m3[t], t < 3 ? s.triangle_strain_energy_J_per_m3[t] : 0.0f) << t;
  s.triangle_strain_energy_J_per_m3.clear();
  to_message(s, 2, &m);  // reused message: the old values must not survive
  ASSERT_EQ(m.triangle_strain_energy_density_J_per_m3.size(), 8u);
  for (const float e : m.triangle_strain_energy_density_J_per_m3) EXPECT_EQ(e, 0.0f);
}

TEST(LcmMessages, StatusBecomesStatsAndHapticState) {
  service::SimStatus st;
  st.sim_time_s = 1.5;
  st.nodes = 610;
  st.tets = 2560;
  st.refines = 485;
  st.real_time_factor = 0.98;
  st.device_position_m = {0.1, 0.2, 0.3};
  st.force_on_device_N = {0, 0, 0.7};
  st.tool_contact = true;
  st.model_version = 100;
  st.tick_model_version = 99;
  const auto stats = to_message(st, 3);
  EXPECT_EQ(stats.node_count, 610);
  EXPECT_EQ(stats.tet_count, 2560);
  EXPECT_EQ(stats.refine_count, 485);
  EXPECT_EQ(stats.real_time_factor, 0.98);
  const auto haptic = haptic_message(st, 4);
  EXPECT_EQ(haptic.device_position_m[2], 0.3);
  EXPECT_EQ(haptic.force_N[2], 0.7);
  EXPECT_TRUE(haptic.in_contact);
  EXPECT_EQ(haptic.local_model_version, 99);
}

TEST(LcmPublisher, AnUnusableUrlIsAClearError) {
  try {
    LcmPublisher p("bogus://nowhere");
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("bogus://nowhere"), std::string::npos) << e.what();
  }
}

// LCM's TCP provider reports good() even when it could not connect, and
// has no socket then: the publisher refuses it, pointing at LCM's message.
TEST(LcmPublisher, AProviderThatCouldNotConnectIsAStartError) {
  const std::string url = testing::refused_tcpq_url();
  try {
    LcmPublisher p(url);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(url), std::string::npos) << what;
    EXPECT_NE(what.find("LCM's own message"), std::string::npos) << what;
    EXPECT_EQ(what.find("multicast"), std::string::npos) << what;
  }
}

// Over UDP multicast on a private loopback (the ctest entry runs this test
// inside tests/transport/in_netns.sh): a > 2 MB mesh reaches two subscribers.
// Plain-function handlers (subscribeFunction): LCM's member-function
// subscription template trips UBSan inside liblcm's header.
struct Received {
  std::optional<surface_mesh> mesh;
  int stats = 0;
};
void on_mesh(const lcm::ReceiveBuffer*, const std::string&, const surface_mesh* m, Received* r) { r->mesh = *m; }
void on_stats(const lcm::ReceiveBuffer*, const std::string&, const tissue_lcm::tissue::sim_stats*, Received* r) {
  ++r->stats;
}

TEST(LcmPublisherNetns, LargeMeshReachesTwoSubscribers) {
  const char* url = std::getenv("TISSUE_TEST_LCM_URL");
  if (!url) GTEST_SKIP() << "run through tests/transport/in_netns.sh (ctest does)";
  lcm::LCM sub_a(url), sub_b(url);
  ASSERT_TRUE(sub_a.good() && sub_b.good());
  Received a, b;
  sub_a.subscribeFunction(kSurfaceMeshChannel, &on_mesh, &a);
  sub_b.subscribeFunction(kSurfaceMeshChannel, &on_mesh, &b);
  sub_a.subscribeFunction(kSimStatsChannel, &on_stats, &a);
  LcmPublisher publisher(url);
  const service::MeshSnapshot big = strip(70000);  // 140k vertices, 140k triangles: ~3.9 MB encoded
  surface_mesh probe;
  to_message(big, 1, &probe);
  ASSERT_GT(probe.getEncodedSize(), 2 << 20);
  publisher.publish_mesh(big);
  publisher.publish_mesh(big);  // the same sequence again: not re-sent
  publisher.publish_stats(service::SimStatus{});
  EXPECT_EQ(publisher.counts().meshes, 1u);
  for (int i = 0; i < 50 && !(a.mesh && b.mesh && a.stats > 0); ++i) {
    sub_a.handleTimeout(100);
    sub_b.handleTimeout(100);
  }
  ASSERT_TRUE(a.mesh.has_value());
  ASSERT_TRUE(b.mesh.has_value());
  expect_mesh_equals(*a.mesh, big);
  expect_mesh_equals(*b.mesh, big);
  EXPECT_EQ(a.stats, 1);
}

void count_message(const lcm::ReceiveBuffer*, const std::string&, std::size_t* n) { ++*n; }

// The port of a udpm:// URL ("udpm://GROUP:PORT?options").
unsigned long udpm_port(const std::string& url) {
  const std::size_t end = url.find('?');
  const std::size_t colon = url.rfind(':', end);
  return std::stoul(url.substr(colon + 1, end == std::string::npos ? std::string::npos : end - colon - 1));
}

// True when no UDP socket on `port` in this (private) network namespace holds
// an unread datagram (/proc/net/udp's rx_queue): every LCM receive thread
// listening there has taken what was sent.
bool udp_port_drained(unsigned long port) {
  std::ifstream in("/proc/net/udp");
  std::string line;
  std::getline(in, line);  // the header
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::string slot, local, remote, state, queues;
    fields >> slot >> local >> remote >> state >> queues;  // queues: "tx:rx" in hex
    if (std::stoul(local.substr(local.rfind(':') + 1), nullptr, 16) != port) continue;
    if (std::stoul(queues.substr(queues.find(':') + 1), nullptr, 16) != 0) return false;
  }
  return true;
}

// A mesh reader that falls behind gets the newest frames and counts the older
// ones it missed, over a real provider. Before, LcmMeshSubscriber ran one LCM
// handle call per wait, which dispatches one message: its queue never held
// more than one frame, overflow stayed 0 and a slow reader got the oldest
// frames (LCM itself drops the newest once its own queue is full). Found by
// the review of the LCM subscriber; the memq:// test of the queue
// (mesh_subscriber_test.cpp) feeds on_message() directly and could not see it.
TEST(LcmPublisherNetns, ASlowMeshReaderGetsTheNewestFramesAndCountsTheOlder) {
  const char* url = std::getenv("TISSUE_TEST_LCM_URL");
  if (!url) GTEST_SKIP() << "run through tests/transport/in_netns.sh (ctest does)";
  LcmMeshSubscriber sub(url);
  // Reads as the meshes come: once it has them all, they have reached every
  // socket on the group (a loss on loopback fails here, not later).
  lcm::LCM witness(url);
  ASSERT_TRUE(witness.good());
  std::size_t witnessed = 0;
  witness.subscribeFunction(kSurfaceMeshChannel, &count_message, &witnessed)->setQueueCapacity(0);
  LcmPublisher publisher(url);
  constexpr std::size_t kSent = LcmMeshSubscriber::kMaxPending + 5;
  for (std::size_t i = 0; i < kSent; ++i) {
    service::MeshSnapshot s = strip(1);  // ~200 bytes: one datagram each
    s.sequence = i + 1;
    s.sim_time_s = static_cast<double>(i);
    publisher.publish_mesh(s);
  }
  ASSERT_EQ(publisher.counts().meshes, kSent);
  for (int i = 0; i < 100 && witnessed < kSent; ++i) witness.handleTimeout(100);
  ASSERT_EQ(witnessed, kSent);
  // ... and once the sockets are empty, the subscriber's LCM receive thread has
  // read them all (it holds at most the last one, not yet queued), so the
  // reader is now behind by at least kSent - 1 messages. (Without this wait
  // the receive thread lagged the witness in about 1 run in 20 at load 8.)
  const unsigned long port = udpm_port(url);
  for (int i = 0; i < 100 && !udp_port_drained(port); ++i) witness.handleTimeout(10);
  ASSERT_TRUE(udp_port_drained(port)) << "datagrams still unread on port " << port << " after 1 s";

  std::vector<double> times;
  while (const auto f = sub.next_frame(sub.counts().received < kSent ? 5.0 : 0.0)) times.push_back(f->time_s);
  const MeshReceiveCounts& c = sub.counts();
  EXPECT_EQ(c.received, kSent);
  EXPECT_EQ(c.accepted, kSent);
  // 5; 4 when the last message was still between the socket and LCM's queue
  // at the first read (it then joins the 63 left, with no overflow).
  EXPECT_GE(c.overflow, 4u);
  EXPECT_LE(c.overflow, 5u);
  ASSERT_EQ(times.size() + c.overflow, kSent);
  // The frames read are the newest, in order: the dropped ones are the oldest.
  for (std::size_t k = 0; k < times.size(); ++k)
    EXPECT_EQ(times[k], static_cast<double>(c.overflow + k)) << "frame " << k << " of " << times.size();
}

}  // namespace
}  // namespace tissue::transport
