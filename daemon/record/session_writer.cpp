#include "record/session_writer.hpp"

#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <system_error>
#include <tuple>

#include "util/output_file.hpp"
#include "util/text.hpp"
#include "util/timestamped_name.hpp"

namespace tissue::record {

namespace {

hid_t file_type(ElementType t) {
  switch (t) {
    case ElementType::kF64:
      return H5T_IEEE_F64LE;
    case ElementType::kF32:
      return H5T_IEEE_F32LE;
    case ElementType::kU8:
      return H5T_STD_U8LE;
    case ElementType::kI32:
      return H5T_STD_I32LE;
    case ElementType::kU64:
      return H5T_STD_U64LE;
    case ElementType::kI64:
      return H5T_STD_I64LE;
    case ElementType::kString:
      break;
  }
  return H5I_INVALID_HID;
}

hid_t memory_type(ElementType t) {
  switch (t) {
    case ElementType::kF64:
      return H5T_NATIVE_DOUBLE;
    case ElementType::kF32:
      return H5T_NATIVE_FLOAT;
    case ElementType::kU8:
      return H5T_NATIVE_UINT8;
    case ElementType::kI32:
      return H5T_NATIVE_INT32;
    case ElementType::kU64:
      return H5T_NATIVE_UINT64;
    case ElementType::kI64:
      return H5T_NATIVE_INT64;
    case ElementType::kString:
      break;
  }
  return H5I_INVALID_HID;
}

std::size_t element_bytes(ElementType t) {
  switch (t) {
    case ElementType::kF64:
    case ElementType::kU64:
    case ElementType::kI64:
      return 8;
    case ElementType::kF32:
    case ElementType::kI32:
      return 4;
    case ElementType::kU8:
      return 1;
    case ElementType::kString:
      return kEventMessageBytes;
  }
  return 0;
}

h5::Handle message_type() {
  h5::Handle t(H5Tcopy(H5T_C_S1));
  H5Tset_size(t.get(), kEventMessageBytes);
  H5Tset_strpad(t.get(), H5T_STR_NULLTERM);
  H5Tset_cset(t.get(), H5T_CSET_UTF8);
  return t;
}

std::string host_name() {
  char buf[256] = {};
  if (::gethostname(buf, sizeof buf - 1) != 0) return "unknown";
  return buf;
}

}  // namespace

void validate_session_name(const std::string& name, const std::string& what) {
  // A name that is not clean text is not echoed: its bytes would go into a
  // JSON reply and a terminal as they are.
  const std::string not_text = util::why_not_clean_text(name);
  const auto bad = [&](const std::string& why) {
    throw RecordError(what + " name " + (not_text.empty() ? "'" + name + "' " : std::string()) + "rejected: " + why +
                      (what.find_first_of("aeiou") == 0 ? " (an " : " (a ") + what +
                      " is a plain file name inside the state directory)");
  };
  if (name.empty()) bad("it is empty");
  if (name.find('/') != std::string::npos) bad("it contains '/'");
  if (name.find("..") != std::string::npos) bad("it contains '..'");
  if (name.find('\0') != std::string::npos) bad("it contains a NUL byte");
  if (name == ".") bad("it is '.'");
  // Hidden names are the daemon's own: ".NAME.creating-PID-N" leftovers are
  // removed at start (remove_abandoned_creations), so a user's file named
  // like one would be deleted with them.
  if (name.front() == '.') bad("it starts with '.' (hidden names are the daemon's temporary files)");
  // Control characters (C0, DEL, C1, U+2028/2029) and bytes that are not UTF-8.
  if (!not_text.empty()) bad(not_text);
  if (name.find_first_not_of(' ') == std::string::npos) bad("it is only spaces");
  // Room for the temporary ".NAME.creating-PID-N" within the 255 bytes a
  // file name may have.
  if (name.size() > kMaxSessionNameBytes) bad("it is longer than " + std::to_string(kMaxSessionNameBytes) + " bytes");
}

void validate_client_session_name(const std::string& name, const std::string& what) {
  validate_session_name(name, what);
  if (name.rfind(kAutomaticPrefix, 0) == 0)
    throw RecordError(what + " name '" + name + "' rejected: it starts with '" + std::string(kAutomaticPrefix) +
                      "', the daemon's automatic recordings, which record.keep_gb removes (choose another name)");
}

namespace {

// ".NAME.creating-PID-N" beside the session: hidden from listings and from
// the *.h5 globs users point tools at. Left behind only by a crash inside
// create(), which takes milliseconds; tissued removes such leftovers at its
// next start (remove_abandoned_creations, keyed on the PID in the name).
std::string hidden_path_for(const std::string& path) {
  static std::atomic<unsigned> counter{0};
  const std::filesystem::path p(path);
  // Appended piecewise: GCC 12 warns falsely (-Wrestrict) on "." + string.
  std::string name(".");
  name.append(p.filename().string())
      .append(kCreatingInfix)
      .append(std::to_string(::getpid()))
      .append("-")
      .append(std::to_string(counter.fetch_add(1)));
  return (p.parent_path() / name).string();
}

}  // namespace

std::vector<std::string> remove_abandoned_creations(const std::string& dir) {
  namespace fs = std::filesystem;
  std::vector<std::string> removed;
  std::error_code ec;
  fs::directory_iterator it(dir, ec), end;
  if (ec) return removed;
  const std::string infix = kCreatingInfix;
  for (; it != end; it.increment(ec)) {
    if (ec) break;
    const std::string name = it->path().filename().string();
    const std::size_t at = name.rfind(infix);
    if (name.size() < 2 || name[0] != '.' || at == std::string::npos || !it->is_regular_file(ec)) continue;
    // "PID-N": the pid the name was made with (hidden_path_for).
    const std::string tail = name.substr(at + infix.size());
    const std::size_t dash = tail.find('-');
    if (dash == 0 || dash == std::string::npos || dash > 9 ||
        !std::all_of(tail.begin(), tail.begin() + static_cast<std::ptrdiff_t>(dash),
                     [](char c) { return c >= '0' && c <= '9'; }))
      continue;
    const pid_t pid = static_cast<pid_t>(std::stol(tail.substr(0, dash)));
    if (pid <= 0 || pid == ::getpid()) continue;
    if (::kill(pid, 0) == 0 || errno != ESRCH) continue;  // alive, or not ours to judge (EPERM)
    if (fs::remove(it->path(), ec)) removed.push_back(it->path().string());
  }
  return removed;
}

std::vector<std::string> remove_oldest_automatic_recordings(const std::string& dir, std::uintmax_t keep_bytes,
                                                            const std::string& keep) {
  namespace fs = std::filesystem;
  // Oldest first: by the time in the name, then by the "-K" a second file
  // of the same second got (by name alone "…-2.h5" sorts before "….h5").
  struct Candidate {
    util::NameStamp stamp;
    std::string path;
    std::uintmax_t bytes = 0;
  };
  std::vector<Candidate> files;
  std::uintmax_t total = 0;
  std::error_code ec;
  fs::directory_iterator it(dir, ec), end;
  if (ec) return {};
  for (; it != end; it.increment(ec)) {
    if (ec) return {};
    const std::string name = it->path().filename().string();
    if (name.rfind(kAutomaticPrefix, 0) != 0 || it->path().extension() != ".h5" || !it->is_regular_file(ec)) continue;
    // Only the names the service makes up: a client's "auto-notes.h5" is the client's.
    const std::optional<util::NameStamp> stamp =
        util::read_name_stamp(it->path().stem().string().substr(kAutomaticPrefix.size()));
    if (!stamp) continue;
    const std::uintmax_t bytes = it->file_size(ec);
    if (ec) continue;
    total += bytes;
    if (!keep.empty() && fs::equivalent(it->path(), keep, ec)) continue;  // counted, never removed
    files.push_back({*stamp, it->path().string(), bytes});
  }
  std::sort(files.begin(), files.end(), [](const Candidate& x, const Candidate& y) {
    return std::tie(x.stamp.time, x.stamp.k, x.path) < std::tie(y.stamp.time, y.stamp.k, y.path);
  });
  std::vector<std::string> removed;
  for (const Candidate& c : files) {
    if (total <= keep_bytes) break;
    if (fs::remove(c.path, ec)) {
      removed.push_back(c.path);
      total -= c.bytes;
    }
  }
  return removed;
}

std::string utc_now_iso8601() {
  const auto now = std::chrono::system_clock::now();
  const std::time_t secs = std::chrono::system_clock::to_time_t(now);
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
  std::tm tm{};
  ::gmtime_r(&secs, &tm);
  char buf[64];
  const std::size_t n = std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%S", &tm);
  char out[80];
  std::snprintf(out, sizeof out, "%.*s.%03dZ", static_cast<int>(n), buf, static_cast<int>(ms));
  return out;
}

std::unique_ptr<SessionWriter> SessionWriter::open_in(const std::string& state_dir, const std::string& name,
                                                      const SessionMetadata& metadata) {
  validate_session_name(name);
  if (state_dir.empty()) throw RecordError("cannot record session '" + name + "': no state directory configured");
  std::error_code ec;
  if (!std::filesystem::is_directory(state_dir, ec))
    throw RecordError("cannot record session '" + name + "': state directory '" + state_dir +
                      "' does not exist or is not a directory");
  return create((std::filesystem::path(state_dir) / name).string(), metadata);
}

std::unique_ptr<SessionWriter> SessionWriter::create(const std::string& path, const SessionMetadata& metadata) {
  h5::QuietErrors quiet;
  const auto fail = [&](const std::string& what) -> RecordError {
    return RecordError("cannot create session file '" + path + "': " + h5::describe(what));
  };
  // HDF5's own message for a missing permission is buried in its stack; the
  // OS says it plainly, so check the directory first.
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  if (::access(parent.empty() ? "." : parent.c_str(), W_OK) != 0)
    throw RecordError("cannot create session file '" + path + "': directory '" + parent.string() +
                      "' is not writable: " + std::strerror(errno));

  std::error_code ec;
  if (std::filesystem::exists(path, ec))
    throw RecordError("cannot create session file '" + path + "': it already exists");

  // The file is built under a hidden name and appears under its own name only
  // once it is a complete SWMR file. A reader polling for the name (`tissue
  // session info`, h5py, a live viewer) can then never open it half-made: its
  // open would hold HDF5's shared file lock, and the writer's exclusive lock
  // (taken right after the create, and again by H5Fstart_swmr_write) fails
  // on it. That failed the create as "already exists" or "Resource
  // temporarily unavailable" in most of the sessions a polling reader
  // watched (tests/record/process_test.cpp).
  const std::string hidden = hidden_path_for(path);
  h5::Handle fapl(H5Pcreate(H5P_FILE_ACCESS));
  // SWMR needs the latest file format (v3 superblock, v4 object headers).
  if (!fapl || H5Pset_libver_bounds(fapl.get(), H5F_LIBVER_LATEST, H5F_LIBVER_LATEST) < 0)
    throw fail("cannot set the file format");
  h5::Handle file(H5Fcreate(hidden.c_str(), H5F_ACC_EXCL, H5P_DEFAULT, fapl.get()));
  if (!file) throw fail("H5Fcreate of '" + hidden + "' failed");

  // A file that could not be set up completely is not a session: remove it
  // so the state directory holds only real sessions.
  std::unique_ptr<SessionWriter> writer;
  try {
    writer = finish_create(path, metadata, std::move(file));
  } catch (const RecordError& e) {
    std::filesystem::remove(hidden, ec);
    throw RecordError("cannot create session file '" + path + "': " + e.what());
  }
  // Marked before it appears, so no reader ever sees it live and unmarked
  // (`tissue session repair` refuses a marked file). The lock is on the
  // inode: the rename keeps it. Without the mark (out of descriptors, a file
  // system without these locks) there is no recording: it would read as
  // left by a crash, and a repair would trim and re-flag it under the
  // writer. Nothing is recorded yet, so the hidden file goes, as below.
  if (const std::string why = writer->lock_.take(hidden); !why.empty()) {
    writer->to_be_removed_ = true;
    writer.reset();
    std::filesystem::remove(hidden, ec);
    throw RecordError("cannot create session file '" + path + "': cannot mark it as being recorded: " + why +
                      "; unmarked, a live recording reads as left by a crash and `tissue session repair` "
                      "would damage it");
  }
  const int moved = util::rename_without_replacing(hidden, path);
  if (moved != 0) {
    writer->to_be_removed_ = true;
    writer.reset();
    std::filesystem::remove(hidden, ec);
    if (moved == EEXIST) throw RecordError("cannot create session file '" + path + "': it already exists");
    throw RecordError("cannot create session file '" + path + "': renaming '" + hidden +
                      "' to it failed: " + std::strerror(moved));
  }
  return writer;
}

std::unique_ptr<SessionWriter> SessionWriter::finish_create(const std::string& path, const SessionMetadata& metadata,
                                                            h5::Handle file) {
  const auto fail = [](const std::string& what) -> RecordError { return RecordError(h5::describe(what)); };
  const auto opened_at = std::chrono::steady_clock::now();
  h5::write_i64_attribute(file.get(), kAttrFormatVersion, kSessionFormatVersion);
  h5::write_string_attribute(file.get(), kAttrSceneName, metadata.scene_name);
  h5::write_string_attribute(file.get(), kAttrSceneText, metadata.scene_text);
  h5::write_string_attribute(file.get(), kAttrConfigText, metadata.config_text);
  h5::write_string_attribute(file.get(), kAttrSoftwareVersion, metadata.software_version);
  h5::write_string_attribute(file.get(), kAttrStartTime,
                             metadata.start_time_utc.empty() ? utc_now_iso8601() : metadata.start_time_utc);
  h5::write_string_attribute(file.get(), kAttrHostName, metadata.host_name.empty() ? host_name() : metadata.host_name);
  h5::write_u8_attribute(file.get(), kAttrClosedCleanly, 0);
  h5::write_string_attribute(file.get(), kAttrEndTime, "", kEndTimeBytes);
  h5::write_f64_attribute(file.get(), kAttrDurationS, std::numeric_limits<double>::quiet_NaN());

  for (const char* group : kGroupPaths) {
    h5::Handle g(H5Gcreate2(file.get(), group, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
    if (!g) throw fail(std::string("cannot create group ") + group);
  }

  std::array<h5::Handle, kDatasetCount> datasets;
  h5::Handle strings = message_type();
  for (std::size_t i = 0; i < kDatasetCount; ++i) {
    const DatasetSpec& spec = kDatasets[i];
    const int rank = spec.columns == 1 ? 1 : 2;
    const hsize_t dims[2] = {0, static_cast<hsize_t>(spec.columns)};
    const hsize_t max_dims[2] = {H5S_UNLIMITED, static_cast<hsize_t>(spec.columns)};
    const hsize_t chunk[2] = {static_cast<hsize_t>(spec.chunk_rows), static_cast<hsize_t>(spec.columns)};
    h5::Handle space(H5Screate_simple(rank, dims, max_dims));
    h5::Handle dcpl(H5Pcreate(H5P_DATASET_CREATE));
    if (!space || !dcpl || H5Pset_chunk(dcpl.get(), rank, chunk) < 0)
      throw fail(std::string("cannot set up ") + spec.path);
    const hid_t type = spec.type == ElementType::kString ? strings.get() : file_type(spec.type);
    h5::Handle ds(H5Dcreate2(file.get(), spec.path, type, space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT));
    if (!ds) throw fail(std::string("cannot create dataset ") + spec.path);
    h5::write_string_attribute(ds.get(), "units", spec.units);
    if (i == kEventKind) h5::write_string_attribute(ds.get(), "kind_names", std::string(kEventKindNames));
    datasets[i] = std::move(ds);
  }

  if (H5Fstart_swmr_write(file.get()) < 0) throw fail("H5Fstart_swmr_write failed");
  auto writer = std::unique_ptr<SessionWriter>(new SessionWriter(path, std::move(file), std::move(datasets)));
  writer->opened_at_ = opened_at;
  return writer;
}

SessionWriter::SessionWriter(std::string path, h5::Handle file, std::array<h5::Handle, kDatasetCount> datasets)
    : path_(std::move(path)), file_(std::move(file)), datasets_(std::move(datasets)) {}

SessionWriter::~SessionWriter() {
  try {
    close();
  } catch (const std::exception&) {
    // Destructors must not throw; the error was recorded in error_ and the
    // file stays marked as not closed cleanly, which is the truth.
  }
}

void SessionWriter::fail(const std::string& what) {
  error_ = "session file '" + path_ + "': " + h5::describe(what);
  detach_from_disk();
  throw RecordError(error_);
}

// After a failed write (disk full, EFBIG, EIO) HDF5 1.10 cannot close the
// file: H5Fclose retries the flush, fails, frees the file anyway and leaves
// a dangling id that crashes the library's atexit cleanup. So the file
// descriptor under HDF5 is pointed at /dev/null: the remaining flushes and
// the close then succeed without touching the disk, and the file on disk
// stays as of its last successful flush, like after a crash (`tissue session
// repair` recovers it).
void SessionWriter::detach_from_disk() {
  if (!file_.valid()) return;
  void* handle = nullptr;
  if (H5Fget_vfd_handle(file_.get(), H5P_DEFAULT, &handle) < 0 || handle == nullptr) return;
  const int fd = *static_cast<int*>(handle);
  const int null_fd = ::open("/dev/null", O_RDWR | O_CLOEXEC);
  if (null_fd < 0) return;
  ::dup3(null_fd, fd, O_CLOEXEC);
  ::close(null_fd);
}

void SessionWriter::throw_if_failed() const {
  if (failed()) throw RecordError(error_);
  if (closed_) throw RecordError("session file '" + path_ + "': already closed");
}

void SessionWriter::append(DatasetId id, const void* data, std::uint64_t rows) {
  if (rows == 0) return;
  const DatasetSpec& spec = kDatasets[id];
  const hid_t ds = datasets_[id].get();
  const int rank = spec.columns == 1 ? 1 : 2;
  const hsize_t cols = static_cast<hsize_t>(spec.columns);
  if (write_fault_) {
    try {
      write_fault_(spec.path);
    } catch (const RecordError& e) {
      fail(std::string("cannot write ") + spec.path + ": " + e.what());
    }
  }
  const hsize_t new_dims[2] = {rows_[id] + rows, cols};
  if (H5Dset_extent(ds, new_dims) < 0) fail(std::string("cannot extend ") + spec.path);
  h5::Handle file_space(H5Dget_space(ds));
  const hsize_t start[2] = {rows_[id], 0};
  const hsize_t count[2] = {rows, cols};
  h5::Handle mem_space(H5Screate_simple(rank, count, nullptr));
  if (!file_space || !mem_space ||
      H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr) < 0)
    fail(std::string("cannot select rows of ") + spec.path);
  h5::Handle strings;
  hid_t mem_type = memory_type(spec.type);
  if (spec.type == ElementType::kString) {
    strings = message_type();
    mem_type = strings.get();
  }
  if (H5Dwrite(ds, mem_type, mem_space.get(), file_space.get(), H5P_DEFAULT, data) < 0)
    fail(std::string("cannot write ") + spec.path);
  rows_[id] += rows;
  dirty_[id] = true;
  bytes_written_ += rows * cols * element_bytes(spec.type);
}

void SessionWriter::append_haptic(std::span<const HapticRow> rows) {
  h5::QuietErrors quiet;
  throw_if_failed();
  if (rows.empty()) return;
  const std::size_t n = rows.size();
  vec3_.resize(n);
  for (std::size_t i = 0; i < n; ++i) vec3_[i] = rows[i].device_position_m;
  append(kHapticDevicePosition, vec3_.data(), n);
  for (std::size_t i = 0; i < n; ++i) vec3_[i] = rows[i].proxy_position_m;
  append(kHapticProxyPosition, vec3_.data(), n);
  for (std::size_t i = 0; i < n; ++i) vec3_[i] = rows[i].force_N;
  append(kHapticForce, vec3_.data(), n);
  u8_.resize(n);
  for (std::size_t i = 0; i < n; ++i) u8_[i] = rows[i].contact;
  append(kHapticContact, u8_.data(), n);
  u64_.resize(n);
  for (std::size_t i = 0; i < n; ++i) u64_[i] = rows[i].model_version;
  append(kHapticModelVersion, u64_.data(), n);
  for (std::size_t i = 0; i < n; ++i) u8_[i] = rows[i].device_fresh;
  append(kHapticDeviceFresh, u8_.data(), n);
  f64_.resize(n);
  for (std::size_t i = 0; i < n; ++i) f64_[i] = rows[i].time_s;
  append(kHapticTime, f64_.data(), n);
}

void SessionWriter::append_sim(std::span<const SimRow> rows) {
  h5::QuietErrors quiet;
  throw_if_failed();
  if (rows.empty()) return;
  const std::size_t n = rows.size();
  f64_.resize(n);
  u64_.resize(n);
  i64_.resize(n);
  const auto f64_column = [&](DatasetId id, double SimRow::*field) {
    for (std::size_t i = 0; i < n; ++i) f64_[i] = rows[i].*field;
    append(id, f64_.data(), n);
  };
  const auto u64_column = [&](DatasetId id, std::uint64_t SimRow::*field) {
    for (std::size_t i = 0; i < n; ++i) u64_[i] = rows[i].*field;
    append(id, u64_.data(), n);
  };
  const auto i64_column = [&](DatasetId id, std::int64_t SimRow::*field) {
    for (std::size_t i = 0; i < n; ++i) i64_[i] = rows[i].*field;
    append(id, i64_.data(), n);
  };
  f64_column(kSimSimTime, &SimRow::sim_time_s);
  f64_column(kSimRealTimeFactor, &SimRow::real_time_factor);
  f64_column(kSimStepMs, &SimRow::step_ms);
  u64_column(kSimNodes, &SimRow::nodes);
  u64_column(kSimTets, &SimRow::tets);
  u64_column(kSimSprings, &SimRow::springs);
  i64_column(kSimRefines, &SimRow::refines);
  i64_column(kSimMerges, &SimRow::merges);
  f64_column(kSimKinetic, &SimRow::kinetic_J);
  f64_column(kSimElastic, &SimRow::elastic_J);
  f64_column(kSimTime, &SimRow::time_s);
}

void SessionWriter::append_events(std::span<const Event> events) {
  h5::QuietErrors quiet;
  throw_if_failed();
  if (events.empty()) return;
  const std::size_t n = events.size();
  i32_.resize(n);
  for (std::size_t i = 0; i < n; ++i) i32_[i] = static_cast<std::int32_t>(events[i].kind);
  append(kEventKind, i32_.data(), n);
  strings_.assign(n * kEventMessageBytes, '\0');
  for (std::size_t i = 0; i < n; ++i) {
    // Copy up to the NUL only and force termination: the struct may have
    // been filled by hand.
    const std::size_t len = ::strnlen(events[i].message, kEventMessageBytes - 1);
    std::memcpy(&strings_[i * kEventMessageBytes], events[i].message, len);
  }
  append(kEventMessage, strings_.data(), n);
  f64_.resize(n);
  for (std::size_t i = 0; i < n; ++i) f64_[i] = events[i].time_s;
  append(kEventTime, f64_.data(), n);
}

void SessionWriter::append_mesh_frame(const MeshFrameView& frame) {
  h5::QuietErrors quiet;
  throw_if_failed();
  const std::size_t nv = frame.vertices_m.size();
  const std::size_t nt = frame.triangles.size();
  if (nv > kMaxMeshFrameVertices) throw std::invalid_argument("mesh frame has too many vertices for int32 indices");
  if (!frame.vertex_level.empty() && frame.vertex_level.size() != nv)
    throw std::invalid_argument("mesh frame has " + std::to_string(frame.vertex_level.size()) + " vertex levels for " +
                                std::to_string(nv) + " vertices");
  triangles_i32_.resize(nt);
  for (std::size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t index = frame.triangles[t][k];
      if (index >= nv)
        throw std::invalid_argument("mesh frame triangle " + std::to_string(t) + " uses vertex " +
                                    std::to_string(index) + " of " + std::to_string(nv));
      triangles_i32_[t][k] = static_cast<std::int32_t>(index);
    }
  vertices_f32_.resize(nv);
  for (std::size_t v = 0; v < nv; ++v)
    for (int k = 0; k < 3; ++k) {
      // The file stores float32: a larger coordinate became inf, silently
      // (and converting it is undefined behaviour), and a NaN one a vertex
      // no viewer can place.
      const double x = frame.vertices_m[v][k];
      if (!(std::fabs(x) <= static_cast<double>(std::numeric_limits<float>::max()))) {
        char what[200];
        std::snprintf(what, sizeof what,
                      "mesh frame vertex %zu coordinate %d (%c) is %g m: must be finite and within float32 range "
                      "(|x| <= %g m, as the file stores vertices)",
                      v, k, "xyz"[k], x, static_cast<double>(std::numeric_limits<float>::max()));
        throw std::invalid_argument(what);
      }
      vertices_f32_[v][k] = static_cast<float>(x);
    }
  const std::uint8_t* levels = frame.vertex_level.data();
  if (frame.vertex_level.empty()) {
    u8_.assign(nv, 0);
    levels = u8_.data();
  }
  // NaN marks "not computed" in the file, so a computed value must never be
  // NaN (or otherwise impossible): refuse it rather than store a lie.
  const std::span<const float> strain_in = frame.triangle_strain_energy_J_per_m3;
  if (!strain_in.empty() && strain_in.size() != nt)
    throw std::invalid_argument("mesh frame has " + std::to_string(strain_in.size()) + " strain values for " +
                                std::to_string(nt) + " triangles");
  for (std::size_t t = 0; t < strain_in.size(); ++t)
    if (!std::isfinite(strain_in[t]) || strain_in[t] < 0.0f)
      throw std::invalid_argument("mesh frame triangle " + std::to_string(t) + " has strain energy density " +
                                  std::to_string(strain_in[t]) + " J/m^3 (must be finite and >= 0)");
  const float* strain = strain_in.data();
  if (strain_in.empty()) {
    strain_f32_.assign(nt, std::numeric_limits<float>::quiet_NaN());
    strain = strain_f32_.data();
  }

  const std::uint64_t vertex_offset = rows_[kMeshVertices];
  const std::uint64_t triangle_offset = rows_[kMeshTriangles];
  append(kMeshVertices, vertices_f32_.data(), nv);
  append(kMeshTriangles, triangles_i32_.data(), nt);
  append(kMeshVertexLevel, levels, nv);
  append(kMeshTriangleStrain, strain, nt);
  const std::uint64_t vertex_count = nv, triangle_count = nt;
  append(kMeshVertexOffset, &vertex_offset, 1);
  append(kMeshVertexCount, &vertex_count, 1);
  append(kMeshTriangleOffset, &triangle_offset, 1);
  append(kMeshTriangleCount, &triangle_count, 1);
  append(kMeshFrameTime, &frame.time_s, 1);
}

void SessionWriter::flush(Sync sync) {
  h5::QuietErrors quiet;
  throw_if_failed();
  bool synced = true;  // nothing new: nothing to sync
  for (std::size_t i = 0; i < kDatasetCount; ++i) {
    if (!dirty_[i]) continue;
    if (flush_fault_) {
      try {
        flush_fault_(kDatasets[i].path);
      } catch (const RecordError& e) {
        fail(std::string("cannot flush ") + kDatasets[i].path + ": " + e.what());
      }
    }
    if (H5Dflush(datasets_[i].get()) < 0) fail(std::string("cannot flush ") + kDatasets[i].path);
    dirty_[i] = false;
    synced = false;
  }
  if (!synced && sync == Sync::kToDisk) sync_to_disk(vfd_descriptor());
}

// HDF5's default (sec2) driver's descriptor, which H5Fget_vfd_handle gives
// as an int*; -1 when it cannot be had.
int SessionWriter::vfd_descriptor() const {
  void* handle = nullptr;
  if (!file_.valid() || H5Fget_vfd_handle(file_.get(), H5P_DEFAULT, &handle) < 0 || handle == nullptr) return -1;
  return *static_cast<int*>(handle);
}

// H5Dflush and H5Fclose hand the data to the page cache only: a power cut
// (or a kernel crash) loses what the kernel has not written back yet, and
// may write HDF5's metadata out of order. fdatasync makes everything up to
// this flush durable. A failure is a write error: the data may not be on
// disk.
void SessionWriter::sync_to_disk(int fd) {
  const int error = fd < 0 ? EBADF : sync_ ? sync_(fd) : (::fdatasync(fd) == 0 ? 0 : errno);
  if (error == 0) return;
  error_ = "session file '" + path_ + "': cannot sync it to disk (fdatasync): " + std::strerror(error);
  detach_from_disk();
  throw RecordError(error_);
}

std::array<std::uint64_t, 4> SessionWriter::group_rows() const {
  return {rows_[kHapticTime], rows_[kSimTime], rows_[kMeshFrameTime], rows_[kEventTime]};
}

void SessionWriter::close(std::optional<double> duration_s) {
  if (closed_) return;
  h5::QuietErrors quiet;
  closed_ = true;
  // However the close ends, the file is no longer being recorded.
  struct Unmark {
    RecordingLock& lock;
    ~Unmark() { lock.release(); }
  } unmark{lock_};
  bool ok = !failed();
  if (ok) {
    try {
      for (std::size_t i = 0; i < kDatasetCount; ++i)
        if (dirty_[i] && H5Dflush(datasets_[i].get()) < 0) fail(std::string("cannot flush ") + kDatasets[i].path);
      // Every row on disk first; only then the mark that says so.
      if (H5Fflush(file_.get(), H5F_SCOPE_LOCAL) < 0) fail("cannot flush the file");
      const double duration =
          duration_s && std::isfinite(*duration_s) && *duration_s >= 0.0
              ? *duration_s
              : std::chrono::duration<double>(std::chrono::steady_clock::now() - opened_at_).count();
      try {
        h5::write_string_attribute(file_.get(), kAttrEndTime, utc_now_iso8601());
        h5::write_f64_attribute(file_.get(), kAttrDurationS, duration);
        h5::write_u8_attribute(file_.get(), kAttrClosedCleanly, 1);
      } catch (const RecordError& e) {
        // e names the attribute and HDF5's reason already (fail() would add
        // the reason twice); the rest is fail()'s: detach, then report.
        error_ = "session file '" + path_ + "': cannot write the clean-close mark: " + e.what();
        detach_from_disk();
        throw RecordError(error_);
      }
    } catch (const RecordError&) {
      ok = false;
    }
  }
  // Synced after the close (the close writes HDF5's last metadata), through
  // a copy of HDF5's descriptor that outlives it.
  const bool sync = ok && !to_be_removed_;
  const int fd = sync ? vfd_descriptor() : -1;
  const int sync_fd = fd >= 0 ? ::fcntl(fd, F_DUPFD_CLOEXEC, 0) : -1;
  for (h5::Handle& ds : datasets_) ok = ds.reset() && ok;
  // The close writes the mark and then clears the superblock's open-for-write
  // flags; a session reads as closed cleanly only with both.
  if (!file_.reset() && ok) {
    ok = false;
    error_ = "session file '" + path_ + "': " + h5::describe("closing the file failed");
  }
  if (ok && sync) {
    try {
      sync_to_disk(sync_fd);
    } catch (const RecordError&) {
      ok = false;  // error_ says why
    }
  }
  if (sync_fd >= 0) ::close(sync_fd);
  if (!ok) {
    if (error_.empty()) error_ = "session file '" + path_ + "': " + h5::describe("closing the file failed");
    throw RecordError(error_);
  }
}

}  // namespace tissue::record
