// The daemon's state as LCM messages (proto/lcm/*.lcm): pure conversions, no
// I/O, so the encoding is tested without a network.
#pragma once

#include <cstdint>

#include "service/sim_thread.hpp"
#include "tissue_lcm/tissue/haptic_state.hpp"
#include "tissue_lcm/tissue/sim_stats.hpp"
#include "tissue_lcm/tissue/surface_mesh.hpp"

namespace tissue::transport {

// Channel names (documented in proto/README.md).
inline constexpr const char* kSurfaceMeshChannel = "TISSUE_SURFACE_MESH";
inline constexpr const char* kHapticStateChannel = "TISSUE_HAPTIC_STATE";
inline constexpr const char* kSimStatsChannel = "TISSUE_SIM_STATS";

// Fills `out` (reusing its buffers). Strain energy per triangle comes from
// the snapshot; zeros when the snapshot has none (empty or short).
void to_message(const service::MeshSnapshot& snapshot, std::int64_t sequence, tissue_lcm::tissue::surface_mesh* out);
tissue_lcm::tissue::sim_stats to_message(const service::SimStatus& status, std::int64_t sequence);
tissue_lcm::tissue::haptic_state haptic_message(const service::SimStatus& status, std::int64_t sequence);

}  // namespace tissue::transport
