// HapticLoop: one 1 kHz tick of the haptic side, with all its state
// preallocated. tick() reads the device, takes the newest LocalModel, renders
// (god-object proxy + virtual coupling, contact_renderer.hpp), applies
// ForceSafety, writes the force and hands a ToolSample to the sim thread.
//
// Real-time contract of tick(): no allocation, no locks, no I/O, no waiting;
// only atomics (stats, heartbeat) and the wait-free hand-offs. The thread that
// calls tick() is the only one that may call start()/tick(); request_stop(),
// trip_watchdog(), stats() and heartbeat() may be called from any thread.
//
// Model updates: a new version is validated (bad ones are dropped and
// counted), copied into the loop's spare slot, and the force is cross-faded:
// at the switch the offset between the old model's force and the new one's is
// recorded and decays linearly to zero over HapticSpec::crossfade_s, so a
// model update changes the force per tick by at most offset * dt / crossfade_s
// (plus the user's own motion). Overlapping updates (the sim publishes every
// step) restart the fade from the force actually rendered, so it stays
// continuous. The offset applies only while the active model's render is in
// contact: it is dropped when the hand is free (no contact, no force).
//
// Device input: a sample is rejected (and counted) when it is non-finite,
// farther than workspace_radius_m from the device origin, or implies a speed
// above max_speed_m_per_s (reported velocity or jump since the last good
// sample). The last good sample is held; none for device_timeout_s ramps the
// force out. Safety limits act in the device frame (what the motors feel).
//
// Passivity observer: energy the virtual environment absorbed from the user,
//   E = -sum F_k . (x_{k+1} - x_k)   (device frame, force held over the tick),
// >= 0 for a passive rendering starting at rest (Hannaford & Ryu 2002).
#pragma once

#include <atomic>
#include <cstdint>

#include "concurrency/latest_value.hpp"
#include "concurrency/spsc_ring.hpp"
#include "config/daemon_config.hpp"
#include "haptics/contact_renderer.hpp"
#include "haptics/device.hpp"
#include "haptics/force_safety.hpp"
#include "haptics/frame_transform.hpp"
#include "haptics/local_model.hpp"

namespace tissue::haptics {

inline constexpr std::size_t kToolSampleRingCapacity = 4096;  // ~4 s of ticks; the service shares this type
using ToolSampleRing = concurrency::SpscRing<ToolSample, kToolSampleRingCapacity>;
using LocalModelBuffer = concurrency::LatestValue<LocalModel>;

struct HapticLoopOptions {
  double extrapolation_horizon_s = 0.02;  // also capped at ForceLimits::stale_model_s
};

// A snapshot of the loop's counters (relaxed atomics: each field is exact,
// the set is not one instant).
struct HapticStats {
  std::uint64_t ticks = 0;
  std::uint64_t heartbeat = 0;
  std::uint64_t rejected_inputs = 0;  // sum of the three below
  std::uint64_t rejected_nonfinite = 0;
  std::uint64_t rejected_workspace = 0;
  std::uint64_t rejected_speed = 0;
  std::uint64_t missing_samples = 0;  // Device::read returned false
  std::uint64_t model_updates = 0;
  std::uint64_t rejected_models = 0;
  std::uint64_t safety_trips = 0;  // rising edges of any fault
  std::uint64_t stale_model_trips = 0;
  std::uint64_t device_lost_trips = 0;
  std::uint64_t nonfinite_forces = 0;
  std::uint64_t ring_drops = 0;
  std::uint64_t model_version = 0;
  bool contact = false;
  bool stopped = false;
  double force_N = 0.0;  // |F| last written (device frame)
  double force_scale = 0.0;
  double passivity_energy_J = 0.0;
  double min_passivity_energy_J = 0.0;  // lowest value seen (negative: the rendering gave energy)
};

// The loop's rule for a device sample, one rule for HapticLoop and the
// start-time checks that predict it (sim_loop_wrap_warning): rejected when
// non-finite, farther than limits.workspace_radius_m from the device origin,
// or faster than limits.max_speed_m_per_s by its reported velocity or by its
// distance from last_accepted over since_last_accepted_s (that jump check
// only with a last accepted sample and a positive time since it).
enum class SampleVerdict { kAccepted, kNonFinite, kOutsideWorkspace, kTooFast };
SampleVerdict judge_device_sample(const config::ForceLimits& limits, const DeviceSample& sample,
                                  const DeviceSample* last_accepted, double since_last_accepted_s) noexcept;

class HapticLoop {
 public:
  // The device must already be started; the loop neither starts nor stops
  // it. models and samples are the hand-offs shared with the sim thread.
  HapticLoop(Device& device, const config::DeviceSpec& device_spec, const config::HapticSpec& haptic_spec,
             LocalModelBuffer& models, ToolSampleRing& samples, const HapticLoopOptions& options = {});
  HapticLoop(const HapticLoop&) = delete;
  HapticLoop& operator=(const HapticLoop&) = delete;

  // (Re)starts the timeline at now_ns: force scale 0, ramp-in begins.
  void start(std::int64_t now_ns) noexcept;
  // One tick at now_ns (steady_clock / CLOCK_MONOTONIC ns).
  void tick(std::int64_t now_ns) noexcept;

  // Any thread: ramp the force to zero and report stopped() once it is zero.
  void request_stop() noexcept { stop_requested_.store(true, std::memory_order_relaxed); }
  // Any thread: a watchdog outside the loop saw trouble; latched until cleared.
  void trip_watchdog() noexcept { watchdog_tripped_.store(true, std::memory_order_relaxed); }
  void clear_watchdog() noexcept { watchdog_tripped_.store(false, std::memory_order_relaxed); }
  bool stopped() const noexcept { return stopped_.load(std::memory_order_acquire); }

  HapticStats stats() const noexcept;
  // Advances once per tick: the systemd watchdog is fed only while it moves.
  const std::atomic<std::uint64_t>& heartbeat() const noexcept { return heartbeat_; }
  double period_s() const noexcept { return period_s_; }
  // Tick-thread only: the last sample handed to the sim (for tests/diagnostics).
  const ToolSample& last_sample() const noexcept { return last_sample_; }

 private:
  bool accept_sample(std::int64_t now_ns, const DeviceSample& s) noexcept;

  Device& device_;
  config::ForceLimits limits_;
  config::HapticSpec haptic_spec_;
  LocalModelBuffer& models_;
  ToolSampleRing& samples_;
  FrameTransform frame_;
  RenderParams render_params_;
  double period_s_;

  // Two model slots: the active one and the previous (still read during the switch tick).
  LocalModel model_slot_[2];
  ContactRenderer renderer_[2];
  int active_ = 0;
  bool have_model_ = false;
  Vec3 fade_offset_N_ = Vec3::Zero();  // scene frame; decays to 0 over crossfade_s
  std::int64_t fade_start_ns_ = 0;

  ForceSafety safety_;
  bool started_ = false;
  std::int64_t last_tick_ns_ = 0;
  bool have_sample_ = false;
  std::int64_t last_sample_ns_ = 0;
  DeviceSample sample_;  // last accepted, device frame
  Vec3 energy_position_m_ = Vec3::Zero();
  bool have_energy_position_ = false;
  Vec3 last_force_device_N_ = Vec3::Zero();
  ToolSample last_sample_;
  double energy_J_ = 0.0;
  double min_energy_J_ = 0.0;

  std::atomic<bool> stop_requested_{false};
  std::atomic<bool> watchdog_tripped_{false};
  std::atomic<bool> stopped_{false};
  std::atomic<std::uint64_t> heartbeat_{0};
  // Counters written by the tick thread only (relaxed load+store, no RMW needed).
  std::atomic<std::uint64_t> ticks_{0}, rejected_nonfinite_{0}, rejected_workspace_{0}, rejected_speed_{0},
      missing_samples_{0}, model_updates_{0}, rejected_models_{0}, safety_trips_{0}, stale_trips_{0},
      device_lost_trips_{0}, nonfinite_forces_{0}, model_version_{0};
  std::atomic<bool> contact_{false};
  std::atomic<double> force_N_{0.0}, force_scale_{0.0}, energy_atomic_J_{0.0}, min_energy_atomic_J_{0.0};
};

}  // namespace tissue::haptics
