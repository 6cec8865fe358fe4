#include "replay/session_replay.hpp"

#include <hdf5.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>

#include "record/h5_util.hpp"
#include "record/session_layout.hpp"
#include "record/session_tools.hpp"
#include "transport/dds_publisher.hpp"
#include "transport/lcm_publisher.hpp"

namespace tissue::replay {

namespace {

using record::h5::Handle;

// Reads the haptic and sim groups. The file checks (foreign, truncated,
// crashed, live) and the complete-row counts come from read_session_info,
// as in the session FrameSource; this only reads columns.
class RowReader {
 public:
  explicit RowReader(const std::string& path) : path_(path) {
    try {
      info_ = record::read_session_info(path);
    } catch (const record::RecordError& e) {
      throw ReplayError(e.what());
    }
    unsigned flags = H5F_ACC_RDONLY;
    // A live or crashed writer leaves the open-for-write flag: only SWMR
    // read opens such a file (read_session_info checked it is SWMR-capable).
    if (info_.open_for_write_flag) flags |= H5F_ACC_SWMR_READ;
    file_ = Handle(H5Fopen(path.c_str(), flags, H5P_DEFAULT));
    if (!file_) fail(record::h5::describe("cannot be opened as HDF5"));
  }

  const record::SessionInfo& info() const { return info_; }

  [[noreturn]] void fail(const std::string& what) const { throw ReplayError("'" + path_ + "': " + what); }

  // Rows [0, count) of a dataset with 1 or 3 columns, flattened.
  template <typename T>
  std::vector<T> column(record::DatasetId id, hid_t mem_type, std::uint64_t count) {
    const record::DatasetSpec& spec = record::kDatasets[id];
    const hsize_t columns = static_cast<hsize_t>(spec.columns);
    std::vector<T> out(count * columns);
    if (count == 0) return out;
    Handle d(H5Dopen2(file_.get(), spec.path, H5P_DEFAULT));
    if (!d) fail(record::h5::describe(std::string("cannot open dataset ") + spec.path));
    Handle space(H5Dget_space(d.get()));
    const int rank = columns == 1 ? 1 : 2;
    const hsize_t start[2] = {0, 0}, n[2] = {count, columns};
    Handle mem(H5Screate_simple(rank, n, nullptr));
    if (!space || !mem || H5Sget_simple_extent_ndims(space.get()) != rank ||
        H5Sselect_hyperslab(space.get(), H5S_SELECT_SET, start, nullptr, n, nullptr) < 0 ||
        H5Sselect_valid(space.get()) <= 0)
      fail(std::string("unexpected shape of ") + spec.path + " (" + std::to_string(count) + " rows expected)");
    if (H5Dread(d.get(), mem_type, mem.get(), space.get(), H5P_DEFAULT, out.data()) < 0)
      fail(record::h5::describe(std::string("cannot read ") + spec.path));
    return out;
  }

  void check_times(const std::vector<double>& t, const char* dataset) const {
    for (std::size_t i = 0; i < t.size(); ++i)
      if (!std::isfinite(t[i]) || (i > 0 && t[i] < t[i - 1]))
        fail(std::string(dataset) + " is not finite and non-decreasing at row " + std::to_string(i));
  }

 private:
  std::string path_;
  record::SessionInfo info_;
  Handle file_;
};

std::array<double, 3> row3(const std::vector<double>& flat, std::size_t i) {
  return {flat[3 * i], flat[3 * i + 1], flat[3 * i + 2]};
}

}  // namespace

SessionRows read_session_rows(const std::string& path) {
  record::h5::QuietErrors quiet;
  RowReader r(path);
  SessionRows rows;
  using namespace record;
  {
    const std::uint64_t n = r.info().rows.haptic_rows;
    const auto t = r.column<double>(kHapticTime, H5T_NATIVE_DOUBLE, n);
    r.check_times(t, kDatasets[kHapticTime].path);
    const auto device = r.column<double>(kHapticDevicePosition, H5T_NATIVE_DOUBLE, n);
    const auto proxy = r.column<double>(kHapticProxyPosition, H5T_NATIVE_DOUBLE, n);
    const auto force = r.column<double>(kHapticForce, H5T_NATIVE_DOUBLE, n);
    const auto contact = r.column<std::uint8_t>(kHapticContact, H5T_NATIVE_UINT8, n);
    const auto version = r.column<std::uint64_t>(kHapticModelVersion, H5T_NATIVE_UINT64, n);
    rows.haptic.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      HapticRow& h = rows.haptic[i];
      h.time_s = t[i];
      h.device_position_m = row3(device, i);
      h.proxy_position_m = row3(proxy, i);
      h.force_N = row3(force, i);
      h.contact = contact[i];
      h.model_version = version[i];
    }
  }
  {
    const std::uint64_t n = r.info().rows.sim_rows;
    const auto t = r.column<double>(kSimTime, H5T_NATIVE_DOUBLE, n);
    r.check_times(t, kDatasets[kSimTime].path);
    const auto sim_time = r.column<double>(kSimSimTime, H5T_NATIVE_DOUBLE, n);
    const auto rtf = r.column<double>(kSimRealTimeFactor, H5T_NATIVE_DOUBLE, n);
    const auto step = r.column<double>(kSimStepMs, H5T_NATIVE_DOUBLE, n);
    const auto nodes = r.column<std::uint64_t>(kSimNodes, H5T_NATIVE_UINT64, n);
    const auto tets = r.column<std::uint64_t>(kSimTets, H5T_NATIVE_UINT64, n);
    const auto springs = r.column<std::uint64_t>(kSimSprings, H5T_NATIVE_UINT64, n);
    const auto refines = r.column<std::int64_t>(kSimRefines, H5T_NATIVE_INT64, n);
    const auto merges = r.column<std::int64_t>(kSimMerges, H5T_NATIVE_INT64, n);
    const auto kinetic = r.column<double>(kSimKinetic, H5T_NATIVE_DOUBLE, n);
    const auto elastic = r.column<double>(kSimElastic, H5T_NATIVE_DOUBLE, n);
    rows.sim.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      SimRow& s = rows.sim[i];
      s.time_s = t[i];
      s.sim_time_s = sim_time[i];
      s.real_time_factor = rtf[i];
      s.step_ms = step[i];
      s.nodes = nodes[i];
      s.tets = tets[i];
      s.springs = springs[i];
      s.refines = refines[i];
      s.merges = merges[i];
      s.kinetic_J = kinetic[i];
      s.elastic_J = elastic[i];
    }
  }
  return rows;
}

service::MeshSnapshot to_snapshot(const x3d::SurfaceFrame& f, std::uint64_t sequence) {
  service::MeshSnapshot s;
  s.sequence = sequence;
  s.sim_time_s = f.time_s;
  s.vertices_m = f.vertices_m;
  s.triangles = f.triangles;
  s.vertex_level = f.vertex_level;
  const std::vector<float>& v = f.vertex_strain_energy_Pa;
  if (!v.empty()) {
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
      throw ReplayError(std::string(what) + " rate " + std::to_string(rate_hz) + " Hz: must be >= 0 (0: every row)");
  if (o.from_s && o.to_s && !(*o.from_s <= *o.to_s))
    throw ReplayError("window --from " + std::to_string(*o.from_s) + " --to " + std::to_string(*o.to_s) +
                      ": the start is after the end");
  const auto inside = [&](double t) { return (!o.from_s || t >= *o.from_s) && (!o.to_s || t <= *o.to_s); };
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
  if (!(o.speed > 0.0) || !std::isfinite(o.speed))
    throw ReplayError("speed " + std::to_string(o.speed) + ": must be a finite number > 0");
  std::vector<double> frame_t(frames.frame_count()), haptic_t(rows.haptic.size()), sim_t(rows.sim.size());
  for (std::size_t k = 0; k < frame_t.size(); ++k) frame_t[k] = frames.frame_time_s(k);
  for (std::size_t i = 0; i < haptic_t.size(); ++i) haptic_t[i] = rows.haptic[i].time_s;
  for (std::size_t i = 0; i < sim_t.size(); ++i) sim_t[i] = rows.sim[i].time_s;
  const std::vector<TimelineItem> items = build_timeline(frame_t, haptic_t, sim_t, o.timeline);
  if (items.empty()) throw ReplayError(frames.name() + ": nothing to replay (no frame or row in the window)");
  if (o.loop && !(items.back().time_s > items.front().time_s))
    throw ReplayError(frames.name() + ": --loop needs a window that spans some time (all items are at " +
                      std::to_string(items.front().time_s) + " s)");

  constexpr double kLate_s = 0.01;
  ReplaySummary sum;
  const double start_wall_s = clock.now_s();
  double pass_wall_s = start_wall_s;  // when the current pass's first item is due
  const double t0_s = items.front().time_s;
  std::uint64_t sequence = 0;
  for (;;) {
    for (const TimelineItem& item : items) {
      // Read before waiting: a large frame takes time to load, and that time
      // should come out of the wait, not delay the send.
      std::optional<service::MeshSnapshot> snapshot;
      if (item.kind == StreamKind::kMesh) snapshot = to_snapshot(frames.read_frame(item.index), ++sequence);
      const double due_s = pass_wall_s + (item.time_s - t0_s) / o.speed;
      if (!clock.wait_until(due_s, stop)) {
        sum.stopped = true;
        return sum;
      }
      const double lag_s = clock.now_s() - due_s;
      if (lag_s > kLate_s) ++sum.late_items;
      sum.max_lag_s = std::max(sum.max_lag_s, lag_s);
      switch (item.kind) {
        case StreamKind::kMesh:
          sink.mesh(*snapshot);
          ++sum.frames;
          break;
        case StreamKind::kHaptic:
          sink.haptic(haptic_status(rows.haptic[item.index]));
          ++sum.haptic_rows;
          break;
        case StreamKind::kStats:
          sink.stats(sim_status(rows.sim[item.index]));
          ++sum.stats;
          break;
      }
      sum.wall_s = clock.now_s() - start_wall_s;
      sum.session_span_s = (item.time_s - t0_s) + sum.passes * (items.back().time_s - t0_s);
    }
    ++sum.passes;
    if (!o.loop || stop.load(std::memory_order_relaxed)) {
      sum.stopped = stop.load(std::memory_order_relaxed) && o.loop;
      return sum;
    }
    pass_wall_s += (items.back().time_s - t0_s) / o.speed;
  }
}

}  // namespace tissue::replay
