// Where export frames come from. Recorded sessions now (SessionFrameSource);
// live LCM/DDS subscribers implement the same interface when the publishers
// exist, and `tissue x3d` selects frames through it without knowing which.
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "export/x3d.hpp"

namespace tissue::x3d {

// The source cannot deliver: unreadable, corrupt or foreign input. The
// message names the source (e.g. the file) and the reason.
class SourceError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The bytes a frame's data takes in memory: its vertices, triangles, levels
// and strain values.
std::size_t frame_bytes(const SurfaceFrame& frame);

// "1 GiB", "1.5 MiB", "300 bytes": a size as a person reads it.
std::string byte_size_text(std::size_t bytes);

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // For messages: e.g. "'/data/s.h5'".
  virtual std::string name() const = 0;
  // Complete frames available, in time order.
  virtual std::size_t frame_count() const = 0;
  // Time of frame k (k < frame_count()) without reading its data.
  virtual double frame_time_s(std::size_t k) const = 0;
  // Frame k. Throws SourceError on I/O failure or impossible stored data
  // (e.g. negative indices); std::out_of_range when k >= frame_count().
  virtual SurfaceFrame read_frame(std::size_t k) = 0;
  // The bytes frame k takes in memory once read (frame_bytes of
  // read_frame(k)), so a caller can refuse a selection too large to hold
  // before reading it. This default reads the frame; a source that knows
  // the sizes from an index (a session) answers without reading, at most
  // what the frame turns out to hold.
  virtual std::size_t frame_data_bytes(std::size_t k) { return frame_bytes(read_frame(k)); }
  // Whether frames carry vertex_strain_energy_Pa.
  virtual bool has_strain() const = 0;
  // Why has_strain() is false, in this source's terms, after name(): a
  // session's format or recording options, a live publisher's frames.
  virtual std::string why_no_strain() const { return "carries no strain energy"; }
  // Frames the source received but did not keep, said for a summary line
  // (e.g. "12 frames dropped: ..."); "" when none.
  virtual std::string dropped_note() const { return {}; }
};

// "--colour strain: NAME WHY; use --colour level": the one message both
// clients give when strain colouring is asked of a source without it.
std::string no_strain_message(const FrameSource& source);

// The frame on screen at time t: the last one with time_s <= t + 1 ns (see
// below). Empty when t is before the first frame (or there are no frames).
std::optional<std::size_t> frame_at_time(const FrameSource& source, double t_s);

// Whether a recorded time lies in a user's window t0 <= t <= t1 (an end
// not given is open), each end with the nanosecond of slack frame_at_time
// allows: a frame recorded at 0.5000000000000003 s is in a window that ends
// at 0.5 s, as --time 0.5 picks it. NaN is in no window.
bool time_in_window(double t_s, std::optional<double> t0_s, std::optional<double> t1_s);

// A frame's time for people, to 9 significant digits: "1.5", not the
// accumulated 1.4999999999999456 (frames 1/30 s apart stay distinct for over
// a year of session time). Both clients say frame times this way.
std::string frame_time_text(double t_s);

// The frames whose times are in the window [t0, t1] (time_in_window), in order.
std::vector<std::size_t> frames_in_window(const FrameSource& source, double t0_s, double t1_s);

// A --from/--to window [t0, t1] for messages, "between 0.5 s and 2 s": each
// end as the user gave it (util::number_text), or, not given, as the frame
// time it stands for (frame_time_text: "0.3", not 0.30000000000000004).
std::string window_text(std::optional<double> from_s, std::optional<double> to_s, double t0_s, double t1_s);

// Why a window that ends before it starts (t0 > t1; an end not given is the
// first or last frame's time) holds no frame, in the options the user gave:
// "--from 1 --to 0.5: the window is empty (--from is after --to)", "--to 0.2
// is before the first frame of NAME (t=0.3 s)", "--from 5 is after the last
// frame of NAME (t=0.6 s)". Both clients refuse such a window with it.
std::string reversed_window_text(const FrameSource& source, std::optional<double> from_s, std::optional<double> to_s,
                                 double t0_s, double t1_s);

// Frame data an export may hold in memory at once (x3d --animate keeps every
// frame of its window, then makes a text 2-3 times their size): the same
// 1 GiB that stops a live collection (kLiveFrameBudgetBytes). A whole
// session, an hour of a 50k-vertex surface at 30 Hz, is hundreds of GB.
inline constexpr std::size_t kExportFrameBudgetBytes = std::size_t{1} << 30;

// Why frames `picked` of `source` (in time order) cannot all be held in
// memory: "3600 frames of 'S.h5' (t=0 s to 120 s) hold 87.2 GiB of frame
// data, more than the 1 GiB an export may hold"; "" when their data
// (frame_data_bytes, summed) is at most `max_bytes`.
std::string frame_budget_problem(FrameSource& source, const std::vector<std::size_t>& picked, std::size_t max_bytes);

// Opens a session file (docs/session-format.md), including one still being
// recorded or left by a crash (SWMR read). Throws SourceError naming the file.
std::unique_ptr<FrameSource> open_session_source(const std::string& path);

}  // namespace tissue::x3d
