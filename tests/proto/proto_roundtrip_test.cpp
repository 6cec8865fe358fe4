// Every generated type survives its own encoding: LCM encode -> decode, and
// Fast DDS PubSubType serialize -> deserialize through a SerializedPayload_t
// (Fast CDR), with no network. Also pins the device_packet wire layout that
// proto/README.md documents for people writing the device side by hand.
#include <gtest/gtest.h>

#include <cstring>
#include <type_traits>
#include <vector>

#include "tissue_dds/device_packetPubSubTypes.h"
#include "tissue_dds/haptic_statePubSubTypes.h"
#include "tissue_dds/sim_statsPubSubTypes.h"
#include "tissue_dds/surface_meshPubSubTypes.h"
#include "tissue_lcm/tissue/device_packet.hpp"
#include "tissue_lcm/tissue/haptic_state.hpp"
#include "tissue_lcm/tissue/sim_stats.hpp"
#include "tissue_lcm/tissue/surface_mesh.hpp"

namespace {

namespace lcmt = tissue_lcm::tissue;

// A mesh larger than fastddsgen's 100-element size estimate for unbounded
// sequences, so the test covers the real-size path.
constexpr int kVertices = 500;
constexpr int kTriangles = 900;

template <typename T>
std::vector<unsigned char> lcm_encode(const T& msg) {
  std::vector<unsigned char> bytes(static_cast<std::size_t>(msg.getEncodedSize()));
  const int n = msg.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  EXPECT_EQ(n, static_cast<int>(bytes.size()));
  return bytes;
}

template <typename T>
T lcm_round_trip(const T& msg) {
  const std::vector<unsigned char> bytes = lcm_encode(msg);
  T back;
  EXPECT_EQ(back.decode(bytes.data(), 0, static_cast<int>(bytes.size())), static_cast<int>(bytes.size()));
  EXPECT_EQ(lcm_encode(back), bytes);  // and it encodes to the same bytes again
  // One byte short must fail, not read past the end.
  T truncated;
  EXPECT_LT(truncated.decode(bytes.data(), 0, static_cast<int>(bytes.size()) - 1), 0);
  return back;
}

template <typename PubSub, typename T>
T dds_round_trip(const T& msg) {
  PubSub type;
  T copy = msg;
  const uint32_t size = type.getSerializedSizeProvider(&copy)();
  eprosima::fastrtps::rtps::SerializedPayload_t payload(size);
  EXPECT_TRUE(type.serialize(&copy, &payload));
  EXPECT_GT(payload.length, 4u);
  EXPECT_LE(payload.length, size);
  T back;
  EXPECT_TRUE(type.deserialize(&payload, &back));
  return back;
}

template <std::size_t N>
void expect_array_eq(const double (&a)[N], const double (&b)[N]) {
  for (std::size_t i = 0; i < N; ++i) EXPECT_EQ(a[i], b[i]) << i;
}

lcmt::surface_mesh lcm_mesh() {
  lcmt::surface_mesh m;
  m.time_s = 12.5;
  m.sequence_number = 4242;
  m.vertex_count = kVertices;
  m.vertex_coordinate_count = 3 * kVertices;
  for (int i = 0; i < 3 * kVertices; ++i) m.vertex_m.push_back(0.001f * static_cast<float>(i) - 0.25f);
  for (int i = 0; i < kVertices; ++i) m.vertex_refinement_level.push_back(static_cast<uint8_t>(i % 7 + 200));
  m.triangle_count = kTriangles;
  m.triangle_index_count = 3 * kTriangles;
  for (int i = 0; i < 3 * kTriangles; ++i) m.triangle_vertex.push_back((i * 37) % kVertices);
  for (int i = 0; i < kTriangles; ++i)
    m.triangle_strain_energy_density_J_per_m3.push_back(1.5f * static_cast<float>(i));
  const double lo[3] = {-0.25, -0.1, -1e-9}, hi[3] = {1.25, 0.1, 3.0};
  std::memcpy(m.bounds_min_m, lo, sizeof lo);
  std::memcpy(m.bounds_max_m, hi, sizeof hi);
  return m;
}

TEST(LcmRoundTrip, SurfaceMesh) {
  const lcmt::surface_mesh m = lcm_mesh();
  const lcmt::surface_mesh b = lcm_round_trip(m);
  EXPECT_EQ(b.time_s, m.time_s);
  EXPECT_EQ(b.sequence_number, m.sequence_number);
  EXPECT_EQ(b.vertex_count, m.vertex_count);
  EXPECT_EQ(b.vertex_coordinate_count, m.vertex_coordinate_count);
  EXPECT_EQ(b.vertex_m, m.vertex_m);
  EXPECT_EQ(b.vertex_refinement_level, m.vertex_refinement_level);
  EXPECT_EQ(b.triangle_count, m.triangle_count);
  EXPECT_EQ(b.triangle_index_count, m.triangle_index_count);
  EXPECT_EQ(b.triangle_vertex, m.triangle_vertex);
  EXPECT_EQ(b.triangle_strain_energy_density_J_per_m3, m.triangle_strain_energy_density_J_per_m3);
  expect_array_eq(b.bounds_min_m, m.bounds_min_m);
  expect_array_eq(b.bounds_max_m, m.bounds_max_m);
}

TEST(LcmRoundTrip, EmptySurfaceMesh) {
  lcmt::surface_mesh m{};
  const lcmt::surface_mesh b = lcm_round_trip(m);
  EXPECT_EQ(b.vertex_count, 0);
  EXPECT_TRUE(b.vertex_m.empty());
  EXPECT_TRUE(b.triangle_vertex.empty());
}

TEST(LcmRoundTrip, HapticState) {
  lcmt::haptic_state m{};
  m.time_s = 3.25;
  m.sequence_number = -7;
  const double d[3] = {0.1, -0.2, 0.3}, p[3] = {0.11, -0.19, 0.29}, f[3] = {-1.5, 2.25, 0.0};
  std::memcpy(m.device_position_m, d, sizeof d);
  std::memcpy(m.proxy_position_m, p, sizeof p);
  std::memcpy(m.force_N, f, sizeof f);
  m.in_contact = 1;
  m.local_model_version = 1234567890123LL;
  const lcmt::haptic_state b = lcm_round_trip(m);
  EXPECT_EQ(b.time_s, m.time_s);
  EXPECT_EQ(b.sequence_number, m.sequence_number);
  expect_array_eq(b.device_position_m, m.device_position_m);
  expect_array_eq(b.proxy_position_m, m.proxy_position_m);
  expect_array_eq(b.force_N, m.force_N);
  EXPECT_EQ(b.in_contact, 1);
  EXPECT_EQ(b.local_model_version, m.local_model_version);
}

TEST(LcmRoundTrip, SimStats) {
  lcmt::sim_stats m{};
  m.time_s = 100.0;
  m.sequence_number = 99;
  m.real_time_factor = 0.97;
  m.step_ms = 0.8;
  m.node_count = 1000;
  m.tet_count = 4500;
  m.spring_count = 6000;
  m.refine_count = 1LL << 40;
  m.merge_count = 77;
  m.kinetic_energy_J = 1e-6;
  m.elastic_energy_J = 2.5e-3;
  const lcmt::sim_stats b = lcm_round_trip(m);
  EXPECT_EQ(b.time_s, m.time_s);
  EXPECT_EQ(b.sequence_number, m.sequence_number);
  EXPECT_EQ(b.real_time_factor, m.real_time_factor);
  EXPECT_EQ(b.step_ms, m.step_ms);
  EXPECT_EQ(b.node_count, m.node_count);
  EXPECT_EQ(b.tet_count, m.tet_count);
  EXPECT_EQ(b.spring_count, m.spring_count);
  EXPECT_EQ(b.refine_count, m.refine_count);
  EXPECT_EQ(b.merge_count, m.merge_count);
  EXPECT_EQ(b.kinetic_energy_J, m.kinetic_energy_J);
  EXPECT_EQ(b.elastic_energy_J, m.elastic_energy_J);
}

lcmt::device_packet lcm_packet() {
  lcmt::device_packet m{};
  m.version = 1;
  m.kind = 1;
  m.sequence_number = 0x0102030405060708LL;
  m.sender_time_ns = 123456789;
  m.echo_sequence_number = 5;
  m.echo_sender_time_ns = 6;
  const double p[3] = {0.01, -0.02, 0.03}, v[3] = {0.5, 0.0, -0.5}, f[3] = {1.0, 2.0, -3.0};
  std::memcpy(m.position_m, p, sizeof p);
  std::memcpy(m.velocity_m_per_s, v, sizeof v);
  std::memcpy(m.force_N, f, sizeof f);
  m.buttons = 0x5;
  return m;
}

TEST(LcmRoundTrip, DevicePacket) {
  const lcmt::device_packet m = lcm_packet();
  const lcmt::device_packet b = lcm_round_trip(m);
  EXPECT_EQ(b.version, m.version);
  EXPECT_EQ(b.kind, m.kind);
  EXPECT_EQ(b.sequence_number, m.sequence_number);
  EXPECT_EQ(b.sender_time_ns, m.sender_time_ns);
  EXPECT_EQ(b.echo_sequence_number, m.echo_sequence_number);
  EXPECT_EQ(b.echo_sender_time_ns, m.echo_sender_time_ns);
  expect_array_eq(b.position_m, m.position_m);
  expect_array_eq(b.velocity_m_per_s, m.velocity_m_per_s);
  EXPECT_EQ(b.buttons, m.buttons);
  expect_array_eq(b.force_N, m.force_N);
}

std::uint64_t be64(const std::vector<unsigned char>& b, std::size_t at) {
  std::uint64_t v = 0;
  for (std::size_t i = 0; i < 8; ++i) v = (v << 8) | b[at + i];
  return v;
}

double be_double(const std::vector<unsigned char>& b, std::size_t at) {
  const std::uint64_t bits = be64(b, at);
  double d;
  std::memcpy(&d, &bits, sizeof d);
  return d;
}

// The byte layout proto/README.md gives to people writing the device side
// without LCM: big-endian, no padding, fingerprint first.
TEST(DevicePacketLayout, IsTheDocumentedOne) {
  const std::vector<unsigned char> b = lcm_encode(lcm_packet());
  ASSERT_EQ(b.size(), 121u);
  EXPECT_EQ(be64(b, 0), static_cast<std::uint64_t>(lcmt::device_packet::getHash()));
  EXPECT_EQ(be64(b, 0), 0x70a2805c6492b75aULL)
      << std::hex << be64(b, 0) << ": the fingerprint changed; update proto/README.md";
  EXPECT_EQ((b[8] << 24) | (b[9] << 16) | (b[10] << 8) | b[11], 1);    // version
  EXPECT_EQ(b[12], 1);                                                 // kind
  EXPECT_EQ(be64(b, 13), 0x0102030405060708ULL);                       // sequence_number
  EXPECT_EQ(be64(b, 21), 123456789u);                                  // sender_time_ns
  EXPECT_EQ(be64(b, 29), 5u);                                          // echo_sequence_number
  EXPECT_EQ(be64(b, 37), 6u);                                          // echo_sender_time_ns
  EXPECT_EQ(be_double(b, 45), 0.01);                                   // position_m[0]
  EXPECT_EQ(be_double(b, 61), 0.03);                                   // position_m[2]
  EXPECT_EQ(be_double(b, 69), 0.5);                                    // velocity_m_per_s[0]
  EXPECT_EQ(be_double(b, 85), -0.5);                                   // velocity_m_per_s[2]
  EXPECT_EQ((b[93] << 24) | (b[94] << 16) | (b[95] << 8) | b[96], 5);  // buttons
  EXPECT_EQ(be_double(b, 97), 1.0);                                    // force_N[0]
  EXPECT_EQ(be_double(b, 113), -3.0);                                  // force_N[2]
}

TEST(DdsRoundTrip, SurfaceMesh) {
  const lcmt::surface_mesh l = lcm_mesh();
  tissue::surface_mesh m;
  m.time_s(l.time_s);
  m.sequence_number(l.sequence_number);
  m.vertex_m(l.vertex_m);
  m.vertex_refinement_level(l.vertex_refinement_level);
  m.triangle_vertex(l.triangle_vertex);
  m.triangle_strain_energy_density_J_per_m3(l.triangle_strain_energy_density_J_per_m3);
  m.bounds_min_m({l.bounds_min_m[0], l.bounds_min_m[1], l.bounds_min_m[2]});
  m.bounds_max_m({l.bounds_max_m[0], l.bounds_max_m[1], l.bounds_max_m[2]});
  const tissue::surface_mesh b = dds_round_trip<tissue::surface_meshPubSubType>(m);
  EXPECT_TRUE(b == m);
  EXPECT_EQ(b.vertex_m().size(), 3u * kVertices);
  EXPECT_EQ(b.triangle_vertex(), l.triangle_vertex);
  EXPECT_EQ(b.bounds_max_m()[2], 3.0);
  tissue::surface_meshPubSubType type;
  EXPECT_STREQ(type.getName(), "tissue::surface_mesh");
}

TEST(DdsRoundTrip, HapticState) {
  tissue::haptic_state m;
  m.time_s(3.25);
  m.sequence_number(-7);
  m.device_position_m({0.1, -0.2, 0.3});
  m.proxy_position_m({0.11, -0.19, 0.29});
  m.force_N({-1.5, 2.25, 0.0});
  m.in_contact(true);
  m.local_model_version(1234567890123LL);
  const tissue::haptic_state b = dds_round_trip<tissue::haptic_statePubSubType>(m);
  EXPECT_TRUE(b == m);
  EXPECT_TRUE(b.in_contact());
  EXPECT_EQ(b.proxy_position_m()[1], -0.19);
}

TEST(DdsRoundTrip, SimStats) {
  tissue::sim_stats m;
  m.time_s(100.0);
  m.sequence_number(99);
  m.real_time_factor(0.97);
  m.step_ms(0.8);
  m.node_count(1000);
  m.tet_count(4500);
  m.spring_count(6000);
  m.refine_count(1LL << 40);
  m.merge_count(77);
  m.kinetic_energy_J(1e-6);
  m.elastic_energy_J(2.5e-3);
  const tissue::sim_stats b = dds_round_trip<tissue::sim_statsPubSubType>(m);
  EXPECT_TRUE(b == m);
  EXPECT_EQ(b.refine_count(), 1LL << 40);
}

TEST(DdsRoundTrip, DevicePacket) {
  tissue::device_packet m;
  m.version(1);
  m.kind(2);
  m.sequence_number(0x0102030405060708LL);
  m.sender_time_ns(123456789);
  m.echo_sequence_number(5);
  m.echo_sender_time_ns(6);
  m.position_m({0.01, -0.02, 0.03});
  m.velocity_m_per_s({0.5, 0.0, -0.5});
  m.buttons(5);
  m.force_N({1.0, 2.0, -3.0});
  const tissue::device_packet b = dds_round_trip<tissue::device_packetPubSubType>(m);
  EXPECT_TRUE(b == m);
  EXPECT_EQ(b.force_N()[2], -3.0);
}

// The two C++ namespaces keep the generated classes apart (proto/CMakeLists.txt).
TEST(ProtoTypes, LcmAndDdsClassesAreDistinct) {
  static_assert(!std::is_same_v<lcmt::device_packet, tissue::device_packet>);
  EXPECT_STREQ(lcmt::device_packet::getTypeName(), "device_packet");
}

}  // namespace
