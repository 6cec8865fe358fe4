#include "export/live_source.hpp"

#include <algorithm>
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
  std::size_t kept_bytes = 0;
  for (;;) {
    if (stopped()) {
      stopped_by_request_ = true;
      break;
    }
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
    // Sizes only: a frame count or a time window alone does not bound the
    // memory (a large surface at 30 Hz for --seconds 600 was ~50 GB).
    const std::size_t bytes = frame_bytes(*f);
    if (!frames_.empty() && bytes > o.max_bytes - std::min(kept_bytes, o.max_bytes)) {
      budget_note_ = "collection stopped after " + std::to_string(frames_.size()) + " frames (" +
                     fmt_s(seconds_since(first)) + " s of the " + fmt_s(o.window_s) +
                     " s window): the next would take the frames kept past " + byte_size_text(o.max_bytes);
      break;
    }
    if (frames_.empty()) first = Clock::now();
    kept_bytes += bytes;
    frames_.push_back(std::move(*f));
  }
  receive_counts_ = subscriber.counts();
  if (frames_.empty() && !stopped_by_request_) {
    std::string why = "no surface_mesh on " + name_ + " within " + fmt_s(o.first_timeout_s) + " s";
    const transport::MeshReceiveCounts& c = receive_counts_;
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

std::string LiveFrameSource::dropped_note() const {
  std::string note;
  if (dropped_backwards_ > 0)
    note = std::to_string(dropped_backwards_) +
           " frames dropped: their time was before the last frame kept (the daemon reset or a replay looped)";
  if (!budget_note_.empty()) note += (note.empty() ? "" : "; ") + budget_note_;
  // What the transport lost or refused while collecting: a gap in the
  // frames a user sees must not go unexplained.
  const transport::MeshReceiveCounts& c = receive_counts_;
  const auto add = [&](const std::string& part) { note += (note.empty() ? "" : "; ") + part; };
  if (c.missed > 0)
    add(std::to_string(c.missed) +
        " messages the publisher sent never arrived (gaps in its sequence numbers: lost on the network, or this "
        "reader fell behind)");
  if (c.overflow > 0) add(std::to_string(c.overflow) + " frames dropped: this reader fell behind");
  if (c.rejected > 0) add(std::to_string(c.rejected) + " malformed messages dropped, the last: " + c.last_rejection);
  return note;
}

bool LiveFrameSource::has_strain() const {
  if (frames_.empty()) return false;
  for (const SurfaceFrame& f : frames_)
    if (f.vertex_strain_energy_Pa.size() != f.vertices_m.size()) return false;
  return true;
}

}  // namespace tissue::x3d
