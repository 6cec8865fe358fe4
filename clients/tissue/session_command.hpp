// `tissue session info|repair|xdmf FILE` and `tissue session list [DIR]`:
// offline tools for recorded sessions (docs/session-format.md). They read
// files only; no daemon needed.
// `tissue session replay FILE --lcm [URL] | --dds ...` publishes a session
// as the daemon would (docs/replay-and-live.md).
// Exit codes: 0 ok, 1 the file is unreadable / corrupt / not a session
// (the message names the file and what is wrong; list: the directory cannot
// be read), 2 bad arguments, 3 (replay) LCM or DDS cannot start.
#pragma once

#include "tissue/subcommand.hpp"

namespace tissue::cli {

Subcommand add_session_command(CLI::App& parent);

}  // namespace tissue::cli
