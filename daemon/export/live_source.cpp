#include "export/live_source.hpp"

#include <chrono>
#include <cstdio>
#include <stdexcept>

namespace tissue::x3d {

namespace {
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

std::string fmt_s(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", s);
  return buf;
}
}  // namespace

LiveFrameSource::LiveFrameSource(transport::MeshSubscriber& subscriber, const LiveCollectOptions& o,
                                 const std::atomic<bool>* stop)
    : name_(subscriber.name()) {
  const auto stopped = [&] { return stop && stop->load(std::memory_order_relaxed); };
  // Short waits so a stop request is seen promptly.
  constexpr double kPoll_s = 0.1;
  const auto start = Clock::now();
  Clock::time_point first{};
  for (;;) {
    if (stopped()) break;
    if (frames_.empty()) {
      if (seconds_since(start) >= o.first_timeout_s) break;
    } else if (seconds_since(first) >= o.window_s || (o.max_frames > 0 && frames_.size() >= o.max_frames)) {
      break;
    }
    std::optional<SurfaceFrame> f = subscriber.next_frame(kPoll_s);
    if (!f) continue;
    if (f->triangles.empty()) {
      ++skipped_empty_;
      continue;
    }
    if (!frames_.empty() && f->time_s < frames_.back().time_s) {
      ++dropped_backwards_;
      continue;
    }
    if (frames_.empty()) first = Clock::now();
    frames_.push_back(std::move(*f));
  }
  if (frames_.empty() && !stopped()) {
    std::string why = "no surface_mesh on " + name_ + " within " + fmt_s(o.first_timeout_s) + " s";
    const transport::MeshReceiveCounts& c = subscriber.counts();
    if (c.rejected > 0)
      why += " (" + std::to_string(c.rejected) + " malformed messages dropped, the last: " + c.last_rejection + ")";
    else if (skipped_empty_ > 0)
      why += " (" + std::to_string(skipped_empty_) + " empty surfaces: is a scene loaded?)";
    throw NoLiveFrameError(why);
  }
}

SurfaceFrame LiveFrameSource::read_frame(std::size_t k) {
  if (k >= frames_.size())
    throw std::out_of_range("frame " + std::to_string(k) + " of " + name_ + " does not exist (" +
                            std::to_string(frames_.size()) + " frames)");
  return frames_[k];
}

bool LiveFrameSource::has_strain() const {
  if (frames_.empty()) return false;
  for (const SurfaceFrame& f : frames_)
    if (f.vertex_strain_energy_Pa.size() != f.vertices_m.size()) return false;
  return true;
}

}  // namespace tissue::x3d
