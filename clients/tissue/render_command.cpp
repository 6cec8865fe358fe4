#include "tissue/render_command.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "export/frame_source.hpp"
#include "export/live_source.hpp"
#include "render/png_writer.hpp"
#include "render/render.hpp"
#include "tissue/cli_checks.hpp"
#include "tissue/live_source_options.hpp"
#include "util/output_file.hpp"
#include "util/text.hpp"

namespace tissue::cli {

namespace {

constexpr int kExitBadInput = 1;

struct RenderCommandOptions {
  std::string session;
  std::optional<double> time_s;
  std::optional<std::size_t> frame;
  bool sequence = false;
  std::optional<double> from_s, to_s;
  render::RenderOptions image;
  bool no_legend = false;
  std::string colour = "level";
  std::string out;
  LiveSourceOptions live;
};

// OUT for frame i of a sequence: "%04d" in OUT is replaced, else -0000 goes
// before the extension.
std::string numbered(const std::string& out, std::size_t i) {
  char num[24];
  std::snprintf(num, sizeof num, "%04zu", i);
  if (const auto p = out.find("%04d"); p != std::string::npos) return out.substr(0, p) + num + out.substr(p + 4);
  const auto dot = out.rfind('.');
  const auto slash = out.rfind('/');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return out + "-" + num;
  return out.substr(0, dot) + "-" + num + out.substr(dot);
}

// Whether numbered() puts each frame in a directory of its own (%04d in a
// directory name of OUT, e.g. run%04d/frame.png).
bool numbers_a_directory(const std::string& out) {
  const auto p = out.find("%04d");
  return p != std::string::npos && out.find('/', p) != std::string::npos;
}

int run_render(RenderCommandOptions o) {
  o.image.legend = !o.no_legend;
  o.image.colour = o.colour == "strain" ? x3d::ColourMode::kStrain : x3d::ColourMode::kLevel;
  try {
    if (o.session.empty() && !o.live.live()) {
      std::cerr << "tissue render: --session is required (or a live source: --lcm [URL] or --dds)\n";
      return kExitBadArguments;
    }
    if (o.out.empty()) {
      std::cerr << "tissue render: -o: the output path is empty\n";
      return kExitBadArguments;
    }
    // An OUT that names a directory is a mistaken argument, exit 2 as the
    // rest: one picture was exit 1 ("cannot write DIR: is a directory"), the
    // code of an output that fails; a sequence put -0000 before OUT's
    // extension, so a directory got DIR/-0000, DIR/-0001, ... with no
    // extension.
    std::error_code ec;
    if (o.out.back() == '/' || std::filesystem::is_directory(o.out, ec)) {
      std::cerr << "tissue render: -o " << o.out << ": a directory; "
                << (o.sequence ? "--sequence numbers a file name in it (-o DIR/frame.png writes DIR/frame-0000.png, "
                                 "DIR/frame-0001.png, ...)"
                               : "name the PNG file to write in it (-o DIR/frame.png)")
                << "\n";
      return kExitBadArguments;
    }
    // A live collection's frames are counted only once it is over, so the
    // directories of run%04d/frame.png could not all be checked before it
    // (below), and a missing one would lose the take.
    if (o.sequence && o.live.live() && numbers_a_directory(o.out)) {
      std::cerr << "tissue render: -o " << o.out
                << ": %04d in a directory name; a live --sequence numbers the file name only (the directories its "
                   "frames would need cannot be checked before the collection)\n";
      return kExitBadArguments;
    }
    // Before the frames are read: a live --sequence collects for up to an
    // hour, and an OUT that cannot be written (a missing directory) was found
    // only after it, losing the take. A live sequence's files share OUT's
    // directory (above): the first one stands for them here, and every file
    // is checked once the frames are counted (a session's before any is read).
    const std::string first_out = o.sequence ? numbered(o.out, 0) : o.out;
    if (const std::string why = output_problem(first_out); !why.empty()) {
      std::cerr << "tissue render: cannot write " << first_out << ": " << why << "\n";
      return kExitBadInput;
    }
    std::string stop_note;
    std::unique_ptr<x3d::FrameSource> source =
        o.live.live() ? open_live_source(o.live, o.sequence, &stop_note) : x3d::open_session_source(o.session);
    if (!stop_note.empty()) std::cerr << "tissue render: " << stop_note << "; rendering those\n";
    if (o.image.colour == x3d::ColourMode::kStrain && !source->has_strain()) {
      std::cerr << "tissue render: " << x3d::no_strain_message(*source) << "\n";
      return kExitBadArguments;
    }
    const std::size_t n = source->frame_count();
    if (n == 0) {
      std::cerr << "tissue render: " << source->name() << ": the session holds no complete mesh frame\n";
      return kExitBadInput;
    }
    std::vector<std::size_t> frames;
    // The sequence's window; an end not given is the first or last frame's time.
    const double t0_s = o.from_s.value_or(source->frame_time_s(0));
    const double t1_s = o.to_s.value_or(source->frame_time_s(n - 1));
    if (o.sequence) {
      frames = x3d::frames_in_window(*source, t0_s, t1_s);
      // Said with the session and the window, as tissue x3d --animate says
      // it (it said "no frame in the --from/--to window", naming neither).
      if (frames.empty()) {
        std::cerr << "tissue render: "
                  << (t0_s > t1_s ? x3d::reversed_window_text(*source, o.from_s, o.to_s, t0_s, t1_s)
                                  : "--sequence: " + source->name() + " has no frame " +
                                        x3d::window_text(o.from_s, o.to_s, t0_s, t1_s))
                  << "\n";
        return kExitBadArguments;
      }
      // Every file the window's frames may need (empty frames, skipped,
      // leave the last numbers unused), before any is written: a later file
      // that could not be written (its own %04d directory missing, its name
      // taken by a directory) was found after the earlier pictures were.
      std::vector<std::string> outs;
      outs.reserve(frames.size());
      for (std::size_t i = 0; i < frames.size(); ++i) outs.push_back(numbered(o.out, i));
      if (const std::optional<OutputProblem> bad = first_output_problem(outs)) {
        std::cerr << "tissue render: cannot write " << bad->path << ": " << bad->why << "\n";
        return kExitBadInput;
      }
    } else if (o.frame) {
      if (*o.frame >= n) {
        std::cerr << "tissue render: --frame " << *o.frame << ": " << source->name() << " has " << n << " frames\n";
        return kExitBadArguments;
      }
      frames = {*o.frame};
    } else if (o.time_s) {
      const auto at = x3d::frame_at_time(*source, *o.time_s);
      if (!at) {
        std::cerr << "tissue render: --time " << util::number_text(*o.time_s) << ": " << source->name()
                  << " has no frame that early (first at " << x3d::frame_time_text(source->frame_time_s(0)) << " s)\n";
        return kExitBadArguments;
      }
      frames = {*at};
    } else {
      frames = {n - 1};
    }
    std::size_t skipped_empty = 0;
    if (o.sequence) {
      // One camera for the whole sequence (as x3d --animate): the union of
      // the frames' bounds, read in a first pass, so motion shows. A session
      // may record an empty surface (before a scene is loaded): skipped and
      // counted, as x3d --animate and xdmf do; it made the whole sequence fail.
      render::Box_m box = render::empty_box_m();
      std::vector<std::size_t> drawn;
      for (const std::size_t i : frames) {
        const x3d::SurfaceFrame frame = source->read_frame(i);
        if (frame.vertices_m.empty() || frame.triangles.empty()) {
          ++skipped_empty;
          continue;
        }
        x3d::validate_frame(frame, false, "frame " + std::to_string(i));  // all finite, indices in range
        render::extend_box_m(box, frame);
        drawn.push_back(i);
      }
      if (drawn.empty()) {
        std::cerr << "tissue render: --sequence: " << source->name() << ": its " << frames.size() << " frames "
                  << x3d::window_text(o.from_s, o.to_s, t0_s, t1_s) << " are all empty surfaces: nothing to draw\n";
        return kExitBadInput;
      }
      frames = std::move(drawn);
      o.image.frame_box_m = box;
    }
    render::Renderer renderer;  // one context for the whole sequence
    for (std::size_t i = 0; i < frames.size(); ++i) {
      const x3d::SurfaceFrame frame = source->read_frame(frames[i]);
      // Checked here first so a bad frame is named by its number (the
      // renderer, given a frame alone, can say only "frame").
      x3d::validate_frame(frame, o.image.colour == x3d::ColourMode::kStrain, "frame " + std::to_string(frames[i]));
      const std::string path = o.sequence ? numbered(o.out, i) : o.out;
      // write_png truncates PATH: were it the session, the recording would be gone.
      if (!o.live.live() && util::same_file(path, o.session)) {
        std::cerr << "tissue render: -o " << path << " is the input session " << o.session
                  << ": writing it would destroy the recording; choose another output file\n";
        return kExitBadInput;
      }
      render::write_png(renderer.render(frame, o.image), path);
      std::ostream& said = util::summary_stream(path);  // not into the picture (-o /dev/stdout)
      said << "wrote " << path << ": frame " << frames[i] << " at t=" << x3d::frame_time_text(frame.time_s) << " s, "
           << frame.triangles.size() << " triangles";
      if (o.image.colour == x3d::ColourMode::kStrain) {  // the ramp legend has no numbers: its ends are here
        const auto range = render::strain_range_Pa(frame, o.image);
        said << ", strain " << range[0] << " to " << range[1] << " Pa";
      }
      said << "\n";
    }
    if (skipped_empty > 0)
      util::summary_stream(o.out) << "tissue render: " << skipped_empty << " empty frames skipped\n";
    if (const std::string dropped = source->dropped_note(); !dropped.empty())
      util::summary_stream(o.out) << "tissue render: " << dropped << "\n";
    return kExitOk;
  } catch (const render::RenderError& e) {
    std::cerr << "tissue render: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const x3d::X3dInputError& e) {
    std::cerr << "tissue render: " << (o.live.live() ? std::string("live frame") : o.session) << ": " << e.what()
              << "\n";
    return kExitBadInput;
  } catch (const x3d::NoLiveFrameError& e) {
    std::cerr << "tissue render: " << e.what() << "\n";
    return kExitNoLiveData;
  } catch (const LiveStartError& e) {
    std::cerr << "tissue render: " << e.what() << "\n";
    return kExitCannotConnect;
  } catch (const x3d::SourceError& e) {
    std::cerr << "tissue render: " << e.what() << "\n";
    return kExitBadInput;
  }
}

}  // namespace

Subcommand add_render_command(CLI::App& parent) {
  auto o = std::make_shared<RenderCommandOptions>();
  CLI::App* cmd =
      parent.add_subcommand("render", "Draw the tissue surface of a recorded session or live data to PNG (OSMesa)");
  CLI::Option* session = cmd->add_option("--session", o->session, "Session file (.h5) to read frames from");
  CLI::Option* time =
      cmd->add_option("--time", o->time_s, "The frame shown at session time T (s)")->check(finite_number());
  CLI::Option* frame =
      cmd->add_option("--frame", o->frame, "Frame K (0-based; default: the last)")->transform(frame_index());
  time->excludes(frame);
  CLI::Option* seq = cmd->add_flag("--sequence", o->sequence, "Every frame in --from..--to, numbered files");
  seq->excludes(time)->excludes(frame);
  cmd->add_option("--from", o->from_s, "Sequence start, session time (s)")->check(finite_number())->needs(seq);
  cmd->add_option("--to", o->to_s, "Sequence end, session time (s)")->check(finite_number())->needs(seq);
  cmd->add_option("--width", o->image.width_px, "Image width (pixels)")
      ->transform(decimal_integer())
      ->check(CLI::Range(16, 8192))
      ->capture_default_str();
  cmd->add_option("--height", o->image.height_px, "Image height (pixels)")
      ->transform(decimal_integer())
      ->check(CLI::Range(16, 8192))
      ->capture_default_str();
  // finite_number(): NaN passes CLI::Range, and reached the renderer as an
  // unwritable-output exit 1 instead of a bad argument.
  cmd->add_option("--azimuth", o->image.azimuth_deg, "Camera azimuth about +z from +x (degrees)")
      ->check(finite_number())
      ->capture_default_str();
  cmd->add_option("--elevation", o->image.elevation_deg, "Camera elevation above the xy plane (degrees)")
      ->check(finite_number())
      ->check(CLI::Range(-90.0, 90.0))
      ->capture_default_str();
  cmd->add_flag("--no-legend", o->no_legend, "Leave out the legend (level swatches, or the strain ramp)");
  cmd->add_option("--colour", o->colour, "Triangle colours: level (bisection depth) or strain (energy density)")
      ->check(CLI::IsMember({"level", "strain"}))
      ->capture_default_str();
  cmd->add_option("-o,--output", o->out, "Output PNG (a sequence numbers it: OUT-0000.png or OUT with %04d)")
      ->required();
  add_live_source_options(cmd, o->live, session, seq);
  // Frame numbers and session times select among a session's frames only.
  for (CLI::Option* opt : {time, frame}) opt->excludes(o->live.lcm_option)->excludes(o->live.dds_option);
  cmd->get_option("--from")->needs(session);
  cmd->get_option("--to")->needs(session);
  cmd->footer(
      "Colours: level: bisection level of the finest vertex of each triangle (the X3D export's palette);\n"
      "strain: mean strain-energy density of the triangle's vertices on the X3D export's ramp, scaled to\n"
      "the frame's min..max (printed; low at the bottom of the legend).\n"
      "Sources: --session FILE, or live: --lcm [URL] / --dds (the next frame received; --sequence: the frames\n"
      "received for --seconds S).\n"
      "OUT's directory must exist (an OUT that is a directory is a bad argument); every file is checked\n"
      "before any frame is read (live: the first before the collection, every one before any is written;\n"
      "%04d in a directory name gives each frame its own directory, session sequences only).\n"
      "Ctrl-C or SIGTERM during a live --sequence ends the collection: the frames so far are rendered.\n"
      "Exit codes: 0 ok (also when the collection was cut short), 1 unreadable input or unwritable output,\n"
      "2 bad arguments, 3 LCM/DDS cannot start, 4 live: no surface_mesh within --timeout S (or stopped before one).");
  return Subcommand{cmd, [o] { return run_render(*o); }};
}

}  // namespace tissue::cli
