#include "service/sim_thread.hpp"

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <span>
#include <stdexcept>

#include "record/recorder.hpp"
#include "service/publish_schedule.hpp"

namespace tissue::service {

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

namespace {

void sleep_until_ns(std::int64_t t_ns) {
  // steady_clock is CLOCK_MONOTONIC on Linux; absolute sleeps do not drift.
  timespec ts{static_cast<time_t>(t_ns / 1000000000), static_cast<long>(t_ns % 1000000000)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

}  // namespace

SimThread::SimThread(std::unique_ptr<SimRunner> runner, ToolSampleRing* samples, LocalModelChannel* models,
                     SimThreadOptions options)
    : runner_(std::move(runner)), samples_(samples), models_(models), options_(options) {
  batch_.reserve(ToolSampleRing::kCapacity);
}

SimThread::~SimThread() { stop(); }

void SimThread::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  std::promise<void> scheduled;
  std::future<void> decided = scheduled.get_future();
  thread_ = std::thread([this, scheduled = std::move(scheduled)]() mutable { run(scheduled); });
  // The start-up line prints scheduling(): read before the thread had set
  // it, it was empty ("sim thread , control ...").
  decided.wait();
}

void SimThread::stop() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void SimThread::replace_runner(std::unique_ptr<SimRunner> runner) {
  std::lock_guard<std::mutex> lock(pending_mutex_);
  pending_ = std::move(runner);
}

bool SimThread::replace_runner(std::unique_ptr<SimRunner> runner, record::Recorder* recorder, double wait_s) {
  std::uint64_t handed = 0;
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    pending_ = std::move(runner);
    pending_recorder_ = recorder;
    pending_has_recorder_ = true;
    handed = ++runners_with_recorder_handed_;
    pending_seq_ = handed;
    // Not running: nothing holds the recorder before; the thread, if it
    // starts, takes both in its first loop.
    if (!thread_.joinable()) {
      recorder_.store(recorder, std::memory_order_release);
      return true;
    }
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(wait_s);
  const auto given_up = [&] { return stop_.load() || std::chrono::steady_clock::now() >= deadline; };
  while (runners_with_recorder_taken_.load(std::memory_order_acquire) < handed) {
    if (given_up()) return false;
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  // The loop that took them may still be writing the drained ticks to the
  // recorder before: it has ended once the heartbeat advances past the
  // value it had then (at most the one read here).
  const std::uint64_t target = heartbeat_.load(std::memory_order_acquire) + 1;
  while (heartbeat_.load(std::memory_order_acquire) < target) {
    if (given_up()) return false;
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  return true;
}

bool SimThread::set_recorder(record::Recorder* recorder, double wait_s) {
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    recorder_.store(recorder, std::memory_order_release);
    // A runner still waiting with a recorder of its own would bring back the
    // one this replaces (stopped, perhaps freed) when the thread takes it.
    if (pending_ && pending_has_recorder_) pending_recorder_ = recorder;
  }
  if (!thread_.joinable()) return true;
  // The iteration that read the old pointer has ended once the heartbeat has
  // advanced twice (it increments at the start of every iteration, paused or
  // not). Release (sim thread, each iteration start) / acquire (here):
  // everything the sim thread did with the old recorder happens before a
  // `true` return.
  const auto beats = [this] { return heartbeat_.load(std::memory_order_acquire); };
  const std::uint64_t target = beats() + 2;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(wait_s);
  while (beats() < target) {
    // Stopping: the heartbeat may never advance again; the caller keeps the
    // old recorder until stop() has joined.
    if (stop_.load() || std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  return true;
}

void SimThread::record_haptic(record::Recorder& recorder) {
  for (const haptics::ToolSample& s : batch_) {
    record::HapticRow row;
    row.time_s = recorder.session_time_s(s.time_ns);
    row.device_position_m = {s.device_position_m.x(), s.device_position_m.y(), s.device_position_m.z()};
    row.proxy_position_m = {s.proxy_position_m.x(), s.proxy_position_m.y(), s.proxy_position_m.z()};
    row.force_N = {s.force_on_device_N.x(), s.force_on_device_N.y(), s.force_on_device_N.z()};
    row.contact = s.contact ? 1 : 0;
    row.model_version = s.model_version;
    row.device_fresh = s.device_fresh ? 1 : 0;
    recorder.push_haptic(row);
  }
}

void SimThread::record_sim(record::Recorder& recorder, std::int64_t t_ns) {
  // A halted runner's state may be half-changed: no rows or frames from it.
  if (halted_) return;
  const physics::Simulation& sim = runner_->simulation();
  const double session_s = recorder.session_time_s(t_ns);
  record::SimRow row;
  row.time_s = session_s;
  row.sim_time_s = sim.time_s();
  row.real_time_factor = rtf_;
  row.step_ms = step_ms_last_;
  row.nodes = sim.body().mesh().node_count();
  row.tets = sim.body().mesh().tet_count();
  row.springs = sim.body().mesh().edge_count();
  row.refines = sim.counters().splits;
  row.merges = sim.counters().merges;
  // Every recorded row carries its energies (a session is where a lab checks
  // energy behaviour after the fact); physics_bench BM_EnergySumsPerStep puts
  // the two sums at 1.3-3.7 % of the step they follow, and only while recording.
  row.kinetic_J = sim.kinetic_energy_J();
  row.elastic_J = sim.elastic_energy_J();
  recorder.push_sim(row);

  if (!recorder.mesh_frame_due(session_s)) return;
  const MeshSnapshot& snap = build_snapshot();
  record::MeshFrameView frame;
  frame.time_s = session_s;
  frame.vertices_m = snap.vertices_m;
  frame.triangles = snap.triangles;
  frame.vertex_level = snap.vertex_level;
  frame.triangle_strain_energy_J_per_m3 = snap.triangle_strain_energy_J_per_m3;
  recorder.push_mesh_frame(frame);  // copies: the snapshot is published after this
  snapshots_.publish();
  // A recording frame is a snapshot too: it takes the due one's place.
  if (t_ns >= next_snapshot_ns_)
    next_snapshot_ns_ = next_snapshot_due_ns(next_snapshot_ns_, t_ns, snapshot_period_ns());
}

void SimThread::halt(const char* what) noexcept {
  halted_ = true;
  last_step_.tool_pushing = false;
  // The advice first: the reason may be cut at the status field's length.
  std::snprintf(halt_reason_, sizeof halt_reason_, "a step threw, so the scene is halted (reset or load a scene): %s",
                what);
}

MeshSnapshot& SimThread::build_snapshot() {
  MeshSnapshot& snap = snapshots_.write_buffer();
  build_mesh_snapshot(runner_->simulation(), &snapshot_scratch_, &snap);
  snap.sequence = ++snapshot_sequence_;
  return snap;
}

std::string SimThread::scheduling() const {
  std::lock_guard<std::mutex> lock(scheduling_mutex_);
  return scheduling_;
}

void SimThread::publish_model(std::int64_t t_ns, bool rebuilt) {
  if (!models_ || !runner_->simulation().has_tool()) return;
  // Re-published while paused too, so the haptic loop does not read a
  // resting object as a stale model: rebuilt (a new version) when the tool
  // moved, re-stamped when it did not.
  if (rebuilt) scratch_model_.version = ++model_version_;
  if (scratch_model_.version == 0) return;  // nothing built yet
  scratch_model_.built_ns = t_ns;
  models_->write(scratch_model_);
}

void SimThread::publish_status(std::int64_t t_ns) {
  const physics::Simulation& sim = runner_->simulation();
  const double window_s = 1e-9 * static_cast<double>(t_ns - window_start_ns_);
  if (window_s >= 1.0 || window_start_ns_ == 0) {
    if (window_start_ns_ != 0) {
      rtf_ = window_sim_s_ / window_s;
      rtf_measured_ = true;
    }
    window_start_ns_ = t_ns;
    window_sim_s_ = 0.0;
  }
  SimStatus& s = status_.write_buffer();
  s.generation = generation_;
  s.sim_time_s = sim.time_s();
  s.steps = sim.counters().steps;
  s.nodes = sim.body().mesh().node_count();
  s.tets = sim.body().mesh().tet_count();
  s.springs = sim.body().mesh().edge_count();
  s.refines = sim.counters().splits;
  s.merges = sim.counters().merges;
  // The energies are O(mesh) sums: at the status rate (100 Hz for haptic
  // messages) they would cost the sim thread for nothing, so they refresh at
  // energy_every_s (the stats rate) and on a new runner.
  // (Not from a halted runner: the sums walk a mesh that may be half-changed.
  // The counts below only read container sizes.)
  if (!halted_ && (energy_generation_ != generation_ || last_energy_ns_ == 0 ||
                   t_ns - last_energy_ns_ >= static_cast<std::int64_t>(options_.energy_every_s * 1e9))) {
    kinetic_energy_J_ = sim.kinetic_energy_J();
    elastic_energy_J_ = sim.elastic_energy_J();
    energy_sim_time_s_ = sim.time_s();
    last_energy_ns_ = t_ns;
    energy_generation_ = generation_;
  }
  s.kinetic_energy_J = kinetic_energy_J_;
  s.elastic_energy_J = elastic_energy_J_;
  s.energy_sim_time_s = energy_sim_time_s_;
  s.real_time_factor = rtf_;
  s.real_time_factor_measured = rtf_measured_;
  s.step_ms_last = step_ms_last_;
  s.step_ms_max_window = step_ms_max_;
  s.paused = paused_.load(std::memory_order_relaxed);
  s.adaptation_shed = shed_;
  s.overruns = overruns_;
  s.failed_steps = failed_steps_;
  s.halted = halted_;
  s.substeps_per_step = sim.counters().substeps_per_step();
  s.solver_iterations_per_step = sim.counters().solver_iterations_per_step();
  s.unconverged_steps = sim.counters().unconverged_steps;
  std::snprintf(s.integrator, sizeof s.integrator, "%s", sim.integrator().name());
  s.model_version = model_version_;
  s.samples = samples_total_;
  s.tool_pushing = last_step_.tool_pushing;
  const physics::Vec3 f = sim.tool_force_N();
  s.tool_force_N = {f.x(), f.y(), f.z()};
  s.device_position_m = {last_tick_.device_position_m.x(), last_tick_.device_position_m.y(),
                         last_tick_.device_position_m.z()};
  s.proxy_position_m = {last_tick_.proxy_position_m.x(), last_tick_.proxy_position_m.y(),
                        last_tick_.proxy_position_m.z()};
  s.force_on_device_N = {last_tick_.force_on_device_N.x(), last_tick_.force_on_device_N.y(),
                         last_tick_.force_on_device_N.z()};
  s.tool_contact = last_tick_.contact;
  s.tick_model_version = last_tick_.model_version;
  std::snprintf(s.last_error, sizeof s.last_error, "%s", halted_ ? halt_reason_ : last_error_.c_str());
  status_.publish();
  step_ms_max_ = 0.0;
}

void SimThread::run(std::promise<void>& scheduled) {
  {
    std::string what = "SCHED_OTHER (no real-time priority asked)";
    if (options_.priority > 0) {
      sched_param param{};
      param.sched_priority = options_.priority;
      const int err = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
      what = err == 0 ? "SCHED_FIFO " + std::to_string(options_.priority)
                      : std::string("SCHED_OTHER (SCHED_FIFO refused: ") + std::strerror(err) + ")";
    }
    {
      std::lock_guard<std::mutex> lock(scheduling_mutex_);
      scheduling_ = what;
    }
    scheduled.set_value();
  }

  std::int64_t next_ns = now_ns();
  std::int64_t last_status_ns = 0;
  while (!stop_.load(std::memory_order_relaxed)) {
    heartbeat_.fetch_add(1, std::memory_order_release);  // see set_recorder
    // The ticks drained below were rendered before this loop: they go to the
    // recorder of the runner they were rendered against, the sim row and
    // mesh frame to the runner stepped here.
    record::Recorder* const haptic_recorder = recorder_.load(std::memory_order_acquire);
    record::Recorder* recorder = haptic_recorder;
    // A new runner (reset / load / set) takes over between steps.
    if (std::unique_lock<std::mutex> lock(pending_mutex_, std::try_to_lock); lock.owns_lock() && pending_) {
      runner_ = std::move(pending_);
      if (pending_has_recorder_) {
        // Its recorder with it: its first row goes there, none to the file
        // describing the scene before.
        recorder = pending_recorder_;
        recorder_.store(recorder, std::memory_order_relaxed);  // the lock orders it with set_recorder's
        pending_has_recorder_ = false;
        // The hand-over's own number, not one more: a runner that replaced
        // another still pending is one take for two hand-overs, and counted
        // as one, every later hand-over waited its whole wait and failed.
        runners_with_recorder_taken_.store(pending_seq_, std::memory_order_release);
      }
      ++generation_;
      first_model_version_ = model_version_ + 1;
      // Its first model comes in this same loop: from its step, or, paused,
      // from refresh_model (a new runner's first call always builds). Paused,
      // none came: the haptic side held the old scene's model until it went
      // stale, and safety ramped the force out with a false trip.
      scratch_model_.version = 0;
      shed_ = false;
      halted_ = false;
      last_step_ = RunnerStep{};
      last_error_.clear();
      next_ns = now_ns();
    }
    physics::Simulation& sim = runner_->simulation();
    const double dt_s = sim.scene().integrator.dt_s;
    const auto dt_ns = static_cast<std::int64_t>(dt_s * 1e9);

    batch_.clear();
    if (samples_)
      samples_->drain([this](const haptics::ToolSample& s) {
        if (batch_.size() >= batch_.capacity()) return;
        batch_.push_back(s);
      });
    samples_total_ += batch_.size();
    if (!batch_.empty()) last_tick_ = batch_.back();
    // Recorded as rendered, before anything below can throw: written after
    // the step, the rows of a loop whose step threw were lost, and those
    // masked below said contact 0 where the device was touching.
    if (haptic_recorder) record_haptic(*haptic_recorder);
    // Pressed on the runner before a reset / load / set: where the tool is
    // still counts, what it touched does not (pushing old node ids into the
    // new mesh would put a force on unrelated nodes).
    for (haptics::ToolSample& s : batch_)
      if (s.model_version < first_model_version_) s.contact = false;

    if (const std::int64_t stall = stall_ns_.exchange(0, std::memory_order_relaxed); stall > 0)
      sleep_until_ns(now_ns() + stall);
    const std::int64_t t0 = now_ns();
    std::int64_t t1 = t0;
    const bool paused = paused_.load(std::memory_order_relaxed);
    // The exception barrier: a library call that throws inside a step
    // (std::bad_alloc while refining, a std::logic_error from a broken mesh
    // invariant) would otherwise end the daemon through std::terminate, the
    // session file unclosed. The runner halts instead; status, control,
    // recording and the haptic side (which ramps its force out on the model
    // that stops refreshing) go on, and a reset / load / set starts afresh.
    try {
      bool rebuilt = false;
      if (!paused && !halted_) {
        if (throw_next_step_.exchange(false, std::memory_order_relaxed))
          throw std::runtime_error("injected step fault (SimThread::inject_step_exception)");
        last_step_ = runner_->step(batch_, &scratch_model_);
        rebuilt = last_step_.model_built;
        if (last_step_.ok) {
          window_sim_s_ += dt_s;
        } else {
          ++failed_steps_;
          last_error_ = last_step_.error;
        }
      } else if (paused && !halted_ && models_) {
        // Paused, the object is frozen but the hand is not: the model follows
        // the tool over the frozen surface (a rigid wall standing still; the
        // paused body takes no force), where it stayed around the tool's
        // position at the pause and met a hand elsewhere with the old patch's
        // edge. The drained ticks give the tool's position, the newest tick
        // when none was drained.
        const std::span<const haptics::ToolSample> tool =
            !batch_.empty() ? std::span<const haptics::ToolSample>(batch_)
                            : std::span<const haptics::ToolSample>(&last_tick_, samples_total_ > 0 ? 1 : 0);
        rebuilt = runner_->refresh_model(tool, &scratch_model_);
      }
      t1 = now_ns();
      step_ms_last_ = 1e-6 * static_cast<double>(t1 - t0);
      step_ms_max_ = std::max(step_ms_max_, step_ms_last_);
      if (!halted_) publish_model(t1, rebuilt);
      if (recorder) record_sim(*recorder, t1);
      if (!halted_ && t1 >= next_snapshot_ns_) {
        build_snapshot();
        snapshots_.publish();
        next_snapshot_ns_ = next_snapshot_due_ns(next_snapshot_ns_, t1, snapshot_period_ns());
      }
    } catch (const std::exception& e) {
      halt(e.what());
      t1 = now_ns();
    } catch (...) {
      halt("an exception that is not a std::exception");
      t1 = now_ns();
    }
    // Every step a halted runner cannot take is a failed step: the status
    // and the failing-steps notices say so, with the reason, until it goes.
    if (halted_ && !paused) ++failed_steps_;
    if (t1 - last_status_ns >= static_cast<std::int64_t>(options_.status_every_s * 1e9)) {
      publish_status(t1);
      last_status_ns = t1;
    }

    if (!options_.pace) continue;
    next_ns += dt_ns;
    const std::int64_t lag_ns = t1 - next_ns;
    // Shed adaptation first when behind; take it back once on time again.
    if (lag_ns > static_cast<std::int64_t>(options_.shed_after_lag_s * 1e9)) {
      shed_ = true;
    } else if (lag_ns < 0) {
      shed_ = false;
    }
    sim.set_adaptation_paused(shed_);
    if (lag_ns > static_cast<std::int64_t>(options_.max_lag_s * 1e9)) {
      ++overruns_;
      next_ns = t1;  // re-anchor: no burst of catch-up steps
    }
    sleep_until_ns(next_ns);
  }
  publish_status(now_ns());
}

void hand_over_recorder(SimThread* sim, std::unique_ptr<record::Recorder>& current,
                        std::unique_ptr<record::Recorder> next, std::vector<std::unique_ptr<record::Recorder>>& retired,
                        std::unique_ptr<SimRunner> runner) {
  // The new one in first, then the old one out: the thread takes the new
  // pointer at its next iteration, and rows drained until then still go to
  // the old one, which is stopped only after the thread let go of it.
  std::unique_ptr<record::Recorder> old = std::move(current);
  current = std::move(next);
  const bool released = !sim     ? true
                        : runner ? sim->replace_runner(std::move(runner), current.get())
                                 : sim->set_recorder(current.get());
  if (released) retired.clear();  // no older one is held either
  if (!old) return;
  old->stop();
  if (!released) retired.push_back(std::move(old));
}

}  // namespace tissue::service
