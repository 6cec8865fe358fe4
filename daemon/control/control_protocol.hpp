// The control protocol (docs/control-protocol.md): one JSON object per line
// in each direction. This file is the transport-free half: it validates a
// request line and dispatches it to a ControlHandler, and defines the
// interface the service implements. The socket side is control_server.hpp.
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

namespace tissue::control {

// A command the handler refuses: the message becomes the response's "error"
// verbatim, so say what was wrong and, where useful, what to do.
class ControlError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// What the daemon does on each command. Called on the control server's thread
// (the io_context thread), one request at a time; an implementation must not
// block for long (hand work to the sim thread and answer, or answer that it
// was queued). Arguments are already checked for presence and JSON type.
// Return the "result" object (null becomes {}); throw ControlError to answer
// ok:false. Any other exception is answered as "internal error: ..." and the
// server keeps running.
class ControlHandler {
 public:
  virtual ~ControlHandler() = default;

  virtual nlohmann::json status() = 0;
  virtual nlohmann::json pause() = 0;
  virtual nlohmann::json resume() = 0;
  virtual nlohmann::json reset() = 0;
  // `path` is non-empty; relative paths are the daemon's business (the
  // `tissue` client sends absolute ones).
  virtual nlohmann::json load_scene(const std::string& path) = 0;
  // `key` is a syntactically valid key path ("material.youngs_modulus_Pa",
  // "loads[0].total_force_N[2]", "haptics.rate_hz"); `value` is any JSON
  // value. set_override_text() turns the pair into a `--set` override.
  virtual nlohmann::json set(const std::string& key, const nlohmann::json& value) = 0;
  // Answered before the daemon stops: the service schedules its shutdown and
  // returns.
  virtual nlohmann::json shutdown() = 0;
  // Starts recording the session to a file in the daemon's state directory.
  // `name` is empty when the request gave none (the daemon picks one); the
  // daemon refuses names that are not a plain file name.
  virtual nlohmann::json record_start(const std::string& name) = 0;
  virtual nlohmann::json record_stop() = 0;
  // Writes the current surface as an X3D file in the state directory; `name`
  // empty: the daemon picks one.
  virtual nlohmann::json export_x3d(const std::string& name) = 0;
};

// Every command has a handler method; anything else is "unknown command".

// Limits on request content, independent of the line length limit.
inline constexpr std::size_t kMaxCommandNameBytes = 64;
inline constexpr std::size_t kMaxKeyPathBytes = 256;
inline constexpr std::size_t kMaxPathBytes = 4096;
inline constexpr std::size_t kMaxFileNameBytes = 255;
// Nesting of "id" and "value": the daemon echoes / forwards them, and
// printing deeply nested JSON recurses.
inline constexpr int kMaxJsonDepth = 16;

// One request line (without its '\n') -> one response line (without '\n').
// Never throws: malformed JSON, a non-object, a missing or unknown "cmd",
// bad arguments and handler failures all become {"id":…,"ok":false,
// "error":"…"} responses.
std::string handle_request_line(std::string_view line, ControlHandler& handler);

// The response for a request that never reached the parser (line too long,
// connection refused). `id` is null.
std::string error_response(const std::string& message);

// "key=value" text in the `--set` override syntax of the scene and daemon
// config loaders. The value is written as JSON, which YAML reads back as the
// same value (strings stay quoted strings, numbers numbers).
std::string set_override_text(const std::string& key, const nlohmann::json& value);

// True when `key` is a key path the loaders accept: names of letters, digits,
// '_' or '-', joined by '.', each optionally followed by [index].
bool is_valid_key_path(std::string_view key);

// Serialises a response (or any JSON) as one line: invalid UTF-8 in strings
// is replaced rather than thrown on, and the text never contains '\n'.
std::string to_line(const nlohmann::json& j);

}  // namespace tissue::control
