// A blocking client of the control protocol, for the `tissue ctl` command
// and the tests: connect to the Unix socket or 127.0.0.1:port, send a request
// line, read the response line. Every wait is bounded by the timeout.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

namespace tissue::control {

class ControlClientError : public std::runtime_error {
 public:
  enum class Kind {
    kConnect,    // nothing to talk to: no socket, refused, permission denied
    kTransport,  // the connection broke (EOF, reset) mid-conversation
    kTimeout,    // the daemon did not answer in time
    kProtocol,   // the answer was not a protocol response
  };
  ControlClientError(Kind kind, const std::string& message) : std::runtime_error(message), kind_(kind) {}
  Kind kind() const noexcept { return kind_; }

 private:
  Kind kind_;
};

class ControlClient {
 public:
  using Timeout = std::chrono::milliseconds;
  static constexpr Timeout kDefaultTimeout{10000};
  // Longest response line accepted, without its '\n' (a status with many
  // fields is still tiny).
  static constexpr std::size_t kMaxResponseBytes = 64u << 20;

  // Throw ControlClientError(kConnect) naming the socket / port.
  static ControlClient connect_unix(const std::string& path, Timeout timeout = kDefaultTimeout);
  static ControlClient connect_tcp(std::uint16_t port, Timeout timeout = kDefaultTimeout);  // 127.0.0.1 only

  ControlClient(ControlClient&&) noexcept;
  ControlClient& operator=(ControlClient&&) noexcept;
  ~ControlClient();

  // Sends `request` (an object; an "id" is added when absent) and returns the
  // parsed response object. Checks that the response has "ok" and echoes
  // the id; does not interpret "ok" (the caller decides).
  nlohmann::json request(nlohmann::json request);
  // request({"cmd": cmd, ...args}).
  nlohmann::json call(const std::string& cmd, const nlohmann::json& args = nlohmann::json::object());

  // Raw access for tests and tools: bytes as they are, and one response line
  // without its '\n'.
  void send_raw(std::string_view bytes);
  std::string read_line();

  // What the client is connected to, for messages ("control socket /run/…").
  const std::string& peer_name() const;

  void close();

  struct Impl;  // defined in the .cpp only

 private:
  explicit ControlClient(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tissue::control
