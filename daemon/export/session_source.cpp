// FrameSource over a recorded session file: the flat /mesh datasets indexed
// by /mesh/*_offset and *_count (docs/session-format.md), read with the HDF5
// C API. tissue_record has no per-frame reader; this one reuses its file
// checks (read_session_info) and its HDF5 handle helpers.
#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "export/frame_source.hpp"
#include "record/h5_util.hpp"
#include "record/record_types.hpp"
#include "record/session_layout.hpp"
#include "record/session_tools.hpp"

namespace tissue::x3d {

namespace {

using record::h5::Handle;
using record::h5::QuietErrors;

class SessionFrameSource final : public FrameSource {
 public:
  explicit SessionFrameSource(const std::string& path) : path_(path) {
    QuietErrors quiet;
    record::SessionInfo info;
    try {
      // Tells foreign, truncated, crashed and live files apart, and counts
      // only complete frames (index and data both flushed).
      info = record::read_session_info(path);
    } catch (const record::RecordError& e) {
      throw SourceError(e.what());
    }
    frames_ = info.rows.mesh_frames;
    unsigned flags = H5F_ACC_RDONLY;
    // A live or crashed writer leaves the open-for-write flag: only SWMR
    // read opens such a file (read_session_info checked it is SWMR-capable).
    if (info.open_for_write_flag) flags |= H5F_ACC_SWMR_READ;
    file_ = Handle(H5Fopen(path.c_str(), flags, H5P_DEFAULT));
    if (!file_) fail(record::h5::describe("cannot be opened as HDF5"));
    times_ = read_column<double>(record::kMeshFrameTime, H5T_NATIVE_DOUBLE, 0, frames_);
    vertex_offset_ = read_column<std::uint64_t>(record::kMeshVertexOffset, H5T_NATIVE_UINT64, 0, frames_);
    vertex_count_ = read_column<std::uint64_t>(record::kMeshVertexCount, H5T_NATIVE_UINT64, 0, frames_);
    triangle_offset_ = read_column<std::uint64_t>(record::kMeshTriangleOffset, H5T_NATIVE_UINT64, 0, frames_);
    triangle_count_ = read_column<std::uint64_t>(record::kMeshTriangleCount, H5T_NATIVE_UINT64, 0, frames_);
    for (std::size_t k = 0; k < frames_; ++k) {
      if (!std::isfinite(times_[k])) fail("/mesh/frame_time_s[" + std::to_string(k) + "] is not finite");
      if (k > 0 && times_[k] < times_[k - 1])
        fail("/mesh/frame_time_s goes backwards at frame " + std::to_string(k) + " (frames must be in time order)");
    }
    // Version 2 stores strain; a frame recorded without it holds NaN. The
    // first frame with triangles says whether this recording computed it
    // (the daemon does for every frame or for none).
    file_has_strain_ = info.has_strain;
    if (file_has_strain_) {
      has_strain_ = true;
      for (std::size_t k = 0; k < frames_; ++k)
        if (triangle_count_[k] > 0) {
          has_strain_ =
              !std::isnan(read_column<float>(record::kMeshTriangleStrain, H5T_NATIVE_FLOAT, triangle_offset_[k], 1)[0]);
          break;
        }
    }
  }

  std::string name() const override { return "'" + path_ + "'"; }
  std::size_t frame_count() const override { return frames_; }
  double frame_time_s(std::size_t k) const override { return times_.at(k); }
  // Format version 1 stores none; version 2 unless recorded without it.
  bool has_strain() const override { return has_strain_; }

  SurfaceFrame read_frame(std::size_t k) override {
    if (k >= frames_)
      throw std::out_of_range("frame " + std::to_string(k) + " of " + name() + " does not exist (" +
                              std::to_string(frames_) + " frames)");
    QuietErrors quiet;
    const std::uint64_t nv = vertex_count_[k], nt = triangle_count_[k];
    // Counts come from the file: bound them before allocating (the
    // complete-frame check in read_session_info already bounded them by the
    // dataset extents, this is the int32 index limit of the format).
    if (nv > static_cast<std::uint64_t>(std::numeric_limits<std::int32_t>::max()))
      fail("frame " + std::to_string(k) + " claims " + std::to_string(nv) + " vertices");
    SurfaceFrame f;
    f.time_s = times_[k];
    const auto xyz = read_column<float>(record::kMeshVertices, H5T_NATIVE_FLOAT, vertex_offset_[k], nv);
    f.vertices_m.resize(nv);
    for (std::size_t i = 0; i < nv; ++i)
      for (int a = 0; a < 3; ++a) f.vertices_m[i][a] = static_cast<double>(xyz[3 * i + a]);
    const auto idx = read_column<std::int32_t>(record::kMeshTriangles, H5T_NATIVE_INT32, triangle_offset_[k], nt);
    f.triangles.resize(nt);
    for (std::size_t t = 0; t < nt; ++t)
      for (int c = 0; c < 3; ++c) {
        const std::int32_t v = idx[3 * t + c];
        if (v < 0)
          fail("/mesh/triangles row " + std::to_string(triangle_offset_[k] + t) + " (frame " + std::to_string(k) +
               ") holds the negative index " + std::to_string(v));
        f.triangles[t][c] = static_cast<std::uint32_t>(v);
      }
    f.vertex_level = read_column<std::uint8_t>(record::kMeshVertexLevel, H5T_NATIVE_UINT8, vertex_offset_[k], nv);
    if (file_has_strain_ && nt > 0) {
      std::vector<float> strain =
          read_column<float>(record::kMeshTriangleStrain, H5T_NATIVE_FLOAT, triangle_offset_[k], nt);
      const std::string dataset = record::kDatasets[record::kMeshTriangleStrain].path;
      const bool not_computed = std::isnan(strain[0]);
      for (std::size_t t = 0; t < nt; ++t) {
        const float e = strain[t];
        // All NaN: recorded without strain. Anything else must be a real
        // energy density: finite and >= 0.
        if (std::isnan(e) != not_computed || (!not_computed && (!std::isfinite(e) || e < 0.0f)))
          fail(dataset + " row " + std::to_string(triangle_offset_[k] + t) + " (frame " + std::to_string(k) +
               ") holds " + std::to_string(e) + " J/m^3: not a strain energy density (must be finite and >= 0)");
      }
      if (!not_computed) {
        try {
          f.vertex_strain_energy_Pa = vertex_strain_from_triangles(nv, f.triangles, strain);
        } catch (const X3dInputError& e) {
          fail("frame " + std::to_string(k) + ": " + e.what());
        }
      }
    }
    return f;
  }

 private:
  [[noreturn]] void fail(const std::string& what) const { throw SourceError(name() + ": " + what); }

  // Rows [first, first+count) of a dataset with 1 or 3 columns, flattened.
  template <typename T>
  std::vector<T> read_column(record::DatasetId id, hid_t mem_type, std::uint64_t first, std::uint64_t count) {
    const record::DatasetSpec& spec = record::kDatasets[id];
    const hsize_t columns = static_cast<hsize_t>(spec.columns);
    std::vector<T> out(count * columns);
    if (count == 0) return out;
    Handle d(H5Dopen2(file_.get(), spec.path, H5P_DEFAULT));
    if (!d) fail(record::h5::describe(std::string("cannot open dataset ") + spec.path));
    Handle space(H5Dget_space(d.get()));
    const int rank = columns == 1 ? 1 : 2;
    const hsize_t start[2] = {first, 0}, n[2] = {count, columns};
    Handle mem(H5Screate_simple(rank, n, nullptr));
    if (!space || !mem || H5Sget_simple_extent_ndims(space.get()) != rank ||
        H5Sselect_hyperslab(space.get(), H5S_SELECT_SET, start, nullptr, n, nullptr) < 0 ||
        H5Sselect_valid(space.get()) <= 0)
      fail(std::string("unexpected shape of ") + spec.path + " (rows " + std::to_string(first) + " to " +
           std::to_string(first + count) + " not inside it)");
    if (H5Dread(d.get(), mem_type, mem.get(), space.get(), H5P_DEFAULT, out.data()) < 0)
      fail(record::h5::describe(std::string("cannot read ") + spec.path));
    return out;
  }

  std::string path_;
  Handle file_;
  std::size_t frames_ = 0;
  bool file_has_strain_ = false;  // the dataset exists (format version >= 2)
  bool has_strain_ = false;       // and the frames carry values
  std::vector<double> times_;
  std::vector<std::uint64_t> vertex_offset_, vertex_count_, triangle_offset_, triangle_count_;
};

}  // namespace

std::optional<std::size_t> frame_at_time(const FrameSource& source, double t_s) {
  // Frames are in time order: binary search for the last time <= t.
  std::size_t lo = 0, hi = source.frame_count();
  while (lo < hi) {
    const std::size_t mid = lo + (hi - lo) / 2;
    if (source.frame_time_s(mid) <= t_s)
      lo = mid + 1;
    else
      hi = mid;
  }
  if (lo == 0) return std::nullopt;
  return lo - 1;
}

std::vector<std::size_t> frames_in_window(const FrameSource& source, double t0_s, double t1_s) {
  std::vector<std::size_t> out;
  for (std::size_t k = 0; k < source.frame_count(); ++k) {
    const double t = source.frame_time_s(k);
    if (t >= t0_s && t <= t1_s) out.push_back(k);
  }
  return out;
}

std::unique_ptr<FrameSource> open_session_source(const std::string& path) {
  return std::make_unique<SessionFrameSource>(path);
}

}  // namespace tissue::x3d
