// The plain records a session is made of. Producers (haptic thread, sim
// thread, control) fill these; the recorder writes them to HDF5
// (docs/session-format.md). They do not depend on the service, so the
// integrator converts ToolSample / SimStatus / SurfaceMesh into them.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

namespace tissue::record {

// Every recording failure: the message names the file and the reason.
class RecordError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// One 1 kHz haptic tick. time_s is session time (seconds since the session
// started, steady clock; see Recorder::session_time_s).
struct HapticRow {
  double time_s = 0.0;
  std::array<double, 3> device_position_m{};
  std::array<double, 3> proxy_position_m{};
  std::array<double, 3> force_N{};  // force rendered on the device (after safety)
  std::uint8_t contact = 0;         // 1 while the proxy touches the surface
  std::uint64_t model_version = 0;  // LocalModel version the tick rendered against
  // 1 when the device delivered a new sample this tick and the loop accepted
  // it (device_position_m is that sample); 0 when the tick held the last one.
  // Also 0 in rows read from files of format version < 3, which did not
  // record it (SessionInfo::has_device_fresh).
  std::uint8_t device_fresh = 0;
};

// One simulation statistics sample.
struct SimRow {
  double time_s = 0.0;      // session time of the sample
  double sim_time_s = 0.0;  // simulated time
  double real_time_factor = 0.0;
  double step_ms = 0.0;
  std::uint64_t nodes = 0, tets = 0, springs = 0;
  std::int64_t refines = 0, merges = 0;  // cumulative counts
  double kinetic_J = 0.0, elastic_J = 0.0;
};

// Event kinds, stored as int32 in /events/kind (the names are listed in the
// dataset's `kind_names` attribute).
enum class EventKind : std::int32_t {
  kInfo = 0,
  kWarning = 1,
  kError = 2,
  kSceneLoaded = 3,
  kParameterChanged = 4,
  kRecordingError = 5,  // the recorder itself failed (disk full, ...)
};
inline constexpr std::string_view kEventKindNames =
    "0=info,1=warning,2=error,3=scene_loaded,4=parameter_changed,5=recording_error";

inline constexpr std::size_t kEventMessageBytes = 256;  // fixed string in the file, NUL included

struct Event {
  double time_s = 0.0;
  EventKind kind = EventKind::kInfo;
  char message[kEventMessageBytes] = {};  // NUL-terminated; longer text is cut at a UTF-8 boundary

  // Never allocates: safe on the real-time threads.
  static Event make(double time_s, EventKind kind, std::string_view text) noexcept;
};

// A stretch of haptic ticks the recorder dropped: its ring was full (the
// disk stalled longer than the ring holds), so the rows between two recorded
// ones are missing. Without a record of it, the jump in /haptic/time_s looked
// like the haptic loop skipping ticks, and a replay took the stretch for the
// device sending nothing (docs/session-format.md, "Holes"). The recorder
// writes one as a warning event (haptic_hole_message); readers take it back
// with parse_haptic_hole. No format change: old readers see a warning.
struct HapticHole {
  std::uint64_t ticks_lost = 0;  // rows dropped, > 0
  // The /haptic row that follows the hole (row_after - 1 precedes it). With
  // no row after it (the recording stopped while rows were being dropped)
  // time_after_s is NaN and row_after is the row count at that time.
  std::uint64_t row_after = 0;
  double time_before_s = std::numeric_limits<double>::quiet_NaN();  // NaN: no row before it
  double time_after_s = std::numeric_limits<double>::quiet_NaN();   // NaN: no row after it
  bool has_row_before() const noexcept { return !std::isnan(time_before_s); }
  bool has_row_after() const noexcept { return !std::isnan(time_after_s); }
};

// Every hole event's message starts with this (kind warning).
inline constexpr std::string_view kHapticHolePrefix = "haptic rows dropped by the recorder (ring full): ";

// The event text of `hole`, e.g. "haptic rows dropped by the recorder (ring
// full): 50 ticks between /haptic rows 8191 (8.191000000 s) and 8192
// (8.242000000 s)"; "... 7 ticks after /haptic row 9 (0.009000000 s), the last
// recorded" when no row follows. Times to the nanosecond (a tick's clock).
// Well under the 255 bytes of an event.
std::string haptic_hole_message(const HapticHole& hole);
// Reads back what haptic_hole_message wrote: false for any other text
// (another event, or a damaged one that no longer reads as a hole).
bool parse_haptic_hole(std::string_view message, HapticHole* hole);

// A borrowed view of one surface mesh frame. Triangle indices are local to
// the frame (0 .. vertices_m.size()-1). vertex_level may be empty (all 0) or
// hold one value per vertex (bisection depth, for colouring).
// triangle_strain_energy_J_per_m3 may be empty (not computed: stored as NaN,
// which readers take as "no strain for this frame") or hold one finite,
// non-negative value per triangle (strain-energy density of the leaf tet
// behind the triangle, J/m^3 = Pa).
struct MeshFrameView {
  double time_s = 0.0;
  std::span<const std::array<double, 3>> vertices_m;
  std::span<const std::array<std::uint32_t, 3>> triangles;
  std::span<const std::uint8_t> vertex_level;
  std::span<const float> triangle_strain_energy_J_per_m3;
};

// What the file says about itself (root attributes, written once at open).
struct SessionMetadata {
  std::string scene_name;
  std::string scene_text;   // the scene file's text, verbatim
  std::string config_text;  // the daemon config's text, verbatim
  std::string software_version;
  std::string host_name;       // empty: taken from gethostname()
  std::string start_time_utc;  // ISO-8601 UTC; empty: now
};

}  // namespace tissue::record
