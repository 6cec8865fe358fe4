#include "config/daemon_config_yaml.hpp"

#include <sys/un.h>

#include <boost/asio/ip/address.hpp>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string_view>
#include <utility>

#include "config/daemon_config_keys.hpp"
#include "scene/yaml_util.hpp"
#include "util/lcm_url.hpp"

namespace tissue::config {

namespace {

using yaml_util::Choices;
using yaml_util::FieldMap;
using yaml_util::fmt_num;
using yaml_util::join_index;
using yaml_util::join_key;
using yaml_util::printable;

// A hand-written settings file is a few kilobytes; anything near this is not one.
constexpr std::uintmax_t kMaxConfigFileBytes = 1u << 20;
// Limits on the control socket settings: a line must hold a small request,
// and neither bound may let one client pin a large share of the daemon's memory.
constexpr std::size_t kMinLineBytes = 256;
constexpr std::size_t kMaxLineBytes = 64u << 20;
constexpr int kMaxConnections = 1024;
// control.stalled_after_s: the server counts it in whole milliseconds (below
// one it would be 0: every request in progress evictable at once) and adds
// twice it to steady_clock time points in int64 nanoseconds: 1e300 s does not
// convert to an integer at all, and past about 4e9 s the sum overflows. An
// hour is far inside that, and past it a silent client would keep its place
// for good anyway.
constexpr double kMinStalledAfter_s = 0.001;
constexpr double kMaxStalledAfter_s = 3600.0;
// The haptic loop is 1 kHz; faster than this no device or scheduler keeps up.
constexpr double kMaxHapticRateHz = 10000.0;
constexpr double kMinHapticRateHz = 1.0;
constexpr double kMaxRamp_s = 10.0;
// A ramp-out is waited for on the io thread, which also feeds systemd's
// watchdog (WatchdogSec 5 s in the shipped unit, fed every 2.5 s): a longer
// wait would get the daemon killed by its own safety fade.
constexpr double kMaxRampOut_s = 1.0;
constexpr double kMaxTimeout_s = 60.0;
constexpr double kMaxCrossfade_s = 1.0;
// status_interval_s: each period writes a line to stdout (the journal) and
// STATUS= to systemd; 1e-9 s wrote 108,120 lines in 3 s. Ten a second is
// more than a person reads.
constexpr double kMinStatusInterval_s = 0.1;
constexpr double kMaxStatusInterval_s = 3600.0;
// record.rotate_s: a week at most (files of a few GB at 1 kHz haptic rows).
constexpr double kMinRotate_s = 1.0;
constexpr double kMaxRotate_s = 7 * 24 * 3600.0;
// A replayed device track faster than this is no longer a hand.
constexpr double kMaxReplaySpeed = 100.0;
// Linux SCHED_FIFO priorities.
constexpr int kMinRtPriority = 1;
constexpr int kMaxRtPriority = 99;
// CPU_SETSIZE: sched_setaffinity cannot name a CPU beyond it.
constexpr int kMaxCpuIndex = 1023;

constexpr const auto& kTopLevelKeys = kDaemonTopLevelKeys;

const yaml_util::DocumentKind kConfigDocument{
    "daemon config", "a daemon config needs at least a 'scene' key (see docs/daemon-config.md)"};

constexpr std::array<std::pair<std::string_view, DeviceSpec::Kind>, 5> kDeviceKinds{
    {{"none", DeviceSpec::Kind::kNone},
     {"sim", DeviceSpec::Kind::kSim},
     {"udp", DeviceSpec::Kind::kUdp},
     {"openhaptics", DeviceSpec::Kind::kOpenHaptics},
     {"replay", DeviceSpec::Kind::kReplay}}};
constexpr std::array<std::pair<std::string_view, SimDeviceSpec::Mode>, 2> kSimModes{
    {{"trajectory", SimDeviceSpec::Mode::kTrajectory}, {"hand", SimDeviceSpec::Mode::kHand}}};

// ------------------------------------------------------------ YAML -> config

class Converter : public yaml_util::Reader {
 public:
  explicit Converter(const std::string& source) : Reader(source) {}

  DaemonConfig config(const YAML::Node& root) {
    if (!root.IsMap()) fail("", "a daemon config must be a map of sections, got " + yaml_util::describe_kind(root));
    const FieldMap f = fields(root, "", kTopLevelKeys);
    DaemonConfig c;
    c.source = source_;
    read(require(f, "scene", ""), "scene", c.scene_path);
    opt(f, "state_dir", "", c.state_dir);
    opt(f, "status_interval_s", "", c.status_interval_s);
    opt(f, "max_scene_tets", "", c.max_scene_tets);
    if (const auto it = f.find("device"); it != f.end()) device(it->second, "device", c.device);
    if (const auto it = f.find("haptics"); it != f.end()) haptics(it->second, "haptics", c.haptics);
    if (const auto it = f.find("realtime"); it != f.end()) realtime(it->second, "realtime", c.realtime);
    if (const auto it = f.find("control"); it != f.end()) control(it->second, "control", c.control);
    if (const auto it = f.find("publish"); it != f.end()) publish(it->second, "publish", c.publish);
    if (const auto it = f.find("record"); it != f.end()) {
      const FieldMap g = fields(it->second, "record", {"auto_start", "rotate_s", "keep_gb"});
      opt(g, "auto_start", "record", c.record.auto_start);
      opt(g, "rotate_s", "record", c.record.rotate_s);
      opt(g, "keep_gb", "record", c.record.keep_gb);
    }
    return c;
  }

 private:
  void device(const YAML::Node& n, const std::string& p, DeviceSpec& d) const {
    const FieldMap f = fields(n, p, {"kind", "limits", "offset_m", "scale", "sim", "udp", "openhaptics", "replay"});
    opt_choice<DeviceSpec::Kind>(f, "kind", p, kDeviceKinds, d.kind);
    if (const auto it = f.find("limits"); it != f.end()) limits(it->second, join_key(p, "limits"), d.limits);
    opt(f, "offset_m", p, d.offset_m);
    opt(f, "scale", p, d.scale);
    if (const auto it = f.find("sim"); it != f.end()) sim(it->second, join_key(p, "sim"), d.sim);
    if (const auto it = f.find("udp"); it != f.end()) {
      const std::string up = join_key(p, "udp");
      const FieldMap g = fields(it->second, up, {"bind_address", "port", "timeout_s"});
      opt(g, "bind_address", up, d.udp.bind_address);
      opt(g, "port", up, d.udp.port);
      opt(g, "timeout_s", up, d.udp.timeout_s);
    }
    if (const auto it = f.find("openhaptics"); it != f.end()) {
      const std::string op = join_key(p, "openhaptics");
      const FieldMap g = fields(it->second, op, {"library", "device_name"});
      opt(g, "library", op, d.openhaptics.library);
      opt(g, "device_name", op, d.openhaptics.device_name);
    }
    if (const auto it = f.find("replay"); it != f.end()) {
      const std::string rp = join_key(p, "replay");
      const FieldMap g = fields(it->second, rp, {"session", "speed", "loop"});
      opt(g, "session", rp, d.replay.session);
      opt(g, "speed", rp, d.replay.speed);
      opt(g, "loop", rp, d.replay.loop);
    }
  }

  void limits(const YAML::Node& n, const std::string& p, ForceLimits& l) const {
    const FieldMap f =
        fields(n, p,
               {"max_force_N", "max_force_rate_N_per_s", "max_stiffness_N_per_m", "ramp_in_s", "ramp_out_s",
                "stale_model_s", "device_timeout_s", "max_speed_m_per_s", "workspace_radius_m"});
    opt(f, "max_force_N", p, l.max_force_N);
    opt(f, "max_force_rate_N_per_s", p, l.max_force_rate_N_per_s);
    opt(f, "max_stiffness_N_per_m", p, l.max_stiffness_N_per_m);
    opt(f, "ramp_in_s", p, l.ramp_in_s);
    opt(f, "ramp_out_s", p, l.ramp_out_s);
    opt(f, "stale_model_s", p, l.stale_model_s);
    opt(f, "device_timeout_s", p, l.device_timeout_s);
    opt(f, "max_speed_m_per_s", p, l.max_speed_m_per_s);
    opt(f, "workspace_radius_m", p, l.workspace_radius_m);
  }

  void sim(const YAML::Node& n, const std::string& p, SimDeviceSpec& s) const {
    const FieldMap f =
        fields(n, p, {"mode", "waypoints", "loop", "hand_mass_kg", "hand_stiffness_N_per_m", "hand_damping_N_s_per_m"});
    opt_choice<SimDeviceSpec::Mode>(f, "mode", p, kSimModes, s.mode);
    if (const auto it = f.find("waypoints"); it != f.end()) {
      s.waypoints.clear();
      for_each(it->second, join_key(p, "waypoints"), [&](const YAML::Node& w, const std::string& wp) {
        const FieldMap g = fields(w, wp, {"time_s", "position_m"});
        Waypoint point;
        read(require(g, "time_s", wp), join_key(wp, "time_s"), point.time_s);
        read(require(g, "position_m", wp), join_key(wp, "position_m"), point.position_m);
        s.waypoints.push_back(point);
      });
    }
    opt(f, "loop", p, s.loop);
    opt(f, "hand_mass_kg", p, s.hand_mass_kg);
    opt(f, "hand_stiffness_N_per_m", p, s.hand_stiffness_N_per_m);
    opt(f, "hand_damping_N_s_per_m", p, s.hand_damping_N_s_per_m);
  }

  void haptics(const YAML::Node& n, const std::string& p, HapticSpec& h) const {
    const FieldMap f =
        fields(n, p, {"rate_hz", "coupling_stiffness_N_per_m", "coupling_damping_N_s_per_m", "crossfade_s"});
    opt(f, "rate_hz", p, h.rate_hz);
    opt(f, "coupling_stiffness_N_per_m", p, h.coupling_stiffness_N_per_m);
    opt(f, "coupling_damping_N_s_per_m", p, h.coupling_damping_N_s_per_m);
    opt(f, "crossfade_s", p, h.crossfade_s);
  }

  void realtime(const YAML::Node& n, const std::string& p, RealtimeSpec& r) const {
    const FieldMap f = fields(n, p, {"sched_fifo", "haptic_priority", "sim_priority", "lock_memory", "haptic_cpu"});
    opt(f, "sched_fifo", p, r.sched_fifo);
    opt(f, "haptic_priority", p, r.haptic_priority);
    opt(f, "sim_priority", p, r.sim_priority);
    opt(f, "lock_memory", p, r.lock_memory);
    opt(f, "haptic_cpu", p, r.haptic_cpu);
  }

  void publish(const YAML::Node& n, const std::string& p, PublishSpec& s) const {
    const FieldMap f = fields(n, p, {"lcm", "dds", "mesh_rate_hz", "haptic_rate_hz", "stats_rate_hz"});
    if (const auto it = f.find("dds"); it != f.end()) {
      const std::string dp = join_key(p, "dds");
      const FieldMap g =
          fields(it->second, dp, {"enabled", "domain_id", "topic_prefix", "loopback_only", "max_mesh_bytes"});
      opt(g, "enabled", dp, s.dds.enabled);
      opt(g, "domain_id", dp, s.dds.domain_id);
      opt(g, "topic_prefix", dp, s.dds.topic_prefix);
      opt(g, "loopback_only", dp, s.dds.loopback_only);
      opt(g, "max_mesh_bytes", dp, s.dds.max_mesh_bytes);
    }
    if (const auto it = f.find("lcm"); it != f.end()) {
      const std::string lp = join_key(p, "lcm");
      const FieldMap g = fields(it->second, lp, {"enabled", "url"});
      opt(g, "enabled", lp, s.lcm.enabled);
      opt(g, "url", lp, s.lcm.url);
    }
    opt(f, "mesh_rate_hz", p, s.mesh_rate_hz);
    opt(f, "haptic_rate_hz", p, s.haptic_rate_hz);
    opt(f, "stats_rate_hz", p, s.stats_rate_hz);
  }

  void control(const YAML::Node& n, const std::string& p, ControlSpec& c) const {
    const FieldMap f =
        fields(n, p, {"unix_socket_path", "tcp_port", "max_line_bytes", "max_connections", "stalled_after_s"});
    if (const auto it = f.find("unix_socket_path"); it != f.end()) {
      // `unix_socket_path: ~` (null) or "" both switch the Unix socket off.
      if (it->second.IsNull())
        c.unix_socket_path.clear();
      else
        read(it->second, join_key(p, "unix_socket_path"), c.unix_socket_path);
    }
    opt(f, "tcp_port", p, c.tcp_port);
    opt(f, "max_line_bytes", p, c.max_line_bytes);
    opt(f, "max_connections", p, c.max_connections);
    opt(f, "stalled_after_s", p, c.stalled_after_s);
  }
};

// ------------------------------------------------------------- validation

class Validator : private yaml_util::ValueChecks<Validator> {
  friend class yaml_util::ValueChecks<Validator>;

 public:
  explicit Validator(const DaemonConfig& c) : c_(c) {}

  void run() const {
    if (c_.scene_path.empty()) fail("scene", "must not be empty (the scene file to load)");
    if (c_.state_dir.empty()) fail("state_dir", "must not be empty (recordings and exports go there)");
    positive(c_.status_interval_s, "status_interval_s");
    at_least(c_.status_interval_s, kMinStatusInterval_s, "status_interval_s",
             "each period writes a status line to stdout (the journal) and to systemd, and ten a second is more than "
             "anyone reads");
    at_most(c_.status_interval_s, kMaxStatusInterval_s, "status_interval_s", "the status timer must fit its clock");
    if (c_.max_scene_tets < 1) fail("max_scene_tets", "must be >= 1 (got " + std::to_string(c_.max_scene_tets) + ")");

    const DeviceSpec& d = c_.device;
    const int kind = static_cast<int>(d.kind);
    if (kind < 0 || kind >= static_cast<int>(kDeviceKinds.size()))
      fail("device.kind", "invalid device kind " + std::to_string(kind));
    finite(d.offset_m, "device.offset_m");
    positive(d.scale, "device.scale");
    // Every section is checked whatever the kind, so a typo in an unused
    // section does not wait for the day someone switches to it. Only "has
    // waypoints" and "names a session" depend on the kind.
    limits(d.limits, "device.limits");
    sim(d.sim, "device.sim", d.kind == DeviceSpec::Kind::kSim, d.limits.workspace_radius_m);
    udp(d.udp, "device.udp");
    // The bridge drops a sender silent for udp.timeout_s; shorter than the
    // loop's device_timeout_s, a slow device's every pose started a new
    // session (no sequence order, any address could take over) while the
    // loop still rendered and sent forces to it.
    if (d.kind == DeviceSpec::Kind::kUdp && d.udp.timeout_s < d.limits.device_timeout_s)
      fail("device.udp.timeout_s", "must be >= device.limits.device_timeout_s (" + fmt_num(d.limits.device_timeout_s) +
                                       "): the bridge would drop the sender while the haptic loop still takes it as "
                                       "present; raise both for a slow device (got " +
                                       fmt_num(d.udp.timeout_s) + ")");
    if (!(d.replay.speed > 0.0 && d.replay.speed <= kMaxReplaySpeed))
      fail("device.replay.speed",
           "must be in (0, " + fmt_num(kMaxReplaySpeed) + "] (got " + fmt_num(d.replay.speed) + ")");
    if (d.kind == DeviceSpec::Kind::kReplay && d.replay.session.empty())
      fail("device.replay.session", "a replay device needs the session file to play back");
    if (d.openhaptics.library.empty()) fail("device.openhaptics.library", "must not be empty");
    if (d.openhaptics.device_name.empty()) fail("device.openhaptics.device_name", "must not be empty");

    const HapticSpec& h = c_.haptics;
    positive(h.rate_hz, "haptics.rate_hz");
    // The tick period is kept in int64 nanoseconds; 1e-300 Hz overflowed it.
    at_least(h.rate_hz, kMinHapticRateHz, "haptics.rate_hz", "the loop's period must fit its clock");
    if (h.rate_hz > kMaxHapticRateHz)
      fail("haptics.rate_hz", "must be <= " + fmt_num(kMaxHapticRateHz) + " Hz (got " + fmt_num(h.rate_hz) + ")");
    positive(h.coupling_stiffness_N_per_m, "haptics.coupling_stiffness_N_per_m");
    non_negative(h.coupling_damping_N_s_per_m, "haptics.coupling_damping_N_s_per_m");
    non_negative(h.crossfade_s, "haptics.crossfade_s");
    // Every model the sim publishes (one a step) restarts the fade from the
    // force rendered, so the force follows the sim about crossfade_s late:
    // 10 s rendered models seconds old.
    at_most(h.crossfade_s, kMaxCrossfade_s, "haptics.crossfade_s",
            "the hand would feel the sim's force that late (every new model restarts the fade)");
    // The safety clamp would silently cut a stiffer coupling: say so instead.
    // The limit is on what the hand feels: positions map in and forces map
    // out times device.scale, so the device sees the coupling times scale².
    const double scale2 = d.scale * d.scale;
    if (d.kind != DeviceSpec::Kind::kNone && h.coupling_stiffness_N_per_m * scale2 > d.limits.max_stiffness_N_per_m) {
      const std::string per_scale = scale2 == 1.0 ? ""
                                                  : " / device.scale^2 (" + fmt_num(scale2) +
                                                        ") = " + fmt_num(d.limits.max_stiffness_N_per_m / scale2) +
                                                        ", as the hand feels the coupling times scale^2";
      fail("haptics.coupling_stiffness_N_per_m", "must be <= device.limits.max_stiffness_N_per_m (" +
                                                     fmt_num(d.limits.max_stiffness_N_per_m) + ")" + per_scale +
                                                     " (got " + fmt_num(h.coupling_stiffness_N_per_m) + ")");
    }

    const RealtimeSpec& r = c_.realtime;
    priority(r.haptic_priority, "realtime.haptic_priority");
    priority(r.sim_priority, "realtime.sim_priority");
    if (r.haptic_cpu < -1 || r.haptic_cpu > kMaxCpuIndex)
      fail("realtime.haptic_cpu", "must be -1 (no pinning) or a CPU index 0.." + std::to_string(kMaxCpuIndex) +
                                      " (got " + std::to_string(r.haptic_cpu) + ")");

    const ControlSpec& k = c_.control;
    // sockaddr_un::sun_path holds the path and its terminating NUL.
    constexpr std::size_t kMaxSocketPath = sizeof(sockaddr_un{}.sun_path) - 1;
    if (k.unix_socket_path.size() > kMaxSocketPath)
      fail("control.unix_socket_path", "too long for a Unix socket (" + std::to_string(k.unix_socket_path.size()) +
                                           " bytes, at most " + std::to_string(kMaxSocketPath) + ")");
    if (k.unix_socket_path.find('\0') != std::string::npos)
      fail("control.unix_socket_path", "must not contain a NUL byte");
    port(k.tcp_port, 0, "control.tcp_port", " (0 switches TCP off)");
    if (k.max_line_bytes < kMinLineBytes || k.max_line_bytes > kMaxLineBytes)
      fail("control.max_line_bytes", "must be in [" + std::to_string(kMinLineBytes) + ", " +
                                         std::to_string(kMaxLineBytes) + "] (got " + std::to_string(k.max_line_bytes) +
                                         ")");
    if (k.max_connections < 1 || k.max_connections > kMaxConnections)
      fail("control.max_connections",
           "must be in [1, " + std::to_string(kMaxConnections) + "] (got " + std::to_string(k.max_connections) + ")");
    positive(k.stalled_after_s, "control.stalled_after_s");
    at_least(k.stalled_after_s, kMinStalledAfter_s, "control.stalled_after_s",
             "the server counts it in whole milliseconds");
    at_most(k.stalled_after_s, kMaxStalledAfter_s, "control.stalled_after_s",
            "twice it must fit the server's clock, and a silent client would keep its place for good anyway");

    positive(c_.record.rotate_s, "record.rotate_s");
    at_least(c_.record.rotate_s, kMinRotate_s, "record.rotate_s", "a file every few seconds is not a session");
    at_most(c_.record.rotate_s, kMaxRotate_s, "record.rotate_s", "the rotation timer must fit its clock");
    non_negative(c_.record.keep_gb, "record.keep_gb");
    at_most(c_.record.keep_gb, 1e9, "record.keep_gb",
            "an exabyte; 0 sets no size budget (a nearly full disk still removes the oldest automatic files)");

    const PublishSpec& pub = c_.publish;
    for (const auto& [rate, key] :
         {std::pair{pub.mesh_rate_hz, "publish.mesh_rate_hz"}, std::pair{pub.haptic_rate_hz, "publish.haptic_rate_hz"},
          std::pair{pub.stats_rate_hz, "publish.stats_rate_hz"}})
      // At least 0.01 Hz: the timer's period (1 / rate) must fit its clock.
      if (!(rate >= 0.01 && rate <= 1000.0)) fail(key, "must be in [0.01, 1000] Hz (got " + fmt_num(rate) + ")");
    if (pub.dds.domain_id < 0 || pub.dds.domain_id > 232)
      fail("publish.dds.domain_id",
           "must be a DDS domain id in [0, 232] (got " + std::to_string(pub.dds.domain_id) + ")");
    if (pub.dds.max_mesh_bytes < (std::size_t{64} << 10) || pub.dds.max_mesh_bytes > (std::size_t{1} << 30))
      fail("publish.dds.max_mesh_bytes",
           "must be in [64 KiB, 1 GiB] (got " + std::to_string(pub.dds.max_mesh_bytes) + ")");
    // No file:// log: LCM opens one for reading unless ?mode=w (every publish
    // then fails silently), and with it truncates the file named (a session
    // in state_dir) and writes past the recorder's free-space reserve.
    if (pub.lcm.url.rfind("file://", 0) == 0)
      fail("publish.lcm.url",
           "file:// logs are not written by the daemon: record a session instead (record_start, "
           "record.auto_start), which keeps the meshes, haptic ticks and statistics (got '" +
               pub.lcm.url + "')");
    if (pub.lcm.url.rfind("udpm://", 0) != 0 && pub.lcm.url.rfind("memq://", 0) != 0)
      fail("publish.lcm.url",
           "must be an LCM provider URL: udpm://GROUP:PORT?ttl=N or memq:// (got '" + pub.lcm.url + "')");
    if (const std::string why = util::udpm_url_problem(pub.lcm.url); !why.empty())
      fail("publish.lcm.url", why + " (got '" + pub.lcm.url + "')");
  }

 private:
  [[noreturn]] void fail(const std::string& path, const std::string& reason) const {
    throw ConfigError(c_.source, path, reason);
  }

  void priority(int v, const std::string& path) const {
    if (v < kMinRtPriority || v > kMaxRtPriority)
      fail(path, "must be a SCHED_FIFO priority in [" + std::to_string(kMinRtPriority) + ", " +
                     std::to_string(kMaxRtPriority) + "] (got " + std::to_string(v) + ")");
  }
  void port(int v, int min, const std::string& path, const std::string& note) const {
    if (v < min || v > 65535)
      fail(path, "port out of range: must be in [" + std::to_string(min) + ", 65535]" + note + " (got " +
                     std::to_string(v) + ")");
  }

  void limits(const ForceLimits& l, const std::string& p) const {
    positive(l.max_force_N, p + ".max_force_N");
    positive(l.max_force_rate_N_per_s, p + ".max_force_rate_N_per_s");
    positive(l.max_stiffness_N_per_m, p + ".max_stiffness_N_per_m");
    non_negative(l.ramp_in_s, p + ".ramp_in_s");
    non_negative(l.ramp_out_s, p + ".ramp_out_s");
    // A stop waits for the ramp out: 1e308 s made the daemon unstoppable.
    at_most(l.ramp_in_s, kMaxRamp_s, p + ".ramp_in_s", "a ramp longer than that is not a ramp");
    at_most(l.ramp_out_s, kMaxRampOut_s, p + ".ramp_out_s",
            "a stop waits for it on the thread that feeds the watchdog");
    // A stop also waits for the rate limit to bring the force to exactly 0:
    // up to max_force_N / max_force_rate_N_per_s. At 0.5 N/s a 3 N hold took
    // 6 s, past the watchdog, whatever ramp_out_s said.
    if (l.max_force_N / l.max_force_rate_N_per_s > kMaxRampOut_s)
      fail(p + ".max_force_rate_N_per_s",
           "must be >= max_force_N / " + fmt_num(kMaxRampOut_s) + " s (" + fmt_num(l.max_force_N / kMaxRampOut_s) +
               " N/s): a stop waits for the force to reach 0 on the thread that feeds the watchdog (got " +
               fmt_num(l.max_force_rate_N_per_s) + ")");
    positive(l.stale_model_s, p + ".stale_model_s");
    positive(l.device_timeout_s, p + ".device_timeout_s");
    at_most(l.stale_model_s, kMaxTimeout_s, p + ".stale_model_s", "a hand would feel a frozen model that long");
    at_most(l.device_timeout_s, kMaxTimeout_s, p + ".device_timeout_s", "a lost device would keep its force that long");
    positive(l.max_speed_m_per_s, p + ".max_speed_m_per_s");
    positive(l.workspace_radius_m, p + ".workspace_radius_m");
  }

  void sim(const SimDeviceSpec& s, const std::string& p, bool in_use, double workspace_radius_m) const {
    const int mode = static_cast<int>(s.mode);
    if (mode < 0 || mode >= static_cast<int>(kSimModes.size()))
      fail(p + ".mode", "invalid mode " + std::to_string(mode));
    const std::string wl = p + ".waypoints";
    if (in_use && s.waypoints.empty())
      fail(wl,
           "a simulated device (device.kind: sim, the default) needs at least one waypoint; "
           "device.kind: none serves without a device");
    for (std::size_t i = 0; i < s.waypoints.size(); ++i) {
      const Waypoint& w = s.waypoints[i];
      const std::string wp = join_index(wl, i);
      finite(w.time_s, wp + ".time_s");
      if (w.time_s < 0.0) fail(wp + ".time_s", "must be >= 0 (got " + fmt_num(w.time_s) + ")");
      if (i > 0 && !(w.time_s > s.waypoints[i - 1].time_s))
        fail(wp + ".time_s", "waypoint times must increase: must be > " + join_index(wl, i - 1) + ".time_s (" +
                                 fmt_num(s.waypoints[i - 1].time_s) + ") (got " + fmt_num(w.time_s) + ")");
      finite(w.position_m, wp + ".position_m");
      // The waypoints are the device's own samples (device frame: the haptic
      // loop maps them with offset_m and scale), and the loop rejects every
      // sample beyond the workspace: the hand would never reach the scene
      // ("inputs rejected: 2968 outside the workspace"). Between two waypoints
      // inside the ball the path stays inside it.
      const double distance_m = std::hypot(w.position_m[0], w.position_m[1], w.position_m[2]);
      if (in_use && distance_m > workspace_radius_m)
        fail(wp + ".position_m", "is " + fmt_num(distance_m) +
                                     " m from the device origin, farther than device.limits.workspace_radius_m (" +
                                     fmt_num(workspace_radius_m) +
                                     " m): the haptic loop would reject those samples (waypoints are in the device "
                                     "frame, before offset_m and scale)");
    }
    if (in_use && s.loop && !(s.waypoints.back().time_s > s.waypoints.front().time_s))
      fail(p + ".loop", "looping needs a timeline of positive length (at least 2 waypoints)");
    positive(s.hand_mass_kg, p + ".hand_mass_kg");
    positive(s.hand_stiffness_N_per_m, p + ".hand_stiffness_N_per_m");
    non_negative(s.hand_damping_N_s_per_m, p + ".hand_damping_N_s_per_m");
    if (in_use && s.mode == SimDeviceSpec::Mode::kHand &&
        !(s.hand_stability_index() <= SimDeviceSpec::kMaxHandStabilityIndex))
      fail(p + ".hand_mass_kg", "too light for hand_stiffness_N_per_m " + fmt_num(s.hand_stiffness_N_per_m) +
                                    " and hand_damping_N_s_per_m " + fmt_num(s.hand_damping_N_s_per_m) +
                                    ": the hand's 0.5 ms integration sub-steps need h²k/m + 2hc/m <= " +
                                    fmt_num(SimDeviceSpec::kMaxHandStabilityIndex) + " (here " +
                                    fmt_num(s.hand_stability_index()) + "; unstable from 4), so a mass of at least " +
                                    fmt_num(s.min_hand_mass_kg()) + " kg, or less stiffness and damping (got " +
                                    fmt_num(s.hand_mass_kg) + ")");
  }

  void udp(const UdpDeviceSpec& u, const std::string& p) const {
    boost::system::error_code ec;
    boost::asio::ip::make_address(u.bind_address, ec);
    if (ec) fail(p + ".bind_address", "not an IP address: " + printable(u.bind_address));
    port(u.port, 1, p + ".port", "");
    positive(u.timeout_s, p + ".timeout_s");
    // The device keeps it in int64 nanoseconds: 1e10 s was out of range.
    at_most(u.timeout_s, kMaxTimeout_s, p + ".timeout_s", "a lost sender would hold its session that long");
  }

  const DaemonConfig& c_;
};

// Relative paths in a config file mean "next to this file", so a config and
// its scenes can move together (/etc/tissued/, or config/ in the source tree).
std::string resolve(const std::string& path, const std::string& source) {
  namespace fs = std::filesystem;
  const fs::path p(path);
  if (path.empty() || p.is_absolute()) return path;
  const fs::path dir = fs::path(source).parent_path();
  if (dir.empty()) return p.lexically_normal().string();
  return (dir / p).lexically_normal().string();
}

DaemonConfig build(const std::string& text, const std::string& source, const std::vector<std::string>& overrides) {
  return yaml_util::convert_document<ConfigError>(
      text, source, overrides, kConfigDocument, [&](const YAML::Node& root) {
        DaemonConfig c = Converter(source).config(root);
        c.source_text = text;
        c.scene_path = resolve(c.scene_path, source);
        c.state_dir = resolve(c.state_dir, source);
        if (!c.device.replay.session.empty()) c.device.replay.session = resolve(c.device.replay.session, source);
        validate_daemon_config(c);
        return c;
      });
}

}  // namespace

void validate_daemon_config(const DaemonConfig& c) { Validator(c).run(); }

DaemonConfig parse_daemon_config(const std::string& yaml_text, const std::string& source,
                                 const std::vector<std::string>& overrides) {
  return build(yaml_text, source, overrides);
}

DaemonConfig load_daemon_config(const std::string& path, const std::vector<std::string>& overrides) {
  return build(yaml_util::read_text_file_as<ConfigError>(path, kMaxConfigFileBytes, "daemon config file"), path,
               overrides);
}

bool is_daemon_config_key(std::string_view key_path) {
  // Trimmed as the override parser trims its key ("scene =x.yaml" sets
  // `scene`): untrimmed, the service sent such an override to the scene.
  const std::size_t first = key_path.find_first_not_of(" \t");
  if (first == std::string_view::npos) return false;
  key_path.remove_prefix(first);
  const std::size_t end = key_path.find_first_of(".[ \t");
  const std::string_view head = key_path.substr(0, end);
  for (const std::string_view k : kTopLevelKeys)
    if (head == k) return true;
  return false;
}

}  // namespace tissue::config
