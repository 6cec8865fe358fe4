#include "record/session_tools.hpp"
#include "record/recording_lock.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <optional>
#include <sstream>
#include <string_view>
#include <type_traits>

#include "record/h5_util.hpp"
#include "record/session_layout.hpp"
#include "record/session_writer.hpp"
#include "util/output_file.hpp"
#include "util/text.hpp"
#include "util/xml.hpp"

namespace tissue::record {

namespace {

using h5::Handle;

[[noreturn]] void bad_file(const std::string& path, const std::string& what) {
  throw RecordError("'" + path + "': " + what);
}

// What info, list and the readers' refusals say of a file a crash left with
// rows past its complete ones (SessionInfo::crash_tail).
constexpr const char* kRepairTrims = "`tissue session repair FILE` trims it to its last complete frame";

// A string from a session file or a directory, as `info` and `list` print
// it. The file may hold anything (a foreign writer, an edit, damage): printed
// raw, an escape sequence drove the terminal and a line break forged a line
// of the report ("\nstate: closed cleanly"). Clean text (util/text.hpp's
// rule) stays as it is; each byte of a control character or of what is not
// UTF-8 shows as \xNN.
std::string shown(std::string_view text) {
  if (util::why_not_clean_text(text).empty()) return std::string(text);
  std::string out;
  for (std::size_t i = 0; i < text.size();) {
    const std::optional<util::Utf8Char> c = util::decode_utf8(text, i);
    const std::size_t length = c ? c->length : 1;
    if (c && util::why_not_clean_text(text.substr(i, length)).empty()) {
      out.append(text.substr(i, length));
    } else {
      for (std::size_t k = i; k < i + length; ++k) {
        char hex[8];
        std::snprintf(hex, sizeof hex, "\\x%02X", static_cast<unsigned>(static_cast<unsigned char>(text[k])));
        out += hex;
      }
    }
    i += length;
  }
  return out;
}

// What the first bytes say, before HDF5 is asked anything: foreign, empty
// and truncated files get a plain answer, and the superblock's file
// consistency flags (HDF5 file format spec, superblock v2/v3, byte 11: bit 0
// open for write, bit 2 open for SWMR write) tell a live or crashed session
// from a closed one without tripping over them.
struct Preamble {
  int superblock_version = 0;
  std::uint8_t consistency_flags = 0;
  std::uintmax_t size_bytes = 0;
};

Preamble read_preamble(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) bad_file(path, std::string("cannot open: ") + std::strerror(errno));
  if (S_ISDIR(st.st_mode)) bad_file(path, "is a directory, not a session file");
  if (!S_ISREG(st.st_mode)) bad_file(path, "is not a regular file");
  Preamble p;
  p.size_bytes = static_cast<std::uintmax_t>(st.st_size);
  if (p.size_bytes == 0) bad_file(path, "is empty (0 bytes): not a session file");
  std::ifstream in(path, std::ios::binary);
  if (!in) bad_file(path, std::string("cannot open: ") + std::strerror(errno));
  std::array<unsigned char, 12> head{};
  in.read(reinterpret_cast<char*>(head.data()), head.size());
  const std::size_t got = static_cast<std::size_t>(in.gcount());
  static constexpr unsigned char kSignature[8] = {0x89, 'H', 'D', 'F', '\r', '\n', 0x1a, '\n'};
  if (got < 8 || std::memcmp(head.data(), kSignature, 8) != 0)
    bad_file(path, "is not an HDF5 file (no HDF5 signature at the start): not a session file");
  if (got < head.size())
    bad_file(path, "is truncated: " + std::to_string(got) + " bytes, shorter than an HDF5 superblock");
  p.superblock_version = head[8];
  if (p.superblock_version >= 2) p.consistency_flags = head[11];
  return p;
}

// How often a SWMR reader reads a metadata entry whose checksum fails before
// it gives up. HDF5 (1.10.8, H5C_load_entry; the same in 1.12) retries such
// a read, sleeping 1 ns after the first failure and twice as long after each
// next one, so N attempts sleep 2^N - 1 ns in all. Its default for SWMR
// reads is 100 attempts (H5F_SWMR_METADATA_READ_ATTEMPTS): 2^100 ns, so a
// crashed session with one bad metadata byte hung every reader for good.
// A live writer's torn read (the entry read while the writer's pwrite of it,
// a few KB, is under way) mends as soon as that write completes: 28 attempts
// keep retrying for 2^28 ns = 0.27 s (the last wait alone 0.13 s, plus the
// kernel's timer slack per sleep), hundreds of times longer than such a
// write even on a loaded machine, yet a damaged entry fails within that
// bound, well under a second.
constexpr unsigned kSwmrMetadataReadAttempts = 28;

// Opens for reading: SWMR read when the superblock says a writer has (or
// had) it open, since an ordinary open refuses such a file.
Handle open_for_reading(const std::string& path, const Preamble& pre) {
  Handle fapl(H5Pcreate(H5P_FILE_ACCESS));
  unsigned flags = H5F_ACC_RDONLY;
  if (pre.consistency_flags != 0) {
    if (pre.superblock_version < 3)
      bad_file(path, "is marked open for writing but is not in the SWMR file format: cannot be read");
    flags |= H5F_ACC_SWMR_READ;
    if (!fapl || H5Pset_metadata_read_attempts(fapl.get(), kSwmrMetadataReadAttempts) < 0)
      bad_file(path, h5::describe("cannot bound the metadata read attempts"));
  }
  Handle file(H5Fopen(path.c_str(), flags, fapl.get()));
  if (!file) bad_file(path, h5::describe("cannot be opened as HDF5 (corrupt or truncated?)"));
  return file;
}

Handle open_dataset(hid_t file, const std::string& path, const char* dataset) {
  if (H5Lexists(file, kGroupPaths[0], H5P_DEFAULT) <= 0 && std::strncmp(dataset, "/haptic", 7) == 0)
    bad_file(path, "has no /haptic group: not a tissue session file");
  // H5Lexists on "/a/b" fails (rather than returning 0) when /a is missing.
  const std::string ds(dataset);
  const std::string group = ds.substr(0, ds.find('/', 1));
  // A failed look-up (< 0) is damage, not absence: a flipped byte in a
  // group's link index (a fractal heap block has no checksum) was reported
  // as "dataset ... is missing: not a complete tissue session file".
  for (const char* link : {group.c_str(), dataset}) {
    const htri_t exists = H5Lexists(file, link, H5P_DEFAULT);
    if (exists < 0)
      bad_file(path, h5::describe(std::string("cannot look up dataset ") + dataset + ": corrupt metadata"));
    if (exists == 0)
      bad_file(path, std::string("dataset ") + dataset + " is missing: not a complete tissue session file");
  }
  Handle d(H5Dopen2(file, dataset, H5P_DEFAULT));
  if (!d) bad_file(path, h5::describe(std::string("cannot open dataset ") + dataset));
  return d;
}

H5T_class_t stored_class(ElementType type) {
  switch (type) {
    case ElementType::kF64:
    case ElementType::kF32:
      return H5T_FLOAT;
    case ElementType::kString:
      return H5T_STRING;
    case ElementType::kU8:
    case ElementType::kI32:
    case ElementType::kU64:
    case ElementType::kI64:
      break;
  }
  return H5T_INTEGER;
}

const char* class_name(H5T_class_t c) {
  switch (c) {
    case H5T_INTEGER:
      return "integer";
    case H5T_FLOAT:
      return "floating-point";
    case H5T_STRING:
      return "string";
    default:
      return "other (not integer, floating-point or string)";
  }
}

// Rows of dataset `d` (kDatasets[id]) after checking what every reader
// relies on: rank 1 for a column, N x columns otherwise, and the type class
// of the layout. HDF5 converts within a class on read (int32 to uint64,
// float64 to float32), but a string column read as numbers, or a V x 2
// vertex table read 3 values a row, would be garbage.
std::uint64_t checked_rows(hid_t d, const std::string& path, DatasetId id) {
  const DatasetSpec& spec = kDatasets[id];
  Handle space(H5Dget_space(d));
  const int rank = space ? H5Sget_simple_extent_ndims(space.get()) : -1;
  if (rank < 0) bad_file(path, h5::describe(std::string("cannot read the shape of ") + spec.path));
  hsize_t dims[H5S_MAX_RANK] = {};
  if (rank > 0 && H5Sget_simple_extent_dims(space.get(), dims, nullptr) < 0)
    bad_file(path, h5::describe(std::string("cannot read the shape of ") + spec.path));
  const int want_rank = spec.columns == 1 ? 1 : 2;
  if (rank != want_rank || (rank == 2 && dims[1] != static_cast<hsize_t>(spec.columns))) {
    std::string shape;
    for (int i = 0; i < rank; ++i) shape += (i ? " x " : "") + std::to_string(dims[i]);
    bad_file(path, std::string("dataset ") + spec.path + " has shape (" + shape + "), rank " + std::to_string(rank) +
                       ", expected " +
                       (spec.columns == 1 ? std::string("rank 1 (one value per row)")
                                          : "N x " + std::to_string(spec.columns)) +
                       ": corrupt session file");
  }
  Handle type(H5Dget_type(d));
  const H5T_class_t cls = type ? H5Tget_class(type.get()) : H5T_NO_CLASS;
  if (cls != stored_class(spec.type))
    bad_file(path, std::string("dataset ") + spec.path + " stores " + class_name(cls) + " values, expected " +
                       class_name(stored_class(spec.type)) + ": corrupt session file");
  return dims[0];
}

std::uint64_t dataset_rows(hid_t file, const std::string& path, DatasetId id) {
  Handle d = open_dataset(file, path, kDatasets[id].path);
  return checked_rows(d.get(), path, id);
}

// The HDF5 memory type of T (H5T_NATIVE_* are run-time values, so this is a
// function, not a table). HDF5 converts from the stored type on read.
template <typename T>
hid_t memory_type() {
  if constexpr (std::is_same_v<T, double>)
    return H5T_NATIVE_DOUBLE;
  else if constexpr (std::is_same_v<T, float>)
    return H5T_NATIVE_FLOAT;
  else if constexpr (std::is_same_v<T, std::uint8_t>)
    return H5T_NATIVE_UINT8;
  else if constexpr (std::is_same_v<T, std::int32_t>)
    return H5T_NATIVE_INT32;
  else if constexpr (std::is_same_v<T, std::uint64_t>)
    return H5T_NATIVE_UINT64;
  else if constexpr (std::is_same_v<T, std::int64_t>)
    return H5T_NATIVE_INT64;
  else
    static_assert(sizeof(T) == 0, "no HDF5 memory type for this element type");
}

// Rows [first, first+count) of a dataset, opened and selected for a read
// into `memory` (count x columns values).
struct RowSelection {
  Handle dataset, file_space, memory;
};

// Every reader of a session goes through here, so the shape and range
// checks (a damaged index must not read past a dataset) are in one place.
// count > 0.
RowSelection select_rows(hid_t file, const std::string& path, DatasetId id, std::uint64_t first, std::uint64_t count) {
  const DatasetSpec& spec = kDatasets[id];
  const hsize_t columns = static_cast<hsize_t>(spec.columns);
  RowSelection r;
  r.dataset = open_dataset(file, path, spec.path);
  checked_rows(r.dataset.get(), path, id);
  // A damaged extent (1e8 rows in a 1 MB file: chunks never written read as
  // fill values) must not become a gigabyte allocation or a bare bad_alloc.
  // Session datasets are stored unfiltered, so every row that was written
  // takes its bytes in the file: rows to read whose bytes exceed the whole
  // file were never written. The bound holds for crashed files too: their
  // readers read only rows every column of the group has (or a frame the
  // index places inside the data), and an extent set just before a crash is
  // at most one flush ahead of the data, far smaller than the file's other
  // columns and metadata.
  hsize_t file_bytes = 0;
  if (H5Fget_filesize(file, &file_bytes) < 0) bad_file(path, h5::describe("cannot read the file size"));
  Handle stored(H5Dget_type(r.dataset.get()));
  const std::size_t element_bytes = stored ? H5Tget_size(stored.get()) : 0;
  const long double want_bytes = static_cast<long double>(count) * columns * std::max<std::size_t>(element_bytes, 1);
  if (want_bytes > static_cast<long double>(file_bytes))
    bad_file(path, std::string("dataset ") + spec.path + ": rows " + std::to_string(first) + " to " +
                       std::to_string(first + count) + " would take " + std::to_string(count) + " x " +
                       std::to_string(columns * element_bytes) + " bytes, more than the whole file (" +
                       std::to_string(file_bytes) + " bytes): its extent is corrupt");
  r.file_space = Handle(H5Dget_space(r.dataset.get()));
  const int rank = columns == 1 ? 1 : 2;
  const hsize_t start[2] = {first, 0}, n[2] = {count, columns};
  r.memory = Handle(H5Screate_simple(rank, n, nullptr));
  if (!r.file_space || !r.memory || H5Sget_simple_extent_ndims(r.file_space.get()) != rank ||
      H5Sselect_hyperslab(r.file_space.get(), H5S_SELECT_SET, start, nullptr, n, nullptr) < 0 ||
      H5Sselect_valid(r.file_space.get()) <= 0)
    bad_file(path, std::string("unexpected shape of ") + spec.path + " (rows " + std::to_string(first) + " to " +
                       std::to_string(first + count) + " not inside it)");
  return r;
}

// Rows [first, first+count) of a dataset with 1 or 3 columns, flattened.
template <typename T>
std::vector<T> read_column(hid_t file, const std::string& path, DatasetId id, std::uint64_t first,
                           std::uint64_t count) {
  if (count == 0) return {};
  const RowSelection r = select_rows(file, path, id, first, count);
  std::vector<T> out(count * static_cast<std::size_t>(kDatasets[id].columns));
  if (H5Dread(r.dataset.get(), memory_type<T>(), r.memory.get(), r.file_space.get(), H5P_DEFAULT, out.data()) < 0)
    bad_file(path, h5::describe(std::string("cannot read ") + kDatasets[id].path));
  return out;
}

// Rows [first, first+count) of a fixed-size string column (/events/message),
// each cut at its first NUL. HDF5 converts another fixed size to ours
// (longer strings are cut); a variable-length one is refused by H5Dread.
std::vector<std::string> read_strings(hid_t file, const std::string& path, DatasetId id, std::uint64_t first,
                                      std::uint64_t count) {
  if (count == 0) return {};
  const RowSelection r = select_rows(file, path, id, first, count);
  // HDF5 converts no character sets: read in the stored one (the writer's
  // is UTF-8).
  Handle stored(H5Dget_type(r.dataset.get()));
  const H5T_cset_t cset = stored ? H5Tget_cset(stored.get()) : H5T_CSET_ERROR;
  Handle type(H5Tcopy(H5T_C_S1));
  if (cset == H5T_CSET_ERROR || !type || H5Tset_size(type.get(), kEventMessageBytes) < 0 ||
      H5Tset_strpad(type.get(), H5T_STR_NULLTERM) < 0 || H5Tset_cset(type.get(), cset) < 0)
    bad_file(path, h5::describe(std::string("cannot read ") + kDatasets[id].path));
  std::vector<char> bytes(count * kEventMessageBytes, '\0');
  if (H5Dread(r.dataset.get(), type.get(), r.memory.get(), r.file_space.get(), H5P_DEFAULT, bytes.data()) < 0)
    bad_file(path, h5::describe(std::string("cannot read ") + kDatasets[id].path));
  std::vector<std::string> out;
  out.reserve(count);
  for (std::uint64_t i = 0; i < count; ++i) {
    const char* text = bytes.data() + i * kEventMessageBytes;
    out.emplace_back(text, ::strnlen(text, kEventMessageBytes));
  }
  return out;
}

// What is wrong with `t`, row `row` of the time column `column`, as a
// session time, or "" when nothing is: finite and within kMaxSessionTime_s.
std::string session_time_problem(const char* column, std::uint64_t row, double t) {
  const std::string at = std::string(column) + "[" + std::to_string(row) + "]";
  if (!std::isfinite(t)) return at + " is not finite";
  if (std::abs(t) > kMaxSessionTime_s)
    return at + " is " + std::to_string(t) + " s, beyond any session (" + std::to_string(kMaxSessionTime_s) + " s)";
  return {};
}

struct Counts {
  GroupCounts rows;
  std::array<std::uint64_t, kDatasetCount> extents{};  // 0 for datasets the file's version does not have
  double last_time_s = 0.0;
};

// Complete rows per group: the shortest column of the group (columns are
// flushed one after another), and for the mesh the frames whose index and
// data are all present. `partial_ok`: the file was (or is) open for writing,
// so data columns may be one write apart; otherwise the per-triangle columns
// must have exactly one row per triangle.
Counts count_rows(hid_t file, const std::string& path, std::int64_t version, bool partial_ok) {
  Counts c;
  for (std::size_t i = 0; i < kDatasetCount; ++i)
    if (dataset_in_version(kDatasets[i], version)) c.extents[i] = dataset_rows(file, path, static_cast<DatasetId>(i));
  const auto group_min = [&](Group g, bool index_only) {
    std::uint64_t m = UINT64_MAX;
    for (std::size_t i = 0; i < kDatasetCount; ++i) {
      if (kDatasets[i].group != g || !dataset_in_version(kDatasets[i], version)) continue;
      if (index_only &&
          (i == kMeshVertices || i == kMeshTriangles || i == kMeshVertexLevel || i == kMeshTriangleStrain))
        continue;
      m = std::min(m, c.extents[i]);
    }
    return m;
  };
  c.rows.haptic_rows = group_min(Group::kHaptic, false);
  c.rows.sim_rows = group_min(Group::kSim, false);
  c.rows.events = group_min(Group::kEvents, false);

  const std::uint64_t indexed = group_min(Group::kMesh, true);
  const auto voff = read_column<std::uint64_t>(file, path, kMeshVertexOffset, 0, indexed);
  const auto vcnt = read_column<std::uint64_t>(file, path, kMeshVertexCount, 0, indexed);
  const auto toff = read_column<std::uint64_t>(file, path, kMeshTriangleOffset, 0, indexed);
  const auto tcnt = read_column<std::uint64_t>(file, path, kMeshTriangleCount, 0, indexed);
  const std::uint64_t vertex_rows = std::min(c.extents[kMeshVertices], c.extents[kMeshVertexLevel]);
  std::uint64_t triangle_rows = c.extents[kMeshTriangles];
  if (dataset_in_version(kDatasets[kMeshTriangleStrain], version)) {
    const std::uint64_t strain_rows = c.extents[kMeshTriangleStrain];
    if (strain_rows != triangle_rows && !partial_ok)
      bad_file(path, std::string("dataset ") + kDatasets[kMeshTriangleStrain].path + " has " +
                         std::to_string(strain_rows) + " rows but /mesh/triangles has " +
                         std::to_string(triangle_rows) + " (one strain value per triangle): corrupt session file");
    // A crash between the two writes: only triangles with their strain count.
    triangle_rows = std::min(triangle_rows, strain_rows);
  }
  // Frames are appended back to back: every index row the writer wrote
  // continues where the previous frame ended, so an offset that does not is
  // damage, wherever it is. The writer flushes a frame's data before its
  // index (session_layout.hpp), so a crash (partial_ok) can leave only the
  // last frames' index rows ahead of their data: the file counts up to the
  // first frame whose count runs past the data, and every row after it, its
  // offset still continuing, starts past the data too. A count past the data
  // followed by a row that does not continue it is damage, not a crash:
  // counting up to it made repair delete every frame after it. In a closed
  // or repaired file every index row was written with its data, so any
  // break is an error naming the row.
  const auto corrupt = [&](std::uint64_t f, DatasetId id, const std::string& why) {
    bad_file(path, std::string(kDatasets[id].path) + "[" + std::to_string(f) + "] " + why + " (frame " +
                       std::to_string(f) + " of " + std::to_string(indexed) + "): corrupt frame index");
  };
  std::uint64_t v_end = 0, t_end = 0;  // where frame f starts
  std::uint64_t frames = indexed;      // the first frame not all in the data (a crash tail), or all of them
  std::string tail;                    // what that frame's index row says, for errors after it
  for (std::uint64_t f = 0; f < indexed; ++f) {
    const std::string after =
        f > frames ? " (after " + tail + "; a crash leaves only the last frames past the data)" : "";
    if (voff[f] != v_end)
      corrupt(f, kMeshVertexOffset, "is " + std::to_string(voff[f]) + ", expected " + std::to_string(v_end) + after);
    if (toff[f] != t_end)
      corrupt(f, kMeshTriangleOffset, "is " + std::to_string(toff[f]) + ", expected " + std::to_string(t_end) + after);
    if (f < frames) {
      DatasetId past = kMeshVertexCount;
      std::string why;
      if (vcnt[f] > vertex_rows - v_end) {
        why = "is " + std::to_string(vcnt[f]) + ": past the end of the " + std::to_string(vertex_rows) +
              " vertex rows (/mesh/vertices_m, /mesh/vertex_level)";
      } else if (tcnt[f] > triangle_rows - t_end) {
        past = kMeshTriangleCount;
        why = "is " + std::to_string(tcnt[f]) + ": past the end of the " + std::to_string(triangle_rows) +
              " triangle rows";
      }
      if (!why.empty()) {
        if (!partial_ok) corrupt(f, past, why);
        frames = f;
        tail = std::string(kDatasets[past].path) + "[" + std::to_string(f) + "], which " + why;
        c.rows.mesh_vertices = v_end;
        c.rows.mesh_triangles = t_end;
      }
    }
    // Only a tail's count can exceed the data; one no offset can follow (the
    // sum would wrap) is damage.
    if (vcnt[f] > UINT64_MAX - v_end)
      corrupt(f, kMeshVertexCount, "is " + std::to_string(vcnt[f]) + ": more rows than any file holds");
    if (tcnt[f] > UINT64_MAX - t_end)
      corrupt(f, kMeshTriangleCount, "is " + std::to_string(tcnt[f]) + ": more rows than any file holds");
    // Nor does a writer make a frame its int32 triangle indices cannot
    // reach, crash or not. Checked here, for every reader at open, so none
    // reads (or allocates for) such a frame: the data extents may make room
    // for it when they are damaged too.
    if (vcnt[f] > kMaxMeshFrameVertices)
      corrupt(f, kMeshVertexCount,
              "is " + std::to_string(vcnt[f]) + ": more vertices than a frame's int32 triangle indices reach (" +
                  std::to_string(kMaxMeshFrameVertices) + ")");
    v_end += vcnt[f];
    t_end += tcnt[f];
  }
  c.rows.mesh_frames = frames;
  if (frames == indexed) {
    c.rows.mesh_vertices = v_end;
    c.rows.mesh_triangles = t_end;
  }

  // The last time stamp of every group (the duration of a session without a
  // recorded one) is a session time like those the row and frame readers
  // check: finite and within kMaxSessionTime_s. An inf here was skipped (the
  // duration silently another group's) and 1e300 s reported as the duration.
  const auto last_time = [&](DatasetId id, std::uint64_t n) {
    if (n == 0) return;
    const double t = read_column<double>(file, path, id, n - 1, 1)[0];
    if (const std::string problem = session_time_problem(kDatasets[id].path, n - 1, t); !problem.empty())
      bad_file(path, problem + " (its last row)");
    c.last_time_s = std::max(c.last_time_s, t);
  };
  last_time(kHapticTime, c.rows.haptic_rows);
  last_time(kSimTime, c.rows.sim_rows);
  last_time(kEventTime, c.rows.events);
  last_time(kMeshFrameTime, c.rows.mesh_frames);
  return c;
}

// Rows of each dataset its readers use: the complete rows of its group, and
// for the mesh data the rows the complete frames reference.
std::array<std::uint64_t, kDatasetCount> rows_in_use(const Counts& counts) {
  std::array<std::uint64_t, kDatasetCount> used{};
  for (std::size_t i = 0; i < kDatasetCount; ++i) {
    switch (kDatasets[i].group) {
      case Group::kHaptic:
        used[i] = counts.rows.haptic_rows;
        break;
      case Group::kSim:
        used[i] = counts.rows.sim_rows;
        break;
      case Group::kEvents:
        used[i] = counts.rows.events;
        break;
      case Group::kMesh:
        used[i] = counts.rows.mesh_frames;
        break;
    }
  }
  used[kMeshVertices] = used[kMeshVertexLevel] = counts.rows.mesh_vertices;
  used[kMeshTriangles] = used[kMeshTriangleStrain] = counts.rows.mesh_triangles;
  return used;
}

// Which rules count the rows (count_rows' partial_ok): a crash leaves
// columns one write apart and the last index rows ahead of their data.
enum class RowRules {
  kByFlags,  // crash rules while the superblock says open for writing (every reader)
  // Also for a file neither closed cleanly nor repaired: what h5clear -s
  // leaves of a crashed one (repair's first look, so it trims that too). A
  // repaired file was trimmed then, so uneven columns there are damage.
  kUnlessClosedOrRepaired,
  kCrashRules,  // always (repair, after it has cleared the flags itself)
};

SessionInfo info_of(hid_t file, const std::string& path, const Preamble& pre, Counts* counts_out = nullptr,
                    RowRules rules = RowRules::kByFlags) {
  SessionInfo info;
  info.path = path;
  info.open_for_write_flag = pre.consistency_flags != 0;
  info.being_recorded = info.open_for_write_flag && being_recorded(path);
  // A root group whose metadata cannot be read (a bad checksum) is damage,
  // not a foreign file without the attribute.
  if (H5Aexists(file, kAttrFormatVersion) < 0)
    bad_file(path, h5::describe("cannot read the root group's attributes (corrupt metadata)"));
  // The writer has always stored format_version as int64 and closed_cleanly
  // as uint8 (docs/session-format.md): any other kind of value is damage or
  // a foreign writer's, refused by name, never truncated (2.5 read as 2).
  const auto integer_attribute = [&](const char* name, std::int64_t* out) {
    if (h5::read_i64_attribute(file, name, out)) return true;
    const std::string holds = h5::describe_attribute(file, name);
    if (holds == "missing") return false;
    bad_file(path, std::string("root attribute ") + name + " is " + holds +
                       ", expected an integer: corrupt, or not a tissue session file");
  };
  if (!integer_attribute(kAttrFormatVersion, &info.format_version))
    bad_file(path, "HDF5 file without a format_version attribute: not a tissue session file");
  if (info.format_version < kOldestReadableFormatVersion || info.format_version > kSessionFormatVersion)
    bad_file(path, "session format version " + std::to_string(info.format_version) +
                       " is not supported (this tool reads " + std::to_string(kOldestReadableFormatVersion) + " to " +
                       std::to_string(kSessionFormatVersion) + ")");
  info.has_strain = dataset_in_version(kDatasets[kMeshTriangleStrain], info.format_version);
  info.has_device_fresh = dataset_in_version(kDatasets[kHapticDeviceFresh], info.format_version);
  std::int64_t clean = 0;  // missing: a file from before the mark was created with it
  if (integer_attribute(kAttrClosedCleanly, &clean) && clean != 0 && clean != 1)
    bad_file(path, std::string("root attribute ") + kAttrClosedCleanly + " is " + std::to_string(clean) +
                       ", expected 0 or 1: corrupt session file");
  info.closed_cleanly = clean == 1 && !info.open_for_write_flag;
  h5::read_string_attribute(file, kAttrSceneName, &info.scene_name);
  h5::read_string_attribute(file, kAttrStartTime, &info.start_time_utc);
  h5::read_string_attribute(file, kAttrEndTime, &info.end_time_utc);
  h5::read_string_attribute(file, kAttrHostName, &info.host_name);
  h5::read_string_attribute(file, kAttrSoftwareVersion, &info.software_version);
  h5::read_string_attribute(file, kAttrRepairedTime, &info.repaired_utc);
  const SessionState state = session_state(info);
  const bool partial_ok = rules == RowRules::kCrashRules || state == SessionState::kOpenForWrite ||
                          (rules == RowRules::kUnlessClosedOrRepaired && state == SessionState::kNotClosed);
  Counts counts;
  try {
    counts = count_rows(file, path, info.format_version, partial_ok);
  } catch (const RecordError& e) {
    // Readers read a file whose flags were cleared without a repair by the
    // rules of a closed one, repair by the crash rules (it trims such a
    // file): when those take what these refuse (the last frames' index
    // ahead of their data, a strain column a write short), the refusal says
    // what repair does. Not for damage repair refuses too.
    if (partial_ok || state != SessionState::kNotClosed) throw;
    bool repair_takes = true;
    try {
      count_rows(file, path, info.format_version, true);
    } catch (const RecordError&) {
      repair_takes = false;
    }
    if (!repair_takes) throw;
    throw RecordError(std::string(e.what()) +
                      "; the file was not closed cleanly, and a crash leaves this: " + kRepairTrims);
  }
  info.rows = counts.rows;
  // A recorded duration is a session's length: finite, >= 0 and within
  // kMaxSessionTime_s (a damaged 1e300 was printed as the duration). Without
  // one (not closed cleanly, or damaged), the last time stamp recorded.
  double duration = 0.0;
  info.duration_recorded = info.closed_cleanly && h5::read_f64_attribute(file, kAttrDurationS, &duration) &&
                           duration >= 0.0 && duration <= kMaxSessionTime_s;
  info.duration_s = info.duration_recorded ? duration : counts.last_time_s;
  // A file left open by a crash (or being recorded) has rows one write ahead
  // of their group or frame index: repair trims them. The writer leaves none
  // in a closed file, so any there are data no tool reads (damage, or a
  // foreign writer's): reported, not hidden. The rows that are read stay
  // readable: each row is aligned by its number, and a frame is what the
  // index says (an index that does not match the data is an error above).
  const std::array<std::uint64_t, kDatasetCount> used = rows_in_use(counts);
  if (!partial_ok) {
    for (std::size_t i = 0; i < kDatasetCount; ++i)
      if (counts.extents[i] > used[i]) info.unreferenced_rows[i] = counts.extents[i] - used[i];
  }
  // What repair would trim (repair_session's rows_to_trim): a file it
  // repairs, with rows past those in use. Where the rules above are a
  // closed file's ("NOT closed cleanly"), the counts are the crash rules'
  // too, since those differ only where these refuse the file.
  if ((state == SessionState::kOpenForWrite && !info.being_recorded) || state == SessionState::kNotClosed)
    for (std::size_t i = 0; i < kDatasetCount; ++i) info.crash_tail = info.crash_tail || counts.extents[i] > used[i];
  if (counts_out) *counts_out = counts;
  return info;
}

}  // namespace

struct SessionFile::Impl {
  std::string path;
  SessionInfo info;
  Handle file;
};

SessionFile::SessionFile(const std::string& path) : impl_(std::make_unique<Impl>()) {
  h5::QuietErrors quiet;
  impl_->path = path;
  const Preamble pre = read_preamble(path);
  impl_->file = open_for_reading(path, pre);
  impl_->info = info_of(impl_->file.get(), path, pre);
}

SessionFile::~SessionFile() = default;
SessionFile::SessionFile(SessionFile&&) noexcept = default;
SessionFile& SessionFile::operator=(SessionFile&&) noexcept = default;

const std::string& SessionFile::path() const { return impl_->path; }
const SessionInfo& SessionFile::info() const { return impl_->info; }

template <typename T>
std::vector<T> SessionFile::rows(DatasetId id, std::uint64_t first, std::uint64_t count) const {
  h5::QuietErrors quiet;
  return read_column<T>(impl_->file.get(), impl_->path, id, first, count);
}
template std::vector<double> SessionFile::rows(DatasetId, std::uint64_t, std::uint64_t) const;
template std::vector<float> SessionFile::rows(DatasetId, std::uint64_t, std::uint64_t) const;
template std::vector<std::uint8_t> SessionFile::rows(DatasetId, std::uint64_t, std::uint64_t) const;
template std::vector<std::int32_t> SessionFile::rows(DatasetId, std::uint64_t, std::uint64_t) const;
template std::vector<std::uint64_t> SessionFile::rows(DatasetId, std::uint64_t, std::uint64_t) const;
template std::vector<std::int64_t> SessionFile::rows(DatasetId, std::uint64_t, std::uint64_t) const;

std::vector<std::string> SessionFile::event_messages(std::uint64_t first, std::uint64_t count) const {
  h5::QuietErrors quiet;
  return read_strings(impl_->file.get(), impl_->path, kEventMessage, first, count);
}

void SessionFile::fail(const std::string& what) const { bad_file(impl_->path, what); }

std::vector<HapticHole> read_haptic_holes(const SessionFile& f, std::vector<std::string>* damaged) {
  const std::uint64_t events = f.info().rows.events, rows = f.info().rows.haptic_rows;
  if (events == 0) return {};
  const std::vector<std::int32_t> kinds = f.rows<std::int32_t>(kEventKind, 0, events);
  const std::vector<std::string> messages = f.event_messages(0, events);
  std::vector<HapticHole> holes;
  for (std::uint64_t e = 0; e < events; ++e) {
    HapticHole hole;
    if (kinds[e] != static_cast<std::int32_t>(EventKind::kWarning) || !parse_haptic_hole(messages[e], &hole)) continue;
    // The rows it names, where the file holds them, must be the rows around
    // the hole: the replay skips the device's judgement there, and a hole
    // in the wrong place (a damaged number) would skip a real device loss.
    // Returns what is wrong ("" when the row matches).
    const auto check = [&](std::uint64_t row, double t_s, const char* side) -> std::string {
      if (row >= rows) return {};
      const double recorded_s = f.rows<double>(kHapticTime, row, 1)[0];
      if (std::abs(recorded_s - t_s) <= 1e-6) return {};
      return std::string(kDatasets[kEventMessage].path) + "[" + std::to_string(e) + "] says the recorder dropped " +
             "haptic rows " + side + " /haptic row " + std::to_string(row) + " at " + std::to_string(t_s) +
             " s, but that row is at " + std::to_string(recorded_s) + " s";
    };
    std::string wrong;
    if (hole.has_row_before()) wrong = check(hole.row_after - 1, hole.time_before_s, "after");
    if (wrong.empty() && hole.has_row_after()) wrong = check(hole.row_after, hole.time_after_s, "before");
    if (wrong.empty()) {
      holes.push_back(hole);
    } else if (damaged) {
      damaged->push_back("hole event " + std::to_string(e) + " does not match its rows (damaged): " + wrong);
    } else {
      f.fail(wrong + ": corrupt session file");
    }
  }
  std::stable_sort(holes.begin(), holes.end(),
                   [](const HapticHole& a, const HapticHole& b) { return a.row_after < b.row_after; });
  return holes;
}

SessionInfo read_session_info(const std::string& path) {
  const SessionFile f(path);
  SessionInfo info = f.info();
  // A damaged hole event is reported, not a reason to hide the rest: repair
  // does not touch events, so the file could never be summarised again.
  for (const HapticHole& hole : read_haptic_holes(f, &info.damaged_hole_events)) {
    ++info.haptic_holes;
    // The jump in /haptic/time_s it explains. Its rows' times were checked
    // where the file holds them; one past them (a crash's last write) is the
    // event's own number. Never negative: rows out of order are not a span.
    if (hole.has_row_before() && hole.has_row_after())
      info.haptic_hole_time_s += std::max(0.0, hole.time_after_s - hole.time_before_s);
    // Saturated: a damaged or forged count must not wrap to a small one.
    info.haptic_ticks_lost = hole.ticks_lost > std::numeric_limits<std::uint64_t>::max() - info.haptic_ticks_lost
                                 ? std::numeric_limits<std::uint64_t>::max()
                                 : info.haptic_ticks_lost + hole.ticks_lost;
  }
  return info;
}

namespace {

// Reads column `id` (the complete rows: rows.size()) into `field` of every row.
template <typename Row, typename T>
void read_into(const SessionFile& f, DatasetId id, std::vector<Row>& rows, T Row::*field) {
  if constexpr (std::is_same_v<T, std::array<double, 3>>) {
    const std::vector<double> flat = f.rows<double>(id, 0, rows.size());
    for (std::size_t i = 0; i < rows.size(); ++i) rows[i].*field = {flat[3 * i], flat[3 * i + 1], flat[3 * i + 2]};
  } else {
    const std::vector<T> column = f.rows<T>(id, 0, rows.size());
    for (std::size_t i = 0; i < rows.size(); ++i) rows[i].*field = column[i];
  }
}

// Session times must be finite, in order and within kMaxSessionTime_s:
// replay paces by them and the replay device interpolates between them.
// The time column is read first and a Row made per time read: the column
// read refuses rows the file cannot hold, whereas a Row per claimed row,
// allocated before any read, made a damaged extent of 10^10 rows a
// std::bad_alloc (960 GB of HapticRow) instead of an error.
}  // namespace

std::string frame_times_problem(const std::vector<double>& times_s) {
  const std::string column = kDatasets[kMeshFrameTime].path;
  for (std::size_t f = 0; f < times_s.size(); ++f) {
    if (!std::isfinite(times_s[f])) return session_time_problem(column.c_str(), f, times_s[f]);
    if (f > 0 && times_s[f] < times_s[f - 1])
      return column + " goes backwards at frame " + std::to_string(f) + " (frames must be in time order)";
    if (std::string problem = session_time_problem(column.c_str(), f, times_s[f]); !problem.empty()) return problem;
  }
  return {};
}

std::string mesh_frame_problem(std::uint64_t frame, std::uint64_t vertex_offset, const std::vector<float>& vertices_xyz,
                               std::uint64_t triangle_offset, const std::vector<std::int32_t>& triangles,
                               const std::vector<float>& triangle_strain) {
  const std::uint64_t nv = vertices_xyz.size() / 3, nt = triangles.size() / 3;
  const std::string in_frame = " (frame " + std::to_string(frame) + ")";
  for (std::uint64_t i = 0; i < nv; ++i)
    for (int a = 0; a < 3; ++a)
      if (const float coordinate = vertices_xyz[3 * i + a]; !std::isfinite(coordinate))
        return std::string(kDatasets[kMeshVertices].path) + " row " + std::to_string(vertex_offset + i) + in_frame +
               " holds the coordinate " + std::to_string(coordinate) + ": not a position";
  for (std::uint64_t t = 0; t < nt; ++t)
    for (int c = 0; c < 3; ++c) {
      const std::int32_t v = triangles[3 * t + c];
      const std::string row =
          std::string(kDatasets[kMeshTriangles].path) + " row " + std::to_string(triangle_offset + t);
      if (v < 0) return row + in_frame + " holds the negative index " + std::to_string(v);
      if (static_cast<std::uint64_t>(v) >= nv)
        return row + in_frame + " holds the index " + std::to_string(v) + ", past the frame's " + std::to_string(nv) +
               " vertices";
    }
  if (triangle_strain.empty()) return {};
  const std::string dataset = kDatasets[kMeshTriangleStrain].path;
  // The session reader refuses a strain column whose length is not the
  // triangles'; a caller's mismatch must not become a read past the values.
  if (triangle_strain.size() != nt)
    return dataset + in_frame + ": " + std::to_string(triangle_strain.size()) + " values for " + std::to_string(nt) +
           " triangles";
  const bool not_computed = std::isnan(triangle_strain[0]);
  for (std::uint64_t t = 0; t < nt; ++t) {
    const float e = triangle_strain[t];
    // All NaN: recorded without strain. Anything else must be a real energy
    // density: finite and >= 0. A value after a first NaN is named as the
    // mix it is (the value itself may be fine).
    if (not_computed && !std::isnan(e))
      return dataset + " row " + std::to_string(triangle_offset + t) + in_frame + " holds " + std::to_string(e) +
             " J/m^3 but row " + std::to_string(triangle_offset) +
             " is NaN (recorded without strain): a frame's strain is all NaN or all finite and >= 0";
    if (!not_computed && (!std::isfinite(e) || e < 0.0f))
      return dataset + " row " + std::to_string(triangle_offset + t) + in_frame + " holds " + std::to_string(e) +
             " J/m^3: not a strain energy density (must be finite and >= 0)";
  }
  return {};
}

namespace {

template <typename Row>
std::vector<Row> read_times(const SessionFile& f, DatasetId id, std::uint64_t count) {
  const std::vector<double> times = f.rows<double>(id, 0, count);
  std::vector<Row> rows(times.size());
  for (std::size_t i = 0; i < rows.size(); ++i) rows[i].time_s = times[i];
  for (std::size_t i = 0; i < rows.size(); ++i) {
    if (!std::isfinite(rows[i].time_s) || (i > 0 && rows[i].time_s < rows[i - 1].time_s))
      f.fail(std::string(kDatasets[id].path) + " is not finite and non-decreasing at row " + std::to_string(i));
    if (std::abs(rows[i].time_s) > kMaxSessionTime_s)
      f.fail(std::string(kDatasets[id].path) + " is " + std::to_string(rows[i].time_s) + " s at row " +
             std::to_string(i) + ", beyond any session (" + std::to_string(kMaxSessionTime_s) + " s)");
  }
  return rows;
}

// Values that go out to subscribers as they are: a damaged file's NaN or inf
// would reach every client (the recorder never writes one; real_time_factor
// is NaN until measured, by design, and not checked).
template <typename Row, typename Field>
void require_finite(const SessionFile& f, DatasetId id, const std::vector<Row>& rows, Field Row::*field) {
  for (std::size_t i = 0; i < rows.size(); ++i) {
    bool finite = true;
    if constexpr (std::is_floating_point_v<Field>)
      finite = std::isfinite(rows[i].*field);
    else
      for (const auto x : rows[i].*field) finite = finite && std::isfinite(x);
    if (!finite) f.fail(std::string(kDatasets[id].path) + " is not finite at row " + std::to_string(i));
  }
}

std::vector<HapticRow> read_haptic_rows(const SessionFile& f) {
  std::vector<HapticRow> rows = read_times<HapticRow>(f, kHapticTime, f.info().rows.haptic_rows);
  read_into(f, kHapticDevicePosition, rows, &HapticRow::device_position_m);
  read_into(f, kHapticProxyPosition, rows, &HapticRow::proxy_position_m);
  read_into(f, kHapticForce, rows, &HapticRow::force_N);
  read_into(f, kHapticContact, rows, &HapticRow::contact);
  read_into(f, kHapticModelVersion, rows, &HapticRow::model_version);
  // Files of format version < 3 did not record it: 0 there, and
  // read_haptic_track says the flags are unknown.
  if (f.info().has_device_fresh) {
    read_into(f, kHapticDeviceFresh, rows, &HapticRow::device_fresh);
    // The replay device spreads each step over the time since the last
    // flagged row: a damaged value must not become a guess at which.
    for (std::size_t i = 0; i < rows.size(); ++i)
      if (rows[i].device_fresh > 1)
        f.fail(std::string(kDatasets[kHapticDeviceFresh].path) + " is " + std::to_string(rows[i].device_fresh) +
               " at row " + std::to_string(i) + ": a flag is 0 or 1");
  }
  require_finite(f, kHapticDevicePosition, rows, &HapticRow::device_position_m);
  require_finite(f, kHapticProxyPosition, rows, &HapticRow::proxy_position_m);
  require_finite(f, kHapticForce, rows, &HapticRow::force_N);
  return rows;
}

std::vector<SimRow> read_sim_rows(const SessionFile& f) {
  std::vector<SimRow> rows = read_times<SimRow>(f, kSimTime, f.info().rows.sim_rows);
  read_into(f, kSimSimTime, rows, &SimRow::sim_time_s);
  read_into(f, kSimRealTimeFactor, rows, &SimRow::real_time_factor);
  read_into(f, kSimStepMs, rows, &SimRow::step_ms);
  read_into(f, kSimNodes, rows, &SimRow::nodes);
  read_into(f, kSimTets, rows, &SimRow::tets);
  read_into(f, kSimSprings, rows, &SimRow::springs);
  read_into(f, kSimRefines, rows, &SimRow::refines);
  read_into(f, kSimMerges, rows, &SimRow::merges);
  read_into(f, kSimKinetic, rows, &SimRow::kinetic_J);
  read_into(f, kSimElastic, rows, &SimRow::elastic_J);
  require_finite(f, kSimSimTime, rows, &SimRow::sim_time_s);
  require_finite(f, kSimStepMs, rows, &SimRow::step_ms);
  require_finite(f, kSimKinetic, rows, &SimRow::kinetic_J);
  require_finite(f, kSimElastic, rows, &SimRow::elastic_J);
  // NaN until the first second has been measured (by design); otherwise a
  // pace. An infinite or negative one is damage, sent on to every
  // sim_stats subscriber of a replay.
  for (std::size_t i = 0; i < rows.size(); ++i)
    if (const double r = rows[i].real_time_factor; !std::isnan(r) && !(std::isfinite(r) && r >= 0.0))
      f.fail(std::string(kDatasets[kSimRealTimeFactor].path) + " is " + std::to_string(r) + " at row " +
             std::to_string(i) + ": a pace is NaN (not yet measured) or finite and >= 0");
  return rows;
}

}  // namespace

SessionRows read_session_rows(const std::string& path) {
  const SessionFile f(path);
  SessionRows rows{read_haptic_rows(f), read_sim_rows(f), {}};
  // A damaged hole event is left out, not a reason to refuse the rows: the
  // publishing replay only says where holes are (it judges no device), and
  // info and list name the damage.
  std::vector<std::string> damaged;
  rows.haptic_holes = read_haptic_holes(f, &damaged);
  return rows;
}

HapticTrack read_haptic_track(const std::string& path) {
  const SessionFile f(path);
  if (f.info().rows.haptic_rows == 0) f.fail("the session has no haptic rows to replay");
  const std::vector<HapticRow> rows = read_haptic_rows(f);
  HapticTrack track;
  track.time_s.reserve(rows.size());
  track.device_position_m.reserve(rows.size());
  track.force_N.reserve(rows.size());
  if (f.info().has_device_fresh) track.device_fresh.reserve(rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    // The device drives the haptic loop with these: a NaN would reach the
    // force renderer.
    for (double x : rows[i].device_position_m)
      if (!std::isfinite(x)) f.fail("/haptic/device_position_m is not finite at row " + std::to_string(i));
    track.time_s.push_back(rows[i].time_s);
    track.device_position_m.push_back(rows[i].device_position_m);
    track.force_N.push_back(rows[i].force_N);
    if (f.info().has_device_fresh) track.device_fresh.push_back(rows[i].device_fresh);
  }
  // Only holes between two rows of the track change how it plays.
  for (const HapticHole& hole : read_haptic_holes(f))
    if (hole.row_after > 0 && hole.row_after < rows.size() &&
        (track.rows_after_holes.empty() || track.rows_after_holes.back() != hole.row_after))
      track.rows_after_holes.push_back(static_cast<std::size_t>(hole.row_after));
  return track;
}

std::string format_session_info(const SessionInfo& info) {
  std::ostringstream o;
  o << "file:             " << shown(info.path) << "\n";
  o << "state:            ";
  switch (session_state(info)) {
    case SessionState::kClosedCleanly:
      o << "closed cleanly\n";
      break;
    case SessionState::kOpenForWrite:
      if (info.being_recorded)
        o << "being recorded (a running recorder holds it; it closes when the recording stops)\n";
      else
        o << "NOT closed cleanly: left by a crash (no recorder on this machine holds it); run `tissue session "
             "repair`\n";
      break;
    case SessionState::kRepaired:
      o << "NOT closed cleanly: left by a crash, repaired " << shown(info.repaired_utc) << "\n";
      break;
    case SessionState::kNotClosed:
      o << "NOT closed cleanly (the clean-close mark is missing)\n";
      break;
  }
  if (info.crash_tail)
    o << "repair:           its last write is incomplete (rows past the complete ones, as a crash leaves them): "
      << kRepairTrims << "\n";
  o << "scene:            " << (info.scene_name.empty() ? "(none)" : shown(info.scene_name)) << "\n";
  o << "start time (UTC): " << shown(info.start_time_utc) << "\n";
  if (!info.end_time_utc.empty()) o << "end time (UTC):   " << shown(info.end_time_utc) << "\n";
  char duration[64];
  std::snprintf(duration, sizeof duration, "%.3f s", info.duration_s);
  o << "duration:         " << duration << (info.duration_recorded ? "" : " (last time stamp recorded)") << "\n";
  o << "host:             " << shown(info.host_name) << "\n";
  o << "software version: " << shown(info.software_version) << "\n";
  o << "format version:   " << info.format_version << "\n";
  o << "rows:\n";
  // Whether a replay of the hand knows when each new device sample came
  // (device.replay: exact) or has to guess it from the positions.
  o << "  /haptic         " << info.rows.haptic_rows << " ticks"
    << (info.has_device_fresh ? ", each flagged when a new device sample came"
                              : ", no device_fresh flags (format version " + std::to_string(info.format_version) + ")")
    << "\n";
  o << "  /sim            " << info.rows.sim_rows << " samples\n";
  o << "  /mesh           " << info.rows.mesh_frames << " frames (" << info.rows.mesh_vertices << " vertices, "
    << info.rows.mesh_triangles << " triangles"
    << (info.has_strain ? ", strain energy density per triangle" : ", no strain (format version 1)") << ")\n";
  o << "  /events         " << info.rows.events << " events\n";
  // Ticks the recorder dropped (its ring full: the disk stalled) are not in
  // /haptic; a hole is otherwise just a jump in /haptic/time_s.
  if (info.haptic_holes > 0) {
    char span[64];
    std::snprintf(span, sizeof span, "%.3f s", info.haptic_hole_time_s);
    o << "haptic holes:     " << info.haptic_holes << (info.haptic_holes == 1 ? " hole, " : " holes, ")
      << info.haptic_ticks_lost << (info.haptic_ticks_lost == 1 ? " tick" : " ticks")
      << " the recorder dropped (its ring was full), " << span
      << " of session time between the rows on either side; a warning event each names those rows\n";
  }
  // The replay refuses the file while one is there (it would skip the
  // device's judgement in the wrong place); everything else reads.
  for (const std::string& damaged : info.damaged_hole_events)
    o << "damaged:          " << shown(damaged) << "; not counted as a hole, and device.replay refuses the file\n";
  if (std::any_of(info.unreferenced_rows.begin(), info.unreferenced_rows.end(),
                  [](std::uint64_t n) { return n > 0; })) {
    o << "unreferenced rows (past the shortest column of their group, or in no frame of the index; no tool reads "
         "them):\n";
    for (std::size_t i = 0; i < kDatasetCount; ++i)
      if (const std::uint64_t n = info.unreferenced_rows[i]; n > 0)
        o << "  " << std::left << std::setw(40) << kDatasets[i].path << std::right << n << (n == 1 ? " row" : " rows")
          << "\n";
  }
  return o.str();
}

SessionState session_state(const SessionInfo& info) {
  if (info.closed_cleanly) return SessionState::kClosedCleanly;
  if (info.open_for_write_flag) return SessionState::kOpenForWrite;
  if (!info.repaired_utc.empty()) return SessionState::kRepaired;
  return SessionState::kNotClosed;
}

SessionListing list_sessions(const std::string& dir) {
  namespace fs = std::filesystem;
  SessionListing listing;
  listing.dir = dir;
  std::error_code ec;
  // A directory that cannot be reached (EACCES on the way, a symbolic link
  // loop) has no type: its error says why, not "not a directory".
  if (const fs::file_status st = fs::status(dir, ec); !fs::is_directory(st))
    throw RecordError("cannot list sessions in '" + dir + "': " +
                      (st.type() == fs::file_type::not_found ? "no such directory"
                       : ec                                  ? ec.message()
                                                             : "not a directory"));
  std::vector<fs::path> candidates;
  fs::directory_iterator it(dir, ec), end;
  if (ec) throw RecordError("cannot list sessions in '" + dir + "': " + ec.message());
  for (; it != end; it.increment(ec)) {
    if (ec) throw RecordError("cannot list sessions in '" + dir + "': " + ec.message());
    const fs::path& p = it->path();
    const std::string name = p.filename().string();
    if (!it->is_regular_file(ec)) continue;
    if (name.size() > 1 && name[0] == '.') {
      if (name.find(kCreatingInfix) != std::string::npos) listing.unfinished.push_back(p.string());
      continue;
    }
    bool hdf5 = p.extension() == ".h5";
    if (!hdf5) {
      // HDF5's signature at offset 0 (where this writer puts the superblock).
      static constexpr char kSignature[8] = {'\x89', 'H', 'D', 'F', '\r', '\n', '\x1a', '\n'};
      char head[8] = {};
      std::ifstream in(p, std::ios::binary);
      hdf5 = in.read(head, sizeof head) && std::equal(head, head + 8, kSignature);
    }
    if (hdf5) candidates.push_back(p);
  }
  std::sort(candidates.begin(), candidates.end());
  std::sort(listing.unfinished.begin(), listing.unfinished.end());
  for (const fs::path& p : candidates) {
    try {
      listing.sessions.push_back(read_session_info(p.string()));
    } catch (const RecordError& e) {
      listing.unreadable.push_back({p.string(), e.what()});
    }
  }
  return listing;
}

namespace {

const char* state_label(SessionState state) {
  switch (state) {
    case SessionState::kClosedCleanly:
      return "closed cleanly";
    case SessionState::kOpenForWrite:
      return "OPEN (crashed)";
    case SessionState::kRepaired:
      return "repaired";
    case SessionState::kNotClosed:
      break;
  }
  return "NOT closed cleanly";
}

// A file not closed cleanly, flags clear, with a crash's incomplete last
// write (repair trims it).
constexpr const char* kCrashTailLabel = "NOT closed (crash tail)";

// The holes column: "-" for none, else the count and, when any has a row on
// either side, the session time they span ("2 (0.031 s)"); damaged hole
// events add "+N damaged" (each also gets its own "damaged:" line), so a
// user scanning the table sees every file whose /haptic has holes without
// `info` on each. From read_session_info's count: the rows are not read.
std::string holes_cell(const SessionInfo& s) {
  if (s.haptic_holes == 0 && s.damaged_hole_events.empty()) return "-";
  std::string cell = std::to_string(s.haptic_holes);
  if (s.haptic_hole_time_s > 0.0) {
    char span[48];
    std::snprintf(span, sizeof span, " (%.3f s)", s.haptic_hole_time_s);
    cell += span;
  }
  if (!s.damaged_hole_events.empty()) cell += " +" + std::to_string(s.damaged_hole_events.size()) + " damaged";
  return cell;
}

}  // namespace

std::string format_session_listing(const SessionListing& listing) {
  std::ostringstream o;
  o << listing.sessions.size() << " session" << (listing.sessions.size() == 1 ? "" : "s") << " in "
    << shown(listing.dir) << "\n";
  // Left-aligned text columns, right-aligned numbers; a long name widens its
  // row rather than being cut.
  // The holes column is as wide as its widest cell: "2 (0.051 s) +1
  // damaged" outgrows any fixed width, and a wider cell pushed its row's
  // scene out of line with the others.
  std::size_t holes_width = std::string_view("holes").size();
  for (const SessionInfo& s : listing.sessions) holes_width = std::max(holes_width, holes_cell(s).size());
  const auto row = [&o, holes_width](const std::string& file, const std::string& state, const std::string& start,
                                     const std::string& duration, const std::string& haptic, const std::string& frames,
                                     const std::string& holes, const std::string& scene) {
    o << std::left << std::setw(28) << file << ' ' << std::setw(28) << state << ' ' << std::setw(24) << start << ' '
      << std::right << std::setw(10) << duration << ' ' << std::setw(10) << haptic << ' ' << std::setw(7) << frames
      << ' ' << std::setw(static_cast<int>(holes_width)) << holes << "  " << scene << "\n";
  };
  if (!listing.sessions.empty())
    row("file", "state", "start (UTC)", "duration s", "haptic", "frames", "holes", "scene");
  for (const SessionInfo& s : listing.sessions) {
    char duration[32];
    std::snprintf(duration, sizeof duration, "%.3f", s.duration_s);
    const SessionState state = session_state(s);
    row(shown(std::filesystem::path(s.path).filename().string()),
        s.being_recorded                                    ? "being recorded"
        : state == SessionState::kNotClosed && s.crash_tail ? kCrashTailLabel
                                                            : state_label(state),
        shown(s.start_time_utc), duration, std::to_string(s.rows.haptic_rows), std::to_string(s.rows.mesh_frames),
        holes_cell(s), shown(s.scene_name));
  }
  // What the column means, once, when a session has any (as the OPEN hint).
  if (std::any_of(listing.sessions.begin(), listing.sessions.end(),
                  [](const SessionInfo& s) { return s.haptic_holes > 0 || !s.damaged_hole_events.empty(); }))
    o << "holes: runs of haptic ticks the recorder dropped (its ring was full), with the session time between the "
         "rows on either side; `tissue session info FILE` counts the ticks\n";
  for (const SessionListing::Unreadable& u : listing.unreadable) o << "unreadable: " << shown(u.reason) << "\n";
  for (const SessionInfo& s : listing.sessions)
    for (const std::string& damaged : s.damaged_hole_events)
      o << "damaged: " << shown(std::filesystem::path(s.path).filename().string()) << ": " << shown(damaged) << "\n";
  for (const std::string& f : listing.unfinished)
    o << "unfinished: " << shown(f)
      << ": a session being created right now, or left by a recorder that stopped while creating it (not a "
         "session, no data in it; tissued removes it at its next start once that process is gone)\n";
  if (std::any_of(listing.sessions.begin(), listing.sessions.end(), [](const SessionInfo& s) {
        return session_state(s) == SessionState::kOpenForWrite && !s.being_recorded;
      }))
    o << "OPEN (crashed): left open by a recorder that is gone: " << kRepairTrims
      << " and makes it readable by ordinary readers\n";
  if (std::any_of(listing.sessions.begin(), listing.sessions.end(),
                  [](const SessionInfo& s) { return session_state(s) == SessionState::kNotClosed && s.crash_tail; }))
    o << kCrashTailLabel << ": not closed cleanly, its last write incomplete as a crash leaves it: " << kRepairTrims
      << "\n";
  return o.str();
}

RepairReport repair_session(const std::string& path) {
  h5::QuietErrors quiet;
  // The file's type and signature first: read_preamble refuses anything but
  // a regular file before opening it (opening a FIFO blocks until a writer
  // comes).
  const Preamble pre = read_preamble(path);
  // Repair clears the open-for-write flags and trims the columns to a
  // common length: done to a live recording, it corrupted the file under
  // the writer.
  if (being_recorded(path))
    throw RecordError("cannot repair '" + path +
                      "': it is being recorded (a running recorder holds it); stop the recording first "
                      "(`tissue ctl record_stop`): repair is for a session a crash left open");
  RepairReport report;
  {
    Handle file = open_for_reading(path, pre);
    Counts counts;
    const SessionInfo before = info_of(file.get(), path, pre, &counts, RowRules::kUnlessClosedOrRepaired);
    report.before = before.rows;
    // A file whose flags h5clear -s cleared after a crash still has its
    // columns as the crash left them: trimmed like a crashed one. (A closed
    // file's unreferenced rows are not a crash's: they stay.)
    const std::array<std::uint64_t, kDatasetCount> used = rows_in_use(counts);
    bool rows_to_trim = false;
    for (std::size_t i = 0; i < kDatasetCount; ++i)
      rows_to_trim =
          rows_to_trim || (dataset_in_version(kDatasets[i], before.format_version) && counts.extents[i] != used[i]);
    if (!before.open_for_write_flag && !(session_state(before) == SessionState::kNotClosed && rows_to_trim)) {
      if (before.closed_cleanly)
        report.notes.push_back("closed cleanly: nothing to repair");
      else
        report.notes.push_back("already readable by ordinary readers: nothing to repair");
      report.after = before;
      return report;
    }
  }
  report.repair_needed = true;

  // h5clear -s: HDF5's private fapl property "clear_status_flags" makes the
  // open ignore and reset the superblock's open-for-write flags (h5clear uses
  // it the same way; there is no public API in 1.10.8).
  Handle fapl(H5Pcreate(H5P_FILE_ACCESS));
  hbool_t clear = true;
  if (!fapl || H5Pset_libver_bounds(fapl.get(), H5F_LIBVER_LATEST, H5F_LIBVER_LATEST) < 0 ||
      H5Pset(fapl.get(), "clear_status_flags", &clear) < 0)
    bad_file(path, h5::describe("this HDF5 library cannot clear status flags"));
  Handle file(H5Fopen(path.c_str(), H5F_ACC_RDWR, fapl.get()));
  if (!file) bad_file(path, h5::describe("cannot be opened for repair"));
  // --increment: after a crash the superblock's end-of-allocation can lie
  // below data the writer already put in the file ("addr overflow" on read).
  // Moving it past the end of file (plus 1 MiB, as h5clear does) covers it.
  if (H5Fincrement_filesize(file.get(), 1 << 20) < 0) bad_file(path, h5::describe("cannot move the end of allocation"));

  Counts counts;
  const SessionInfo mid = info_of(file.get(), path, Preamble{}, &counts, RowRules::kCrashRules);
  // Trim every column to what its whole group has, so plain readers see
  // aligned columns and only complete mesh frames.
  const std::array<std::uint64_t, kDatasetCount> keep = rows_in_use(counts);
  for (std::size_t i = 0; i < kDatasetCount; ++i) {
    if (!dataset_in_version(kDatasets[i], mid.format_version) || counts.extents[i] == keep[i]) continue;
    Handle d = open_dataset(file.get(), path, kDatasets[i].path);
    const hsize_t dims[2] = {keep[i], static_cast<hsize_t>(kDatasets[i].columns)};
    if (H5Dset_extent(d.get(), dims) < 0) bad_file(path, h5::describe(std::string("cannot trim ") + kDatasets[i].path));
    report.notes.push_back(std::string("trimmed ") + kDatasets[i].path + " from " + std::to_string(counts.extents[i]) +
                           " to " + std::to_string(keep[i]) + " rows (incomplete last write)");
  }
  try {
    h5::write_string_attribute(file.get(), kAttrRepairedTime, utc_now_iso8601());
  } catch (const RecordError& e) {
    bad_file(path, e.what());
  }
  if (!file.reset()) bad_file(path, h5::describe("closing after repair failed"));

  // Prove it: an ordinary open must work now.
  const Preamble after = read_preamble(path);
  if (after.consistency_flags != 0) bad_file(path, "repair did not clear the superblock's open-for-write flags");
  Handle plain = open_for_reading(path, after);
  report.after = info_of(plain.get(), path, after);
  return report;
}

XdmfReport write_xdmf(const std::string& h5_path, const std::string& out_path_in) {
  h5::QuietErrors quiet;
  const Preamble pre = read_preamble(h5_path);
  if (pre.consistency_flags != 0)
    bad_file(
        h5_path,
        "is still marked open for writing (crashed or being recorded): ParaView cannot open it; run `tissue session "
        "repair` first");
  Handle file = open_for_reading(h5_path, pre);
  Counts counts;
  const SessionInfo info = info_of(file.get(), h5_path, pre, &counts);
  const std::uint64_t frames = info.rows.mesh_frames;
  const auto times = read_column<double>(file.get(), h5_path, kMeshFrameTime, 0, frames);
  const auto voff = read_column<std::uint64_t>(file.get(), h5_path, kMeshVertexOffset, 0, frames);
  const auto vcnt = read_column<std::uint64_t>(file.get(), h5_path, kMeshVertexCount, 0, frames);
  const auto toff = read_column<std::uint64_t>(file.get(), h5_path, kMeshTriangleOffset, 0, frames);
  const auto tcnt = read_column<std::uint64_t>(file.get(), h5_path, kMeshTriangleCount, 0, frames);
  // The same rule as every other reader of frames (the frame source, replay):
  // ParaView steps through the grids by these times.
  if (const std::string problem = frame_times_problem(times); !problem.empty()) bad_file(h5_path, problem);
  // And every frame's data by the rule the frame source (x3d, render,
  // replay) applies: ParaView indexes the vertices with the stored triangles
  // (VTK does not bounds-check) and draws the stored coordinates and strain.
  // One frame in memory at a time. On the way, whether a frame has strain:
  // a session recorded without it holds NaN for every triangle
  // (mesh_frame_problem: a frame's strain is all NaN or all finite and
  // >= 0), and a Cell attribute of NaN alone is nothing to colour by.
  bool any_strain = false;
  for (std::uint64_t f = 0; f < frames; ++f) {
    const auto xyz = read_column<float>(file.get(), h5_path, kMeshVertices, voff[f], vcnt[f]);
    const auto idx = read_column<std::int32_t>(file.get(), h5_path, kMeshTriangles, toff[f], tcnt[f]);
    const auto strain = info.has_strain ? read_column<float>(file.get(), h5_path, kMeshTriangleStrain, toff[f], tcnt[f])
                                        : std::vector<float>{};
    if (const std::string problem = mesh_frame_problem(f, voff[f], xyz, toff[f], idx, strain); !problem.empty())
      bad_file(h5_path, problem);
    any_strain = any_strain || (!strain.empty() && !std::isnan(strain[0]));
  }

  namespace fs = std::filesystem;
  XdmfReport report;
  report.out_path = out_path_in.empty() ? fs::path(h5_path).replace_extension(".xdmf").string() : out_path_in;
  if (util::same_file(report.out_path, h5_path))
    bad_file(h5_path, "is also the XDMF output '" + report.out_path +
                          "': writing it would destroy the recording; choose another output file");
  std::error_code ec;
  const fs::path out_dir = fs::absolute(report.out_path, ec).parent_path();
  fs::path h5_ref = fs::relative(fs::absolute(h5_path, ec), out_dir, ec);
  if (ec || h5_ref.empty()) h5_ref = fs::absolute(h5_path, ec);
  // XDMF 3 reads a Format="HDF" DataItem as FILE:DATASET, FILE up to the
  // first ':' (one in a directory too), splits a reference on '|', and
  // ParaView takes the XML as UTF-8 (escape_xml would put U+FFFD for a byte
  // that is not): a path it cannot name gave a sidecar that does not open.
  const std::string ref_text = h5_ref.string();
  std::string ref_problem = util::why_not_clean_text(ref_text);
  if (!ref_problem.empty())
    ref_problem = "is not UTF-8 text or holds a control character (" + ref_problem + ")";
  else if (ref_text.find(':') != std::string::npos)
    ref_problem = "contains ':'";
  else if (ref_text.find('|') != std::string::npos)
    ref_problem = "contains '|'";
  if (!ref_problem.empty())
    bad_file(h5_path, "the session's path as the sidecar would reference it ('" + shown(ref_text) + "') " +
                          ref_problem + ", which an XDMF data reference cannot name; rename it");
  const std::string ref = util::escape_xml(ref_text);

  // Inner DataItems name the whole dataset with its full shape (XDMF
  // readers check it against the file).
  const std::uint64_t all_vertices = counts.extents[kMeshVertices];
  const std::uint64_t all_triangles = counts.extents[kMeshTriangles];
  const std::uint64_t all_levels = counts.extents[kMeshVertexLevel];
  const std::uint64_t all_strain = counts.extents[kMeshTriangleStrain];

  std::ostringstream x;
  x << "<?xml version=\"1.0\" ?>\n";
  // No path in the comment: "--" (run--2.h5) may not appear inside an XML
  // comment, and the DataItems below name the file anyway.
  x << "<!-- Written by `tissue session xdmf`: one grid per mesh frame of the session the DataItems read. -->\n";
  x << "<Xdmf Version=\"3.0\">\n <Domain>\n";
  x << "  <Grid Name=\"session\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
  for (std::uint64_t f = 0; f < frames; ++f) {
    if (tcnt[f] == 0 || vcnt[f] == 0) {
      ++report.skipped_empty;
      continue;
    }
    char time[40];
    std::snprintf(time, sizeof time, "%.9g", times[f]);
    x << "   <Grid Name=\"frame_" << f << "\" GridType=\"Uniform\">\n";
    x << "    <Time Value=\"" << time << "\"/>\n";
    x << "    <Topology TopologyType=\"Triangle\" NumberOfElements=\"" << tcnt[f] << "\">\n";
    x << "     <DataItem ItemType=\"HyperSlab\" Dimensions=\"" << tcnt[f] << " 3\" Type=\"HyperSlab\">\n";
    x << "      <DataItem Dimensions=\"3 2\" Format=\"XML\">" << toff[f] << " 0 1 1 " << tcnt[f] << " 3</DataItem>\n";
    x << "      <DataItem Dimensions=\"" << all_triangles << " 3\" NumberType=\"Int\" Precision=\"4\" Format=\"HDF\">"
      << ref << ":/mesh/triangles</DataItem>\n";
    x << "     </DataItem>\n    </Topology>\n";
    x << "    <Geometry GeometryType=\"XYZ\">\n";
    x << "     <DataItem ItemType=\"HyperSlab\" Dimensions=\"" << vcnt[f] << " 3\" Type=\"HyperSlab\">\n";
    x << "      <DataItem Dimensions=\"3 2\" Format=\"XML\">" << voff[f] << " 0 1 1 " << vcnt[f] << " 3</DataItem>\n";
    x << "      <DataItem Dimensions=\"" << all_vertices << " 3\" NumberType=\"Float\" Precision=\"4\" Format=\"HDF\">"
      << ref << ":/mesh/vertices_m</DataItem>\n";
    x << "     </DataItem>\n    </Geometry>\n";
    x << "    <Attribute Name=\"vertex_level\" AttributeType=\"Scalar\" Center=\"Node\">\n";
    x << "     <DataItem ItemType=\"HyperSlab\" Dimensions=\"" << vcnt[f] << "\" Type=\"HyperSlab\">\n";
    x << "      <DataItem Dimensions=\"3 1\" Format=\"XML\">" << voff[f] << " 1 " << vcnt[f] << "</DataItem>\n";
    x << "      <DataItem Dimensions=\"" << all_levels << "\" NumberType=\"UChar\" Precision=\"1\" Format=\"HDF\">"
      << ref << ":/mesh/vertex_level</DataItem>\n";
    x << "     </DataItem>\n    </Attribute>\n";
    // Per triangle: a Cell attribute ParaView can colour by. On every grid
    // or none, so the arrays ParaView offers stay the same over the time
    // steps: a frame recorded without strain, in a session whose other
    // frames have it, shows NaN there.
    if (any_strain) {
      x << "    <Attribute Name=\"strain_energy_density_J_per_m3\" AttributeType=\"Scalar\" Center=\"Cell\">\n";
      x << "     <DataItem ItemType=\"HyperSlab\" Dimensions=\"" << tcnt[f] << "\" Type=\"HyperSlab\">\n";
      x << "      <DataItem Dimensions=\"3 1\" Format=\"XML\">" << toff[f] << " 1 " << tcnt[f] << "</DataItem>\n";
      x << "      <DataItem Dimensions=\"" << all_strain << "\" NumberType=\"Float\" Precision=\"4\" Format=\"HDF\">"
        << ref << ":" << kDatasets[kMeshTriangleStrain].path << "</DataItem>\n";
      x << "     </DataItem>\n    </Attribute>\n";
    }
    x << "   </Grid>\n";
    ++report.frames;
  }
  x << "  </Grid>\n </Domain>\n</Xdmf>\n";

  // A regular file through a temporary and a rename (a failed write never
  // leaves half a sidecar behind); a device or FIFO in place.
  const std::string reason = util::write_output_file(report.out_path, x.str());
  if (!reason.empty()) throw RecordError("cannot write XDMF sidecar '" + report.out_path + "': " + reason);
  return report;
}

}  // namespace tissue::record
