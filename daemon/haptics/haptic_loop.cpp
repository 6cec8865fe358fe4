#include "haptics/haptic_loop.hpp"

#include <algorithm>
#include <cmath>

namespace tissue::haptics {
namespace {

// Counters have one writer (the tick thread): a relaxed load + store is an
// exact increment without a locked read-modify-write on the hot path.
inline void bump(std::atomic<std::uint64_t>& counter) noexcept {
  counter.store(counter.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
}

RenderParams render_params_for(const config::DeviceSpec& device, const config::HapticSpec& haptic,
                               const HapticLoopOptions& options) {
  RenderParams p;
  // The limit is on the device: positions map in and forces map out times
  // scale, so a scene-frame stiffness k reaches the hand as scale² k. Clamped
  // in the scene frame alone, scale 2 let the hand feel 1600 N/m of a 1000
  // N/m limit.
  const double scale = std::isfinite(device.scale) && device.scale > 0.0 ? device.scale : 1.0;
  const double max_stiffness_N_per_m = std::max(0.0, device.limits.max_stiffness_N_per_m) / (scale * scale);
  // The coupling spring is the stiffest thing the user can feel: clamp it to the device.
  p.coupling_stiffness_N_per_m = std::clamp(haptic.coupling_stiffness_N_per_m, 0.0, max_stiffness_N_per_m);
  p.coupling_damping_N_s_per_m = std::max(0.0, haptic.coupling_damping_N_s_per_m);
  p.max_stiffness_N_per_m = max_stiffness_N_per_m;
  p.extrapolation_horizon_s =
      std::clamp(options.extrapolation_horizon_s, 0.0, std::max(0.0, device.limits.stale_model_s));
  return p;
}

}  // namespace

namespace {

// Copies what a validated model uses: the header, the contact linearisation
// and the first vertex_count / triangle_count entries. A patch rarely fills
// the fixed capacity, and the whole struct is several kilobytes: copying it
// every tick would be most of the switch's cost.
void copy_used_part(const LocalModel& from, LocalModel* to) noexcept {
  to->version = from.version;
  to->sim_time_s = from.sim_time_s;
  to->built_ns = from.built_ns;
  to->vertex_count = from.vertex_count;
  to->triangle_count = from.triangle_count;
  std::copy_n(from.vertex_m.begin(), from.vertex_count, to->vertex_m.begin());
  std::copy_n(from.vertex_velocity_m_per_s.begin(), from.vertex_count, to->vertex_velocity_m_per_s.begin());
  std::copy_n(from.vertex_node.begin(), from.vertex_count, to->vertex_node.begin());
  std::copy_n(from.triangle.begin(), from.triangle_count, to->triangle.begin());
  to->in_contact = from.in_contact;
  to->position_ref_m = from.position_ref_m;
  to->force_ref_N = from.force_ref_N;
  to->contact_stiffness_N_per_m = from.contact_stiffness_N_per_m;
}

}  // namespace

HapticLoop::HapticLoop(Device& device, const config::DeviceSpec& device_spec, const config::HapticSpec& haptic_spec,
                       LocalModelBuffer& models, ToolSampleRing& samples, const HapticLoopOptions& options)
    : device_(device),
      limits_(device_spec.limits),
      haptic_spec_(haptic_spec),
      models_(models),
      samples_(samples),
      frame_(FrameTransform::from(device_spec.offset_m, device_spec.scale)),
      render_params_(render_params_for(device_spec, haptic_spec, options)),
      period_s_(haptic_spec.rate_hz > 0.0 ? 1.0 / haptic_spec.rate_hz : 1e-3),
      renderer_{ContactRenderer(render_params_), ContactRenderer(render_params_)},
      safety_(device_spec.limits) {
  if (!(std::isfinite(frame_.scale) && frame_.scale > 0.0)) frame_.scale = 1.0;  // the loader rejects this; stay finite
}

void HapticLoop::start(std::int64_t now_ns) noexcept {
  started_ = true;
  last_tick_ns_ = now_ns - static_cast<std::int64_t>(period_s_ * 1e9);
  safety_.reset();
  renderer_[0].reset();
  renderer_[1].reset();
  have_sample_ = false;
  have_energy_position_ = false;
  last_force_device_N_.setZero();
  fade_offset_N_.setZero();
  stopped_.store(false, std::memory_order_release);
}

SampleVerdict judge_device_sample(const config::ForceLimits& limits, const DeviceSample& sample,
                                  const DeviceSample* last_accepted, double since_last_accepted_s) noexcept {
  if (!sample.position_m.allFinite() || !sample.velocity_m_per_s.allFinite()) return SampleVerdict::kNonFinite;
  if (sample.position_m.norm() > limits.workspace_radius_m) return SampleVerdict::kOutsideWorkspace;
  if (sample.velocity_m_per_s.norm() > limits.max_speed_m_per_s) return SampleVerdict::kTooFast;
  // A position jump is a glitch even when the reported velocity looks sane.
  if (last_accepted && since_last_accepted_s > 0.0 &&
      (sample.position_m - last_accepted->position_m).norm() > limits.max_speed_m_per_s * since_last_accepted_s)
    return SampleVerdict::kTooFast;
  return SampleVerdict::kAccepted;
}

bool HapticLoop::accept_sample(std::int64_t now_ns, const DeviceSample& s) noexcept {
  const double since_s =
      have_sample_ && now_ns > last_sample_ns_ ? 1e-9 * static_cast<double>(now_ns - last_sample_ns_) : 0.0;
  switch (judge_device_sample(limits_, s, have_sample_ ? &sample_ : nullptr, since_s)) {
    case SampleVerdict::kAccepted:
      return true;
    case SampleVerdict::kNonFinite:
      bump(rejected_nonfinite_);
      return false;
    case SampleVerdict::kOutsideWorkspace:
      bump(rejected_workspace_);
      return false;
    case SampleVerdict::kTooFast:
      bump(rejected_speed_);
      return false;
  }
  return false;
}

void HapticLoop::tick(std::int64_t now_ns) noexcept {
  if (!started_) start(now_ns);
  heartbeat_.store(heartbeat_.load(std::memory_order_relaxed) + 1, std::memory_order_release);
  bump(ticks_);
  // A stalled tick must not widen the rate limit beyond a few periods.
  const double dt_s = std::min(1e-9 * static_cast<double>(now_ns - last_tick_ns_), 4.0 * period_s_);
  last_tick_ns_ = now_ns;

  // 1. Device input.
  DeviceSample raw;
  bool device_fresh = false;  // a new sample accepted this tick: the session records it
  if (device_.read(now_ns, &raw)) {
    if (accept_sample(now_ns, raw)) {
      if (have_energy_position_) {
        energy_J_ -= last_force_device_N_.dot(raw.position_m - energy_position_m_);
        min_energy_J_ = std::min(min_energy_J_, energy_J_);
      }
      energy_position_m_ = raw.position_m;
      have_energy_position_ = true;
      sample_ = raw;
      have_sample_ = true;
      last_sample_ns_ = now_ns;
      device_fresh = true;
    }
  } else {
    bump(missing_samples_);
  }
  const bool device_lost =
      !have_sample_ || 1e-9 * static_cast<double>(now_ns - last_sample_ns_) > limits_.device_timeout_s;
  const Vec3 device_m = frame_.position_to_scene(sample_.position_m);
  const Vec3 device_velocity_m_per_s = frame_.velocity_to_scene(sample_.velocity_m_per_s);

  // 2. Newest model (validated, copied into the spare slot).
  bool switched = false;
  const bool had_model = have_model_;
  if (const auto read = models_.read(); read.is_new) {
    const LocalModel& m = *read.value;
    if (have_model_ && m.version == model_slot_[active_].version) {
      // The same model re-published (the sim re-affirms it while paused):
      // it is fresh as of now. Ignored, it went stale after stale_model_s
      // and a paused object stopped pushing back.
      model_slot_[active_].built_ns = std::max(model_slot_[active_].built_ns, m.built_ns);
    } else if (m.version != 0) {
      if (!local_model_is_valid(m)) {
        bump(rejected_models_);
      } else {
        const int next = 1 - active_;
        copy_used_part(m, &model_slot_[next]);
        renderer_[next].set_model(&model_slot_[next]);
        // Both renderers continue from the same pre-tick proxy state.
        renderer_[next].carry_state_from(renderer_[active_]);
        active_ = next;
        have_model_ = true;
        switched = true;
        bump(model_updates_);
      }
    }
  }
  const LocalModel& model = model_slot_[active_];
  const bool stale = !have_model_ || 1e-9 * static_cast<double>(now_ns - model.built_ns) > limits_.stale_model_s;

  // 3. Render, with the cross-fade offset of the last model switch.
  RenderOutput render;
  render.proxy_m = device_m;
  Vec3 force_scene_N = Vec3::Zero();
  if (have_sample_) {
    render = renderer_[active_].render(now_ns, device_m, device_velocity_m_per_s);
    const double crossfade_s = haptic_spec_.crossfade_s;
    auto remaining = [&](std::int64_t t_ns) {
      if (!(crossfade_s > 0.0)) return 0.0;
      return std::clamp(1.0 - 1e-9 * static_cast<double>(t_ns - fade_start_ns_) / crossfade_s, 0.0, 1.0);
    };
    if (switched && had_model && crossfade_s > 0.0) {
      const RenderOutput old = renderer_[1 - active_].render(now_ns, device_m, device_velocity_m_per_s);
      const Vec3 old_total_N = old.force_on_device_N + remaining(now_ns) * fade_offset_N_;
      fade_offset_N_ = old_total_N - render.force_on_device_N;
      if (!fade_offset_N_.allFinite()) fade_offset_N_.setZero();
      fade_start_ns_ = now_ns;
    }
    // The fade smooths a model switch under the hand in contact. A free hand
    // must feel nothing: the sample says no contact and the sim gets no
    // reaction, so a leftover offset would push it with a force nothing
    // answers (a 1 N update just before lifting off pushed the free hand with
    // 0.4 N). The contact force itself reaches zero at the release, and the
    // device's rate limit smooths what the offset still held.
    if (!render.contact) fade_offset_N_.setZero();
    force_scene_N = render.force_on_device_N + remaining(now_ns) * fade_offset_N_;
  }

  // 4. Safety (device frame) and output.
  unsigned faults = kFaultNone;
  if (stale) faults |= kFaultStaleModel;
  if (device_lost) faults |= kFaultDeviceLost;
  if (stop_requested_.load(std::memory_order_relaxed)) faults |= kFaultStop;
  if (watchdog_tripped_.load(std::memory_order_relaxed)) faults |= kFaultWatchdog;
  const Vec3 force_device_N = safety_.apply(frame_.force_to_device(force_scene_N), dt_s, faults);
  device_.write(now_ns, force_device_N);
  last_force_device_N_ = force_device_N;

  // 5. Tell the sim what the tool did: the object gets the reaction of what the user felt.
  ToolSample& s = last_sample_;
  s.time_ns = now_ns;
  s.device_position_m = device_m;
  s.proxy_position_m = render.proxy_m;
  s.force_on_device_N = frame_.force_to_scene(force_device_N);
  s.contact = render.contact;
  s.force_on_object_N = render.contact ? Vec3(-s.force_on_device_N) : Vec3::Zero();
  s.contact_node = render.contact ? render.contact_node : std::array<std::uint32_t, 3>{};
  s.contact_weight = render.contact ? render.contact_weight : std::array<double, 3>{};
  s.model_version = have_model_ ? model.version : 0;
  s.device_fresh = device_fresh;
  samples_.try_push(s);

  // 6. Counters.
  stopped_.store(stop_requested_.load(std::memory_order_relaxed) && safety_.quiescent(), std::memory_order_release);
  safety_trips_.store(safety_.total_trips(), std::memory_order_relaxed);
  stale_trips_.store(safety_.trips(0), std::memory_order_relaxed);
  device_lost_trips_.store(safety_.trips(1), std::memory_order_relaxed);
  nonfinite_forces_.store(safety_.nonfinite_inputs(), std::memory_order_relaxed);
  model_version_.store(s.model_version, std::memory_order_relaxed);
  contact_.store(render.contact, std::memory_order_relaxed);
  force_N_.store(force_device_N.norm(), std::memory_order_relaxed);
  force_scale_.store(safety_.scale(), std::memory_order_relaxed);
  energy_atomic_J_.store(energy_J_, std::memory_order_relaxed);
  min_energy_atomic_J_.store(min_energy_J_, std::memory_order_relaxed);
}

HapticStats HapticLoop::stats() const noexcept {
  HapticStats st;
  st.ticks = ticks_.load(std::memory_order_relaxed);
  st.heartbeat = heartbeat_.load(std::memory_order_relaxed);
  st.rejected_nonfinite = rejected_nonfinite_.load(std::memory_order_relaxed);
  st.rejected_workspace = rejected_workspace_.load(std::memory_order_relaxed);
  st.rejected_speed = rejected_speed_.load(std::memory_order_relaxed);
  st.rejected_inputs = st.rejected_nonfinite + st.rejected_workspace + st.rejected_speed;
  st.missing_samples = missing_samples_.load(std::memory_order_relaxed);
  st.model_updates = model_updates_.load(std::memory_order_relaxed);
  st.rejected_models = rejected_models_.load(std::memory_order_relaxed);
  st.safety_trips = safety_trips_.load(std::memory_order_relaxed);
  st.stale_model_trips = stale_trips_.load(std::memory_order_relaxed);
  st.device_lost_trips = device_lost_trips_.load(std::memory_order_relaxed);
  st.nonfinite_forces = nonfinite_forces_.load(std::memory_order_relaxed);
  st.ring_drops = samples_.drops();
  st.model_version = model_version_.load(std::memory_order_relaxed);
  st.contact = contact_.load(std::memory_order_relaxed);
  st.stopped = stopped_.load(std::memory_order_acquire);
  st.force_N = force_N_.load(std::memory_order_relaxed);
  st.force_scale = force_scale_.load(std::memory_order_relaxed);
  st.passivity_energy_J = energy_atomic_J_.load(std::memory_order_relaxed);
  st.min_passivity_energy_J = min_energy_atomic_J_.load(std::memory_order_relaxed);
  return st;
}

}  // namespace tissue::haptics
