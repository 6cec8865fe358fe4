// The control client on its own (daemon/control/control_client): what it
// sends, how it checks what comes back, and how each failure is reported.
// Against the real server (ServerHarness) where a well-behaved daemon is
// wanted, and against a scripted peer on a Unix socket in a temp dir where
// the daemon must misbehave: close, stall, answer garbage or too much.
#include "control/control_client.hpp"

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <fstream>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "control/line_socket.hpp"
#include "control/server_harness.hpp"

namespace tissue::control {
namespace {

using nlohmann::json;
using testing::ServerHarness;
using testing::TempDir;
using Kind = ControlClientError::Kind;
using std::chrono::milliseconds;

// The accepted end of a scripted peer's connection.
using PeerConnection = testing::LineSocket;

// A Unix socket in a temp dir whose single connection is served by `script`
// on a thread. Declare it before the client, so the client is gone (and the
// script's reads and writes end) before the peer joins its thread.
class ScriptedPeer {
 public:
  explicit ScriptedPeer(std::function<void(PeerConnection&)> script) : path_(dir_ / "peer.sock") {
    listen_fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, path_.data(), path_.size());
    listening_ = listen_fd_ >= 0 && ::bind(listen_fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) == 0 &&
                 ::listen(listen_fd_, 4) == 0;
    if (!listening_) return;
    thread_ = std::thread([this, script = std::move(script)] {
      pollfd p{listen_fd_, POLLIN, 0};
      if (::poll(&p, 1, 10000) <= 0) return;  // no client came
      const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0) return;
      PeerConnection connection(fd);  // closes it
      script(connection);
    });
  }
  ~ScriptedPeer() {
    join();
    if (listen_fd_ >= 0) ::close(listen_fd_);
  }
  ScriptedPeer(const ScriptedPeer&) = delete;
  ScriptedPeer& operator=(const ScriptedPeer&) = delete;

  bool listening() const { return listening_; }
  const std::string& path() const { return path_; }
  // Waits for the script to finish; what it recorded is then safe to read.
  void join() {
    if (thread_.joinable()) thread_.join();
  }

 private:
  TempDir dir_;
  std::string path_;
  int listen_fd_ = -1;
  bool listening_ = false;
  std::thread thread_;
};

// `fn` throws a ControlClientError of `kind` whose message contains every
// one of `parts`; returns the message.
std::string expect_client_error(const std::function<void()>& fn, Kind kind, const std::vector<std::string>& parts) {
  try {
    fn();
    ADD_FAILURE() << "no error";
  } catch (const ControlClientError& e) {
    EXPECT_EQ(e.kind(), kind) << e.what();
    for (const std::string& p : parts) EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
    return e.what();
  }
  return {};
}

// ------------------------------------------------------------- requests

TEST(ControlClient, RequestSendsOneLineWithAnIdAddedWhenAbsent) {
  std::vector<std::string> received;
  ScriptedPeer peer([&](PeerConnection& c) {
    while (auto line = c.read_line()) {
      received.push_back(*line);
      const json request = json::parse(*line, nullptr, false);
      const json id = request.is_object() ? request.value("id", json()) : json();
      c.send_all(json({{"id", id}, {"ok", true}, {"result", json::object()}}).dump() + "\n");
    }
  });
  ASSERT_TRUE(peer.listening());
  {
    ControlClient client = ControlClient::connect_unix(peer.path());
    EXPECT_EQ(client.request({{"cmd", "status"}}), json({{"id", 1}, {"ok", true}, {"result", json::object()}}));
    EXPECT_EQ(client.request({{"cmd", "pause"}, {"id", "mine"}}).at("id"), "mine");  // kept as given
    EXPECT_EQ(client.request({{"cmd", "status"}}).at("id"), 2);                      // the next own id
    EXPECT_EQ(client.request({{"cmd", "status"}, {"id", nullptr}}).at("id"), nullptr);
  }
  peer.join();
  EXPECT_EQ(received, (std::vector<std::string>{R"({"cmd":"status","id":1})", R"({"cmd":"pause","id":"mine"})",
                                                R"({"cmd":"status","id":2})", R"({"cmd":"status","id":null})"}));
}

TEST(ControlClient, CallPutsTheCommandAmongTheArguments) {
  std::vector<std::string> received;
  ScriptedPeer peer([&](PeerConnection& c) {
    while (auto line = c.read_line()) {
      received.push_back(*line);
      c.send_all(R"({"ok":false,"error":"x"})"
                 "\n");
    }
  });
  ASSERT_TRUE(peer.listening());
  {
    ControlClient client = ControlClient::connect_unix(peer.path());
    // The caller decides what "ok": false means; the client just returns it.
    EXPECT_EQ(client.call("set", {{"key", "material.E"}, {"value", 8e4}}).at("ok"), false);
    EXPECT_EQ(client.call("load_scene", {{"cmd", "shutdown"}, {"path", "/s.yaml"}}).at("error"), "x");
    EXPECT_EQ(client.call("status", json::array({1, 2})).at("ok"), false);  // not an object: no arguments
    EXPECT_EQ(client.call("reset").at("ok"), false);
  }
  peer.join();
  EXPECT_EQ(received, (std::vector<std::string>{R"({"cmd":"set","id":1,"key":"material.E","value":80000.0})",
                                                R"({"cmd":"load_scene","id":2,"path":"/s.yaml"})",
                                                R"({"cmd":"status","id":3})", R"({"cmd":"reset","id":4})"}));
}

TEST(ControlClient, NonObjectRequestIsRefusedBeforeAnythingIsSent) {
  ServerHarness h;
  ControlClient client = ControlClient::connect_unix(h.socket_path());
  // The error names the socket, as every other client error does.
  expect_client_error([&] { client.request(json::array({"status"})); }, Kind::kProtocol,
                      {client.peer_name() + ": a request must be a JSON object, not array [\"status\"]"});
  expect_client_error([&] { client.request("status"); }, Kind::kProtocol,
                      {client.peer_name() + ": a request must be a JSON object, not string \"status\""});
  EXPECT_EQ(h.handler().call_count(), 0u);
  // Nothing is left half-sent: the next request is answered, with id 1.
  const json r = client.call("status");
  EXPECT_EQ(r.at("id"), 1);
  EXPECT_EQ(r.at("ok"), true);
  EXPECT_EQ(r.at("result").at("calls_before"), 0);
}

// A response with a null id answers a line the server could not read (here:
// too long); the caller still gets it rather than an id mismatch.
TEST(ControlClient, NullIdResponseFromTheServerIsReturned) {
  ServerSettings settings = ServerHarness::default_settings(nullptr);
  settings.max_line_bytes = 64;
  ServerHarness h(settings);
  ControlClient client = ControlClient::connect_unix(h.socket_path());
  const json r = client.request({{"cmd", "status"}, {"pad", std::string(200, 'x')}});
  EXPECT_EQ(r.at("ok"), false);
  EXPECT_TRUE(r.at("id").is_null());
  EXPECT_NE(r.at("error").get<std::string>().find("request line too long"), std::string::npos) << r;
  EXPECT_EQ(h.handler().call_count(), 0u);
  EXPECT_EQ(client.call("status").at("ok"), true);  // the connection lives on
}

// A daemon over its connection limit answers and closes before reading: the
// request's send fails (broken pipe), and the client returns the answer
// waiting for it instead of "cannot send: Broken pipe".
TEST(ControlClient, AnAnswerSentBeforeTheDaemonClosedIsReturnedWhenTheSendFails) {
  const std::string refusal = R"j({"id":null,"ok":false,"error":"too many connections (the limit is 16)"})j";
  ScriptedPeer peer([&](PeerConnection& c) { c.send_all(refusal + "\n"); });
  ASSERT_TRUE(peer.listening());
  ControlClient client = ControlClient::connect_unix(peer.path());
  peer.join();  // answered and closed
  const json r = client.call("status");
  EXPECT_EQ(r.at("ok"), false);
  EXPECT_EQ(r.at("error"), "too many connections (the limit is 16)");
}

// ------------------------------------------------------- bad responses

TEST(ControlClient, ResponsesThatAreNotProtocolResponsesAreProtocolErrors) {
  const std::vector<std::string> replies = {
      "this is not json",
      "[true]",
      R"({"id":1,"result":{}})",               // no "ok"
      R"({"id":2,"ok":"yes"})",                // "ok" not a boolean
      R"({"id":99,"ok":true})",                // another request's id
      R"({"id":"4","ok":true})",               // the id as a string is another id
      std::string(1000, '#'),                  // garbage, shown only in part
      std::string("{\"ok\":tru\xff}", 10),     // broken bytes
      R"({"id":9,"ok":true,"result":[1,2]})",  // a result that is not an object
      R"({"id":10,"ok":true})",                // no result
      R"({"id":11,"ok":false,"error":5})",     // an error that is not a sentence
  };
  ScriptedPeer peer([&](PeerConnection& c) {
    for (const std::string& reply : replies) {
      if (!c.read_line()) return;
      c.send_all(reply + "\n");
    }
    if (c.read_line())
      c.send_all(R"({"id":12,"ok":true,"result":{"fine":true}})"
                 "\n");
  });
  ASSERT_TRUE(peer.listening());
  ControlClient client = ControlClient::connect_unix(peer.path());
  const std::string name = "control socket " + peer.path();
  const auto status = [&] { client.call("status"); };
  expect_client_error(status, Kind::kProtocol, {name + ": not a control protocol response: this is not json"});
  expect_client_error(status, Kind::kProtocol, {name + ": not a control protocol response: [true]"});
  expect_client_error(status, Kind::kProtocol, {"not a control protocol response: {\"id\":1,\"result\":{}}"});
  expect_client_error(status, Kind::kProtocol, {"not a control protocol response: {\"id\":2,\"ok\":\"yes\"}"});
  expect_client_error(status, Kind::kProtocol, {name + ": response id 99 does not match request id 5"});
  expect_client_error(status, Kind::kProtocol, {"response id \"4\" does not match request id 6"});
  const std::string long_one = expect_client_error(status, Kind::kProtocol, {"not a control protocol response: "});
  EXPECT_NE(long_one.find(std::string(200, '#')), std::string::npos) << long_one;
  EXPECT_EQ(long_one.find(std::string(201, '#')), std::string::npos) << "the line is cut to 200 bytes";
  expect_client_error(status, Kind::kProtocol, {"not a control protocol response: {\"ok\":tru"});
  expect_client_error(status, Kind::kProtocol, {name + ": a success without an object 'result': {\"id\":9"});
  expect_client_error(status, Kind::kProtocol, {name + ": a success without an object 'result': {\"id\":10"});
  expect_client_error(status, Kind::kProtocol, {name + ": a failure without an 'error' sentence: {\"id\":11"});
  // After all that the connection still carries a good answer.
  EXPECT_EQ(client.call("status").at("result"), nlohmann::json({{"fine", true}}));
}

TEST(ControlClient, ReadLineSplitsLinesAndKeepsBytesPastTheLast) {
  ScriptedPeer peer([](PeerConnection& c) {
    c.send_all("first\nsecond\nthi");
    if (c.read_line()) c.send_all("rd\n\n{\"id\":1,\"ok\":true,\"result\":{}}\nlast\n");
    c.read_to_eof();
  });
  ASSERT_TRUE(peer.listening());
  ControlClient client = ControlClient::connect_unix(peer.path());
  EXPECT_EQ(client.read_line(), "first");
  EXPECT_EQ(client.read_line(), "second");
  client.send_raw("go on\n");
  EXPECT_EQ(client.read_line(), "third");  // joined across two writes
  EXPECT_EQ(client.read_line(), "");       // an empty line is a line
  EXPECT_EQ(client.request({{"cmd", "status"}}).at("ok"), true);
  EXPECT_EQ(client.read_line(), "last");
}

// The longest line the client takes is kMaxResponseBytes before its '\n'
// (as the server counts); anything longer is refused without waiting for
// the end of it.
TEST(ControlClient, OversizedResponseLineIsAProtocolError) {
  constexpr std::size_t kMax = ControlClient::kMaxResponseBytes;
  ScriptedPeer peer([](PeerConnection& c) {
    if (!c.send_all(std::string(kMax, 'a') + "\n")) return;
    c.send_all(std::string(kMax + 2, 'b'));  // no newline at all; ends when the client leaves
  });
  ASSERT_TRUE(peer.listening());
  ControlClient client = ControlClient::connect_unix(peer.path());
  const std::string line = client.read_line();
  EXPECT_EQ(line.size(), kMax);
  EXPECT_EQ(line.find_first_not_of('a'), std::string::npos);
  expect_client_error(
      [&] { client.read_line(); }, Kind::kProtocol,
      {"control socket " + peer.path() + ": response line longer than " + std::to_string(kMax) + " bytes"});
}

// ------------------------------------------------- broken conversations

TEST(ControlClient, PeerClosingBeforeAnsweringIsATransportError) {
  ScriptedPeer peer([](PeerConnection& c) {
    c.read_line();  // takes the request, answers nothing
  });
  ASSERT_TRUE(peer.listening());
  ControlClient client = ControlClient::connect_unix(peer.path());
  const std::string name = "control socket " + peer.path();
  expect_client_error([&] { client.call("status"); }, Kind::kTransport,
                      {name + ": the daemon closed the connection without answering"});
  peer.join();  // the peer's end is closed now
  // Sending into the closed connection fails too (and does not raise SIGPIPE).
  expect_client_error([&] { client.send_raw(std::string(1 << 20, 'x') + "\n"); }, Kind::kTransport,
                      {name + ": cannot send: "});
}

TEST(ControlClient, PeerClosingMidLineIsATransportError) {
  ScriptedPeer peer([](PeerConnection& c) {
    if (c.read_line()) c.send_all(R"({"id":1,"ok":tr)");  // half a response, then gone
  });
  ASSERT_TRUE(peer.listening());
  ControlClient client = ControlClient::connect_unix(peer.path());
  expect_client_error([&] { client.call("status"); }, Kind::kTransport,
                      {"the daemon closed the connection without answering"});
}

TEST(ControlClient, SilentPeerTimesOutWithinTheTimeout) {
  ScriptedPeer peer([](PeerConnection& c) { c.read_to_eof(); });  // reads, never answers
  ASSERT_TRUE(peer.listening());
  ControlClient client = ControlClient::connect_unix(peer.path(), milliseconds(200));
  const auto start = std::chrono::steady_clock::now();
  expect_client_error([&] { client.call("status"); }, Kind::kTimeout,
                      {"control socket " + peer.path() + ": no response within 200 ms"});
  const auto waited = std::chrono::steady_clock::now() - start;
  EXPECT_GE(waited, milliseconds(190));
  EXPECT_LT(waited, milliseconds(5000));
}

// ---------------------------------------------------------- connecting

TEST(ControlClient, ConnectFailuresNameTheSocketOrPort) {
  TempDir dir;
  // Paths a Unix socket cannot have.
  expect_client_error([] { ControlClient::connect_unix(""); }, Kind::kConnect,
                      {"cannot connect to control socket : not a valid Unix socket path"});
  const std::string too_long = dir / std::string(107 - dir.path().size(), 'L');  // 108 bytes
  ASSERT_EQ(too_long.size(), sizeof(sockaddr_un{}.sun_path));
  expect_client_error([&] { ControlClient::connect_unix(too_long); }, Kind::kConnect,
                      {"cannot connect to control socket " + too_long + ": not a valid Unix socket path"});
  // The longest path that fits is tried (and is simply not there).
  const std::string longest = too_long.substr(0, too_long.size() - 1);
  const std::string what = expect_client_error([&] { ControlClient::connect_unix(longest); }, Kind::kConnect,
                                               {"cannot connect to control socket " + longest + ": "});
  EXPECT_EQ(what.find("not a valid Unix socket path"), std::string::npos) << what;
  // Something that is there but serves nothing: a regular file, a stale socket.
  std::ofstream(dir / "file") << "x";
  expect_client_error([&] { ControlClient::connect_unix(dir / "file"); }, Kind::kConnect,
                      {"cannot connect to control socket " + dir / "file" + ": Connection refused"});
  const std::string stale = dir / "stale.sock";
  {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, stale.data(), stale.size());
    ASSERT_EQ(::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr), 0);
    ::close(fd);
  }
  expect_client_error([&] { ControlClient::connect_unix(stale); }, Kind::kConnect,
                      {"cannot connect to control socket " + stale + ": Connection refused"});
  // A loopback port that is bound but not listening.
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in in{};
  in.sin_family = AF_INET;
  in.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(fd, reinterpret_cast<const sockaddr*>(&in), sizeof in), 0);
  socklen_t len = sizeof in;
  ASSERT_EQ(::getsockname(fd, reinterpret_cast<sockaddr*>(&in), &len), 0);
  const std::uint16_t port = ntohs(in.sin_port);
  expect_client_error([&] { ControlClient::connect_tcp(port, milliseconds(2000)); }, Kind::kConnect,
                      {"cannot connect to control port 127.0.0.1:" + std::to_string(port) + ": Connection refused"});
  ::close(fd);
}

TEST(ControlClient, PeerNameSaysWhatTheClientIsConnectedTo) {
  ServerHarness unix_server;
  ControlClient by_path = ControlClient::connect_unix(unix_server.socket_path());
  EXPECT_EQ(by_path.peer_name(), "control socket " + unix_server.socket_path());

  ServerSettings tcp;  // no Unix socket; any free loopback port
  tcp.tcp_port = 0;
  ServerHarness tcp_server(tcp);
  const auto endpoint = tcp_server.server().tcp_endpoint();
  ASSERT_TRUE(endpoint.has_value());
  ControlClient by_port = ControlClient::connect_tcp(endpoint->port());
  EXPECT_EQ(by_port.peer_name(), "control port 127.0.0.1:" + std::to_string(endpoint->port()));
  EXPECT_EQ(by_port.call("status").at("id"), 1);
}

// ------------------------------------------------------------- closing

TEST(ControlClient, CloseEndsTheConnectionAndMovesKeepItWorking) {
  ServerHarness h;
  ControlClient first = ControlClient::connect_unix(h.socket_path());
  ControlClient second = ControlClient::connect_unix(h.socket_path());
  EXPECT_EQ(first.call("status").at("ok"), true);
  ASSERT_TRUE(h.wait_for_connections(2));
  first.close();
  ASSERT_TRUE(h.wait_for_connections(1)) << "the server did not see the close";
  EXPECT_NO_THROW(first.close());  // twice is harmless
  expect_client_error([&] { first.call("status"); }, Kind::kTransport, {"control socket " + h.socket_path()});

  // A move carries the connection and its id sequence; the moved-from
  // client may still be closed (and destroyed) safely.
  EXPECT_EQ(second.call("status").at("id"), 1);
  ControlClient moved(std::move(second));
  EXPECT_NO_THROW(second.close());
  EXPECT_EQ(moved.call("status").at("id"), 2);
  first = std::move(moved);
  EXPECT_EQ(first.call("status").at("id"), 3);
  EXPECT_EQ(first.peer_name(), "control socket " + h.socket_path());
  EXPECT_EQ(h.connections(), 1u);
}

}  // namespace
}  // namespace tissue::control
