// The live-source options `tissue x3d` and `tissue render` share: --lcm
// [URL] | --dds [--dds-domain N] [--dds-prefix P] [--dds-remote], --seconds,
// --timeout; and opening the chosen source (docs/replay-and-live.md).
#pragma once

#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "export/frame_source.hpp"
#include "tissue/dds_cli.hpp"

namespace CLI {
class App;
class Option;
}  // namespace CLI

namespace tissue::cli {

// Nothing arrived on the live source within --timeout.
constexpr int kExitNoLiveData = 4;

// LCM or DDS could not start (exit 3, kExitCannotConnect).
struct LiveStartError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct LiveSourceOptions {
  std::optional<std::string> lcm_url;
  DdsCliOptions dds;
  double seconds = 2.0;     // frames collected for an animation / sequence (wall)
  double timeout_s = 10.0;  // wait for the first frame
  // Frames a collection of many (--animate, --sequence) cut short by a
  // signal must hold to be exported: an X3D animation needs frames at 2 times
  // (x3d_command.cpp sets 2), a PNG sequence of one frame is whole.
  std::size_t frames_needed = 1;
  CLI::Option* lcm_option = nullptr;
  CLI::Option* dds_option = nullptr;

  bool live() const { return lcm_url.has_value() || dds.enabled; }
};

// Adds the options to `cmd`; `session` is the command's --session option
// (exactly one of --session, --lcm, --dds is allowed), `many` the flag that
// asks for several frames (--animate, --sequence) and uses --seconds.
void add_live_source_options(CLI::App* cmd, LiveSourceOptions& o, CLI::Option* session, CLI::Option* many);

// Subscribes, collects one frame (or frames for --seconds when `many`) and
// returns them as a FrameSource. SIGINT / SIGTERM during the collection end
// it (the signals are the caller's again afterwards): the frames so far are
// returned and *stop_note says so ("the collection was cut short by SIGINT
// after N frames of the S s window"); otherwise it is left empty. Throws
// x3d::NoLiveFrameError when nothing arrives within --timeout or a signal
// came before the first frame, LiveStartError when the transport cannot
// start.
std::unique_ptr<x3d::FrameSource> open_live_source(const LiveSourceOptions& o, bool many, std::string* stop_note);

}  // namespace tissue::cli
