// Offline tools over session files: what `tissue session info | repair |
// xdmf` do, as library functions the tests call directly, and the one reader
// of a session's rows (replay, the replay haptic device, the frame source).
// Every failure throws RecordError naming the file and what is wrong with
// it; nothing here crashes on random, truncated or foreign files (HDF5's own
// error printing is silenced).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "record/record_types.hpp"
#include "record/session_layout.hpp"

namespace tissue::record {

struct GroupCounts {
  std::uint64_t haptic_rows = 0, sim_rows = 0, mesh_frames = 0, events = 0;
  std::uint64_t mesh_vertices = 0, mesh_triangles = 0;  // rows used by the complete frames
  bool operator==(const GroupCounts&) const = default;
};

struct SessionInfo {
  std::string path;
  std::int64_t format_version = 0;
  // Format version 2 and later store per-triangle strain energy density
  // (/mesh/triangle_strain_energy_J_per_m3); version 1 files do not.
  bool has_strain = false;
  // Format version 3 and later record per haptic tick whether the device
  // delivered a new sample (/haptic/device_fresh); older files do not.
  bool has_device_fresh = false;
  bool closed_cleanly = false;
  // The superblock still says "open for (SWMR) writing": the writer crashed
  // (or is still running). Ordinary readers refuse such a file until it is
  // repaired.
  bool open_for_write_flag = false;
  // A recorder holds the file now (record/recording_lock.hpp): open for
  // writing because it is being written, not because a crash left it so.
  bool being_recorded = false;
  std::string repaired_utc;  // set by repair_session
  std::string scene_name, start_time_utc, end_time_utc, host_name, software_version;
  // Clean close: the recorded duration; otherwise (or when the recorded one
  // is not finite, negative or beyond kMaxSessionTime_s) the last time stamp
  // of any group. Always finite, within kMaxSessionTime_s.
  double duration_s = 0.0;
  bool duration_recorded = false;  // duration_s is the clean close's duration_s attribute
  // Rows every column of the group has (a crash between column flushes can
  // leave columns of unequal length; readers should use these counts).
  GroupCounts rows;
  // Closed or repaired files (the superblock's flags clear): rows a dataset
  // holds beyond those its readers use (past the shortest column of its
  // group; vertex and triangle rows in no frame of the index), by DatasetId.
  // The writer leaves none; `tissue session info` lists them. Always 0 in a
  // file open for writing, whose last write may be ahead of its group.
  std::array<std::uint64_t, kDatasetCount> unreferenced_rows{};
  // Left by a crash (open for writing with no recorder holding it, or
  // neither closed cleanly nor repaired) with rows past its complete ones:
  // a column past the shortest of its group, mesh data or index rows past
  // the last complete frame. `tissue session repair` trims them; info and
  // list say so.
  bool crash_tail = false;
  // Holes the recorder left in /haptic (HapticHole: ticks it dropped when
  // its ring was full, one warning event each) and the ticks they lost in
  // all. Filled by read_session_info (so `info` and `list`); SessionFile's
  // info() leaves them 0 (read_haptic_holes reads them).
  std::uint64_t haptic_holes = 0, haptic_ticks_lost = 0;
  // The session time those holes span: for each hole with a recorded row on
  // either side, the time between those two rows (the jump in
  // /haptic/time_s the hole explains; the time a replay leaves out of
  // device_timeout_s), summed. A hole at either end of /haptic has no such
  // span and adds nothing. Filled by read_session_info.
  double haptic_hole_time_s = 0.0;
  // Hole events that do not match the rows they name (damage), one line each
  // naming the event row; not counted above. Filled by read_session_info:
  // info and list report them and show the rest of the file (repair does not
  // touch events, so refusing the file would hide it for good); the replay
  // refuses such a file (read_haptic_track).
  std::vector<std::string> damaged_hole_events;
};

// Opens read-only (SWMR read when the superblock says it is still open for
// writing, so it works on a live or crashed session too).
SessionInfo read_session_info(const std::string& path);
// Human-readable multi-line summary (what `tissue session info` prints).
std::string format_session_info(const SessionInfo& info);

// How a session file ended, from its clean-close mark, superblock flags and
// repair mark.
enum class SessionState : std::uint8_t {
  kClosedCleanly,
  kOpenForWrite,  // being recorded (SessionInfo::being_recorded), or left by a crash and not yet repaired
  kRepaired,      // left by a crash, repaired
  kNotClosed,     // no clean-close mark, flags clear (e.g. a failed close)
};
SessionState session_state(const SessionInfo& info);

// What a state directory holds (`tissue session list`). Every regular file
// whose name ends in ".h5" or that starts with HDF5's signature is read as a
// session; other files (exports, sidecars) and subdirectories are skipped.
struct SessionListing {
  std::string dir;
  std::vector<SessionInfo> sessions;  // sorted by file name
  struct Unreadable {
    std::string path, reason;  // reason: RecordError's message
  };
  std::vector<Unreadable> unreadable;  // session-like files that are not readable sessions
  // Hidden ".NAME.creating-PID-N" files: a session being created right now,
  // or one whose recorder stopped while creating it (not a session).
  std::vector<std::string> unfinished;
};
// Throws RecordError naming `dir` when it cannot be listed.
SessionListing list_sessions(const std::string& dir);
// One line per session (name, state, start, duration, haptic ticks, mesh
// frames, scene), then the unreadable and unfinished files with reasons.
std::string format_session_listing(const SessionListing& listing);

// ---------------------------------------------------------------- readers
// The one reader of a session's rows (replay, the replay haptic device, the
// frame source): the same file checks as read_session_info (foreign, empty,
// truncated, crashed or live files), one open (SWMR read while a writer has
// or had it open), and only the rows every column of a group has. Every
// failure throws RecordError "'FILE': what", naming the dataset and reason.
class SessionFile {
 public:
  explicit SessionFile(const std::string& path);
  ~SessionFile();
  SessionFile(SessionFile&&) noexcept;
  SessionFile& operator=(SessionFile&&) noexcept;

  const std::string& path() const;
  // Counts of complete rows, format version, strain, state.
  const SessionInfo& info() const;

  // Rows [first, first + count) of dataset `id`, flattened (3 values a row
  // for the N x 3 datasets), converted to T by HDF5. T is one of double,
  // float, std::uint8_t, std::int32_t, std::uint64_t, std::int64_t. A range
  // outside the dataset is an error naming it (never a read past its end).
  template <typename T>
  std::vector<T> rows(DatasetId id, std::uint64_t first, std::uint64_t count) const;
  // Rows [first, first + count) of /events/message, each cut at its first
  // NUL (at most kEventMessageBytes - 1 bytes), with the same checks.
  std::vector<std::string> event_messages(std::uint64_t first, std::uint64_t count) const;

  // Throws RecordError "'FILE': what".
  [[noreturn]] void fail(const std::string& what) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Beyond this a session time (any group's, frame times too) is damage, not a
// session (31 years): replay would wait for it (1e308 s kept a replay running
// with no end).
inline constexpr double kMaxSessionTime_s = 1e9;

// What is wrong with a session's frame times (/mesh/frame_time_s), or "" when
// nothing is: each finite, within kMaxSessionTime_s and none before the one
// ahead of it. The one rule of every reader of frames (the frame source,
// replay, xdmf): replay paces by them, ParaView steps through them.
std::string frame_times_problem(const std::vector<double>& times_s);

// What is wrong with the rows of mesh frame `frame`, or "" when nothing is:
// every coordinate finite, every triangle index within the frame's vertices,
// and the strain all NaN (recorded without it) or every value finite and
// >= 0 (a mix is named as one). The one rule of every reader of a frame's
// data (the frame source, so x3d, render and replay; xdmf): they index the
// frame's vertices with these (VTK does not bounds-check) and draw or
// publish the values. `vertices_xyz` holds 3 floats a vertex (rows from
// `vertex_offset`), `triangles` 3 indices a triangle and `triangle_strain`
// one value a triangle, or none when the file stores no strain (rows from
// `triangle_offset`); the message names the dataset, row and frame.
std::string mesh_frame_problem(std::uint64_t frame, std::uint64_t vertex_offset, const std::vector<float>& vertices_xyz,
                               std::uint64_t triangle_offset, const std::vector<std::int32_t>& triangles,
                               const std::vector<float>& triangle_strain);

// Every column of /haptic and /sim (docs/session-format.md), complete rows
// only, session times finite and non-decreasing. Held in memory (about 100
// bytes per haptic tick).
struct SessionRows {
  std::vector<HapticRow> haptic;
  std::vector<SimRow> sim;
  // The holes the recorder left in /haptic (read_haptic_holes; a damaged
  // hole event is left out, as info and list leave it out of their count),
  // by row_after: a replay says where it reaches one.
  std::vector<HapticHole> haptic_holes;
};
SessionRows read_session_rows(const std::string& path);

// The recorded hand motion for the replay haptic device: the haptic rows'
// time, device position and force (read by read_session_rows' reader).
struct HapticTrack {
  std::vector<double> time_s;                            // session time, non-decreasing
  std::vector<std::array<double, 3>> device_position_m;  // scene frame
  std::vector<std::array<double, 3>> force_N;            // rendered on the device
  // /haptic/device_fresh, one 0/1 per row; empty for a file of format
  // version < 3, which did not record it (the replay then guesses).
  std::vector<std::uint8_t> device_fresh;
  // The rows that follow a hole the recorder left (read_haptic_holes):
  // ticks between row r - 1 and row r are missing, so the replay does not
  // judge the device over them. Increasing, each in [1, rows).
  std::vector<std::size_t> rows_after_holes;
};
// Throws RecordError naming the file and what is wrong (not a session, no
// haptic rows, times not increasing or not finite, positions not finite, a
// device_fresh flag other than 0 or 1, a hole event that does not match the
// rows it names: see read_haptic_holes).
HapticTrack read_haptic_track(const std::string& path);

// The holes the recorder left in /haptic (its warning events that
// parse_haptic_hole reads; other events are not holes), by row_after. Each
// is checked against the rows it names: a row before or after it that the
// file holds must be at the time the event gives (within 1 us: the text has
// nanoseconds), else the file is refused naming the event row. A hole whose
// next row is past the rows readers use (a crash's last write, trimmed by
// repair) is kept: its ticks were lost all the same. Files written before
// the recorder recorded holes have none. With `damaged`, a hole event that
// does not match its rows is left out and described there (one line each,
// "hole event N does not match its rows (damaged): ...") instead: for info
// and list, which show the rest of the file.
std::vector<HapticHole> read_haptic_holes(const SessionFile& f, std::vector<std::string>* damaged = nullptr);

struct RepairReport {
  bool repair_needed = false;      // false: the file was already fine; nothing changed
  GroupCounts before;              // complete rows found (SWMR view) before repair
  SessionInfo after;               // read back with an ordinary (non-SWMR) open
  std::vector<std::string> notes;  // what was trimmed, etc.
};

// Makes a session left by a crash readable by ordinary readers: clears the
// superblock's open-for-write flags and moves the end-of-allocation past the
// end of file (the effect of `h5clear -s --increment`), then trims columns to
// the rows every column of their group has and the mesh to its last
// complete frame, and stamps `repaired_utc`. Do not run it on a session that
// is still being recorded.
RepairReport repair_session(const std::string& path);

struct XdmfReport {
  std::string out_path;
  std::uint64_t frames = 0;         // grids written
  std::uint64_t skipped_empty = 0;  // frames without triangles (XDMF cannot express them)
};

// Writes an XDMF 3 sidecar: a temporal collection with one triangle grid per
// complete mesh frame, HyperSlab DataItems into the flat /mesh datasets
// (vertex_level as a Node attribute; strain energy density, when a frame of
// the session has it, as a Cell attribute of every grid: NaN on a frame
// recorded without it; none for a session recorded without strain or of
// format version 1). The HDF5 path in the XML is relative to the sidecar's
// directory when possible.
// out_path empty: FILE with its extension replaced by .xdmf.
XdmfReport write_xdmf(const std::string& h5_path, const std::string& out_path);

}  // namespace tissue::record
