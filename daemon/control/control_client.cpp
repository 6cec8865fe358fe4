#include "control/control_client.hpp"

#include <optional>

#include <boost/asio/connect.hpp>
#include <boost/asio/generic/stream_protocol.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/local/stream_protocol.hpp>
#include <boost/asio/read_until.hpp>
#include <boost/asio/write.hpp>

#include <utility>

#include "control/control_protocol.hpp"

namespace tissue::control {

namespace asio = boost::asio;
using Kind = ControlClientError::Kind;

struct ControlClient::Impl {
  Impl(std::string name, Timeout t) : peer(std::move(name)), timeout(t), socket(io) {}

  // Runs one asynchronous operation to completion or until the timeout, then
  // cancels it. Returns the operation's error code.
  template <class Start>
  boost::system::error_code run(Start&& start, const char* what) {
    boost::system::error_code result;
    bool done = false;
    start([&](const boost::system::error_code& ec, auto&&...) {
      result = ec;
      done = true;
    });
    io.restart();
    io.run_for(timeout);
    if (!done) {
      boost::system::error_code ignored;
      socket.cancel(ignored);
      io.restart();
      io.run();  // lets the cancelled handler finish before the locals go away
      throw ControlClientError(Kind::kTimeout,
                               peer + ": no " + what + " within " + std::to_string(timeout.count()) + " ms");
    }
    return result;
  }

  std::string peer;
  Timeout timeout;
  asio::io_context io;
  asio::generic::stream_protocol::socket socket;
  std::string inbox;  // bytes read past the last line
  std::uint64_t next_id = 1;
};

namespace {

template <class Endpoint>
std::unique_ptr<ControlClient::Impl> connect(const Endpoint& endpoint, const std::string& name,
                                             ControlClient::Timeout timeout) {
  auto impl = std::make_unique<ControlClient::Impl>(name, timeout);
  const asio::generic::stream_protocol::endpoint generic(endpoint);
  boost::system::error_code ec;
  impl->socket.open(generic.protocol(), ec);
  if (ec) throw ControlClientError(Kind::kConnect, "cannot connect to " + name + ": " + ec.message());
  ec = impl->run([&](auto handler) { impl->socket.async_connect(generic, handler); }, "connection");
  if (ec) throw ControlClientError(Kind::kConnect, "cannot connect to " + name + ": " + ec.message());
  return impl;
}

}  // namespace

ControlClient::ControlClient(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ControlClient::ControlClient(ControlClient&&) noexcept = default;
ControlClient& ControlClient::operator=(ControlClient&&) noexcept = default;
ControlClient::~ControlClient() = default;

ControlClient ControlClient::connect_unix(const std::string& path, Timeout timeout) {
  const std::string name = "control socket " + path;
  // asio would throw its own length_error for a path longer than sun_path.
  if (path.empty() || path.size() >= sizeof(sockaddr_un{}.sun_path))
    throw ControlClientError(Kind::kConnect, "cannot connect to " + name + ": not a valid Unix socket path");
  return ControlClient(connect(asio::local::stream_protocol::endpoint(path), name, timeout));
}

ControlClient ControlClient::connect_tcp(std::uint16_t port, Timeout timeout) {
  const std::string name = "control port 127.0.0.1:" + std::to_string(port);
  return ControlClient(connect(asio::ip::tcp::endpoint(asio::ip::address_v4::loopback(), port), name, timeout));
}

const std::string& ControlClient::peer_name() const { return impl_->peer; }

void ControlClient::send_raw(std::string_view bytes) {
  const auto ec =
      impl_->run([&](auto handler) { asio::async_write(impl_->socket, asio::buffer(bytes), handler); }, "send");
  if (ec) throw ControlClientError(Kind::kTransport, impl_->peer + ": cannot send: " + ec.message());
}

std::string ControlClient::read_line() {
  Impl& s = *impl_;
  // Room for the longest line and its '\n' (the server's limit counts the
  // same way: a line of exactly the limit is accepted).
  auto buffer = asio::dynamic_buffer(s.inbox, kMaxResponseBytes + 1);
  const auto ec = s.run([&](auto handler) { asio::async_read_until(s.socket, buffer, '\n', handler); }, "response");
  if (ec == asio::error::eof)
    throw ControlClientError(Kind::kTransport, s.peer + ": the daemon closed the connection without answering");
  if (ec == asio::error::not_found)
    throw ControlClientError(Kind::kProtocol,
                             s.peer + ": response line longer than " + std::to_string(kMaxResponseBytes) + " bytes");
  if (ec) throw ControlClientError(Kind::kTransport, s.peer + ": cannot read the response: " + ec.message());
  const std::size_t nl = s.inbox.find('\n');
  std::string line = s.inbox.substr(0, nl);
  s.inbox.erase(0, nl + 1);
  return line;
}

nlohmann::json ControlClient::request(nlohmann::json request) {
  if (!request.is_object())
    throw ControlClientError(Kind::kProtocol, impl_->peer + ": a request must be a JSON object, not " +
                                                  std::string(request.type_name()) + " " +
                                                  to_line(request).substr(0, 80));
  if (!request.contains("id")) request["id"] = impl_->next_id++;
  std::optional<std::string> answered;
  try {
    send_raw(to_line(request) + "\n");
  } catch (const ControlClientError& e) {
    // A daemon that refuses a connection (too many connections) answers and
    // closes before reading: the send then fails (broken pipe), but its
    // answer is waiting, and it says why.
    if (e.kind() != Kind::kTransport) throw;
    try {
      answered = read_line();
    } catch (const ControlClientError&) {
      throw e;
    }
  }
  const std::string line = answered ? *answered : read_line();
  nlohmann::json response = nlohmann::json::parse(line, nullptr, false);
  if (response.is_discarded() || !response.is_object() || !response.contains("ok") || !response["ok"].is_boolean())
    throw ControlClientError(Kind::kProtocol,
                             impl_->peer + ": not a control protocol response: " + line.substr(0, 200));
  // A null id answers a request the server could not read (connection
  // refused, line too long): the caller still gets the error.
  const nlohmann::json id = response.value("id", nlohmann::json());
  if (!id.is_null() && id != request["id"])
    throw ControlClientError(Kind::kProtocol, impl_->peer + ": response id " + to_line(id) +
                                                  " does not match request id " + to_line(request["id"]));
  // docs/control-protocol.md: a success carries an object `result`, a
  // failure a sentence `error`. Anything else is not tissued answering.
  const bool ok = response["ok"].get<bool>();
  if (ok && !(response.contains("result") && response["result"].is_object()))
    throw ControlClientError(Kind::kProtocol,
                             impl_->peer + ": a success without an object 'result': " + line.substr(0, 200));
  if (!ok && !(response.contains("error") && response["error"].is_string()))
    throw ControlClientError(Kind::kProtocol,
                             impl_->peer + ": a failure without an 'error' sentence: " + line.substr(0, 200));
  return response;
}

nlohmann::json ControlClient::call(const std::string& cmd, const nlohmann::json& args) {
  nlohmann::json req = args.is_object() ? args : nlohmann::json::object();
  req["cmd"] = cmd;
  return request(std::move(req));
}

void ControlClient::close() {
  if (!impl_) return;
  boost::system::error_code ignored;
  impl_->socket.shutdown(asio::socket_base::shutdown_both, ignored);
  impl_->socket.close(ignored);
}

}  // namespace tissue::control
