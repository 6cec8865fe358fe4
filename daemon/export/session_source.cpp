// FrameSource over a recorded session file: the flat /mesh datasets indexed
// by /mesh/*_offset and *_count (docs/session-format.md), read through
// record::SessionFile, the one session reader (its file checks, complete-frame
// counts and range-checked row reads).
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <limits>

#include "export/frame_source.hpp"
#include "record/record_types.hpp"
#include "record/session_layout.hpp"
#include "record/session_tools.hpp"
#include "util/text.hpp"

namespace tissue::x3d {

namespace {

// A nanosecond of slack when a user's time meets a stored one: times summed
// from steps land a hair off the grid (500 steps of 1 ms end at
// 0.5000000000000003 s), and --time 0.5 or --to 0.5 means that frame.
constexpr double kSlack_s = 1e-9;

// Opens the file; its RecordError ("'FILE': what") becomes a SourceError
// with the same message.
record::SessionFile open_file(const std::string& path) {
  try {
    return record::SessionFile(path);
  } catch (const record::RecordError& e) {
    throw SourceError(e.what());
  }
}

class SessionFrameSource final : public FrameSource {
 public:
  explicit SessionFrameSource(const std::string& path) : file_(open_file(path)) {
    // The file checks tell foreign, truncated, crashed and live files apart,
    // and count only complete frames (index and data both flushed).
    const record::SessionInfo& info = file_.info();
    frames_ = info.rows.mesh_frames;
    times_ = read<double>(record::kMeshFrameTime, 0, frames_);
    vertex_offset_ = read<std::uint64_t>(record::kMeshVertexOffset, 0, frames_);
    vertex_count_ = read<std::uint64_t>(record::kMeshVertexCount, 0, frames_);
    triangle_offset_ = read<std::uint64_t>(record::kMeshTriangleOffset, 0, frames_);
    triangle_count_ = read<std::uint64_t>(record::kMeshTriangleCount, 0, frames_);
    // Replay paces by these (1e300 s waited for ever, -1.7e308 to 1.7e308 s
    // made its span NaN).
    if (const std::string problem = record::frame_times_problem(times_); !problem.empty()) fail(problem);
    // Version 2 stores strain; a frame recorded without it holds NaN. The
    // first frame with triangles says whether this recording computed it
    // (the daemon does for every frame or for none).
    file_has_strain_ = info.has_strain;
    if (file_has_strain_) {
      has_strain_ = true;
      for (std::size_t k = 0; k < frames_; ++k)
        if (triangle_count_[k] > 0) {
          has_strain_ = !std::isnan(read<float>(record::kMeshTriangleStrain, triangle_offset_[k], 1)[0]);
          break;
        }
    }
  }

  std::string name() const override { return "'" + file_.path() + "'"; }
  std::size_t frame_count() const override { return frames_; }
  double frame_time_s(std::size_t k) const override { return times_.at(k); }
  // Format version 1 stores none; version 2 unless recorded without it.
  bool has_strain() const override { return has_strain_; }
  std::string why_no_strain() const override {
    return "stores no strain energy (session format version 1, or recorded without it)";
  }

  // From the index: what read_frame(k) fills. Strain is counted whenever
  // the file has the dataset and the frame has triangles, so a frame
  // recorded without it (NaN, not returned) is counted high, never low.
  std::size_t frame_data_bytes(std::size_t k) override {
    if (k >= frames_)
      throw std::out_of_range("frame " + std::to_string(k) + " of " + name() + " does not exist (" +
                              std::to_string(frames_) + " frames)");
    SurfaceFrame one;  // element sizes as frame_bytes counts them
    std::uint64_t per_vertex = sizeof(one.vertices_m[0]) + sizeof(one.vertex_level[0]);
    std::uint64_t per_triangle = sizeof(one.triangles[0]);
    if (file_has_strain_ && triangle_count_[k] > 0) {
      per_vertex += sizeof(one.vertex_strain_energy_Pa[0]);
      per_triangle += sizeof(one.triangle_strain_energy_J_per_m3[0]);
    }
    // Counts are below 2^63 rows (HDF5 extents), but their product with the
    // element size need not fit: saturate rather than wrap to a small size.
    const std::uint64_t max = std::numeric_limits<std::size_t>::max();
    const auto times = [&](std::uint64_t count, std::uint64_t size) { return count > max / size ? max : count * size; };
    const std::uint64_t v = times(vertex_count_[k], per_vertex), t = times(triangle_count_[k], per_triangle);
    return static_cast<std::size_t>(v > max - t ? max : v + t);
  }

  SurfaceFrame read_frame(std::size_t k) override {
    if (k >= frames_)
      throw std::out_of_range("frame " + std::to_string(k) + " of " + name() + " does not exist (" +
                              std::to_string(frames_) + " frames)");
    // Counts come from the file, bounded by the session reader at open: by
    // the dataset extents (complete frames), the int32 index limit of the
    // format (kMaxMeshFrameVertices) and, as the rows are read, the file's
    // size.
    const std::uint64_t nv = vertex_count_[k], nt = triangle_count_[k];
    const auto xyz = read<float>(record::kMeshVertices, vertex_offset_[k], nv);
    const auto idx = read<std::int32_t>(record::kMeshTriangles, triangle_offset_[k], nt);
    std::vector<float> strain;
    if (file_has_strain_ && nt > 0) strain = read<float>(record::kMeshTriangleStrain, triangle_offset_[k], nt);
    // Every consumer (x3d, render, replay) indexes the frame's vertices with
    // the triangles and draws or publishes the values: checked here, by the
    // rule every reader of frames shares.
    if (const std::string problem =
            record::mesh_frame_problem(k, vertex_offset_[k], xyz, triangle_offset_[k], idx, strain);
        !problem.empty())
      fail(problem);
    SurfaceFrame f;
    f.time_s = times_[k];
    f.vertices_m.resize(nv);
    for (std::size_t i = 0; i < nv; ++i)
      for (int a = 0; a < 3; ++a) f.vertices_m[i][a] = static_cast<double>(xyz[3 * i + a]);
    f.triangles.resize(nt);
    for (std::size_t t = 0; t < nt; ++t)
      for (int c = 0; c < 3; ++c) f.triangles[t][c] = static_cast<std::uint32_t>(idx[3 * t + c]);
    f.vertex_level = read<std::uint8_t>(record::kMeshVertexLevel, vertex_offset_[k], nv);
    // All NaN: recorded without strain (no per-vertex values).
    if (!strain.empty() && !std::isnan(strain[0])) {
      try {
        f.vertex_strain_energy_Pa = vertex_strain_from_triangles(nv, f.triangles, strain);
      } catch (const X3dInputError& e) {
        fail("frame " + std::to_string(k) + ": " + e.what());
      }
      // Both: per-vertex for colouring, the recorded per-triangle values
      // for consumers that send them on (replay), unchanged.
      f.triangle_strain_energy_J_per_m3 = std::move(strain);
    }
    return f;
  }

 private:
  [[noreturn]] void fail(const std::string& what) const { throw SourceError(name() + ": " + what); }

  // Rows of a dataset through the session reader; its RecordError (which
  // names the file) becomes a SourceError.
  template <typename T>
  std::vector<T> read(record::DatasetId id, std::uint64_t first, std::uint64_t count) const {
    try {
      return file_.rows<T>(id, first, count);
    } catch (const record::RecordError& e) {
      throw SourceError(e.what());
    }
  }

  record::SessionFile file_;
  std::size_t frames_ = 0;
  bool file_has_strain_ = false;  // the dataset exists (format version >= 2)
  bool has_strain_ = false;       // and the frames carry values
  std::vector<double> times_;
  std::vector<std::uint64_t> vertex_offset_, vertex_count_, triangle_offset_, triangle_count_;
};

}  // namespace

std::size_t frame_bytes(const SurfaceFrame& f) {
  return f.vertices_m.size() * sizeof(f.vertices_m[0]) + f.triangles.size() * sizeof(f.triangles[0]) +
         f.vertex_level.size() * sizeof(f.vertex_level[0]) +
         f.vertex_strain_energy_Pa.size() * sizeof(f.vertex_strain_energy_Pa[0]) +
         f.triangle_strain_energy_J_per_m3.size() * sizeof(f.triangle_strain_energy_J_per_m3[0]);
}

std::string byte_size_text(std::size_t bytes) {
  constexpr const char* kUnits[] = {"bytes", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
  double v = static_cast<double>(bytes);
  std::size_t u = 0;
  while (v >= 1024.0 && u + 1 < std::size(kUnits)) v /= 1024.0, ++u;
  char buf[48];
  std::snprintf(buf, sizeof buf, "%g %s", v, kUnits[u]);
  return buf;
}

std::string frame_budget_problem(FrameSource& source, const std::vector<std::size_t>& picked, std::size_t max_bytes) {
  // The whole sum, saturating, so the message says how far over it is (a
  // session answers from its index: nothing is read).
  std::size_t total = 0;
  for (const std::size_t k : picked) {
    const std::size_t bytes = source.frame_data_bytes(k);
    total = bytes > std::numeric_limits<std::size_t>::max() - total ? std::numeric_limits<std::size_t>::max()
                                                                    : total + bytes;
  }
  if (total <= max_bytes) return {};
  return std::to_string(picked.size()) + " frames of " + source.name() +
         " (t=" + frame_time_text(source.frame_time_s(picked.front())) + " s to " +
         frame_time_text(source.frame_time_s(picked.back())) + " s) hold " + byte_size_text(total) +
         " of frame data, more than the " + byte_size_text(max_bytes) + " an export may hold";
}

std::string no_strain_message(const FrameSource& source) {
  return "--colour strain: " + source.name() + " " + source.why_no_strain() + "; use --colour level";
}

std::optional<std::size_t> frame_at_time(const FrameSource& source, double t_s) {
  // Frames are in time order: binary search for the last time <= t.
  std::size_t lo = 0, hi = source.frame_count();
  while (lo < hi) {
    const std::size_t mid = lo + (hi - lo) / 2;
    if (source.frame_time_s(mid) <= t_s + kSlack_s)
      lo = mid + 1;
    else
      hi = mid;
  }
  if (lo == 0) return std::nullopt;
  return lo - 1;
}

std::string frame_time_text(double t_s) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, t_s, std::chars_format::general, 9);
  return std::string(buf, r.ptr);
}

bool time_in_window(double t_s, std::optional<double> t0_s, std::optional<double> t1_s) {
  if (std::isnan(t_s)) return false;
  return (!t0_s || t_s >= *t0_s - kSlack_s) && (!t1_s || t_s <= *t1_s + kSlack_s);
}

std::vector<std::size_t> frames_in_window(const FrameSource& source, double t0_s, double t1_s) {
  std::vector<std::size_t> out;
  for (std::size_t k = 0; k < source.frame_count(); ++k)
    if (time_in_window(source.frame_time_s(k), t0_s, t1_s)) out.push_back(k);
  return out;
}

std::string window_text(std::optional<double> from_s, std::optional<double> to_s, double t0_s, double t1_s) {
  const auto end_text = [](const std::optional<double>& given_s, double t_s) {
    return given_s ? util::number_text(*given_s) : frame_time_text(t_s);
  };
  return "between " + end_text(from_s, t0_s) + " s and " + end_text(to_s, t1_s) + " s";
}

std::string reversed_window_text(const FrameSource& source, std::optional<double> from_s, std::optional<double> to_s,
                                 double t0_s, double t1_s) {
  if (from_s && to_s)
    return "--from " + util::number_text(*from_s) + " --to " + util::number_text(*to_s) +
           ": the window is empty (--from is after --to)";
  // One end given: the other is the session's first or last frame, said as
  // its time (it said "--from 0.25 --to 0.1" to a user who gave no --from).
  if (to_s)
    return "--to " + util::number_text(*to_s) + " is before the first frame of " + source.name() +
           " (t=" + frame_time_text(t0_s) + " s)";
  return "--from " + util::number_text(from_s.value_or(t0_s)) + " is after the last frame of " + source.name() +
         " (t=" + frame_time_text(t1_s) + " s)";
}

std::unique_ptr<FrameSource> open_session_source(const std::string& path) {
  return std::make_unique<SessionFrameSource>(path);
}

}  // namespace tissue::x3d
