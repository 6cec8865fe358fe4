// The layout of a session file: every dataset, its element type, columns
// and units, in one table shared by the writer, the tools and the tests
// (docs/session-format.md is this table in prose).
//
// SWMR forbids creating objects once writing has started, so every dataset
// exists from the start: one extendable dataset per column, first dimension
// unlimited. Mesh frames of varying size are concatenated into flat datasets
// and indexed by /mesh/*_offset and *_count.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>

namespace tissue::record {

// Version 2 added /mesh/triangle_strain_energy_J_per_m3, version 3
// /haptic/device_fresh. Readers accept every version from 1 (a dataset's
// since_version says which files have it).
inline constexpr std::int64_t kSessionFormatVersion = 3;
inline constexpr std::int64_t kOldestReadableFormatVersion = 1;

enum class ElementType : std::uint8_t { kF64, kF32, kU8, kI32, kU64, kI64, kString };

enum class Group : std::uint8_t { kHaptic, kSim, kMesh, kEvents };
inline constexpr std::array<const char*, 4> kGroupPaths = {"/haptic", "/sim", "/mesh", "/events"};

struct DatasetSpec {
  const char* path;
  Group group;
  ElementType type;
  int columns;        // 1: shape (N); 3: shape (N, 3)
  const char* units;  // stored as the dataset's `units` attribute
  std::size_t chunk_rows;
  std::int64_t since_version = 1;  // files of older format versions do not have it
};

// Files of format version `v` have a dataset iff this is true.
constexpr bool dataset_in_version(const DatasetSpec& spec, std::int64_t v) { return spec.since_version <= v; }

// Index into kDatasets. Order matters for flushing: within a group the data
// columns come before the columns readers use to count rows (frame index
// last), so a reader never sees an index entry whose data is not yet there.
enum DatasetId : std::size_t {
  kHapticDevicePosition,
  kHapticProxyPosition,
  kHapticForce,
  kHapticContact,
  kHapticModelVersion,
  kHapticDeviceFresh,
  kHapticTime,
  kSimSimTime,
  kSimRealTimeFactor,
  kSimStepMs,
  kSimNodes,
  kSimTets,
  kSimSprings,
  kSimRefines,
  kSimMerges,
  kSimKinetic,
  kSimElastic,
  kSimTime,
  kMeshVertices,
  kMeshTriangles,
  kMeshVertexLevel,
  kMeshTriangleStrain,
  kMeshVertexOffset,
  kMeshVertexCount,
  kMeshTriangleOffset,
  kMeshTriangleCount,
  kMeshFrameTime,
  kEventKind,
  kEventMessage,
  kEventTime,
  kDatasetCount
};

// Chunks: ~1 s of haptic rows, a few hundred KB of mesh data. Small enough
// that a 4 Hz flush rewrites little, large enough that chunk indices stay small.
inline constexpr std::array<DatasetSpec, kDatasetCount> kDatasets = {{
    {"/haptic/device_position_m", Group::kHaptic, ElementType::kF64, 3, "m", 1024},
    {"/haptic/proxy_position_m", Group::kHaptic, ElementType::kF64, 3, "m", 1024},
    {"/haptic/force_N", Group::kHaptic, ElementType::kF64, 3, "N", 1024},
    {"/haptic/contact", Group::kHaptic, ElementType::kU8, 1, "1 (0/1)", 1024},
    {"/haptic/model_version", Group::kHaptic, ElementType::kU64, 1, "1 (counter)", 1024},
    // 1: the device delivered a new sample that tick and the loop accepted
    // it. A replay spreads each step over the time since the last such row,
    // as the loop measured it live (without it, a held pose is a lost
    // sample or a still hand, and the replay can only guess which).
    {"/haptic/device_fresh", Group::kHaptic, ElementType::kU8, 1, "1 (0/1: a new device sample that tick)", 1024, 3},
    {"/haptic/time_s", Group::kHaptic, ElementType::kF64, 1, "s (session time)", 1024},
    {"/sim/sim_time_s", Group::kSim, ElementType::kF64, 1, "s (simulated)", 512},
    {"/sim/real_time_factor", Group::kSim, ElementType::kF64, 1, "1", 512},
    {"/sim/step_ms", Group::kSim, ElementType::kF64, 1, "ms", 512},
    {"/sim/nodes", Group::kSim, ElementType::kU64, 1, "1 (count)", 512},
    {"/sim/tets", Group::kSim, ElementType::kU64, 1, "1 (count)", 512},
    {"/sim/springs", Group::kSim, ElementType::kU64, 1, "1 (count)", 512},
    {"/sim/refines", Group::kSim, ElementType::kI64, 1, "1 (cumulative count)", 512},
    {"/sim/merges", Group::kSim, ElementType::kI64, 1, "1 (cumulative count)", 512},
    {"/sim/kinetic_J", Group::kSim, ElementType::kF64, 1, "J", 512},
    {"/sim/elastic_J", Group::kSim, ElementType::kF64, 1, "J", 512},
    {"/sim/time_s", Group::kSim, ElementType::kF64, 1, "s (session time)", 512},
    {"/mesh/vertices_m", Group::kMesh, ElementType::kF32, 3, "m", 32768},
    {"/mesh/triangles", Group::kMesh, ElementType::kI32, 3, "1 (vertex index within the frame)", 32768},
    {"/mesh/vertex_level", Group::kMesh, ElementType::kU8, 1, "1 (bisection depth)", 65536},
    // One row per /mesh/triangles row (same offset and count); NaN: the
    // frame was recorded without strain.
    {"/mesh/triangle_strain_energy_J_per_m3", Group::kMesh, ElementType::kF32, 1,
     "J/m^3 (strain-energy density of the leaf tet behind the triangle)", 65536, 2},
    {"/mesh/vertex_offset", Group::kMesh, ElementType::kU64, 1, "1 (row of /mesh/vertices_m)", 256},
    {"/mesh/vertex_count", Group::kMesh, ElementType::kU64, 1, "1 (rows)", 256},
    {"/mesh/triangle_offset", Group::kMesh, ElementType::kU64, 1, "1 (row of /mesh/triangles)", 256},
    {"/mesh/triangle_count", Group::kMesh, ElementType::kU64, 1, "1 (rows)", 256},
    {"/mesh/frame_time_s", Group::kMesh, ElementType::kF64, 1, "s (session time)", 256},
    {"/events/kind", Group::kEvents, ElementType::kI32, 1, "1 (see kind_names)", 64},
    {"/events/message", Group::kEvents, ElementType::kString, 1, "text (UTF-8, 255 bytes max)", 64},
    {"/events/time_s", Group::kEvents, ElementType::kF64, 1, "s (session time)", 64},
}};

// The most vertices a mesh frame has: /mesh/triangles indexes them with
// int32. The writer refuses a frame of more; every reader refuses a
// /mesh/vertex_count beyond it as damage, naming the row, before it reads
// (or allocates for) the frame.
inline constexpr std::uint64_t kMaxMeshFrameVertices = std::numeric_limits<std::int32_t>::max();

// Root attributes.
inline constexpr const char* kAttrFormatVersion = "format_version";
inline constexpr const char* kAttrSceneName = "scene_name";
inline constexpr const char* kAttrSceneText = "scene_text";
inline constexpr const char* kAttrConfigText = "config_text";
inline constexpr const char* kAttrSoftwareVersion = "software_version";
inline constexpr const char* kAttrStartTime = "start_time_utc";
inline constexpr const char* kAttrHostName = "host_name";
// All three are created with the file (closed_cleanly 0, end_time_utc empty,
// duration_s NaN) and rewritten in place at the clean close, after every row
// is flushed and while still in SWMR mode: SWMR forbids creating attributes,
// and a clean close must not depend on no reader having the file open. A
// session counts as closed cleanly only when closed_cleanly is 1 and the
// superblock's open-for-write flags are clear, so a crash anywhere before
// the close completes reads as not clean. (Files written before 2026-11-25
// get end_time_utc and duration_s only at the clean close.)
inline constexpr const char* kAttrClosedCleanly = "closed_cleanly";
inline constexpr const char* kAttrEndTime = "end_time_utc";
inline constexpr const char* kAttrDurationS = "duration_s";
// Room for "YYYY-MM-DDTHH:MM:SS.mmmZ" and its NUL, reserved at creation.
inline constexpr std::size_t kEndTimeBytes = 32;
// A session is built under ".NAME" + kCreatingInfix + "PID-N" beside its
// final name and renamed into place once complete (SessionWriter::create).
inline constexpr const char* kCreatingInfix = ".creating-";
// Added by `tissue session repair`.
inline constexpr const char* kAttrRepairedTime = "repaired_utc";

}  // namespace tissue::record
