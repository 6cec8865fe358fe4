// A FrameSource over live data: frames taken from a MeshSubscriber (LCM or
// DDS, daemon/transport) for a wall-clock window or up to a count, then
// served like a session's frames. `tissue x3d --lcm/--dds` and `tissue render
// --lcm/--dds` read through it.
#pragma once

#include <atomic>
#include <cstddef>
#include <string>
#include <vector>

#include "export/frame_source.hpp"
#include "transport/mesh_subscriber.hpp"

namespace tissue::x3d {

// Nothing arrived in time. Its own type so clients can give it its own exit
// code; the message is "no surface_mesh on <source> within S s".
class NoLiveFrameError : public SourceError {
 public:
  using SourceError::SourceError;
};

// Collected frames are held in memory until the window ends: a 50k-vertex
// surface at 30 Hz is ~80 MB a second, and an export then makes a text copy
// 2-3 times that size. This much frame data (1 GiB) stops a collection.
constexpr std::size_t kLiveFrameBudgetBytes = kExportFrameBudgetBytes;

struct LiveCollectOptions {
  double first_timeout_s = 10.0;  // wait this long (wall) for the first frame
  double window_s = 0.0;          // then keep collecting this long (wall); 0: the first frame only
  std::size_t max_frames = 0;     // stop once this many are collected; 0: no limit
  // Stop before a frame whose data (frame_bytes) would take the frames kept
  // past this many bytes. The first frame is always kept.
  std::size_t max_bytes = kLiveFrameBudgetBytes;
};

class LiveFrameSource final : public FrameSource {
 public:
  // Collects from `subscriber` (blocking). Frames without triangles (an
  // empty scene) are not kept; a frame whose time goes backwards (the daemon
  // reset, a replay looped) is dropped, so frames stay in time order. Stops
  // early when `stop` is set, or at options.max_bytes (dropped_note says so).
  // Throws NoLiveFrameError when no frame arrives within first_timeout_s.
  LiveFrameSource(transport::MeshSubscriber& subscriber, const LiveCollectOptions& options,
                  const std::atomic<bool>* stop = nullptr);

  std::string name() const override { return name_; }
  std::size_t frame_count() const override { return frames_.size(); }
  double frame_time_s(std::size_t k) const override { return frames_.at(k).time_s; }
  SurfaceFrame read_frame(std::size_t k) override;
  std::size_t frame_data_bytes(std::size_t k) override { return frame_bytes(frames_.at(k)); }
  // True when every collected frame carries strain.
  bool has_strain() const override;
  // The subscriber keeps a frame whose strain is missing or not finite and
  // >= 0, without its strain (transport/mesh_subscriber.cpp).
  std::string why_no_strain() const override {
    return frames_.empty() ? "sent no frame"
                           : "sent frames without a finite, non-negative strain energy for every triangle (an old or "
                             "foreign publisher?)";
  }

  // Frames that went back in time, a collection cut short by max_bytes, and
  // what the subscriber counted lost, dropped or malformed meanwhile.
  std::string dropped_note() const override;

  std::size_t skipped_empty() const { return skipped_empty_; }
  std::size_t dropped_backwards() const { return dropped_backwards_; }
  // Whether collection stopped at options.max_bytes before the window ended.
  bool stopped_at_budget() const { return !budget_note_.empty(); }
  // Whether `stop` ended the collection (before the window, the first-frame
  // timeout or max_frames did). A stop raised after it ended is not seen.
  bool stopped_by_request() const { return stopped_by_request_; }

 private:
  std::string name_;
  std::vector<SurfaceFrame> frames_;
  std::size_t skipped_empty_ = 0, dropped_backwards_ = 0;
  std::string budget_note_;  // "" unless max_bytes stopped the collection
  bool stopped_by_request_ = false;
  transport::MeshReceiveCounts receive_counts_;  // the subscriber's, when collection ended
};

}  // namespace tissue::x3d
