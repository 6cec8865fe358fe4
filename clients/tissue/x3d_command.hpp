// `tissue x3d --session FILE [--time T | --frame K] [--animate [--from T0]
// [--to T1]] [--colour level|strain] -o OUT.x3d`: exports the surface of a
// recorded session as X3D (docs/x3d-export.md). Reads files only; no daemon.
// Exit codes: 0 ok, 1 the input is unreadable (or the output cannot be
// written; the message names the file and why), 2 bad arguments.
#pragma once

#include "tissue/subcommand.hpp"

namespace tissue::cli {

Subcommand add_x3d_command(CLI::App& parent);

}  // namespace tissue::cli
