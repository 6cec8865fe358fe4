// SessionWriter: one HDF5 session file written in SWMR mode
// (docs/session-format.md). Single-threaded: the Recorder's thread owns it.
// A concurrent reader (another process, H5F_ACC_SWMR_READ + H5Drefresh) sees
// the datasets grow after each flush(); after a crash everything flushed is
// there (`tissue session repair` makes it readable by ordinary readers).
//
// Errors throw RecordError naming the file and the reason (disk full,
// permission denied, ...). After the first failure the writer is failed: every
// later append/flush throws the same error, close() only releases handles.
#pragma once

#include <hdf5.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "record/h5_util.hpp"
#include "record/record_types.hpp"
#include "record/recording_lock.hpp"
#include "record/session_layout.hpp"

namespace tissue::record {

// Throws RecordError unless `name` is a plain file name: not empty, no '/',
// no "..", no NUL or other control character, not hidden (no leading '.'),
// not only spaces, at most kMaxSessionNameBytes. Sessions (and the daemon's
// X3D exports, by the same rule) only ever land inside the state directory.
// `what` names the file in the message ("session", "export").
inline constexpr std::size_t kMaxSessionNameBytes = 200;
void validate_session_name(const std::string& name, const std::string& what = "session");

// Removes the hidden ".NAME.creating-PID-N" files in `dir` whose process is
// gone: a recorder killed inside SessionWriter::create, before the file was
// published, so no recorded row is in it. Files of a live process (this one
// included) stay, and so does anything that is not such a file. Returns the
// removed paths; a directory that cannot be read removes nothing.
std::vector<std::string> remove_abandoned_creations(const std::string& dir);

// The service's automatic recordings (record.auto_start) are named
// kAutomaticPrefix + "YYYYmmdd-HHMMSS[-K].h5" (util/timestamped_name).
inline constexpr std::string_view kAutomaticPrefix = "auto-";

// validate_session_name, and not a name starting with kAutomaticPrefix:
// those are the daemon's own, and record.keep_gb removes the old ones, so a
// client's "auto-20000101-000000.h5" would be deleted as automatic. For the
// names a client gives (record_start, --record in service mode, export_x3d:
// an export named like a recording would be deleted as one too).
void validate_client_session_name(const std::string& name, const std::string& what = "session");
// Removes the oldest automatic recordings in `dir` (regular files named
// kAutomaticPrefix + "YYYYmmdd-HHMMSS[-K].h5", oldest first by that time,
// then K) until those left hold at most `keep_bytes` together, never `keep`
// (the file being written) nor any other file, whatever its prefix. Returns
// the removed paths; a directory that cannot be read removes nothing.
std::vector<std::string> remove_oldest_automatic_recordings(const std::string& dir, std::uintmax_t keep_bytes,
                                                            const std::string& keep);

// Current UTC time as ISO-8601 with milliseconds, e.g. 2024-05-01T12:00:00.123Z.
std::string utc_now_iso8601();

class SessionWriter {
 public:
  // Creates `state_dir/name` (never overwrites: an existing file is an
  // error). The directory must exist. The file is built under a hidden name
  // and renamed into place once in SWMR mode, so no reader ever finds it
  // half-made (or blocks its creation). Throws RecordError, also when the
  // file cannot be marked as being recorded (RecordingLock: out of file
  // descriptors, a file system without the lock), leaving nothing behind.
  static std::unique_ptr<SessionWriter> open_in(const std::string& state_dir, const std::string& name,
                                                const SessionMetadata& metadata);
  // Same, for a full path (tests, tools). Prefer open_in in the daemon.
  static std::unique_ptr<SessionWriter> create(const std::string& path, const SessionMetadata& metadata);

  // Closes like close(), swallowing errors.
  ~SessionWriter();
  SessionWriter(const SessionWriter&) = delete;
  SessionWriter& operator=(const SessionWriter&) = delete;

  // Each append extends the group's datasets and writes the rows; they
  // become visible to readers at the next flush().
  void append_haptic(std::span<const HapticRow> rows);
  void append_sim(std::span<const SimRow> rows);
  void append_events(std::span<const Event> events);
  // Throws std::invalid_argument (file untouched) when a triangle index is
  // out of range, a vertex coordinate is not finite or beyond float32 range,
  // the level or strain count does not match, a strain value is negative or
  // not finite, or the frame is too big for int32 indices; RecordError on
  // I/O failure.
  void append_mesh_frame(const MeshFrameView& frame);

  // H5Dflush on every dataset that grew since the last flush (data columns
  // before the columns readers count by), then, with Sync::kToDisk,
  // fdatasync of the file, so what was flushed survives a power cut too
  // (RecordError if it fails). Sync::kNone leaves the data in the page cache
  // (readers see it, a process crash keeps it): for a writer that flushes
  // far more often than durability is worth, such as a batch run's frame
  // every 1/30 s of simulated time, which close() syncs once.
  enum class Sync { kToDisk, kNone };
  void flush(Sync sync = Sync::kToDisk);

  // Flushes every row, rewrites closed_cleanly = 1, end_time_utc and
  // duration_s in place (still in SWMR mode, so readers may keep the file
  // open), then closes the file and syncs it to disk (fdatasync). Throws RecordError (the file then does not
  // read as closed cleanly). Idempotent. duration_s: the session's length in
  // its own time when that is not the wall time since opening (a batch run's
  // simulated seconds); unset, negative or not finite: the wall time.
  void close(std::optional<double> duration_s = std::nullopt);

  const std::string& path() const { return path_; }
  bool failed() const { return !error_.empty(); }
  const std::string& error() const { return error_; }
  // Rows written so far per group: haptic, sim, mesh frames, events.
  std::array<std::uint64_t, 4> group_rows() const;
  std::uint64_t bytes_written() const { return bytes_written_; }

  // Test seam (never set in the daemon): called before each dataset write
  // with the dataset's path, so a test can make an append fail at one
  // dataset, which real faults do not reliably do (HDF5 buffers appends in
  // its caches; a full disk shows at the flush). A RecordError thrown from
  // it is taken as an I/O error of that write (the writer fails, as on a
  // full disk); any other exception comes out of the append unchanged, the
  // writer still healthy (as std::bad_alloc from a scratch column would).
  using WriteFault = std::function<void(const char* dataset_path)>;
  void set_write_fault_for_testing(WriteFault fault) { write_fault_ = std::move(fault); }
  // Test seam (never set in the daemon): called in flush() before each
  // dataset's H5Dflush with the dataset's path. A RecordError thrown from it
  // fails that flush as a real one fails: the writer fails and the file
  // stays as of the datasets flushed before, which is what a crash at that
  // point leaves (the order of a flush matters to what a crash can leave).
  void set_flush_fault_for_testing(WriteFault fault) { flush_fault_ = std::move(fault); }
  // Test seam (never set in the daemon): replaces fdatasync(2) on the file's
  // descriptor (flush() and close() sync the file to disk). Returns 0 or an
  // errno value, which fails the writer like a write error.
  using SyncFile = std::function<int(int fd)>;
  void set_sync_for_testing(SyncFile sync) { sync_ = std::move(sync); }

 private:
  static std::unique_ptr<SessionWriter> finish_create(const std::string& path, const SessionMetadata& metadata,
                                                      h5::Handle file);
  SessionWriter(std::string path, h5::Handle file, std::array<h5::Handle, kDatasetCount> datasets);

  void append(DatasetId id, const void* data, std::uint64_t rows);
  [[noreturn]] void fail(const std::string& what);
  void detach_from_disk();
  int vfd_descriptor() const;
  void sync_to_disk(int fd);
  void throw_if_failed() const;

  std::string path_;
  h5::Handle file_;
  std::array<h5::Handle, kDatasetCount> datasets_;
  std::array<std::uint64_t, kDatasetCount> rows_{};
  std::array<bool, kDatasetCount> dirty_{};
  std::chrono::steady_clock::time_point opened_at_;
  std::uint64_t bytes_written_ = 0;
  std::string error_;
  bool closed_ = false;
  RecordingLock lock_;      // from before the file appears under its name until close()
  WriteFault write_fault_;  // see set_write_fault_for_testing
  WriteFault flush_fault_;  // see set_flush_fault_for_testing
  SyncFile sync_;           // see set_sync_for_testing; empty: fdatasync
  // A create that failed after the file was made removes it: its close
  // syncs nothing (out of descriptors, the copy for the sync failed and the
  // close reported "cannot sync it to disk" for a file about to go).
  bool to_be_removed_ = false;

  // Column scratch (reused, so steady state allocates nothing).
  std::vector<double> f64_;
  std::vector<std::array<double, 3>> vec3_;
  std::vector<std::uint8_t> u8_;
  std::vector<std::uint64_t> u64_;
  std::vector<std::int64_t> i64_;
  std::vector<std::int32_t> i32_;
  std::vector<std::array<float, 3>> vertices_f32_;
  std::vector<std::array<std::int32_t, 3>> triangles_i32_;
  std::vector<float> strain_f32_;
  std::vector<char> strings_;
};

}  // namespace tissue::record
