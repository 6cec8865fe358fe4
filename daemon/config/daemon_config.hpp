// The daemon's settings (config/tissued.yaml): plain data in SI units,
// validated by the loader (daemon_config_yaml) before anyone reads it.
// Scenes are separate (scene/scene.hpp); this file says which scene to load,
// which device to drive, how the threads run and where the control socket is.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace tissue::config {

using Vec3 = std::array<double, 3>;

// Per-device force safety. Every limit applies after the coupling computes a
// force and before the device sees it.
struct ForceLimits {
  double max_force_N = 3.0;                             // |F| clamp (Phantom Omni/Touch peak is 3.3 N)
  double max_force_rate_N_per_s = 300.0;                // |dF/dt| clamp
  double max_stiffness_N_per_m = 1000.0;                // rendered stiffness clamp (coupling and K_c)
  double ramp_in_s = 0.5;                               // force scale ramps 0 -> 1 after start
  double ramp_out_s = 0.05;                             // ... and 1 -> 0 on a fault or stop
  double stale_model_s = 0.1;                           // no new LocalModel for this long: ramp to zero
  double device_timeout_s = 0.01;                       // no valid device sample for this long: ramp to zero
  double max_speed_m_per_s = 5.0;                       // device input faster than this is rejected as a glitch
  double workspace_radius_m = 1.0;                      // device input farther than this from the origin is rejected
  bool operator==(const ForceLimits&) const = default;  // a reload tells what changed
};

// A scripted target position at a time (piecewise-linear in between).
struct Waypoint {
  double time_s = 0.0;
  Vec3 position_m{};
  bool operator==(const Waypoint&) const = default;  // a reload tells what changed
};

// The simulated device. kTrajectory: the tip follows the waypoints exactly.
// kHand: a virtual hand (point mass) is pulled towards the waypoint target by
// a spring-damper and pushed back by the rendered force, so the full force
// path is exercised and the "user" yields when the object pushes.
struct SimDeviceSpec {
  enum class Mode { kTrajectory, kHand };
  Mode mode = Mode::kHand;
  std::vector<Waypoint> waypoints;  // at least one
  bool loop = false;                // repeat the waypoint timeline
  double hand_mass_kg = 0.1;
  double hand_stiffness_N_per_m = 200.0;
  double hand_damping_N_s_per_m = 4.0;
  bool operator==(const SimDeviceSpec&) const = default;  // a reload tells what changed

  // The hand is integrated with semi-implicit Euler in sub-steps of at most
  // kHandSubstep_s. Its update matrix is stable while h²k/m + 2hc/m < 4 and
  // hc/m < 2 (the Jury conditions); past that the hand's position grows
  // without bound and turns non-finite within a few hundred sub-steps (a
  // 0.1 g hand with the default spring and damper, pushed by 1 N: 240). Specs are held to half the limit.
  static constexpr double kHandSubstep_s = 0.0005;
  static constexpr double kMaxHandStabilityIndex = 2.0;
  // h²k/m + 2hc/m at kHandSubstep_s (NaN unless the mass is > 0).
  double hand_stability_index() const {
    const double h = kHandSubstep_s;
    return hand_mass_kg > 0.0 ? (h * h * hand_stiffness_N_per_m + 2.0 * h * hand_damping_N_s_per_m) / hand_mass_kg
                              : std::numeric_limits<double>::quiet_NaN();
  }
  // The lightest hand the stiffness and damping allow.
  double min_hand_mass_kg() const {
    const double h = kHandSubstep_s;
    return (h * h * hand_stiffness_N_per_m + 2.0 * h * hand_damping_N_s_per_m) / kMaxHandStabilityIndex;
  }
};

struct UdpDeviceSpec {
  std::string bind_address = "127.0.0.1";
  int port = 47800;
  double timeout_s = 0.05;
  bool operator==(const UdpDeviceSpec&) const = default;  // a reload tells what changed
};

struct OpenHapticsSpec {
  std::string library = "libHD.so";
  std::string device_name = "Default Device";
  bool operator==(const OpenHapticsSpec&) const = default;  // a reload tells what changed
};

// Plays the device positions of a recorded session back (scene frame), at
// `speed` times the recorded pace: the user's motion without the user.
struct ReplayDeviceSpec {
  std::string session;  // session file (.h5); relative paths resolve against the config's directory
  double speed = 1.0;
  bool loop = false;
  bool operator==(const ReplayDeviceSpec&) const = default;  // a reload tells what changed
};

struct DeviceSpec {
  enum class Kind { kNone, kSim, kUdp, kOpenHaptics, kReplay };
  Kind kind = Kind::kSim;
  ForceLimits limits;
  // Device frame -> scene frame: p_scene = offset_m + scale * p_device.
  Vec3 offset_m{};
  double scale = 1.0;
  SimDeviceSpec sim;
  UdpDeviceSpec udp;
  OpenHapticsSpec openhaptics;
  ReplayDeviceSpec replay;
  bool operator==(const DeviceSpec&) const = default;  // a reload tells what changed
};

struct HapticSpec {
  double rate_hz = 1000.0;
  double coupling_stiffness_N_per_m = 400.0;  // virtual coupling spring, proxy <-> device
  double coupling_damping_N_s_per_m = 1.0;
  double crossfade_s = 0.01;                           // blend time when a new LocalModel arrives
  bool operator==(const HapticSpec&) const = default;  // a reload tells what changed
};

struct RealtimeSpec {
  bool sched_fifo = true;  // try SCHED_FIFO; fall back to SCHED_OTHER and say so
  int haptic_priority = 80;
  int sim_priority = 60;
  bool lock_memory = true;                               // try mlockall; undo it when the memlock limit is too small
  int haptic_cpu = -1;                                   // pin the haptic thread to this CPU (-1: no pinning)
  bool operator==(const RealtimeSpec&) const = default;  // a reload tells what changed
};

struct ControlSpec {
  std::string unix_socket_path = "/run/tissued/control.sock";  // empty: no Unix socket
  int tcp_port = 0;                                            // 0: no TCP; otherwise bound to 127.0.0.1 only
  std::size_t max_line_bytes = 65536;
  int max_connections = 16;
  // When full, a connection mid-request with no byte moved for this long
  // makes way for a newcomer, and so does one whose request has been going on
  // for twice this long (ServerSettings::stalled_after).
  double stalled_after_s = 5.0;
  bool operator==(const ControlSpec&) const = default;  // a reload tells what changed
};

// Live data out (proto/README.md). LCM by default sends to a multicast group
// with ttl=0: subscribers on this host only. Off unless enabled.
struct LcmPublishSpec {
  bool enabled = false;
  std::string url = "udpm://239.255.76.67:7667?ttl=0";
  bool operator==(const LcmPublishSpec&) const = default;  // a reload tells what changed
};

// Fast DDS: loopback + shared memory by default (this host only); the lab
// network with loopback_only: false.
struct DdsPublishSpec {
  bool enabled = false;
  int domain_id = 0;
  std::string topic_prefix = "tissue/";
  bool loopback_only = true;
  std::size_t max_mesh_bytes = std::size_t{8} << 20;
  bool operator==(const DdsPublishSpec&) const = default;  // a reload tells what changed
};

struct PublishSpec {
  LcmPublishSpec lcm;
  DdsPublishSpec dds;
  double mesh_rate_hz = 30.0;                           // surface_mesh on channel TISSUE_SURFACE_MESH
  double haptic_rate_hz = 100.0;                        // haptic_state (decimated from 1 kHz) on TISSUE_HAPTIC_STATE
  double stats_rate_hz = 5.0;                           // sim_stats on TISSUE_SIM_STATS
  bool operator==(const PublishSpec&) const = default;  // a reload tells what changed
};

// Recording without a client asking: the service records from its start
// (auto-<UTC time>.h5 in state_dir) and starts a new file every rotate_s, so
// a daemon that runs for weeks leaves files of a size a tool can open. The
// oldest automatic files go once they hold more than keep_gb together (the
// shipped scene writes ~1.2 GB an hour), and, whatever keep_gb, when the disk
// is nearly full (Service::make_room_for_automatic_recording); files a client
// named, or started with record_start, are never removed.
struct RecordSpec {
  bool auto_start = false;
  double rotate_s = 3600.0;
  double keep_gb = 50.0;                               // 0: no budget (a nearly full disk still removes)
  bool operator==(const RecordSpec&) const = default;  // a reload tells what changed
};

struct DaemonConfig {
  std::string source;                          // file the config came from (for messages)
  std::string source_text;                     // its YAML text as read (recordings keep it)
  std::string scene_path;                      // resolved against the config file's directory when relative
  std::string state_dir = "/var/lib/tissued";  // recordings and exports go here only
  DeviceSpec device;
  HapticSpec haptics;
  RealtimeSpec realtime;
  ControlSpec control;
  PublishSpec publish;
  RecordSpec record;
  double status_interval_s = 1.0;  // live status line on stdout and STATUS= to systemd
  // Largest starting mesh the service builds (scene::starting_tet_count). A
  // scene is built on the control thread, ~1.3 us per tet: 6e6 tets blocked
  // every client for 7.6 s, past systemd's 5 s watchdog, and could never run
  // in real time anyway.
  int max_scene_tets = 1'000'000;
  bool operator==(const DaemonConfig&) const = default;  // a reload tells what changed
};

}  // namespace tissue::config
