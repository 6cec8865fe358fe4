// The daemon's state as Fast DDS messages (proto/idl/*.idl): pure conversions,
// no I/O, so the encoding is tested without a network. Same conventions as
// lcm_messages.hpp: float vertices, axis-aligned bounds of the vertices
// (zeros for an empty mesh), strain energy per triangle from the snapshot
// (zeros when the snapshot has none).
#pragma once

#include <cstdint>

#include "service/sim_thread.hpp"
#include "tissue_dds/haptic_state.h"
#include "tissue_dds/sim_stats.h"
#include "tissue_dds/surface_mesh.h"

namespace tissue::transport {

// Topic names (proto/README.md) and the prefix they are built from.
inline constexpr const char* kDdsTopicPrefix = "tissue/";
inline constexpr const char* kSurfaceMeshTopic = "surface_mesh";  // tissue/surface_mesh
inline constexpr const char* kHapticStateTopic = "haptic_state";  // tissue/haptic_state
inline constexpr const char* kSimStatsTopic = "sim_stats";        // tissue/sim_stats

// Fills `out`, reusing its sequences' storage (a steady-size mesh does not
// allocate).
void to_dds(const service::MeshSnapshot& snapshot, std::int64_t sequence, ::tissue::surface_mesh* out);
::tissue::sim_stats to_dds_stats(const service::SimStatus& status, std::int64_t sequence);
::tissue::haptic_state to_dds_haptic(const service::SimStatus& status, std::int64_t sequence);

}  // namespace tissue::transport
