// The control server: the protocol of control_protocol.hpp over a Unix stream
// socket and, optionally, TCP on 127.0.0.1 (docs/control-protocol.md).
//
// Everything runs on the caller's boost::asio::io_context: the server never
// starts a thread and calls the ControlHandler on whichever thread runs that
// io_context. One request per connection is in flight at a time (the next
// line is read only after the response is written), so a client that never
// reads its responses stalls only itself, and per-connection memory is bounded
// by max_line_bytes plus one response.
//
// Typical service wiring:
//
//   boost::asio::io_context io;
//   tissue::control::ControlServer server(io, ServerSettings::from_spec(cfg.control), handler);
//   server.start();                 // throws ControlError naming the socket
//   ... io.run() on the io thread ...
//   boost::asio::post(io, [&] { server.stop(); });  // from any other thread
#pragma once

#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "config/daemon_config.hpp"
#include "control/control_protocol.hpp"

namespace tissue::control {

struct ServerSettings {
  std::string unix_socket_path;           // empty: no Unix socket
  std::optional<std::uint16_t> tcp_port;  // nullopt: no TCP; 0: any free port (tests); bound to 127.0.0.1 only
  std::size_t max_line_bytes = 65536;     // longest request line, without its '\n'
  int max_connections = 16;               // open connections over both listeners; more are refused
  // When full, a connection mid-request with no byte moved for this long
  // makes way for a newcomer (after any idle one), and so does one whose
  // request has been going on for twice this long (its line received, or its
  // answer sent, a byte now and then).
  std::chrono::milliseconds stalled_after{5000};

  // ControlSpec's tcp_port 0 means "no TCP".
  static ServerSettings from_spec(const config::ControlSpec& spec);
};

class ControlServer {
 public:
  // `handler` must outlive the server or at least every run of `io` until
  // stop() returns.
  ControlServer(boost::asio::io_context& io, ServerSettings settings, ControlHandler& handler);
  // Calls stop(); must then run on the io thread or with the io_context not running.
  ~ControlServer();

  ControlServer(const ControlServer&) = delete;
  ControlServer& operator=(const ControlServer&) = delete;

  // Creates the listeners and starts accepting. The Unix socket gets mode
  // 0660; an existing socket file is replaced only when nothing answers on
  // it (a stale socket from a crash), never when another process is serving
  // it and never when the path is not a socket. Throws ControlError naming
  // the socket and the reason. Call once.
  void start();

  // Closes the listeners and every connection, removes the socket file (if
  // it is still the one start() created). Pending handlers complete as
  // aborted; the handler is never called again. Idempotent. Call it on the
  // io thread (post it there from others) or while the io_context is not running.
  void stop();

  // The TCP endpoint actually bound (the port chosen when tcp_port was 0);
  // nullopt without TCP. Valid after start().
  std::optional<boost::asio::ip::tcp::endpoint> tcp_endpoint() const;
  const std::string& unix_socket_path() const;
  // Open, accepted (not refused) connections; read it on the io thread.
  std::size_t connection_count() const;
  // Of those, the ones waiting for a request with nothing of one received
  // (a full server closes the longest idle of them for a newcomer); io thread.
  std::size_t idle_connection_count() const;

  struct State;

 private:
  std::shared_ptr<State> state_;  // shared with in-flight handlers, which may outlive *this
};

}  // namespace tissue::control
