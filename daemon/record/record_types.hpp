// The plain records a session is made of. Producers (haptic thread, sim
// thread, control) fill these; the recorder writes them to HDF5
// (docs/session-format.md). They do not depend on the service, so the
// integrator converts ToolSample / SimStatus / SurfaceMesh into them.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
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
