#include "service/service.hpp"

#include <fcntl.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <boost/asio/post.hpp>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <exception>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string_view>
#include <tuple>
#include <utility>
#include <vector>

#include "config/daemon_config_yaml.hpp"
#include "control/control_server.hpp"
#include "control/systemd_notify.hpp"
#include "export/x3d.hpp"
#include "record/recorder.hpp"
#include "record/session_writer.hpp"
#include "scene/scene_yaml.hpp"
#include "service/haptic_side.hpp"
#include "service/publish_schedule.hpp"
#include "transport/dds_publisher.hpp"
#include "transport/lcm_publisher.hpp"
#include "util/output_file.hpp"
#include "util/timestamped_name.hpp"

namespace tissue::service {

namespace {

nlohmann::json status_json(const SimStatus& s) {
  return {// Goes up when the sim thread starts a new scene (after a reset,
          // load_scene, set or reload): a client waiting for the new scene's
          // steps tells them from the old one's (a status read just after the
          // change may still be the old scene's).
          {"generation", s.generation},
          {"sim_time_s", s.sim_time_s},
          {"steps", s.steps},
          {"nodes", s.nodes},
          {"tets", s.tets},
          {"springs", s.springs},
          {"refines", s.refines},
          {"merges", s.merges},
          // Summed at the stats rate: `at_sim_time_s` says when (it can trail sim_time_s).
          {"energy_J",
           {{"kinetic", s.kinetic_energy_J}, {"elastic", s.elastic_energy_J}, {"at_sim_time_s", s.energy_sim_time_s}}},
          // null, not 0, until the first one-second window has been measured
          {"real_time_factor", s.real_time_factor_measured ? nlohmann::json(s.real_time_factor) : nlohmann::json()},
          {"step_ms", {{"last", s.step_ms_last}, {"max_recent", s.step_ms_max_window}}},
          {"paused", s.paused},
          {"adaptation_shed", s.adaptation_shed},
          {"overruns", s.overruns},
          {"failed_steps", s.failed_steps},
          {"halted", s.halted},
          {"solver",
           {{"integrator", std::string(s.integrator)},
            {"substeps_per_step", s.substeps_per_step},
            {"iterations_per_step", s.solver_iterations_per_step},
            {"unconverged_steps", s.unconverged_steps}}},
          {"last_error", s.last_error[0] ? nlohmann::json(std::string(s.last_error)) : nlohmann::json(nullptr)},
          {"tool", {{"pushing", s.tool_pushing}, {"force_N", s.tool_force_N}, {"model_version", s.model_version}}}};
}

// Event texts of at most kEventMessageBytes - 1 bytes for `parts` in order:
// as many whole parts as fit in each (one event when all do), the next
// event starting with `continued` and the part without its leading
// separator. A part too long for an event on its own is spread over
// consecutive events "CONTINUED(part i of n): ...", which joined in order
// give it back whole: an override is never cut short or lost.
std::vector<std::string> pack_event_texts(const std::vector<std::string>& parts, const std::string& continued) {
  constexpr std::size_t kMax = record::kEventMessageBytes - 1;
  std::vector<std::string> events;
  std::string current;
  for (const std::string& part : parts) {
    if (current.size() + part.size() <= kMax && (!current.empty() || events.empty())) {
      current += part;
      continue;
    }
    if (!current.empty()) events.push_back(std::move(current));
    current.clear();
    std::string_view rest(part);
    while (!rest.empty() && (rest.front() == ',' || rest.front() == ';' || rest.front() == ' ')) rest.remove_prefix(1);
    if (continued.size() + rest.size() <= kMax) {
      current = continued + std::string(rest);
      continue;
    }
    // Room for the longest label; cut before a UTF-8 continuation byte.
    const std::string widest = continued + "(part 9999 of 9999): ";
    const std::size_t room = kMax - widest.size();
    std::vector<std::string_view> pieces;
    while (!rest.empty()) {
      std::size_t n = std::min(room, rest.size());
      if (n < rest.size())
        while (n > 1 && (static_cast<unsigned char>(rest[n]) & 0xC0u) == 0x80u) --n;
      pieces.push_back(rest.substr(0, n));
      rest.remove_prefix(n);
    }
    for (std::size_t k = 0; k < pieces.size(); ++k)
      events.push_back(continued + "(part " + std::to_string(k + 1) + " of " + std::to_string(pieces.size()) +
                       "): " + std::string(pieces[k]));
  }
  if (!current.empty()) events.push_back(std::move(current));
  return events;
}

// Free bytes for an unprivileged writer on the file system holding `dir`.
std::optional<std::uint64_t> free_bytes_in(const std::string& dir) {
  struct statvfs fs {};
  if (::statvfs(dir.c_str(), &fs) != 0) return std::nullopt;
  return static_cast<std::uint64_t>(fs.f_bavail) * fs.f_frsize;
}

// The automatic recordings in `dir` (the names the service makes up, as
// record::remove_oldest_automatic_recordings takes them), oldest first,
// without `live`.
std::vector<std::string> automatic_recordings_oldest_first(const std::string& dir, const std::string& live) {
  namespace fs = std::filesystem;
  std::vector<std::pair<util::NameStamp, std::string>> files;
  std::error_code ec;
  fs::directory_iterator it(dir, ec), end;
  for (; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(record::kAutomaticPrefix, 0) != 0 || it->path().extension() != ".h5" || !it->is_regular_file(ec))
      continue;
    const std::optional<util::NameStamp> stamp =
        util::read_name_stamp(it->path().stem().string().substr(record::kAutomaticPrefix.size()));
    if (!stamp || (!live.empty() && fs::equivalent(it->path(), live, ec))) continue;
    files.emplace_back(*stamp, it->path().string());
  }
  std::sort(files.begin(), files.end(), [](const auto& x, const auto& y) {
    return std::tie(x.first.time, x.first.k, x.second) < std::tie(y.first.time, y.first.k, y.second);
  });
  std::vector<std::string> out;
  for (auto& f : files) out.push_back(std::move(f.second));
  return out;
}

std::string mib(std::uint64_t bytes) { return std::to_string(bytes >> 20) + " MiB"; }

// The key of a `key=value` override, trimmed of blanks as the override parser
// trims it ("scene = x.yaml" sets `scene`).
std::string_view override_key(std::string_view text) {
  std::string_view key = text.substr(0, text.find('='));
  const std::size_t first = key.find_first_not_of(" \t");
  if (first == std::string_view::npos) return {};
  key.remove_prefix(first);
  return key.substr(0, key.find_last_not_of(" \t") + 1);
}

// A refused `set`, naming the override: the running scene took every value
// before it, so this one broke the scene. The loader blames it itself when
// the error is at its key ("(set by the override '...')"); an error at
// another key (a load region the new cube size leaves outside the object) or
// at the trial step (a gravity of 1e308: "its first step fails") said neither
// the key nor the value the client had sent.
std::string naming_the_override(const std::string& error, const std::string& override) {
  const std::string named = yaml_util::printable_override(override);
  if (error.find(named) != std::string::npos) return error;
  return error + " (caused by the override " + named + ")";
}
}  // namespace

Service::Service(ServiceOptions options)
    : options_(std::move(options)),
      signals_(io_, SIGINT, SIGTERM, SIGHUP),
      status_timer_(io_),
      watchdog_timer_(io_),
      duration_timer_(io_),
      mesh_timer_(io_),
      haptic_timer_(io_),
      stats_timer_(io_) {}

Service::~Service() { stop_threads(); }

std::vector<std::string> Service::config_overrides() const {
  std::vector<std::string> out;
  for (const std::string& o : options_.overrides)
    if (config::is_daemon_config_key(o.substr(0, o.find('=')))) out.push_back(o);
  return out;
}

std::vector<std::string> Service::scene_overrides() const {
  std::vector<std::string> out;
  for (const std::string& o : options_.overrides)
    if (!config::is_daemon_config_key(o.substr(0, o.find('=')))) out.push_back(o);
  return out;
}

scene::Scene Service::load_scene_file(const std::string& path) const {
  return scene::load_scene_file_with_overrides(path, scene_overrides());
}

scene::Scene Service::load_config_scene(const config::DaemonConfig& config) const {
  try {
    return load_scene_file(config.scene_path);
  } catch (const scene::SceneFileUnreadable& e) {
    // A scene file that cannot be read is the config's `scene` at fault (or
    // the --set that changed it): name them. Errors inside the file name
    // the file and key themselves.
    std::string blame;
    for (const std::string& o : config_overrides())
      if (override_key(o) == "scene") blame = " (set by the override " + yaml_util::printable_override(o) + ")";
    throw config::ConfigError(config.source, "scene", e.source() + ": " + e.reason() + blame);
  }
}

void Service::load_config() {
  config_ = config::load_daemon_config(options_.config_path, config_overrides());
  scene_path_ = config_.scene_path;
  base_scene_overrides_ = scene_overrides();
  scene_ = load_config_scene(config_);
  require_servable(scene_);
  try {
    require_steppable(scene_);
  } catch (const scene::SceneModelError& e) {
    throw scene::model_error(scene_, e);
  }
}

namespace {
// What a scene's trial step may cost the control thread, at most (estimated).
constexpr double kMaxTrial_s = 1.0;
}  // namespace

void Service::require_steppable(const scene::Scene& scene) const {
  // One step of a throwaway copy: a scene whose first step fails (forces
  // beyond range, an explicit step above its sub-step cap) would otherwise be
  // answered "ok" and then sit at t = 0 failing every step. The copy doubles
  // the build and adds a step on this (the control) thread, whose timer
  // feeds systemd's 5 s watchdog: a scene whose trial could cost more than
  // about a second starts untried, and a failing step is reported as it
  // happens (note_failing_steps). The estimate takes the worst the caps
  // allow, from measured rates: ~1.2 springs per tet; a CG iteration or an
  // explicit sub-step 2-7 ns per spring (docs/performance.md), taken as 15
  // (a 750,000-tet implicit step at 100 iterations, setup included, took
  // 1.2 s: 13 ns); 750,000 tets build in ~1 s. Projective factors its system
  // first: up to 50,000 tets.
  const double tets = scene::starting_tet_count(scene);
  const scene::IntegratorSpec& g = scene.integrator;
  const double per_spring_s = 15e-9, springs = 1.2 * tets;
  double trial_s = tets * (1.0 / 750'000);
  if (g.kind == scene::IntegratorKind::kExplicit) trial_s += springs * per_spring_s * g.max_substeps;
  if (g.kind == scene::IntegratorKind::kImplicit) trial_s += springs * per_spring_s * g.cg_max_iterations;
  if (g.kind == scene::IntegratorKind::kProjective && tets > 50'000) return;
  if (trial_s > kMaxTrial_s) return;
  physics::Simulation trial(scene);
  if (const physics::StepResult r = trial.step(); !r.ok)
    throw std::invalid_argument("scene '" + scene.name + "' (" + scene.source + "): its first step fails: " + r.error +
                                "; nothing changed");
}

void Service::require_servable(const scene::Scene& scene) const {
  const double tets = scene::starting_tet_count(scene);
  if (tets > config_.max_scene_tets) {
    char count[32];
    std::snprintf(count, sizeof count, "%.0f", tets);
    throw std::invalid_argument("scene '" + scene.name + "': its starting mesh has " + count +
                                " tetrahedra, more than max_scene_tets = " + std::to_string(config_.max_scene_tets) +
                                " in " + options_.config_path +
                                " (it would block the daemon while it is built and cannot run in real time); "
                                "raise max_scene_tets to serve it anyway");
  }
}

void Service::start_threads() {
  samples_ = std::make_unique<ToolSampleRing>();
  models_ = std::make_unique<LocalModelChannel>();
  sim_ = std::make_unique<SimThread>(std::make_unique<SimRunner>(scene_), samples_.get(), models_.get(),
                                     sim_thread_options(config_));
  sim_->start();
  if (scene_.tool && config_.device.kind != config::DeviceSpec::Kind::kNone) start_haptic_side();
}

void Service::stop_threads() {
  // Forces first: the haptic side ramps to zero before anything else stops.
  stop_haptic_side();
  if (sim_) sim_->stop();
  retired_recorders_.clear();  // the sim thread has joined: nothing holds them
  stop_recording();            // after the producers: everything they pushed is written
}

void Service::start_recording(const std::string& name) { install_recorder(open_recorder(name)); }

std::unique_ptr<record::Recorder> Service::open_recorder(const std::string& name) {
  record::SessionMetadata meta;
  meta.scene_name = scene_.name;
  // The texts the running scene and config were built from, not the files as
  // they may be now (edited, gone, or a FIFO that would block this thread);
  // the overrides in force are the first event's.
  meta.scene_text = scene_.source_text;
  meta.config_text = config_.source_text;
  meta.software_version = TISSUE_VERSION;
  record::RecorderOptions options;
  options.on_error = [this](const std::string& message) {
    // Recorder thread: hand the news to the io thread, touch nothing here.
    boost::asio::post(io_, [this, message] {
      std::fprintf(options_.err, "tissued: recording stopped: %s (the simulation goes on)\n", message.c_str());
      std::fflush(options_.err);
      // An automatic recording the reserve stopped goes on in a new file
      // once older automatic files made room (not at the next rotation,
      // up to record.rotate_s later).
      const std::optional<std::uint64_t> free = free_bytes_in(config_.state_dir);
      if (automatic_recording_ && !stopping_ && recorder_ && recorder_->state() == record::RecorderState::kFailed &&
          free && *free < record::RecorderOptions{}.min_free_bytes)
        start_automatic_recording();
    });
  };
  return record::Recorder::start(
      config_.state_dir,
      name.empty() ? util::free_timestamped_name(config_.state_dir, "session-", ".h5", std::time(nullptr)) : name, meta,
      options);
}

void Service::install_recorder(std::unique_ptr<record::Recorder> recorder, std::unique_ptr<SimRunner> runner) {
  // Straight from the old file (if any) to the new one: no row in neither.
  hand_over_recorder(sim_.get(), recorder_, std::move(recorder), retired_recorders_, std::move(runner));
  recorded_description_ = recording_description();
  for (const std::string& text : recording_started_events())
    record_event(static_cast<int>(record::EventKind::kSceneLoaded), text);
  std::fprintf(options_.out, "tissued: recording to %s\n", recorder_->path().c_str());
  std::fflush(options_.out);
}

std::vector<std::string> Service::recording_started_events() const {
  // The parts of the text, each kept whole in one event: the scene and its
  // file, then each override with the separator before it.
  std::vector<std::string> parts{"recording " + scene_.name + " from " + scene_path_};
  const auto add_list = [&parts](const std::string& lead, const std::vector<std::string>& list) {
    for (std::size_t i = 0; i < list.size(); ++i) parts.push_back((i == 0 ? lead : ", ") + list[i]);
  };
  // The scene_text attribute is the file before these (the command line's
  // --set, then the control socket's set).
  add_list(" with ", scene_.overrides);
  add_list("; daemon config " + options_.config_path + " with ", config_overrides());
  // config_text is the file as last (re)loaded; what in it a reload could
  // not apply still runs with the old values (the motor scale, say).
  if (!waiting_for_restart_.empty()) {
    add_list("; ", waiting_for_restart_);
    parts.back() += " in config_text are not in use until a restart (the values before the reload run)";
  }
  return pack_event_texts(parts, "recording, continued: ");
}

std::vector<std::string> Service::make_room_for_automatic_recording() {
  // The reserve stops a recording; a new file needs room above it, as much
  // as the file it follows took (at least kAutomaticRoom_bytes).
  const std::uint64_t reserve = record::RecorderOptions{}.min_free_bytes;
  std::uint64_t room = kAutomaticRoom_bytes;
  std::string live;
  if (recorder_) {
    live = recorder_->path();
    std::error_code ec;
    const std::uintmax_t size = std::filesystem::file_size(live, ec);
    if (!ec) room = std::max<std::uint64_t>(room, size);
  }
  std::optional<std::uint64_t> free = free_bytes_in(config_.state_dir);
  std::vector<std::string> said;
  if (!free || *free >= reserve + room) return said;
  // Only automatic files, never a client's, never the one being written.
  for (const std::string& old : automatic_recordings_oldest_first(config_.state_dir, live)) {
    std::error_code ec;
    if (!std::filesystem::remove(old, ec)) continue;
    said.push_back("removed the oldest automatic recording " + old + " (" + mib(*free) + " free in state_dir " +
                   config_.state_dir + ", less than the " + mib(reserve) + " reserve and " + mib(room) +
                   " for the next file)");
    std::fprintf(options_.out, "tissued: %s\n", said.back().c_str());
    std::fflush(options_.out);
    free = free_bytes_in(config_.state_dir);
    if (!free || *free >= reserve + room) return said;
  }
  if (free && *free < reserve)
    throw std::runtime_error("state_dir " + config_.state_dir + ": disk almost full (" + mib(*free) +
                             " free, reserve " + mib(reserve) +
                             ") and no older automatic recording left to remove: no new file");
  return said;
}

std::unique_ptr<record::Recorder> Service::open_automatic_recorder(std::vector<std::string>* removed) {
  // Room first: past the reserve a new file would stop at once.
  *removed = make_room_for_automatic_recording();
  return open_recorder(
      util::free_timestamped_name(config_.state_dir, record::kAutomaticPrefix, ".h5", std::time(nullptr)));
}

void Service::note_automatic_recording_started(const std::vector<std::string>& removed) {
  for (const std::string& what : removed) record_event(static_cast<int>(record::EventKind::kInfo), what);
  // The oldest automatic files go once they hold more than keep_gb, this
  // one counted; said on stdout and in the new file's events.
  if (config_.record.keep_gb > 0.0)
    for (const std::string& gone : record::remove_oldest_automatic_recordings(
             config_.state_dir, static_cast<std::uintmax_t>(config_.record.keep_gb * 1e9), recorder_->path())) {
      const std::string what = "removed the oldest automatic recording " + gone + " (record.keep_gb " +
                               yaml_util::fmt_num(config_.record.keep_gb) + " reached)";
      std::fprintf(options_.out, "tissued: %s\n", what.c_str());
      record_event(static_cast<int>(record::EventKind::kInfo), what);
    }
}

void Service::start_automatic_recording() {
  automatic_recording_ = true;
  automatic_since_ = std::chrono::steady_clock::now();
  try {
    std::vector<std::string> removed;
    install_recorder(open_automatic_recorder(&removed));
    note_automatic_recording_started(removed);
  } catch (const std::exception& e) {
    // A rotation whose new file cannot be made keeps the old one going.
    const bool going_on = recorder_ && recorder_->state() == record::RecorderState::kRecording;
    std::fprintf(options_.err, "tissued: automatic recording: %s; %s, trying again in %s s\n", e.what(),
                 going_on ? ("the recording goes on in " + recorder_->path()).c_str() : "serving without it",
                 yaml_util::fmt_num(config_.record.rotate_s).c_str());
    std::fflush(options_.err);
  }
}

void Service::rotate_automatic_recording() {
  if (!automatic_recording_) return;
  const std::chrono::duration<double> running = std::chrono::steady_clock::now() - automatic_since_;
  if (running.count() < config_.record.rotate_s) return;
  record_event(static_cast<int>(record::EventKind::kInfo), "record.rotate_s (" +
                                                               yaml_util::fmt_num(config_.record.rotate_s) +
                                                               " s) reached: the recording goes on in a new file");
  start_automatic_recording();  // the new file takes over from this one
}

Service::RecordingHandover Service::continue_recording_in_new_file(const std::string& what,
                                                                   std::unique_ptr<SimRunner> runner) {
  // A session file's scene_name, scene_text and config_text are written once
  // (SWMR): rows of another scene under them would be described as the old
  // one. The new scene's rows go to a new file, which describes them; the
  // old file ends with an event naming it. The new file is made while the
  // old scene still runs (its rows still go to the old file, which describes
  // them), then the sim thread takes the new runner and the new file between
  // two steps: handed the runner first, it stepped the new scene into the
  // old file while the new one was being made.
  RecordingHandover out;
  // The haptic side's trips since the last status tick happened under the
  // scene before: said now, they go to its file. (Said when the side stops,
  // after the hand-over, they went to the new scene's.)
  note_safety_trips();
  // The same scene text, overrides and config text (a load_scene of the
  // running file, a reload of unchanged files): the file still describes it.
  if (!recorder_ || recorder_->state() != record::RecorderState::kRecording ||
      recording_description() == recorded_description_) {
    record_event(static_cast<int>(record::EventKind::kSceneLoaded), what);  // a failed one's last events
    sim_->replace_runner(std::move(runner));
    return out;
  }
  std::vector<std::string> removed;  // automatic files the new one's room took
  std::unique_ptr<record::Recorder> next;
  try {
    next =
        automatic_recording_ ? open_automatic_recorder(&removed) : open_recorder(next_part_name(client_record_name_));
  } catch (const std::exception& e) {
    // Stopped rather than go on under the old scene's description (an
    // automatic recording kept its old file at a failed rotation, where the
    // file still describes the scene running; not here).
    out.stopped = std::string(automatic_recording_ ? "automatic " : "") + "recording stopped at the scene change (" +
                  what + "): the next file cannot be made: " + e.what();
    if (automatic_recording_) {
      // Tried again as after a failed rotation (with no file going on).
      automatic_since_ = std::chrono::steady_clock::now();
      out.stopped += "; trying again in " + yaml_util::fmt_num(config_.record.rotate_s) + " s";
    }
    record_event(static_cast<int>(record::EventKind::kRecordingError), out.stopped);
    stop_recording(std::move(runner));
    std::fprintf(options_.err, "tissued: %s\n", out.stopped.c_str());
    std::fflush(options_.err);
    return out;
  }
  record_event(static_cast<int>(record::EventKind::kSceneLoaded), what + ": the recording goes on in " + next->path());
  if (automatic_recording_) automatic_since_ = std::chrono::steady_clock::now();
  install_recorder(std::move(next), std::move(runner));
  if (automatic_recording_) note_automatic_recording_started(removed);
  if (recorder_ && recorder_->state() == record::RecorderState::kRecording) out.file = recorder_->path();
  return out;
}

std::string Service::recording_description() const {
  std::string d = scene_.name + '\0' + scene_path_ + '\0' + scene_.source_text + '\0' + config_.source_text;
  for (const std::string& o : scene_.overrides) d += '\0' + o;
  return d;
}

std::string Service::next_part_name(const std::string& first) const {
  // exp1.h5 -> exp1-part2.h5, exp1-part3.h5, ...: the first free one.
  const std::filesystem::path p(first);
  const std::string stem = p.stem().string(), extension = p.extension().string();
  std::error_code ec;
  for (int k = 2;; ++k) {
    const std::string suffix = "-part" + std::to_string(k) + extension;
    // A name near the length limit (accepted by record_start) would be
    // refused with the suffix, stopping the recording at the change: the
    // stem is shortened to fit, never within a UTF-8 character.
    std::string name = stem;
    if (name.size() + suffix.size() > record::kMaxSessionNameBytes && suffix.size() < record::kMaxSessionNameBytes) {
      name.resize(record::kMaxSessionNameBytes - suffix.size());
      std::size_t lead = name.size();
      while (lead > 0 && (static_cast<unsigned char>(name[lead - 1]) & 0xC0) == 0x80) --lead;
      if (lead > 0) {
        const unsigned char b = static_cast<unsigned char>(name[lead - 1]);
        const std::size_t length = b < 0x80 ? 1 : b < 0xE0 ? 2 : b < 0xF0 ? 3 : 4;
        if (lead - 1 + length > name.size()) name.resize(lead - 1);  // a character cut short
      }
    }
    name += suffix;
    if (!std::filesystem::exists(std::filesystem::path(config_.state_dir) / name, ec)) return name;
  }
}

void Service::stop_recording(std::unique_ptr<SimRunner> runner) {
  if (!recorder_) {
    if (runner) sim_->replace_runner(std::move(runner));
    return;
  }
  // Closes the file; later pushes from a stalled sim thread are refused.
  hand_over_recorder(sim_.get(), recorder_, nullptr, retired_recorders_, std::move(runner));
}

void Service::record_event(int kind, const std::string& text) {
  if (!recorder_) return;
  recorder_->push_event(record::EventSource::kControl, record::Event::make(recorder_->session_time_s_now(),
                                                                           static_cast<record::EventKind>(kind), text));
}

std::string Service::apply_scene(scene::Scene scene, bool restart_haptics) {
  std::unique_ptr<SimRunner> runner = build_runner(scene);  // throws: nothing changes
  const bool had_tool = scene_.tool.has_value();
  scene_ = std::move(scene);
  sim_->replace_runner(std::move(runner));
  return match_haptics_to_scene(had_tool, restart_haptics);
}

std::unique_ptr<SimRunner> Service::build_runner(const scene::Scene& scene) const {
  require_servable(scene);  // throws std::invalid_argument: nothing changes
  try {
    require_steppable(scene);                   // ditto
    return std::make_unique<SimRunner>(scene);  // ditto
  } catch (const scene::SceneModelError& e) {
    throw scene::model_error(scene, e);  // the file, the key and any --set or `set` to blame
  }
}

std::string Service::match_haptics_to_scene(bool had_tool, bool restart_haptics) {
  const bool want_haptics = scene_.tool && config_.device.kind != config::DeviceSpec::Kind::kNone;
  if (restart_haptics) stop_haptic_side();
  if (had_tool && !want_haptics) {
    stop_haptic_side();
  } else if (want_haptics && !haptics_) {
    try {
      start_haptic_side();
    } catch (const std::exception& e) {
      // Said, not thrown: the sim thread already runs the new scene, and a
      // caller told "failed" would keep the old scene's path and overrides.
      // The next reset, load_scene, set or reload tries the device again.
      return std::string("the haptic device could not start, the scene runs without it: ") + e.what();
    }
  }
  return {};
}

nlohmann::json Service::with_device_warning(nlohmann::json result, const std::string& device_problem) {
  if (device_problem.empty()) return result;
  std::fprintf(options_.err, "tissued: %s\n", device_problem.c_str());
  std::fflush(options_.err);
  record_event(static_cast<int>(record::EventKind::kWarning), device_problem);
  result["warning"] = device_problem;
  return result;
}

void Service::request_stop(const std::string& why) {
  if (stopping_) return;
  stopping_ = true;
  stop_reason_ = why;
  if (systemd_) systemd_->stopping();
  std::fprintf(options_.out, "tissued: stopping (%s)\n", why.c_str());
  std::fflush(options_.out);
  signals_.cancel();
  status_timer_.cancel();
  watchdog_timer_.cancel();
  duration_timer_.cancel();
  mesh_timer_.cancel();
  haptic_timer_.cancel();
  stats_timer_.cancel();
  if (server_) server_->stop();
  // The threads stop in run() once the io_context has no more work.
}

std::vector<std::string> restart_only_changes(const config::DaemonConfig& running, const config::DaemonConfig& file) {
  std::vector<std::string> changed;
  const config::DeviceSpec& a = running.device;
  const config::DeviceSpec& b = file.device;
  if (a.kind != b.kind) changed.push_back("device.kind");
  if (a.offset_m != b.offset_m || a.scale != b.scale) changed.push_back("device.offset_m/scale");
  if (!(a.sim == b.sim)) changed.push_back("device.sim");
  if (!(a.udp == b.udp)) changed.push_back("device.udp");
  if (!(a.openhaptics == b.openhaptics)) changed.push_back("device.openhaptics");
  if (!(a.replay == b.replay)) changed.push_back("device.replay");
  if (!(running.realtime == file.realtime)) changed.push_back("realtime");
  if (!(running.control == file.control)) changed.push_back("control");
  if (!(running.publish == file.publish)) changed.push_back("publish");
  if (running.state_dir != file.state_dir) changed.push_back("state_dir");
  if (!(running.record == file.record)) changed.push_back("record");
  // Whatever else differs once the settings a reload applies are taken as
  // they run: a section added to DaemonConfig and not named above is still
  // reported, never silently kept.
  config::DaemonConfig rest = file;
  rest.source = running.source;
  rest.scene_path = running.scene_path;
  rest.haptics = running.haptics;
  rest.device.limits = running.device.limits;
  rest.status_interval_s = running.status_interval_s;
  rest.max_scene_tets = running.max_scene_tets;
  if (changed.empty() && !(rest == running)) changed.push_back("other settings");
  return changed;
}

void Service::reload() {
  if (systemd_) systemd_->reloading();
  try {
    config::DaemonConfig config = config::load_daemon_config(options_.config_path, config_overrides());
    scene::Scene scene = load_config_scene(config);
    // The scene, haptics.*, device.limits, status_interval_s and
    // max_scene_tets apply now (the haptic thread restarts for the haptic
    // ones: a lowered force limit must not wait for a restart). The device
    // itself, sockets, publishing, state_dir and threads need a restart:
    // said below, never silently kept. Nothing changes unless the new scene
    // is running: a failed reload keeps it all.
    {
      // The file's haptics and limits run with the device settings in use,
      // which only a restart changes (a scale the file changes too is not
      // the one the hand feels the coupling through until then).
      config::DaemonConfig effective = config_;
      effective.haptics = config.haptics;
      effective.device.limits = config.device.limits;
      try {
        config::validate_daemon_config(effective);
      } catch (const config::ConfigError& e) {
        throw std::runtime_error(std::string(e.what()) + " (with device.scale " +
                                 yaml_util::fmt_num(config_.device.scale) + ", in use until a restart)");
      }
    }
    const config::HapticSpec old_haptics = config_.haptics;
    const config::ForceLimits old_limits = config_.device.limits;
    const bool haptics_changed = !(config.haptics == old_haptics) || !(config.device.limits == old_limits);
    const int old_max_scene_tets = config_.max_scene_tets;
    // What the reload changes besides the scene, for its event.
    std::string applied;
    const auto note = [&](bool changed, const char* what) {
      if (changed) applied += std::string(applied.empty() ? "" : ", ") + what;
    };
    note(!(config.haptics == old_haptics), "haptics");
    note(!(config.device.limits == old_limits), "device.limits");
    note(config.status_interval_s != config_.status_interval_s, "status_interval_s");
    note(config.max_scene_tets != old_max_scene_tets, "max_scene_tets");
    config_.haptics = config.haptics;
    config_.device.limits = config.device.limits;
    config_.max_scene_tets = config.max_scene_tets;
    std::unique_ptr<SimRunner> runner;
    try {
      runner = build_runner(scene);  // with the new max_scene_tets
    } catch (...) {
      config_.haptics = old_haptics;
      config_.device.limits = old_limits;
      config_.max_scene_tets = old_max_scene_tets;
      throw;
    }
    // Committed: what a recording describes first, then the runner goes to
    // the sim thread with the recording's next file (nothing below throws).
    const bool had_tool = scene_.tool.has_value();
    scene_ = std::move(scene);
    if (config.status_interval_s != config_.status_interval_s) {
      config_.status_interval_s = config.status_interval_s;
      arm_status_timer();  // now, not after the old interval (up to an hour) has run out
    }
    // Recordings from now on keep the file as read now (a restart-only change
    // in it is said in a warning event below, and waits for the restart).
    config_.source_text = config.source_text;
    scene_path_ = config.scene_path;
    base_scene_overrides_ = scene_overrides();
    scene_sets_.clear();
    const std::vector<std::string> kept = restart_only_changes(config_, config);
    waiting_for_restart_ = kept;  // before the new file's first events, which name them
    // A new file is said by install_recorder ("recording to ..."), a stopped
    // recording by continue_recording_in_new_file.
    (void)continue_recording_in_new_file("reloaded (SIGHUP): scene " + scene_.name + " from " + scene_path_ +
                                             (applied.empty() ? "" : "; changed: " + applied),
                                         std::move(runner));
    const std::string device_problem = match_haptics_to_scene(had_tool, haptics_changed);
    std::fprintf(options_.out, "tissued: reloaded %s and %s%s\n", options_.config_path.c_str(), scene_path_.c_str(),
                 haptics_changed && haptics_ ? " (haptic settings changed: the haptic thread restarted)" : "");
    (void)with_device_warning({}, device_problem);  // said on stderr and recorded; a signal has no reply
    if (!kept.empty()) {
      std::string list;
      for (const std::string& k : kept) list += (list.empty() ? "" : ", ") + k;
      const std::string warning = "reload: " + list + " changed in " + options_.config_path +
                                  ": a restart applies them; until then the old values stay in use";
      std::fprintf(options_.err, "tissued: %s\n", warning.c_str());
      record_event(static_cast<int>(record::EventKind::kWarning), warning);
    }
  } catch (const std::exception& e) {
    std::fprintf(options_.err, "tissued: reload failed, keeping the running scene: %s\n", e.what());
    record_event(static_cast<int>(record::EventKind::kError),
                 std::string("reload (SIGHUP) failed, running scene kept: ") + e.what());
  }
  std::fflush(options_.out);
  if (systemd_) systemd_->ready();
}

void Service::print_status() {
  const SimStatus s = sim_->status();
  char haptic[320] = "";
  if (haptics_) haptics_->summary(haptic, sizeof haptic);
  // Steps whose CG stopped at cg_max_iterations: faster, less accurate than
  // the scene asked; shown only when there are any.
  char capped[64] = "";
  if (s.unconverged_steps > 0)
    std::snprintf(capped, sizeof capped, " | CG capped in %lld steps", static_cast<long long>(s.unconverged_steps));
  char rtf[16] = "  --";  // not measured yet (the first second)
  if (s.real_time_factor_measured) std::snprintf(rtf, sizeof rtf, "%.2f", s.real_time_factor);
  std::fprintf(options_.out,
               "t %8.2f s | nodes %6zu tets %7zu | refines %6lld merges %6lld | rtf %s step %.2f ms%s%s%s%s\n",
               s.sim_time_s, s.nodes, s.tets, static_cast<long long>(s.refines), static_cast<long long>(s.merges), rtf,
               s.step_ms_last, capped, s.paused ? " | paused" : "", s.adaptation_shed ? " | shedding" : "", haptic);
  std::fflush(options_.out);
  if (systemd_) {
    char line[160];
    std::snprintf(line, sizeof line, "t=%.1fs nodes=%zu tets=%zu rtf=%s%s", s.sim_time_s, s.nodes, s.tets, rtf,
                  s.paused ? " paused" : "");
    systemd_->status(line);
  }
}

void Service::arm_signals() {
  signals_.async_wait([this](const boost::system::error_code& ec, int signo) {
    if (ec || stopping_) return;
    if (signo == SIGHUP) {
      reload();
      arm_signals();
      return;
    }
    request_stop(signo == SIGTERM ? "SIGTERM" : "SIGINT");
  });
}

void Service::start_publishing() {
  const config::PublishSpec& pub = config_.publish;
  // Live data is optional: a transport that cannot start says why and the
  // daemon serves without it.
  if (pub.lcm.enabled) {
    try {
      lcm_ = std::make_unique<transport::LcmPublisher>(pub.lcm.url);
      std::fprintf(options_.out, "tissued: publishing over LCM at %s\n", pub.lcm.url.c_str());
    } catch (const std::exception& e) {
      std::fprintf(options_.err, "tissued: %s; LCM publishing is off\n", e.what());
    }
  }
  if (pub.dds.enabled) {
    try {
      transport::DdsOptions o;
      o.domain_id = pub.dds.domain_id;
      o.topic_prefix = pub.dds.topic_prefix;
      o.loopback_only = pub.dds.loopback_only;
      o.max_mesh_bytes = pub.dds.max_mesh_bytes;
      dds_ = std::make_unique<transport::DdsPublisher>(o);
      std::fprintf(options_.out, "tissued: publishing over DDS, domain %d, topics %s*%s\n", o.domain_id,
                   o.topic_prefix.c_str(), o.loopback_only ? " (this host only)" : "");
    } catch (const std::exception& e) {
      std::fprintf(options_.err, "tissued: %s; DDS publishing is off\n", e.what());
    }
  }
  if (!lcm_ && !dds_) return;
  std::fprintf(options_.out, "tissued: mesh %g Hz, haptic state %g Hz, stats %g Hz\n", pub.mesh_rate_hz,
               pub.haptic_rate_hz, pub.stats_rate_hz);
  arm_publish_timer(mesh_timer_, pub.mesh_rate_hz, &Service::publish_mesh);
  // Armed whether or not a haptic side runs now: a later load_scene, set or
  // reset may start one (and stop it again); publish_haptic skips the ticks
  // without one rather than publish a stopped loop's last state.
  arm_publish_timer(haptic_timer_, pub.haptic_rate_hz, &Service::publish_haptic);
  arm_publish_timer(stats_timer_, pub.stats_rate_hz, &Service::publish_stats);
}

void Service::arm_publish_timer(boost::asio::steady_timer& timer, double rate_hz, void (Service::*publish)()) {
  timer.expires_at(next_publish_time(
      timer.expiry(), std::chrono::steady_clock::now(),
      std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(1.0 / rate_hz))));
  timer.async_wait([this, &timer, rate_hz, publish](const boost::system::error_code& ec) {
    if (ec || stopping_) return;
    (this->*publish)();
    arm_publish_timer(timer, rate_hz, publish);
  });
}

// snapshot() and status() have one reader: read once, hand to both.
void Service::publish_mesh() {
  const MeshSnapshot& s = sim_->snapshot();
  if (lcm_) lcm_->publish_mesh(s);
  if (dds_) {
    const std::uint64_t oversize_before = dds_->counts().oversize_meshes, sent_before = dds_->counts().meshes;
    dds_->publish_mesh(s);
    note_dds_oversize(oversize_before, sent_before);
  }
}
void Service::publish_haptic() {
  if (!haptics_) return;
  const SimStatus s = sim_->status();
  if (lcm_) lcm_->publish_haptic(s);
  if (dds_) dds_->publish_haptic(s);
}
void Service::publish_stats() {
  const SimStatus s = sim_->status();
  if (lcm_) lcm_->publish_stats(s);
  if (dds_) dds_->publish_stats(s);
}

// A mesh over publish.dds.max_mesh_bytes is not sent: DDS subscribers keep
// the last one that fitted. Said once when meshes start being held back
// (and again if they do after some went out), not once per mesh.
void Service::note_dds_oversize(std::uint64_t oversize_before, std::uint64_t sent_before) {
  const transport::DdsPublishCounts& c = dds_->counts();
  if (c.meshes > sent_before) dds_oversize_said_ = false;
  if (c.oversize_meshes == oversize_before || dds_oversize_said_) return;
  dds_oversize_said_ = true;
  const std::string text = "DDS: a surface mesh of " + std::to_string(c.last_oversize_bytes) +
                           " bytes serialized is over publish.dds.max_mesh_bytes (" +
                           std::to_string(dds_->options().max_mesh_bytes) +
                           ") and was not sent; DDS subscribers keep the last mesh that fitted until one fits again "
                           "(raise publish.dds.max_mesh_bytes, and the subscribers' --dds-max-mesh-bytes)";
  std::fprintf(options_.err, "tissued: %s\n", text.c_str());
  std::fflush(options_.err);
  record_event(static_cast<int>(record::EventKind::kWarning), text);
}

void Service::note_failing_steps() {
  const double now_s = std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
  const std::optional<FailingStepsNotice> notice = failing_steps_.update(sim_->status(), now_s);
  if (!notice) return;
  record_event(static_cast<int>(notice->error ? record::EventKind::kError : record::EventKind::kInfo), notice->text);
  std::fprintf(options_.err, "tissued: %s\n", notice->text.c_str());
}

void Service::note_safety_trips() {
  if (!haptics_) return;
  if (const std::optional<std::string> text = safety_trips_.update(haptics_->stats(), haptic_side_number_))
    record_event(static_cast<int>(record::EventKind::kWarning), *text);
}

void Service::start_haptic_side() {
  haptics_ = HapticSide::start(config_, *samples_, *models_, options_.out);
  ++haptic_side_number_;
}

void Service::stop_haptic_side() {
  if (!haptics_) return;
  note_safety_trips();  // the trips since the last status tick, before the counts go
  haptics_->stop();     // ramps the force out first
  haptics_.reset();
}

void Service::arm_status_timer() {
  status_timer_.expires_after(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(config_.status_interval_s)));
  status_timer_.async_wait([this](const boost::system::error_code& ec) {
    if (ec || stopping_) return;
    note_safety_trips();
    note_failing_steps();
    rotate_automatic_recording();
    print_status();
    arm_status_timer();
  });
}

void Service::arm_watchdog_timer() {
  if (!watchdog_ || !watchdog_->enabled()) return;
  watchdog_timer_.expires_after(*watchdog_->poll_period());
  watchdog_timer_.async_wait([this](const boost::system::error_code& ec) {
    if (ec || stopping_) return;
    // Fed only while the real-time loop is alive: the haptic heartbeat when
    // there is a haptic thread, else the sim thread's.
    heartbeat_.store(haptics_ ? haptics_->heartbeat() : sim_->heartbeat(), std::memory_order_relaxed);
    watchdog_->poll(std::chrono::steady_clock::now());
    arm_watchdog_timer();
  });
}

int Service::run() {
  try {
    load_config();
  } catch (const std::exception& e) {
    std::fprintf(options_.err, "tissued: %s\n", e.what());
    return kServiceBadConfig;
  }
  try {
    std::filesystem::create_directories(std::filesystem::path(config_.control.unix_socket_path).parent_path());
  } catch (const std::exception&) {
    // The server names the path when it cannot bind; nothing more to say here.
  }
  // The state directory is made too (README: `--set state_dir=/tmp/tissued`):
  // a missing one would leave the automatic recording off for a whole
  // record.rotate_s and refuse every record_start and export.
  {
    std::error_code ec;
    std::filesystem::create_directories(config_.state_dir, ec);
    if (ec)
      std::fprintf(options_.err, "tissued: state_dir %s: cannot make it (%s); recordings and exports will fail\n",
                   config_.state_dir.c_str(), ec.message().c_str());
  }
  // A recorder killed while creating a session leaves a hidden, never
  // published file with no recorded row in it: remove it, named, rather than
  // let such files pile up in the state directory.
  for (const std::string& f : record::remove_abandoned_creations(config_.state_dir))
    std::fprintf(options_.out, "tissued: removed %s: a session creation whose process is gone (no data in it)\n",
                 f.c_str());
  try {
    systemd_ = std::make_unique<control::SystemdNotifier>();
    if (!systemd_->setup_error().empty())
      std::fprintf(options_.err, "tissued: systemd notifications off: %s\n", systemd_->setup_error().c_str());
    if (!systemd_->watchdog_error().empty())
      std::fprintf(options_.err, "tissued: systemd watchdog off: %s\n", systemd_->watchdog_error().c_str());
    watchdog_ = std::make_unique<control::WatchdogFeeder>(*systemd_, heartbeat_);
    start_threads();
    server_ = std::make_unique<control::ControlServer>(io_, control::ServerSettings::from_spec(config_.control), *this);
    server_->start();
    if (!options_.record_name.empty()) {
      record::validate_client_session_name(options_.record_name);
      client_record_name_ = options_.record_name;
      start_recording(options_.record_name);
    } else if (config_.record.auto_start)
      start_automatic_recording();
  } catch (const std::exception& e) {
    std::fprintf(options_.err, "tissued: %s\n", e.what());
    stop_threads();
    return kServiceStartFailed;
  }

  std::string control;
  if (!config_.control.unix_socket_path.empty()) control = config_.control.unix_socket_path;
  if (config_.control.tcp_port != 0)
    control +=
        (control.empty() ? "" : " and ") + std::string("tcp 127.0.0.1:") + std::to_string(config_.control.tcp_port);
  std::fprintf(options_.out, "tissued: scene '%s' (%s), sim thread %s, control %s%s\n", scene_.name.c_str(),
               scene_path_.c_str(), sim_->scheduling().c_str(), control.empty() ? "off" : control.c_str(),
               haptics_ ? "" : ", no haptic thread (no device or the scene has no tool)");
  if (haptics_) haptics_->print_startup(options_.out);
  std::fflush(options_.out);

  arm_signals();
  if (options_.duration_s > 0.0) {
    duration_timer_.expires_after(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(options_.duration_s)));
    duration_timer_.async_wait([this](const boost::system::error_code& ec) {
      if (!ec) request_stop("--duration elapsed");
    });
  }
  arm_status_timer();
  arm_watchdog_timer();
  start_publishing();
  systemd_->ready();

  int code = kServiceOk;
  try {
    io_.run();
  } catch (const std::exception& e) {
    std::fprintf(options_.err, "tissued: internal error: %s\n", e.what());
    code = kServiceInternal;
  }
  stop_threads();
  print_status();
  return code;
}

// ---------------------------------------------------------------- control

nlohmann::json Service::status() {
  nlohmann::json j = status_json(sim_->status());
  j["scene"] = {{"name", scene_.name}, {"source", scene_path_}, {"tool", scene_.tool.has_value()}};
  j["threads"] = {{"sim", sim_->scheduling()}};
  // Read here on the io thread, where the server's connections live.
  if (server_)
    j["control"] = {{"connections", server_->connection_count()},
                    {"idle_connections", server_->idle_connection_count()}};
  j["haptics"] = haptics_ ? haptics_->status_json() : nlohmann::json(nullptr);
  j["publishing"] = {{"lcm", lcm_ ? nlohmann::json{{"url", lcm_->url()},
                                                   {"meshes", lcm_->counts().meshes},
                                                   {"haptic_states", lcm_->counts().haptic_states},
                                                   {"stats", lcm_->counts().stats},
                                                   {"failures", lcm_->counts().failures}}
                                  : nlohmann::json(nullptr)},
                     {"dds", dds_ ? nlohmann::json{{"domain_id", dds_->options().domain_id},
                                                   {"meshes", dds_->counts().meshes},
                                                   {"haptic_states", dds_->counts().haptic_states},
                                                   {"stats", dds_->counts().stats},
                                                   {"failures", dds_->counts().failures},
                                                   {"oversize_meshes", dds_->counts().oversize_meshes}}
                                  : nlohmann::json(nullptr)}};
  if (recorder_) {
    const record::RecorderStats r = recorder_->stats();
    const record::RecorderState state = recorder_->state();
    j["recording"] = {
        {"file", recorder_->path()},
        {"state", state == record::RecorderState::kRecording ? "recording"
                  : state == record::RecorderState::kFailed  ? "failed"
                                                             : "stopped"},
        {"error", recorder_->error()},
        {"haptic_rows", r.haptic_rows_written},
        {"sim_rows", r.sim_rows_written},
        {"mesh_frames", r.mesh_frames_written},
        // Refused frames (each with a warning event) are not in the file either.
        {"drops", r.haptic_drops + r.sim_drops + r.mesh_frame_drops + r.mesh_frames_invalid + r.event_drops},
        {"bytes", r.bytes_written},
        {"automatic", automatic_recording_}};
  } else {
    j["recording"] = nullptr;
  }
  return j;
}

// Operator actions go in the recording's events too: a session reviewed
// later shows when the clock stopped or the object was put back at rest.
nlohmann::json Service::pause() {
  sim_->pause();
  record_event(static_cast<int>(record::EventKind::kInfo), "simulation paused (control)");
  return {{"paused", true}};
}

nlohmann::json Service::resume() {
  sim_->resume();
  record_event(static_cast<int>(record::EventKind::kInfo), "simulation resumed (control)");
  return {{"paused", false}};
}

nlohmann::json Service::reset() {
  std::string device_problem;
  try {
    device_problem = apply_scene(scene_);
  } catch (const std::exception& e) {
    throw control::ControlError(std::string("reset failed: ") + e.what());
  }
  record_event(static_cast<int>(record::EventKind::kInfo), "scene " + scene_.name + " reset to rest (control)");
  return with_device_warning({{"scene", scene_.name}, {"reset", true}}, device_problem);
}

nlohmann::json Service::load_scene(const std::string& path) {
  scene::Scene scene;
  std::unique_ptr<SimRunner> runner;
  try {
    // The file as written: earlier `set`s and the command line's --set were
    // for the scene that was running.
    scene = scene::load_scene_file_with_overrides(path, {});
    runner = build_runner(scene);
  } catch (const std::exception& e) {
    throw control::ControlError(e.what());  // names the file, the key and the reason
  }
  // Committed: what a recording describes first, then the runner goes to
  // the sim thread with the recording's next file (nothing below throws).
  const bool had_tool = scene_.tool.has_value();
  scene_ = std::move(scene);
  scene_path_ = path;
  base_scene_overrides_.clear();
  scene_sets_.clear();
  nlohmann::json result = {{"scene", scene_.name}, {"source", path}};
  const RecordingHandover handover =
      continue_recording_in_new_file("scene " + scene_.name + " loaded from " + path, std::move(runner));
  const std::string device_problem = match_haptics_to_scene(had_tool, false);
  if (!handover.file.empty()) result["recording"] = handover.file;
  if (!handover.stopped.empty()) result["recording_stopped"] = handover.stopped;
  return with_device_warning(std::move(result), device_problem);
}

nlohmann::json Service::set(const std::string& key, const nlohmann::json& value) {
  const std::string override = control::set_override_text(key, value);
  if (config::is_daemon_config_key(key))
    // Device, socket and thread settings cannot change under a running loop,
    // and a value kept only in memory would be lost at the next restart: the
    // file is where daemon settings live.
    throw control::ControlError(
        "'" + key + "' is a daemon setting: edit " + options_.config_path +
        " and reload (SIGHUP: scene, haptics.*, device.limits.*, status_interval_s, max_scene_tets) or restart; set "
        "changes scene keys only");
  scene::Scene scene;
  std::vector<std::string> sets;
  std::string device_problem;
  try {
    // A new value replaces the old one for its key and for every key inside
    // it (a whole list after one of its elements).
    sets = scene::with_override_replacing(scene_sets_, override, scene_path_);
    std::vector<std::string> overrides = base_scene_overrides_;
    overrides.insert(overrides.end(), sets.begin(), sets.end());
    // The running scene's own text: the file may have been edited (set would
    // bring in those edits unsaid) or removed since it was loaded.
    scene = scene::parse_scene_with_overrides(scene_.source_text, scene_path_, overrides);
    device_problem = apply_scene(std::move(scene));
  } catch (const std::exception& e) {
    throw control::ControlError(naming_the_override(e.what(), override));
  }
  scene_sets_ = std::move(sets);
  record_event(static_cast<int>(record::EventKind::kParameterChanged), override + " (scene restarted)");
  return with_device_warning({{"key", key}, {"value", value}, {"applied", "scene restarted with the new value"}},
                             device_problem);
}

nlohmann::json Service::record_start(const std::string& name) {
  // A name that cannot be the client's is refused before anything stops:
  // an automatic recording goes on.
  if (!name.empty()) {
    try {
      record::validate_client_session_name(name);
    } catch (const record::RecordError& e) {
      throw control::ControlError(e.what());
    }
  }
  // The daemon's own recording gives way to a client's (the lab's "record
  // this as exp1.h5"); a client's is stopped by a client.
  if (recorder_ && recorder_->state() == record::RecorderState::kRecording && !automatic_recording_)
    throw control::ControlError("already recording to " + recorder_->path() + "; record_stop first");
  // The new file first: one that cannot be made (the name taken, the disk
  // full) changes nothing, and an automatic recording goes on.
  std::unique_ptr<record::Recorder> next;
  try {
    next = open_recorder(name);
  } catch (const std::exception& e) {
    throw control::ControlError(e.what());  // names the file and the reason
  }
  if (recorder_ && recorder_->state() == record::RecorderState::kRecording && automatic_recording_)
    record_event(static_cast<int>(record::EventKind::kInfo),
                 "record_start " + next->path() + " (control): the automatic recording ends here");
  automatic_recording_ = false;  // the client's from now on
  client_record_name_ = std::filesystem::path(next->path()).filename().string();
  install_recorder(std::move(next));  // closes the automatic or a failed earlier one
  return {{"file", recorder_->path()}};
}

nlohmann::json Service::record_stop() {
  if (!recorder_ && automatic_recording_) {
    // An automatic recording stopped at a scene change (or whose file could
    // not be made) waits for its next try: record_stop ends it too. Left
    // pending, record.rotate_s later a new file started against the
    // operator's wish.
    automatic_recording_ = false;
    return {{"file", nullptr},
            {"error", nullptr},
            {"cancelled", "no file was open: the automatic recording's next try (record.rotate_s) is cancelled"}};
  }
  if (!recorder_) throw control::ControlError("not recording");
  const std::string path = recorder_->path();
  const std::string error = recorder_->error();
  stop_recording();
  automatic_recording_ = false;
  // Stats are gone with the recorder; the file says it all (tissue session info).
  return {{"file", path}, {"error", error.empty() ? nlohmann::json(nullptr) : nlohmann::json(error)}};
}

nlohmann::json Service::export_x3d(const std::string& name) {
  const std::string file_name =
      name.empty() ? util::free_timestamped_name(config_.state_dir, "surface-", ".x3d", std::time(nullptr)) : name;
  // Same rule as a client's recordings: a plain file name inside the state
  // directory, not named like an automatic recording (record.keep_gb would
  // remove it as one).
  try {
    record::validate_client_session_name(file_name, "export");
  } catch (const std::exception& e) {
    // No "export_x3d:" prefix: tissue ctl puts the command's name before it.
    throw control::ControlError(std::string(e.what()) + "; files go to state_dir " + config_.state_dir);
  }
  const MeshSnapshot& snap = sim_->snapshot();
  if (snap.sequence == 0) throw control::ControlError("no surface yet; try again in a moment");
  x3d::SurfaceFrame frame;
  frame.time_s = snap.sim_time_s;
  frame.vertices_m = snap.vertices_m;
  frame.triangles = snap.triangles;
  frame.vertex_level = snap.vertex_level;
  x3d::X3dOptions options;
  options.title = scene_.name + " at t = " + std::to_string(snap.sim_time_s) + " s";
  const std::filesystem::path path = std::filesystem::path(config_.state_dir) / file_name;
  // Written whole to a hidden temporary file, synced, then given its name
  // only if nothing has it by then: "never overwritten" holds even against a
  // file (or a link) made meanwhile, and a failed write or a crash (a kill,
  // the watchdog, power) leaves no part file under the name.
  const std::string text = x3d::x3d_snapshot(frame, options);
  util::PendingOutputFile file;
  std::string why = file.open_new(path.string());
  if (why.empty()) why = file.commit(text);
  if (why == util::PendingOutputFile::kAlreadyExists)
    throw control::ControlError(path.string() + " exists; files are never overwritten");
  if (!why.empty()) throw control::ControlError("cannot write " + path.string() + ": " + why);
  return {{"file", path.string()}, {"sim_time_s", snap.sim_time_s}, {"triangles", snap.triangles.size()}};
}

nlohmann::json Service::shutdown() {
  boost::asio::post(io_, [this] { request_stop("shutdown command"); });
  return {{"stopping", true}};
}

}  // namespace tissue::service
