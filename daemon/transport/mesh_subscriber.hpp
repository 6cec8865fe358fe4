// Receiving surface meshes (proto/README.md `surface_mesh`) as export frames:
// the interface the LCM and DDS subscribers implement and the live
// FrameSource (export/live_source.hpp) reads from, and the one validation of
// an incoming mesh both transports share. Header-only interface: the export
// library uses it without linking the transports.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>

#include "export/x3d.hpp"

namespace tissue::transport {

// Messages seen on the mesh channel/topic and what became of them.
struct MeshReceiveCounts {
  std::uint64_t received = 0;  // messages delivered by the transport
  std::uint64_t accepted = 0;  // valid frames handed out or queued
  std::uint64_t rejected = 0;  // malformed: dropped (by reason below)
  std::uint64_t overflow = 0;  // valid, but dropped because the caller did not keep up
  // Messages that never reached us: the gaps in the publisher's sequence
  // numbers (proto/README.md), lost on the network or dropped by the
  // transport's own bounded queue (LCM's, DDS's history) before the
  // subscriber saw them. A sequence that does not increase starts a new run
  // (the publisher restarted, or another one joined): no gap is counted.
  std::uint64_t missed = 0;
  std::optional<std::int64_t> last_sequence;                // of the newest decoded message
  std::map<std::string, std::uint64_t> rejected_by_reason;  // reason category -> count
  std::string last_rejection;                               // full message of the newest rejection
};

class MeshSubscriber {
 public:
  virtual ~MeshSubscriber() = default;
  // For messages: "LCM channel TISSUE_SURFACE_MESH on udpm://…",
  // "DDS topic tissue/surface_mesh (domain 0)".
  virtual std::string name() const = 0;
  // The next valid frame, in arrival order; nullopt when none arrives within
  // timeout_s. Malformed messages are counted and skipped.
  virtual std::optional<x3d::SurfaceFrame> next_frame(double timeout_s) = 0;
  virtual const MeshReceiveCounts& counts() const = 0;
};

// A malformed message: `category` is the short counted reason ("size",
// "index", "non_finite", "decode"), what() the details.
class MeshRejected : public std::runtime_error {
 public:
  MeshRejected(std::string category, const std::string& detail)
      : std::runtime_error(detail), category_(std::move(category)) {}
  const std::string& category() const { return category_; }

 private:
  std::string category_;
};

// The arrays of a decoded surface_mesh as a frame. Throws MeshRejected
// unless: time finite; 3 coordinates per vertex, all finite; levels one per
// vertex (or none); 3 indices per triangle, each in [0, vertex count);
// strain one per triangle (or none). Strain becomes per-vertex
// (x3d::vertex_strain_from_triangles); non-finite or negative strain values
// leave the frame without strain (the geometry is still good).
x3d::SurfaceFrame frame_from_mesh_arrays(double time_s, std::span<const float> vertex_m,
                                         std::span<const std::uint8_t> vertex_level,
                                         std::span<const std::int32_t> triangle_vertex,
                                         std::span<const float> triangle_strain);

// Counts the gap before a decoded message's sequence number (shared
// bookkeeping of both subscribers). Unsigned arithmetic: any two int64
// values from the wire give a defined count.
inline void count_sequence(MeshReceiveCounts& c, std::int64_t sequence) {
  if (c.last_sequence && sequence > *c.last_sequence)
    c.missed += static_cast<std::uint64_t>(sequence) - static_cast<std::uint64_t>(*c.last_sequence) - 1;
  c.last_sequence = sequence;
}

// Counts a rejection (shared bookkeeping of both subscribers).
inline void count_rejection(MeshReceiveCounts& c, const MeshRejected& e) {
  ++c.rejected;
  ++c.rejected_by_reason[e.category()];
  c.last_rejection = e.what();
}

}  // namespace tissue::transport
