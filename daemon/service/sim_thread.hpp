// The sim thread: runs a SimRunner paced to the wall clock (one step per
// dt_s of wall time, absolute-time sleeps), feeds it the haptic loop's tool
// samples and hands each new LocalModel to the haptic loop. Commands from the
// control side (pause, resume, a new runner for reset / load / set) are
// picked up between steps; the sim thread never waits for them (try_lock).
//
// Falling behind: when a step ends later than its slot, adaptation is shed
// first (paused until the loop catches up again); past max_lag_s the schedule
// is re-anchored to now and an overrun is counted rather than running a burst
// of catch-up steps. The haptic thread never waits for any of this.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <future>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "concurrency/latest_value.hpp"
#include "concurrency/spsc_ring.hpp"
#include "haptics/haptic_loop.hpp"
#include "haptics/local_model.hpp"
#include "service/mesh_snapshot.hpp"
#include "service/sim_runner.hpp"

namespace tissue::record {
class Recorder;
}

namespace tissue::service {

// The hand-offs shared with the haptic loop (haptics/haptic_loop.hpp).
using ToolSampleRing = haptics::ToolSampleRing;
using LocalModelChannel = haptics::LocalModelBuffer;

// What the sim thread reports; read through a LatestValue by one reader.
struct SimStatus {
  std::uint64_t generation = 0;  // bumps when a new runner (reset / load / set) takes over
  double sim_time_s = 0.0;
  std::int64_t steps = 0;
  std::size_t nodes = 0, tets = 0, springs = 0;
  std::int64_t refines = 0, merges = 0;
  double kinetic_energy_J = 0.0, elastic_energy_J = 0.0;
  // The sim time the energies were summed at: they refresh at the stats rate,
  // not with every status, so they can trail sim_time_s.
  double energy_sim_time_s = 0.0;
  double real_time_factor = 0.0;           // simulated / wall seconds over the last status window
  bool real_time_factor_measured = false;  // false until a first window has ended (status says null)
  double step_ms_last = 0.0, step_ms_max_window = 0.0;
  bool paused = false;
  bool adaptation_shed = false;  // adaptation paused because the loop fell behind
  std::int64_t overruns = 0;     // schedule re-anchored after falling max_lag_s behind
  std::int64_t failed_steps = 0;
  // A step threw (a broken mesh invariant, memory exhausted): the runner's
  // state may be half-changed, so it is not stepped again, and every step it
  // cannot take counts as failed (last_error says why) until a new runner
  // (reset / load / set) takes over.
  bool halted = false;
  // Solver work since the runner started (physics::SimCounters): mean
  // explicit sub-steps and CG / local-global iterations per step, and the
  // steps whose solver stopped at cg_max_iterations short of cg_tolerance.
  double substeps_per_step = 0.0, solver_iterations_per_step = 0.0;
  std::int64_t unconverged_steps = 0;
  char integrator[32] = {};  // the rung running (physics::Integrator::name(), e.g. "explicit float")
  std::uint64_t model_version = 0;
  std::uint64_t samples = 0;
  bool tool_pushing = false;
  std::array<double, 3> tool_force_N{};
  // The newest haptic tick the sim thread drained (scene frame), and the
  // LocalModel version it rendered against (not model_version, the newest
  // the sim published: a loop holding on to an older model, one it refused
  // or has not picked up yet, shows as this one falling behind).
  std::array<double, 3> device_position_m{}, proxy_position_m{}, force_on_device_N{};
  std::uint64_t tick_model_version = 0;
  bool tool_contact = false;
  // The newest failed step's reason (NUL-terminated). Room for the longest
  // the integrators give (the explicit refusals with their advice run to ~300
  // characters; 256 cut the advice off).
  char last_error[1024] = {};
};

struct SimThreadOptions {
  double max_lag_s = 0.1;                // behind by more than this: re-anchor the schedule
  double shed_after_lag_s = 0.01;        // behind by more than this: pause adaptation
  double status_every_s = 0.05;          // publish SimStatus this often (wall)
  int priority = 0;                      // SCHED_FIFO priority to try (0: leave the policy alone)
  bool pace = true;                      // false: as fast as possible (tests)
  double snapshot_every_s = 1.0 / 30.0;  // MeshSnapshot rate (wall); recording frames come on top
  double energy_every_s = 0.0;           // refresh SimStatus energies this often (wall; 0: every status)
};

class SimThread {
 public:
  // `samples` and `models` may be null (no haptic loop). The runner is owned.
  SimThread(std::unique_ptr<SimRunner> runner, ToolSampleRing* samples, LocalModelChannel* models,
            SimThreadOptions options);
  ~SimThread();
  SimThread(const SimThread&) = delete;
  SimThread& operator=(const SimThread&) = delete;

  void start();
  void stop();  // joins; idempotent

  // Any thread; applied at the next step boundary.
  void pause() { paused_.store(true, std::memory_order_relaxed); }
  void resume() { paused_.store(false, std::memory_order_relaxed); }
  bool paused() const { return paused_.load(std::memory_order_relaxed); }
  // Hands over a new runner (built on the caller's thread: construction
  // allocates and may throw, neither belongs on the sim thread).
  void replace_runner(std::unique_ptr<SimRunner> runner);
  // Hands over a new runner together with the recorder its rows go to (null:
  // none), taken by the sim thread at one step boundary: none of the new
  // runner's rows reaches the recorder before (a file describing the old
  // scene), none of the old runner's reaches `recorder`. The ticks drained in
  // the loop that switches were rendered against the old runner's model and
  // go to the recorder before. Returns as set_recorder does: true once the
  // sim thread has taken both and let go of the recorder before, false when
  // it has not within `wait_s` (the recorder before must then be kept alive).
  // Any thread but the sim thread.
  bool replace_runner(std::unique_ptr<SimRunner> runner, record::Recorder* recorder,
                      double wait_s = kRecorderHandOverWait_s);

  // Fault injection (tests, drills): the sim thread's next iteration blocks
  // for this long, as a pathological step would. The haptic side must ride
  // it out: it keeps its rate and ramps the force out on a stale model.
  void inject_stall(std::chrono::nanoseconds duration) { stall_ns_.store(duration.count(), std::memory_order_relaxed); }
  // Fault injection: the next step throws, as a library call that fails
  // inside it would (std::bad_alloc while refining, a std::logic_error from
  // a broken mesh invariant). The runner halts (SimStatus::halted); the
  // thread, its status and the haptic side keep going.
  void inject_step_exception() { throw_next_step_.store(true, std::memory_order_relaxed); }

  // Recording: the sim thread is the single producer of the session's
  // haptic rows (from the tool samples it drains anyway), sim rows and mesh
  // frames. Returns once the sim thread has taken the change, so after
  // set_recorder(nullptr) the old recorder is no longer touched and may be
  // stopped and destroyed. Any thread but the sim thread. Waits at most
  // `wait_s` (a stalled sim thread must not hang the control side): returns
  // false when the sim thread has not taken the change by then, and the old
  // recorder must then be kept alive (it may still be used) until a later
  // set_recorder returns true or the thread has stopped.
  // The default wait is short because the caller is the io thread, which
  // also feeds systemd's watchdog: blocking it longer than about a quarter of
  // WatchdogSec (5 s in the shipped unit) gets a healthy daemon killed
  // mid-session. A stalled sim thread's recorder is retired instead.
  static constexpr double kRecorderHandOverWait_s = 1.0;
  bool set_recorder(record::Recorder* recorder, double wait_s = kRecorderHandOverWait_s);

  // One reader (the service's io thread).
  SimStatus status() { return *status_.read().value; }
  // One reader (the service's io thread): the newest surface, stable until the
  // next call.
  const MeshSnapshot& snapshot() { return *snapshots_.read().value; }
  // Advances every loop iteration, paused or not: the watchdog's heartbeat
  // when there is no haptic thread.
  std::uint64_t heartbeat() const { return heartbeat_.load(std::memory_order_relaxed); }
  // Scheduling actually obtained ("SCHED_FIFO 60" or why not); known once
  // start() has returned (the start-up line prints it), "" before.
  std::string scheduling() const;

 private:
  // `scheduled` is set once the thread has asked for its scheduling.
  void run(std::promise<void>& scheduled);
  // A step (or reading the mesh after it) threw: stop using the runner.
  // Allocates nothing (the exception may be std::bad_alloc).
  void halt(const char* what) noexcept;
  void publish_model(std::int64_t now_ns, bool rebuilt);
  void publish_status(std::int64_t now_ns);
  // The drained ticks as the haptic loop rendered them (batch_ before the
  // new runner's mask), then the sim row and mesh frame of this loop.
  void record_haptic(record::Recorder& recorder);
  void record_sim(record::Recorder& recorder, std::int64_t now_ns);
  // Fills the snapshot write buffer from the current mesh.
  MeshSnapshot& build_snapshot();

  std::unique_ptr<SimRunner> runner_;
  ToolSampleRing* samples_;
  LocalModelChannel* models_;
  SimThreadOptions options_;

  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> paused_{false};
  std::atomic<std::uint64_t> heartbeat_{0};
  std::atomic<std::int64_t> stall_ns_{0};
  std::atomic<bool> throw_next_step_{false};
  std::atomic<record::Recorder*> recorder_{nullptr};

  // Guards pending_, pending_recorder_, pending_has_recorder_,
  // runners_with_recorder_handed_ and pending_seq_, and orders the io side's recorder_ stores
  // with them; the sim thread only try_locks.
  std::mutex pending_mutex_;
  std::unique_ptr<SimRunner> pending_;
  // The recorder the pending runner's rows go to (replace_runner with a
  // recorder); without one the recorder stays as it is.
  record::Recorder* pending_recorder_ = nullptr;
  bool pending_has_recorder_ = false;
  // Runners handed over with a recorder, numbered 1, 2, …; the number of
  // the one pending; and the number of the last one the sim thread took
  // (release, in the loop that took it / acquire, in replace_runner): a
  // hand-over whose runner another replaced while pending is done when that
  // one is taken.
  std::uint64_t runners_with_recorder_handed_ = 0;
  std::uint64_t pending_seq_ = 0;
  std::atomic<std::uint64_t> runners_with_recorder_taken_{0};

  concurrency::LatestValue<SimStatus> status_;
  concurrency::LatestValue<MeshSnapshot> snapshots_;
  mutable std::mutex scheduling_mutex_;
  std::string scheduling_;

  // Sim-thread state.
  std::vector<haptics::ToolSample> batch_;
  haptics::ToolSample last_tick_;
  haptics::LocalModel scratch_model_;
  std::uint64_t model_version_ = 0;
  std::uint64_t generation_ = 0;
  // The first model version the current runner published (or will): ticks
  // rendered against an older model touched the old runner's surface, so
  // their contact is dropped (their nodes mean nothing in the new mesh).
  std::uint64_t first_model_version_ = 0;
  std::uint64_t samples_total_ = 0;
  std::int64_t overruns_ = 0, failed_steps_ = 0;
  bool shed_ = false;
  bool halted_ = false;  // see SimStatus::halted; cleared by a new runner
  char halt_reason_[sizeof(SimStatus::last_error)] = {};
  RunnerStep last_step_;
  std::string last_error_;
  double window_sim_s_ = 0.0;
  std::int64_t window_start_ns_ = 0;
  double step_ms_last_ = 0.0, step_ms_max_ = 0.0;
  // Energies as last summed (publish_status), and when.
  double kinetic_energy_J_ = 0.0, elastic_energy_J_ = 0.0, energy_sim_time_s_ = 0.0;
  std::int64_t last_energy_ns_ = 0;
  std::uint64_t energy_generation_ = 0;
  // NaN until the first one-second window is measured: the recorded rows and
  // the published statistics say "not measured" as status says null (they
  // said 0, a sim that stands still, for the first second).
  double rtf_ = std::numeric_limits<double>::quiet_NaN();
  bool rtf_measured_ = false;
  // Surface scratch (sim thread): reused, so a snapshot allocates only when
  // the surface grows.
  SnapshotScratch snapshot_scratch_;
  std::uint64_t snapshot_sequence_ = 0;
  std::int64_t next_snapshot_ns_ = 0;  // due time on the snapshot grid (next_snapshot_due_ns)
  std::int64_t snapshot_period_ns() const { return static_cast<std::int64_t>(options_.snapshot_every_s * 1e9); }
};

// steady_clock now in nanoseconds (the clock every timestamp here uses).
std::int64_t now_ns();

// Makes `next` (null: none) the recorder `sim` writes to in place of
// `current`, then stops the old one. The thread switches between two of its
// iterations, so every row it produces goes to one file or the other: a
// rotation or a record_start leaves no gap. An old recorder the thread has
// not let go of within the hand-over wait (a stalled thread) is stopped and
// kept in `retired` until a later hand-over, or the thread's stop, releases
// it. A null `sim` holds no recorder. With a `runner`, the thread takes it
// and `next` at one step boundary (SimThread::replace_runner): the new
// runner's rows all go to `next`, the old runner's to `current`. Io thread
// only.
void hand_over_recorder(SimThread* sim, std::unique_ptr<record::Recorder>& current,
                        std::unique_ptr<record::Recorder> next, std::vector<std::unique_ptr<record::Recorder>>& retired,
                        std::unique_ptr<SimRunner> runner = nullptr);

}  // namespace tissue::service
