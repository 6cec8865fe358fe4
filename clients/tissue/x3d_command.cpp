#include "tissue/x3d_command.hpp"

#include <CLI/CLI.hpp>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "export/frame_source.hpp"
#include "export/live_source.hpp"
#include "export/x3d.hpp"
#include "tissue/cli_checks.hpp"
#include "tissue/live_source_options.hpp"
#include "util/output_file.hpp"
#include "util/text.hpp"

namespace tissue::cli {

namespace {

constexpr int kExitBadInput = 1;  // same value as kExitDaemonError: "the thing you asked about is broken"

struct X3dCommandOptions {
  std::string session;
  std::optional<double> time_s;
  std::optional<std::size_t> frame;
  bool animate = false;
  std::optional<double> from_s, to_s;
  std::string colour = "level";
  std::string out;
  LiveSourceOptions live;
};

// Bad arguments, found only once the source is open (e.g. a frame number
// past the end): reported like parse errors, exit 2.
struct BadArguments : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// The window options as the user gave them, for messages: "--from 0.5 --to
// 2", "--to 2", or "(all frames)" when neither was given.
std::string given_window_text(const X3dCommandOptions& o) {
  std::string text;
  if (o.from_s) text = "--from " + util::number_text(*o.from_s);
  if (o.to_s) text += (text.empty() ? "" : " ") + std::string("--to ") + util::number_text(*o.to_s);
  return text.empty() ? "(all frames)" : text;
}

std::string export_snapshot(x3d::FrameSource& source, const X3dCommandOptions& o, const x3d::X3dOptions& xo,
                            std::string* summary) {
  const std::size_t n = source.frame_count();
  if (n == 0) throw x3d::SourceError(source.name() + ": the session holds no complete mesh frame");
  std::size_t k = n - 1;
  if (o.frame) {
    if (*o.frame >= n)
      throw BadArguments("--frame " + std::to_string(*o.frame) + ": " + source.name() + " has " + std::to_string(n) +
                         " frames (0 to " + std::to_string(n - 1) + ")");
    k = *o.frame;
  } else if (o.time_s) {
    const auto at = x3d::frame_at_time(source, *o.time_s);
    if (!at)
      throw BadArguments("--time " + util::number_text(*o.time_s) + ": " + source.name() +
                         " has no frame that early (first at " + x3d::frame_time_text(source.frame_time_s(0)) + " s)");
    k = *at;
  }
  x3d::SurfaceFrame frame = source.read_frame(k);
  try {
    // Validated here first so a bad stored frame is named by its number.
    x3d::validate_frame(frame, xo.colour == x3d::ColourMode::kStrain, "frame " + std::to_string(k));
    std::string text = x3d::x3d_snapshot(frame, xo);
    *summary = "frame " + std::to_string(k) + " at t=" + x3d::frame_time_text(frame.time_s) + " s, " +
               std::to_string(frame.vertices_m.size()) + " vertices, " + std::to_string(frame.triangles.size()) +
               " triangles";
    return text;
  } catch (const x3d::X3dInputError& e) {
    throw x3d::SourceError(source.name() + ": " + e.what());
  }
}

std::string export_animation(x3d::FrameSource& source, const X3dCommandOptions& o, const x3d::X3dOptions& xo,
                             std::string* summary) {
  const std::size_t n = source.frame_count();
  if (n == 0) throw x3d::SourceError(source.name() + ": the session holds no complete mesh frame");
  const double t0 = o.from_s.value_or(source.frame_time_s(0));
  const double t1 = o.to_s.value_or(source.frame_time_s(n - 1));
  // An animation needs two frames, so a window of no length (--from 0.1
  // --to 0.1, which may hold one frame) is refused with the reason. Without
  // --from/--to the window is the source's own: frames all at one time
  // (a live stream from a paused daemon) are the source's, not the
  // arguments' (it said "--from 0 --to 0" to a user who gave neither).
  const bool window_given = o.from_s.has_value() || o.to_s.has_value();
  if (!window_given && !(t0 < t1))
    throw x3d::SourceError(source.name() + ": its " + std::to_string(n) +
                           " frames are all at t=" + x3d::frame_time_text(t0) +
                           " s (a paused simulation sends the same time); an animation needs frames at 2 times");
  // Said with the options the user gave: the other end is the source's
  // first or last frame ("--to 0.05" said "--from 0.1 --to 0.05").
  if (!(t0 < t1)) {
    // A window that ends before it starts, as tissue render says it.
    if (t0 != t1) {
      const std::string why = x3d::reversed_window_text(source, o.from_s, o.to_s, t0, t1);
      throw BadArguments(o.from_s && o.to_s ? why : why + ": an animation needs at least 2 frames");
    }
    if (o.from_s && o.to_s)
      throw BadArguments("--from " + util::number_text(t0) + " --to " + util::number_text(t1) +
                         ": the window has no length; an animation needs at least 2 frames");
    if (o.to_s)
      throw BadArguments("--to " + util::number_text(t1) + " is the time of the first frame (t=" +
                         x3d::frame_time_text(t0) + " s): an animation needs at least 2 frames");
    throw BadArguments("--from " + util::number_text(t0) + " is the time of the last frame (t=" +
                       x3d::frame_time_text(t1) + " s): an animation needs at least 2 frames");
  }
  std::vector<std::size_t> picked = x3d::frames_in_window(source, t0, t1);
  // Every frame of the window is held at once: refused before reading when
  // the source's index says they do not fit (an hour of a large surface is
  // hundreds of GB, and ended in std::bad_alloc or the OOM killer).
  if (const std::string over = x3d::frame_budget_problem(source, picked, x3d::kExportFrameBudgetBytes); !over.empty())
    throw BadArguments("--animate " + given_window_text(o) + ": " + over +
                       "; choose a shorter window with --from/--to");
  std::vector<x3d::SurfaceFrame> frames;
  std::size_t skipped_empty = 0;
  for (const std::size_t k : picked) {
    x3d::SurfaceFrame f = source.read_frame(k);
    // A session may record an empty surface (before a scene is loaded);
    // there is nothing to draw for it.
    if (f.vertices_m.empty() || f.triangles.empty()) {
      ++skipped_empty;
      continue;
    }
    try {
      // Validated on read so errors name the session's frame number, not
      // the position in the window.
      x3d::validate_frame(f, xo.colour == x3d::ColourMode::kStrain, "frame " + std::to_string(k));
    } catch (const x3d::X3dInputError& e) {
      throw x3d::SourceError(source.name() + ": " + e.what());
    }
    frames.push_back(std::move(f));
  }
  if (frames.size() < 2)
    throw BadArguments("--animate: " + source.name() + " has " + std::to_string(frames.size()) + " non-empty frames " +
                       x3d::window_text(o.from_s, o.to_s, t0, t1) + "; an animation needs 2");
  try {
    std::string text = x3d::x3d_animation(frames, xo);
    const std::size_t runs = x3d::animation_runs(frames, xo).size();
    *summary = std::to_string(frames.size()) + " frames from t=" + x3d::frame_time_text(frames.front().time_s) +
               " s to " + x3d::frame_time_text(frames.back().time_s) + " s, " + std::to_string(runs) +
               " topology run(s)";
    if (skipped_empty > 0) *summary += ", " + std::to_string(skipped_empty) + " empty frames skipped";
    if (const std::string dropped = source.dropped_note(); !dropped.empty()) *summary += "; " + dropped;
    return text;
  } catch (const x3d::X3dInputError& e) {
    throw x3d::SourceError(source.name() + ": " + e.what());
  }
}

int run_x3d(const X3dCommandOptions& o) {
  x3d::X3dOptions xo;
  xo.colour = o.colour == "strain" ? x3d::ColourMode::kStrain : x3d::ColourMode::kLevel;
  try {
    if (o.session.empty() && !o.live.live())
      throw BadArguments("--session is required (or a live source: --lcm [URL] or --dds)");
    if (o.out.empty()) throw BadArguments("-o: the output path is empty");
    // A mistaken argument, as in tissue render, not an output that fails
    // (exit 1, "cannot write 'DIR': is a directory").
    std::error_code ec;
    if (o.out.back() == '/' || std::filesystem::is_directory(o.out, ec))
      throw BadArguments("-o " + o.out + ": a directory; name the X3D file to write in it (-o " +
                         (o.out.back() == '/' ? o.out.substr(0, o.out.size() - 1) : o.out) + "/scene.x3d)");
    // The rename would put the export where the recording was.
    if (!o.live.live() && util::same_file(o.out, o.session))
      throw x3d::SourceError("-o " + o.out + " is the input session " + o.session +
                             ": writing it would destroy the recording; choose another output file");
    // Checked before the frames are read: a live --animate collects for up to
    // an hour, and an OUT that cannot be written (a missing directory) was
    // found only after it, losing the take. Only checked (output_problem):
    // the file opened here was held through the collection, so a signal
    // that killed the client left its temporary file behind, and a FIFO's
    // open waited for its reader before collecting began.
    if (const std::string why = output_problem(o.out); !why.empty())
      throw x3d::SourceError("cannot write '" + o.out + "': " + why);
    std::string stop_note;
    std::unique_ptr<x3d::FrameSource> source =
        o.live.live() ? open_live_source(o.live, o.animate, &stop_note) : x3d::open_session_source(o.session);
    if (!stop_note.empty()) std::cerr << "tissue x3d: " << stop_note << "; exporting those\n";
    if (xo.colour == x3d::ColourMode::kStrain && !source->has_strain())
      throw BadArguments(x3d::no_strain_message(*source));
    xo.title = "tissue: " + (o.live.live() ? source->name() : o.session);
    std::string summary;
    const std::string text =
        o.animate ? export_animation(*source, o, xo, &summary) : export_snapshot(*source, o, xo, &summary);
    // Regular files are written via a temporary and a rename (a failed
    // export never leaves a truncated OUT behind), devices and FIFOs in place
    // (util::PendingOutputFile).
    util::PendingOutputFile out;
    std::string why = out.open(o.out);
    if (why.empty()) why = out.commit(text);
    if (!why.empty()) throw x3d::SourceError("cannot write '" + o.out + "': " + why);
    util::summary_stream(o.out) << "wrote " << o.out << ": " << summary << "\n";  // not into the X3D
    return kExitOk;
  } catch (const BadArguments& e) {
    std::cerr << "tissue x3d: " << e.what() << "\n";
    return kExitBadArguments;
  } catch (const x3d::NoLiveFrameError& e) {
    std::cerr << "tissue x3d: " << e.what() << "\n";
    return kExitNoLiveData;
  } catch (const LiveStartError& e) {
    std::cerr << "tissue x3d: " << e.what() << "\n";
    return kExitCannotConnect;
  } catch (const x3d::SourceError& e) {
    std::cerr << "tissue x3d: " << e.what() << "\n";
    return kExitBadInput;
  }
}

}  // namespace

Subcommand add_x3d_command(CLI::App& parent) {
  auto o = std::make_shared<X3dCommandOptions>();
  CLI::App* cmd =
      parent.add_subcommand("x3d", "Export the tissue surface of a recorded session or live data as X3D (XML)");
  CLI::Option* session = cmd->add_option("--session", o->session, "Session file (.h5) to read frames from");
  CLI::Option* time =
      cmd->add_option("--time", o->time_s, "Snapshot of the frame shown at session time T (s)")->check(finite_number());
  CLI::Option* frame = cmd->add_option("--frame", o->frame, "Snapshot of frame K (0-based; default: the last)")
                           ->transform(frame_index());
  time->excludes(frame);
  CLI::Option* animate = cmd->add_flag("--animate", o->animate, "Animation over --from..--to (default: all frames)");
  animate->excludes(time)->excludes(frame);
  cmd->add_option("--from", o->from_s, "Animation window start, session time (s)")
      ->check(finite_number())
      ->needs(animate);
  cmd->add_option("--to", o->to_s, "Animation window end, session time (s)")->check(finite_number())->needs(animate);
  cmd->add_option("--colour", o->colour, "Vertex colours: level (bisection depth) or strain (energy density)")
      ->check(CLI::IsMember({"level", "strain"}))
      ->capture_default_str();
  cmd->add_option("-o,--output", o->out, "Output file (.x3d)")->required();
  add_live_source_options(cmd, o->live, session, animate);
  o->live.frames_needed = 2;  // an animation: frames at 2 times at least (a stop after one is said as such)
  // Frame numbers and session times select among a session's frames only.
  for (CLI::Option* opt : {time, frame}) opt->excludes(o->live.lcm_option)->excludes(o->live.dds_option);
  cmd->get_option("--from")->needs(session);
  cmd->get_option("--to")->needs(session);
  cmd->footer(
      "Sources: --session FILE, or live: --lcm [URL] / --dds (a snapshot of the next frame received; --animate:\n"
      "the frames received for --seconds S).\n"
      "OUT's directory must exist (an OUT that is a directory is a bad argument); OUT is checked before any\n"
      "frame is read or collected.\n"
      "Ctrl-C or SIGTERM during a live --animate ends the collection: the frames so far are exported.\n"
      "Exit codes: 0 ok (also when the collection was cut short), 1 unreadable input or unwritable output,\n"
      "2 bad arguments, 3 LCM/DDS cannot start, 4 live: no surface_mesh within --timeout S (or stopped before one).");
  return Subcommand{cmd, [o] { return run_x3d(*o); }};
}

}  // namespace tissue::cli
