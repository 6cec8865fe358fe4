#include "transport/transport_test_support.hpp"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <string>

#include "transport/lcm_messages.hpp"

namespace tissue::transport::testing {

service::MeshSnapshot bent_strip(int quads, float strain_base) {
  service::MeshSnapshot s;
  s.sequence = 9;
  s.sim_time_s = 2.75;
  for (int i = 0; i <= quads; ++i)
    for (int row = 0; row < 2; ++row) {
      s.vertices_m.push_back({(i - quads / 2) / 64.0, (row ? 3 : -5) / 64.0, ((i * 7) % 5 - 2) / 64.0});
      s.vertex_level.push_back(static_cast<std::uint8_t>((2 * i + row) % 9));
    }
  for (std::uint32_t i = 0; i < static_cast<std::uint32_t>(quads); ++i) {
    s.triangles.push_back({2 * i, 2 * i + 2, 2 * i + 3});
    s.triangles.push_back({2 * i, 2 * i + 3, 2 * i + 1});
  }
  for (std::size_t t = 0; t < s.triangles.size(); ++t)
    s.triangle_strain_energy_J_per_m3.push_back(strain_base + static_cast<float>(t));
  return s;
}

std::vector<std::uint8_t> lcm_encoded(const service::MeshSnapshot& s, std::int64_t sequence) {
  tissue_lcm::tissue::surface_mesh m;
  to_message(s, sequence, &m);
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(bytes.data(), 0, static_cast<int>(bytes.size())), static_cast<int>(bytes.size()));
  return bytes;
}

void expect_frame_is_snapshot(const x3d::SurfaceFrame& f, const service::MeshSnapshot& s) {
  EXPECT_EQ(f.time_s, s.sim_time_s);
  EXPECT_EQ(f.vertices_m, s.vertices_m);
  EXPECT_EQ(f.triangles, s.triangles);
  EXPECT_EQ(f.vertex_level, s.vertex_level);
  EXPECT_EQ(f.triangle_strain_energy_J_per_m3, s.triangle_strain_energy_J_per_m3);
}

void put_be32(std::vector<std::uint8_t>& b, std::size_t at, std::int32_t v) {
  const auto u = static_cast<std::uint32_t>(v);
  for (int i = 0; i < 4; ++i) b[at + i] = static_cast<std::uint8_t>(u >> (24 - 8 * i));
}

std::string refused_tcpq_url() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t length = sizeof address;
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length) != 0) {
    if (fd >= 0) ::close(fd);
    return "tcpq://127.0.0.1:1";
  }
  ::close(fd);  // bound, never listening, now closed: connecting is refused
  return "tcpq://127.0.0.1:" + std::to_string(ntohs(address.sin_port));
}

}  // namespace tissue::transport::testing
