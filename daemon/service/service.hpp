// tissued as a service: `tissued --config FILE`. Owns the threads and wires
// them (ARCHITECTURE.md):
//   sim thread (SimThread)        steps the scene paced to the wall clock
//   haptic thread (1 kHz)         only when the config names a device AND the
//                                 scene has a tool (model only what is asked)
//   io thread (the caller's)      control socket, signals, status line,
//                                 systemd notifications and watchdog
// Control commands and signals act between steps: reset / load_scene / set
// build the new simulation here, on the io thread, and hand it over.
#pragma once

#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "config/daemon_config.hpp"
#include "control/control_protocol.hpp"
#include "scene/scene.hpp"
#include "service/failing_steps.hpp"
#include "service/safety_trips.hpp"
#include "service/sim_thread.hpp"

namespace tissue::record {
class Recorder;
}
namespace tissue::transport {
class LcmPublisher;
class DdsPublisher;
}  // namespace tissue::transport

namespace tissue::control {
class ControlServer;
class SystemdNotifier;
class WatchdogFeeder;
}  // namespace tissue::control

namespace tissue::service {

class HapticSide;

struct ServiceOptions {
  std::string config_path;
  // `--set key.path=value`: daemon keys (haptics.rate_hz) go to the config,
  // the others (material.youngs_modulus_Pa) to the scene.
  std::vector<std::string> overrides;
  double duration_s = 0.0;  // > 0: stop after this many wall seconds (tests, demos)
  std::string record_name;  // non-empty: record from the start to state_dir/record_name
  std::FILE* out = stdout;  // live status lines
  std::FILE* err = stderr;  // one-line errors
};

// The settings that differ between the running config and the file a
// reload read, among those a reload cannot apply (the device, sockets,
// publishing, state_dir, threads): "device.kind", "control", ... in a fixed
// order, or "other settings" for a difference no name above covers (a
// section added later); empty when none.
std::vector<std::string> restart_only_changes(const config::DaemonConfig& running, const config::DaemonConfig& file);

// Process exit codes of the service mode (batch mode shares 0-2).

enum ServiceExit : int { kServiceOk = 0, kServiceInternal = 1, kServiceBadConfig = 2, kServiceStartFailed = 3 };

class Service : public control::ControlHandler {
 public:
  explicit Service(ServiceOptions options);
  ~Service() override;

  // Loads the config and scene, starts the threads and serves until
  // shutdown (control command, SIGTERM/SIGINT, or --duration). Returns the
  // exit code; prints the reason of a failure on options.err.
  int run();

  // ControlHandler (io thread).
  nlohmann::json status() override;
  nlohmann::json pause() override;
  nlohmann::json resume() override;
  nlohmann::json reset() override;
  nlohmann::json load_scene(const std::string& path) override;
  nlohmann::json set(const std::string& key, const nlohmann::json& value) override;
  nlohmann::json shutdown() override;
  nlohmann::json record_start(const std::string& name) override;
  nlohmann::json record_stop() override;
  nlohmann::json export_x3d(const std::string& name) override;

 private:
  void load_config();  // throws config::ConfigError / scene::SceneError
  scene::Scene load_scene_file(const std::string& path) const;
  // The scene `config` names, with the --set scene overrides; a file that
  // cannot be read is a ConfigError at the config's `scene` key.
  scene::Scene load_config_scene(const config::DaemonConfig& config) const;
  void start_threads();
  void stop_threads();
  // New runner on the sim thread, haptics started/stopped to match (and
  // restarted when restart_haptics: its settings changed). Throws before
  // changing anything when the scene cannot be built. Once the scene is
  // committed nothing is thrown: a device that cannot start (its port taken,
  // its session file gone) leaves the scene running without it, and the
  // returned text says so (empty: the device is as the scene wants).
  [[nodiscard]] std::string apply_scene(scene::Scene scene, bool restart_haptics = false);
  // apply_scene's halves. The runner for `scene`: throws, changing nothing,
  // when the scene cannot be served or built. Then, once the scene is
  // committed (scene_ and what a recording describes, the runner handed to
  // the sim thread), the haptic side started or stopped to match; returns
  // apply_scene's device problem.
  std::unique_ptr<SimRunner> build_runner(const scene::Scene& scene) const;
  [[nodiscard]] std::string match_haptics_to_scene(bool had_tool, bool restart_haptics);
  // `result` with apply_scene's device problem as its "warning" (also said on
  // stderr and recorded as a warning event); `result` itself when none.
  nlohmann::json with_device_warning(nlohmann::json result, const std::string& device_problem);
  // Throws std::invalid_argument when the scene's starting mesh is over
  // config max_scene_tets (see DaemonConfig).
  void require_servable(const scene::Scene& scene) const;
  void reload();  // SIGHUP: config and scene again
  void request_stop(const std::string& why);
  void arm_signals();
  void start_publishing();
  // Re-arms `timer` every 1/rate_hz seconds on the io thread, calling `publish`.
  void arm_publish_timer(boost::asio::steady_timer& timer, double rate_hz, void (Service::*publish)());
  void publish_mesh();
  void note_dds_oversize(std::uint64_t oversize_before, std::uint64_t sent_before);
  void publish_haptic();
  void publish_stats();
  // Records a warning event when the haptic safety tripped since the last
  // look (the 1 kHz thread itself does no I/O), at every status line: a
  // session shows when and why the force was ramped out.
  void note_safety_trips();
  // Steps the sim thread failed since the last status line: an error event
  // and a line on stderr (the sim thread itself does no I/O).
  void note_failing_steps();
  // Throws std::invalid_argument (or scene::SceneModelError) when the
  // scene's first step fails.
  void require_steppable(const scene::Scene& scene) const;
  void arm_status_timer();
  // The haptic side comes and goes only through these: each start numbers
  // the side, each stop first records the trips since the last status tick.
  void start_haptic_side();
  void stop_haptic_side();
  void arm_watchdog_timer();
  void print_status();
  void start_recording(const std::string& name);  // throws record::RecordError
  // The two halves of start_recording: a recorder for a new file (throws,
  // changing nothing), and making it the one the threads record to. With a
  // `runner`, the sim thread takes it and the new file at one step boundary:
  // its first row is the runner's first step, and no row of it goes to the
  // file before.
  std::unique_ptr<record::Recorder> open_recorder(const std::string& name);
  void install_recorder(std::unique_ptr<record::Recorder> recorder, std::unique_ptr<SimRunner> runner = nullptr);
  // Closes the file; with a `runner`, the sim thread takes it as it lets go
  // of the recorder (none of the runner's rows goes to the file).
  void stop_recording(std::unique_ptr<SimRunner> runner = nullptr);
  // record.auto_start: a timestamped file, new every record.rotate_s. A
  // file that cannot be created is said and tried again at the next
  // rotation; the service keeps serving.
  void start_automatic_recording();
  // start_automatic_recording's first half: room made, then the recorder for
  // a new automatic file (throws when it cannot be made). `removed` gets the
  // files the room took, for the new file's events.
  std::unique_ptr<record::Recorder> open_automatic_recorder(std::vector<std::string>* removed);
  // Its second half, once the new file is the one recorded to: the removals
  // in its events, and the oldest automatic files past record.keep_gb gone.
  void note_automatic_recording_started(const std::vector<std::string>& removed);
  // Before a new automatic file: removes the oldest automatic files (never
  // a client's, never the live one) until state_dir has the recorder's
  // free-space reserve plus room for the file (the size of the one it
  // follows, at least kAutomaticRoom_bytes) free. Returns what it removed
  // (said on stdout); throws when it stays below the reserve.
  std::vector<std::string> make_room_for_automatic_recording();
  static constexpr std::uint64_t kAutomaticRoom_bytes = 64ull << 20;
  void rotate_automatic_recording();
  void record_event(int kind, const std::string& text);  // no-op when not recording
  std::vector<std::string> scene_overrides() const;
  std::vector<std::string> config_overrides() const;
  // The first events of a recording: the scene, its file and the overrides
  // in force, each override whole (an event holds 255 bytes; one event when
  // they fit).
  std::vector<std::string> recording_started_events() const;
  // Hands `runner` (built for the scene just committed by load_scene or a
  // reload: scene_ and what a recording describes) to the sim thread, and a
  // recording goes on in a new file that describes the new scene (an
  // automatic one rotates, a client's goes on in NAME-partK.h5), `what`
  // recorded as the old file's last event. The sim thread takes the runner
  // and the new file together: the new scene's rows are all in the new file,
  // none in the old. `file` is the new file, `stopped` why there is none: a
  // next file that cannot be made stops the recording at the change (said on
  // stderr), rather than record the new scene under the old one's
  // description; an automatic one is tried again after record.rotate_s.
  struct RecordingHandover {
    std::string file;
    std::string stopped;
  };
  RecordingHandover continue_recording_in_new_file(const std::string& what, std::unique_ptr<SimRunner> runner);
  std::string next_part_name(const std::string& first) const;
  // What a recording's root attributes and first events describe (scene
  // name, path, text and overrides, config text): a change hands over.
  std::string recording_description() const;

  ServiceOptions options_;
  config::DaemonConfig config_;
  scene::Scene scene_;
  std::string scene_path_;  // the scene the running simulation came from
  // Overrides the running scene was loaded with: the command line's scene
  // keys for the configured scene (start, SIGHUP), none for a load_scene.
  std::vector<std::string> base_scene_overrides_;
  // `set` over the socket since: one per key (a new value replaces the old),
  // dropped when another scene is loaded or on SIGHUP (files as written).
  std::vector<std::string> scene_sets_;
  // The settings the last reload found changed and could not apply
  // (restart_only_changes): recordings' first event names them.
  std::vector<std::string> waiting_for_restart_;
  // The file name a client's recording started with: the files it goes on
  // in after a scene change are named after it.
  std::string client_record_name_;
  std::string recorded_description_;  // recording_description() when the live file started

  boost::asio::io_context io_;
  boost::asio::signal_set signals_;
  boost::asio::steady_timer status_timer_, watchdog_timer_, duration_timer_;
  boost::asio::steady_timer mesh_timer_, haptic_timer_, stats_timer_;

  std::unique_ptr<ToolSampleRing> samples_;    // haptic -> sim
  std::unique_ptr<LocalModelChannel> models_;  // sim -> haptic
  std::unique_ptr<SimThread> sim_;
  std::unique_ptr<HapticSide> haptics_;  // null without device or tool
  // Numbers the haptic sides started (SafetyTrips tells a restarted side,
  // which counts from zero, by it); what note_safety_trips last saw.
  std::uint64_t haptic_side_number_ = 0;
  SafetyTrips safety_trips_;
  FailingSteps failing_steps_;      // what note_failing_steps says, and when
  bool dds_oversize_said_ = false;  // note_dds_oversize: said since the last mesh that went out
  std::unique_ptr<control::ControlServer> server_;
  std::unique_ptr<control::SystemdNotifier> systemd_;
  std::unique_ptr<control::WatchdogFeeder> watchdog_;
  // The real-time loop's heartbeat as the watchdog sees it: the haptic
  // thread's when there is one, else the sim thread's (copied at each poll).
  std::atomic<std::uint64_t> heartbeat_{0};
  std::unique_ptr<record::Recorder> recorder_;
  // Stopped recorders the sim thread may still hold (it stalled through
  // set_recorder's wait): freed once a later hand-over completes or the sim
  // thread has stopped, never under it.
  std::vector<std::unique_ptr<record::Recorder>> retired_recorders_;
  // Recording on its own (record.auto_start) until a client takes over with
  // record_start or record_stop; since when the current file runs.
  bool automatic_recording_ = false;
  std::chrono::steady_clock::time_point automatic_since_{};
  std::unique_ptr<transport::LcmPublisher> lcm_;  // null unless publish.lcm.enabled and LCM started
  std::unique_ptr<transport::DdsPublisher> dds_;  // null unless publish.dds.enabled and DDS started
  bool stopping_ = false;
  std::string stop_reason_;
};

}  // namespace tissue::service
