// Receiving surface meshes (proto/README.md `surface_mesh`) as export frames:
// the interface the LCM and DDS subscribers implement and the live
// FrameSource (export/live_source.hpp) reads from, and the one validation of
// an incoming mesh both transports share. Header-only interface: the export
// library uses it without linking the transports.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

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
  // subscriber saw them, and messages refused before their number was read.
  // A number that does not increase starts a new run (the publisher
  // restarted): no gap is counted. DDS names each sample's writer, so each
  // writer has its own run (PublisherSequences); LCM does not, so two
  // publishers on one channel at once count as gaps (count_sequence).
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

// The numbers between a run's last sequence number and the next one: 0
// unless it increases by more than one. Unsigned arithmetic: any two int64
// values from the wire give a defined count.
inline std::uint64_t sequence_gap(std::int64_t last, std::int64_t next) {
  return next > last ? static_cast<std::uint64_t>(next) - static_cast<std::uint64_t>(last) - 1 : 0;
}

// Counts the gap before a decoded message's sequence number when the
// transport does not say who sent it (LCM): every message on the channel is
// one run. So two publishers on one channel at once (the daemon near 10000,
// a replay at 1, 2, ...) count the distance between them at every switch
// from the lower numbers to the higher; a switch down starts a new run.
inline void count_sequence(MeshReceiveCounts& c, std::int64_t sequence) {
  if (c.last_sequence) c.missed += sequence_gap(*c.last_sequence, sequence);
  c.last_sequence = sequence;
}

// Counts the gap before a decoded message's sequence number in the run of
// the publisher that sent it, for a transport that names it (DDS: the
// writer's GUID, SampleInfo::publication_handle): the daemon and a replay
// interleaved on one topic count only their own gaps. Remembers the
// kMaxPublishers heard most recently (a bound: the ids come from the
// wire); a message from one more forgets the one heard longest ago, whose
// next message, should it come back, starts a new run without a gap.
class PublisherSequences {
 public:
  using PublisherId = std::array<std::uint8_t, 16>;
  static constexpr std::size_t kMaxPublishers = 16;

  void count(MeshReceiveCounts& c, const PublisherId& publisher, std::int64_t sequence) {
    auto run = std::find_if(runs_.begin(), runs_.end(), [&](const Run& r) { return r.publisher == publisher; });
    if (run != runs_.end()) {
      c.missed += sequence_gap(run->last_sequence, sequence);
    } else if (runs_.size() < kMaxPublishers) {
      run = runs_.insert(runs_.end(), Run{publisher, sequence, 0});
    } else {
      run = std::min_element(runs_.begin(), runs_.end(),
                             [](const Run& a, const Run& b) { return a.last_heard < b.last_heard; });
      run->publisher = publisher;
    }
    run->last_sequence = sequence;
    run->last_heard = ++heard_;
    c.last_sequence = sequence;
  }

 private:
  struct Run {
    PublisherId publisher;
    std::int64_t last_sequence;
    std::uint64_t last_heard;  // heard_ when its last message came
  };
  std::vector<Run> runs_;
  std::uint64_t heard_ = 0;  // messages counted: 64 bits never wrap
};

// Counts a rejection (shared bookkeeping of both subscribers).
inline void count_rejection(MeshReceiveCounts& c, const MeshRejected& e) {
  ++c.rejected;
  ++c.rejected_by_reason[e.category()];
  c.last_rejection = e.what();
}

}  // namespace tissue::transport
