// Meshes and encoded messages shared by the transport tests.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "export/x3d.hpp"
#include "service/mesh_snapshot.hpp"

namespace tissue::transport::testing {

// A strip of `quads` squares, bent out of plane and straddling zero on every
// axis; coordinates are multiples of 1/64 (exact in float), levels and
// strain distinct per vertex / triangle (strain_base + t) so a shifted or
// dropped value shows.
service::MeshSnapshot bent_strip(int quads, float strain_base = 0.5f);

// `s` as the daemon's LCM encoder writes it.
std::vector<std::uint8_t> lcm_encoded(const service::MeshSnapshot& s, std::int64_t sequence = 1);

// Expects `f` (a message decoded as a subscriber does) to carry exactly the
// snapshot's time, vertices, triangles, levels and strain.
void expect_frame_is_snapshot(const x3d::SurfaceFrame& f, const service::MeshSnapshot& s);

// Writes v big-endian at b[at .. at + 4) (LCM's byte order).
void put_be32(std::vector<std::uint8_t>& b, std::size_t at, std::int32_t v);

// A tcpq:// URL on 127.0.0.1 at a port nothing listens on (one the kernel
// just handed out and that was closed again): LCM's TCP provider cannot
// connect there, and nothing leaves the machine.
std::string refused_tcpq_url();

}  // namespace tissue::transport::testing
