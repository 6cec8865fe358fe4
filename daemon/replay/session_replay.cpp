#include "replay/session_replay.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

#include "transport/dds_publisher.hpp"
#include "transport/lcm_publisher.hpp"
#include "util/text.hpp"

namespace tissue::replay {

namespace {
// A number as people write it: "1e-300", "0.001", "1e+06".
std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

// Why a timeline came out empty, for the message after "nothing to replay":
// the window as the user gave it and the span of what the session holds, so
// the user sees where the window missed it ("in the window --from 5 --to 6:
// the session's frames and rows are from t=0 s to t=1.47 s"). The span's
// ends are frame times to 9 digits (x3d::frame_time_text), as the clients
// say them.
std::string empty_window_text(const std::vector<double>& frame_t, const std::vector<double>& haptic_t,
                              const std::vector<double>& sim_t, const TimelineOptions& o) {
  std::string window;
  if (o.from_s) window = "--from " + util::number_text(*o.from_s);
  if (o.to_s) window += (window.empty() ? "" : " ") + std::string("--to ") + util::number_text(*o.to_s);
  std::optional<double> first_s, last_s;
  for (const std::vector<double>* times : {&frame_t, &haptic_t, &sim_t})
    for (const double t : *times) {
      if (!first_s || t < *first_s) first_s = t;
      if (!last_s || t > *last_s) last_s = t;
    }
  std::string text = window.empty() ? std::string("(no --from/--to given)") : "in the window " + window;
  if (!first_s) return text + ": the session holds no mesh frame, haptic row or sim row";
  return text + ": the session's frames and rows are from t=" + x3d::frame_time_text(*first_s) +
         " s to t=" + x3d::frame_time_text(*last_s) + " s";
}

}  // namespace

SessionRows read_session_rows(const std::string& path) {
  try {
    return record::read_session_rows(path);
  } catch (const record::RecordError& e) {
    throw ReplayError(e.what());
  }
}

service::MeshSnapshot to_snapshot(const x3d::SurfaceFrame& f, std::uint64_t sequence) {
  service::MeshSnapshot s;
  s.sequence = sequence;
  s.sim_time_s = f.time_s;
  s.vertices_m = f.vertices_m;
  s.triangles = f.triangles;
  s.vertex_level = f.vertex_level;
  if (!f.triangle_strain_energy_J_per_m3.empty()) {
    // What was recorded, exactly (the source checked one value per triangle).
    s.triangle_strain_energy_J_per_m3 = f.triangle_strain_energy_J_per_m3;
    return s;
  }
  const std::vector<float>& v = f.vertex_strain_energy_Pa;
  if (!v.empty()) {
    // Only per-vertex values (a source that has nothing finer): the mean of
    // the triangle's vertices is the closest per-triangle value.
    s.triangle_strain_energy_J_per_m3.resize(f.triangles.size());
    for (std::size_t t = 0; t < f.triangles.size(); ++t) {
      double sum = 0.0;
      // A bad index (the frame is checked by the source, but a snapshot must
      // never read out of bounds) counts as 0.
      for (const std::uint32_t i : f.triangles[t]) sum += i < v.size() ? v[i] : 0.0f;
      s.triangle_strain_energy_J_per_m3[t] = static_cast<float>(sum / 3.0);
    }
  }
  return s;
}

service::SimStatus haptic_status(const record::HapticRow& row) {
  service::SimStatus s;
  s.sim_time_s = row.time_s;
  s.device_position_m = row.device_position_m;
  s.proxy_position_m = row.proxy_position_m;
  s.force_on_device_N = row.force_N;
  s.tool_contact = row.contact != 0;
  s.model_version = row.model_version;
  return s;
}

service::SimStatus sim_status(const record::SimRow& row) {
  service::SimStatus s;
  s.sim_time_s = row.time_s;
  s.real_time_factor = row.real_time_factor;
  s.step_ms_last = row.step_ms;
  s.nodes = row.nodes;
  s.tets = row.tets;
  s.springs = row.springs;
  s.refines = row.refines;
  s.merges = row.merges;
  s.kinetic_energy_J = row.kinetic_J;
  s.elastic_energy_J = row.elastic_J;
  return s;
}

std::vector<TimelineItem> build_timeline(const std::vector<double>& frame_times_s,
                                         const std::vector<double>& haptic_times_s,
                                         const std::vector<double>& sim_times_s, const TimelineOptions& o) {
  for (const auto& [rate_hz, what] : {std::pair{o.haptic_rate_hz, "haptic"}, std::pair{o.stats_rate_hz, "stats"}})
    if (!(rate_hz >= 0.0) || !std::isfinite(rate_hz))
      throw ReplayError(std::string(what) + " rate " + util::number_text(rate_hz) + " Hz: must be >= 0 (0: every row)");
  if (o.from_s && o.to_s && !(*o.from_s <= *o.to_s))
    throw ReplayError("window --from " + util::number_text(*o.from_s) + " --to " + util::number_text(*o.to_s) +
                      ": the start is after the end");
  const auto inside = [&](double t) { return x3d::time_in_window(t, o.from_s, o.to_s); };
  std::vector<TimelineItem> items;
  items.reserve(frame_times_s.size() + sim_times_s.size() + haptic_times_s.size());
  for (std::size_t k = 0; k < frame_times_s.size(); ++k)
    if (inside(frame_times_s[k])) items.push_back({frame_times_s[k], StreamKind::kMesh, k});
  // A row is kept when at least 1/rate has passed since the last kept one,
  // on a grid (as the daemon's publish timers tick), re-anchored after a gap.
  const auto decimated = [&](const std::vector<double>& times_s, double rate_hz, StreamKind kind) {
    const double period_s = rate_hz > 0.0 ? 1.0 / rate_hz : 0.0;
    // Within half a microsecond counts as due: 1 kHz rows stored as i * 1e-3
    // must decimate to exactly every 10th at 100 Hz despite rounding.
    constexpr double kSlack_s = 5e-7;
    std::optional<double> next_due_s;
    for (std::size_t i = 0; i < times_s.size(); ++i) {
      const double t = times_s[i];
      if (!inside(t) || (next_due_s && t < *next_due_s - kSlack_s)) continue;
      items.push_back({t, kind, i});
      next_due_s = (next_due_s && t < *next_due_s + period_s ? *next_due_s : t) + period_s;
    }
  };
  decimated(haptic_times_s, o.haptic_rate_hz, StreamKind::kHaptic);
  decimated(sim_times_s, o.stats_rate_hz, StreamKind::kStats);
  // Each stream is in time order; a stable sort by (time, kind) merges them.
  std::stable_sort(items.begin(), items.end(), [](const TimelineItem& a, const TimelineItem& b) {
    return a.time_s < b.time_s || (a.time_s == b.time_s && a.kind < b.kind);
  });
  return items;
}

void PublisherSink::mesh(const service::MeshSnapshot& snapshot) {
  if (lcm_) lcm_->publish_mesh(snapshot);
  if (dds_) dds_->publish_mesh(snapshot);
}

void PublisherSink::haptic(const service::SimStatus& status) {
  if (lcm_) lcm_->publish_haptic(status);
  if (dds_) dds_->publish_haptic(status);
}

void PublisherSink::stats(const service::SimStatus& status) {
  if (lcm_) lcm_->publish_stats(status);
  if (dds_) dds_->publish_stats(status);
}

double SteadyReplayClock::now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

bool SteadyReplayClock::wait_until(double t_s, const std::atomic<bool>& stop) {
  constexpr double kSlice_s = 0.02;
  for (;;) {
    if (stop.load(std::memory_order_relaxed)) return false;
    const double left_s = t_s - now_s();
    if (left_s <= 0.0) return true;
    std::this_thread::sleep_for(std::chrono::duration<double>(std::min(left_s, kSlice_s)));
  }
}

ReplaySummary replay_session(x3d::FrameSource& frames, const SessionRows& rows, const ReplayOptions& o,
                             ReplaySink& sink, ReplayClock& clock, const std::atomic<bool>& stop) {
  // Outside the bounds a replay either waits for ever (1e-300: the second
  // item is due in 1e299 s) or is no pace at all, everything at once.
  if (!(o.speed >= kMinSpeed && o.speed <= kMaxSpeed))
    throw ReplayError("speed " + fmt(o.speed) + ": must be a number from " + fmt(kMinSpeed) + " to " + fmt(kMaxSpeed));
  std::vector<double> frame_t(frames.frame_count()), haptic_t(rows.haptic.size()), sim_t(rows.sim.size());
  for (std::size_t k = 0; k < frame_t.size(); ++k) frame_t[k] = frames.frame_time_s(k);
  for (std::size_t i = 0; i < haptic_t.size(); ++i) haptic_t[i] = rows.haptic[i].time_s;
  for (std::size_t i = 0; i < sim_t.size(); ++i) sim_t[i] = rows.sim[i].time_s;
  const std::vector<TimelineItem> items = build_timeline(frame_t, haptic_t, sim_t, o.timeline);
  if (items.empty())
    throw ReplayError(frames.name() + ": nothing to replay " + empty_window_text(frame_t, haptic_t, sim_t, o.timeline));
  const double t0_s = items.front().time_s;
  const double span_s = items.back().time_s - t0_s;
  // A pass shorter than the clock's rounding (items 1e-12 s apart, a steady
  // clock at 1e5 s) left the next pass's due time where it was: every later
  // item was already due, and the loop published as fast as it could for ever.
  const double pass_wall_s = span_s / o.speed;
  if (o.loop && !(pass_wall_s >= kMinLoopPass_s))
    throw ReplayError(frames.name() + ": --loop needs a pass of at least 1 ms of wall time: the window spans " +
                      fmt(span_s) + " s of session time, " + fmt(pass_wall_s) + " s at speed " + fmt(o.speed));

  // The recorder's holes the replay crosses: a haptic item followed (before
  // the next haptic item) by a hole with recorded rows on either side. Over
  // it no haptic_state goes out, and a viewer sees the hand stop, as if it
  // were still or lost, though live it moved on: the sink hears of the hole
  // right after that item, when the stream stops (the CLI prints it). A hole
  // the window does not reach across is not crossed. By item position.
  //
  // Only a hole that shows at the published rate: the two states either
  // side of it at least two publish periods apart, so a whole period passes
  // with no state beyond the usual one (a state the stream would carry is
  // missing). A hole no longer than a period never does (the states either
  // side are then less than two periods apart: the next one comes late by
  // less than a period, as network jitter makes it), and announcing it
  // printed a line per pass for nothing a viewer could see; one of two
  // periods or more always does. Every row sent (rate 0): any hole does.
  const double haptic_period_s = o.timeline.haptic_rate_hz > 0.0 ? 1.0 / o.timeline.haptic_rate_hz : 0.0;
  // build_timeline's slack: 1 kHz rows stored as i * 1e-3 are due on time.
  constexpr double kSlack_s = 5e-7;
  std::vector<std::pair<std::size_t, const record::HapticHole*>> holes_after;
  // A window that starts inside a hole (its first haptic item is the row
  // after it): the other streams start while no haptic state comes until
  // that row, the same stop as at a hole crossed, so the sink hears of it
  // before the first item of each pass. Only when that row comes at least a
  // period after the replay's first item (and not with it): a haptic stream
  // starts with the first item, so that is a whole period with no state
  // beyond the usual, the rule above; a window that starts with the row
  // after the hole leaves nothing missing.
  const record::HapticHole* hole_at_start = nullptr;
  {
    std::vector<const record::HapticHole*> holes;
    for (const record::HapticHole& h : rows.haptic_holes)
      if (h.has_row_before() && h.has_row_after()) holes.push_back(&h);
    std::stable_sort(holes.begin(), holes.end(), [](const record::HapticHole* a, const record::HapticHole* b) {
      return a->row_after < b->row_after;
    });
    std::size_t next_hole = 0;
    std::optional<std::size_t> last_haptic;  // position in items
    for (std::size_t pos = 0; pos < items.size() && next_hole < holes.size(); ++pos) {
      if (items[pos].kind != StreamKind::kHaptic) continue;
      if (last_haptic) {
        // Holes at or before the row sent last are not between it and this.
        while (next_hole < holes.size() && holes[next_hole]->row_after <= items[*last_haptic].index) ++next_hole;
        const bool shows = items[pos].time_s - items[*last_haptic].time_s >= 2.0 * haptic_period_s - kSlack_s;
        for (; next_hole < holes.size() && holes[next_hole]->row_after <= items[pos].index; ++next_hole)
          if (shows) holes_after.emplace_back(*last_haptic, holes[next_hole]);
      } else {
        const double late_s = items[pos].time_s - items.front().time_s;
        for (const record::HapticHole* h : holes)
          if (h->row_after == items[pos].index && late_s > 0.0 && late_s >= haptic_period_s - kSlack_s)
            hole_at_start = h;
      }
      last_haptic = pos;
    }
  }

  constexpr double kLate_s = 0.01;
  ReplaySummary sum;
  const auto announce = [&](const record::HapticHole& hole) {
    sink.haptic_hole(hole);
    ++sum.haptic_holes;
    sum.haptic_hole_time_s += std::max(0.0, hole.time_after_s - hole.time_before_s);
  };
  const double start_wall_s = clock.now_s();
  std::uint64_t sequence = 0;
  for (;;) {
    for (std::size_t position = 0; position < items.size(); ++position) {
      const TimelineItem& item = items[position];
      // Read before waiting: a large frame takes time to load, and that time
      // should come out of the wait, not delay the send.
      std::optional<service::MeshSnapshot> snapshot;
      if (item.kind == StreamKind::kMesh) snapshot = to_snapshot(frames.read_frame(item.index), ++sequence);
      // From the start, not summed pass by pass: a sum drops a pass shorter
      // than the clock's rounding (and drifts over many passes).
      const double due_s =
          start_wall_s + static_cast<double>(sum.passes) * pass_wall_s + (item.time_s - t0_s) / o.speed;
      if (!clock.wait_until(due_s, stop)) {
        sum.stopped = true;
        return sum;
      }
      const double lag_s = clock.now_s() - due_s;
      if (lag_s > kLate_s) ++sum.late_items;
      sum.max_lag_s = std::max(sum.max_lag_s, lag_s);
      if (position == 0 && hole_at_start) announce(*hole_at_start);
      switch (item.kind) {
        case StreamKind::kMesh:
          sink.mesh(*snapshot);
          ++sum.frames;
          break;
        case StreamKind::kHaptic:
          sink.haptic(haptic_status(rows.haptic[item.index]));
          ++sum.haptic_rows;
          for (auto it = std::lower_bound(holes_after.begin(), holes_after.end(), position,
                                          [](const auto&entry, std::size_t p) { return entry.first < p; });
               it != holes_after.end() && it->first == position; ++it)
            announce(*it->second);
          break;
        case StreamKind::kStats:
          sink.stats(sim_status(rows.sim[item.index]));
          ++sum.stats;
          break;
      }
      sum.wall_s = clock.now_s() - start_wall_s;
      sum.session_span_s = (item.time_s - t0_s) + static_cast<double>(sum.passes) * span_s;
    }
    ++sum.passes;
    if (!o.loop || stop.load(std::memory_order_relaxed)) {
      sum.stopped = stop.load(std::memory_order_relaxed) && o.loop;
      return sum;
    }
  }
}

}  // namespace tissue::replay
