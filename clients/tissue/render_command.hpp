// `tissue render`: OSMesa pictures of a recorded session's surface, one
// frame or a numbered sequence (docs: README "Running the service").
#pragma once

#include "tissue/subcommand.hpp"

namespace CLI {
class App;
}

namespace tissue::cli {

Subcommand add_render_command(CLI::App& parent);

}  // namespace tissue::cli
