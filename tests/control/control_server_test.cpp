// The control server over real sockets (Unix sockets in a temp dir, TCP on
// 127.0.0.1 only), with the io_context on its own thread as in the daemon.
#include "control/control_server.hpp"

#include <gtest/gtest.h>

#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "control/control_client.hpp"
#include "control/line_socket.hpp"
#include "control/server_harness.hpp"

namespace tissue::control {
namespace {

using nlohmann::json;
using testing::ServerHarness;

ServerSettings unix_settings(std::size_t max_line_bytes = 65536, int max_connections = 16) {
  ServerSettings s;
  s.unix_socket_path = "<temp>";
  s.max_line_bytes = max_line_bytes;
  s.max_connections = max_connections;
  return s;
}

// A fresh client gets a correct status answer: the server is healthy.
void expect_healthy(ServerHarness& h) {
  ControlClient c = ControlClient::connect_unix(h.socket_path());
  const json r = c.call("status");
  EXPECT_EQ(r.at("ok"), true) << r;
  EXPECT_EQ(r.at("result").at("state"), "running") << r;
}

using testing::RawClient;

TEST(ControlServer, StatusRoundTripOverTheUnixSocket) {
  ServerHarness h(unix_settings());
  ControlClient c = ControlClient::connect_unix(h.socket_path());
  const json r = c.request({{"id", "first"}, {"cmd", "status"}});
  EXPECT_EQ(r, json({{"id", "first"},
                     {"ok", true},
                     {"result", {{"state", "running"}, {"scene", "cantilever"}, {"calls_before", 0}}}}));
  // The same connection serves the next request.
  EXPECT_EQ(c.call("status").at("result").at("calls_before"), 1);
}

TEST(ControlServer, EveryCommandReachesTheHandler) {
  ServerHarness h(unix_settings());
  ControlClient c = ControlClient::connect_unix(h.socket_path());
  EXPECT_EQ(c.call("pause").at("result"), json({{"paused", true}}));
  EXPECT_EQ(c.call("resume").at("result"), json({{"paused", false}}));
  EXPECT_EQ(c.call("reset").at("ok"), true);
  EXPECT_EQ(c.call("load_scene", {{"path", "/srv/scenes/beam.yaml"}}).at("ok"), true);
  EXPECT_EQ(c.call("set", {{"key", "material.youngs_modulus_Pa"}, {"value", 8e4}}).at("ok"), true);
  EXPECT_EQ(c.call("shutdown").at("ok"), true);
  const auto calls = h.handler().calls();
  ASSERT_EQ(calls.size(), 6u);
  const char* expected[] = {"pause", "resume", "reset", "load_scene", "set", "shutdown"};
  for (std::size_t i = 0; i < 6; ++i) EXPECT_EQ(calls[i].cmd, expected[i]);
  EXPECT_EQ(calls[3].args.at("path"), "/srv/scenes/beam.yaml");
  EXPECT_EQ(calls[4].args.at("key"), "material.youngs_modulus_Pa");
  EXPECT_EQ(calls[4].args.at("value"), 8e4);
  // Unknown commands and bad arguments do not reach it.
  EXPECT_EQ(c.call("export_vrml").at("error"), "unknown command 'export_vrml'");
  EXPECT_EQ(c.call("set", {{"key", "a.b"}}).at("ok"), false);
  EXPECT_EQ(h.handler().call_count(), 6u);
}

TEST(ControlServer, MalformedLinesGetErrorsAndTheConnectionLivesOn) {
  ServerHarness h(unix_settings());
  RawClient c(h.socket_path());
  ASSERT_TRUE(c.connected());
  // Several requests in one write, a CRLF line, blank lines (ignored).
  // A blank CRLF line (telnet, nc -C) is blank too: no answer.
  ASSERT_TRUE(c.send_all("{oops\n[1,2]\n\n  \n\r\n \t\r\n{\"id\":1}\n{\"id\":2,\"cmd\":\"status\"}\r\n"));
  const char* expected_errors[] = {"malformed JSON", "must be a JSON object", "missing 'cmd'"};
  for (const char* part : expected_errors) {
    const auto line = c.read_line();
    ASSERT_TRUE(line.has_value()) << part;
    const json r = json::parse(*line);
    EXPECT_EQ(r.at("ok"), false);
    EXPECT_NE(r.at("error").get<std::string>().find(part), std::string::npos) << *line;
  }
  const auto ok = c.read_line();
  ASSERT_TRUE(ok.has_value());
  EXPECT_EQ(json::parse(*ok).at("id"), 2);
  EXPECT_EQ(json::parse(*ok).at("ok"), true);
  expect_healthy(h);
}

TEST(ControlServer, RandomBytesAreAnsweredWithErrors) {
  ServerHarness h(unix_settings());
  std::mt19937 rng(1234);
  for (int round = 0; round < 3; ++round) {
    RawClient c(h.socket_path());
    ASSERT_TRUE(c.connected());
    std::string junk(32768, '\0');
    for (char& ch : junk) ch = static_cast<char>(rng() & 0xff);
    std::size_t lines = 0;
    for (std::size_t i = 0; i < junk.size(); ++i) {
      if (junk[i] == '\n') ++lines;
    }
    junk += '\n';
    ++lines;
    ASSERT_TRUE(c.send_all(junk));
    // Every non-blank line gets one error response; read at least a few and
    // check each is a well-formed error.
    for (std::size_t i = 0; i < std::min<std::size_t>(lines, 20); ++i) {
      const auto line = c.read_line();
      ASSERT_TRUE(line.has_value()) << "response " << i << " of " << lines;
      const json r = json::parse(*line);
      EXPECT_EQ(r.at("ok"), false);
      EXPECT_TRUE(r.at("error").is_string());
    }
    // The same connection still answers a proper request (after the rest of
    // the junk's answers).
    ASSERT_TRUE(c.send_all("{\"id\":\"after-junk\",\"cmd\":\"status\"}\n"));
    bool answered = false;
    while (auto line = c.read_line()) {
      const json r = json::parse(*line);
      if (r.at("id") == "after-junk") {
        EXPECT_EQ(r.at("ok"), true);
        answered = true;
        break;
      }
    }
    EXPECT_TRUE(answered);
  }
  EXPECT_EQ(h.handler().call_count(), 3u);  // only the three real status requests
  expect_healthy(h);
}

TEST(ControlServer, OversizedLineIsRefusedAndTheStreamResynchronises) {
  ServerHarness h(unix_settings(65536));
  RawClient c(h.socket_path());
  ASSERT_TRUE(c.connected());
  // A 10 MB line, then a proper request on the same connection.
  std::thread writer([&] {
    std::string big(10u << 20, 'a');
    big += "\n{\"id\":7,\"cmd\":\"status\"}\n";
    EXPECT_TRUE(c.send_all(big));
  });
  const auto first = c.read_line(std::chrono::seconds(20));
  const auto second = c.read_line(std::chrono::seconds(20));
  writer.join();
  ASSERT_TRUE(first.has_value());
  const json e = json::parse(*first);
  EXPECT_EQ(e.at("ok"), false);
  EXPECT_EQ(e.at("id"), nullptr);
  EXPECT_NE(e.at("error").get<std::string>().find("request line too long (more than 65536 bytes)"), std::string::npos);
  ASSERT_TRUE(second.has_value());
  EXPECT_EQ(json::parse(*second).at("id"), 7);
  EXPECT_EQ(json::parse(*second).at("ok"), true);
  // A line of exactly the limit is still accepted.
  const std::string pad = "{\"id\":8,\"cmd\":\"status\"}";
  ControlClient exact = ControlClient::connect_unix(h.socket_path());
  exact.send_raw(pad + std::string(65536 - pad.size(), ' ') + "\n");
  EXPECT_EQ(json::parse(exact.read_line()).at("ok"), true);
  expect_healthy(h);
}

// When every slot is taken, the connection idle the longest (nothing asked
// since its last answer, or since it connected) is closed with one error
// line, and the newcomer is served: 16 forgotten connections used to lock
// every client out until they closed.
TEST(ControlServer, WhenFullTheLongestIdleConnectionMakesWayForANewClient) {
  constexpr int kLimit = 4;
  ServerHarness h(unix_settings(65536, kLimit));
  std::vector<std::unique_ptr<RawClient>> clients;
  for (int i = 0; i < kLimit; ++i) {
    clients.push_back(std::make_unique<RawClient>(h.socket_path()));
    ASSERT_TRUE(clients.back()->connected()) << i;
    ASSERT_TRUE(h.wait_for_connections(static_cast<std::size_t>(i + 1)));
    std::this_thread::sleep_for(std::chrono::milliseconds(5));  // distinct idle times
  }
  // The first one asks something: now the second is the longest idle. The
  // second sends blank lines, which are no requests and change nothing.
  ASSERT_TRUE(clients[0]->send_all("{\"id\":0,\"cmd\":\"status\"}\n"));
  ASSERT_TRUE(clients[0]->read_line().has_value());
  ASSERT_TRUE(clients[1]->send_all("  \n\n"));
  for (int i = 0; i < 1000 && h.idle_connections() < static_cast<std::size_t>(kLimit); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));  // the blank lines read

  for (int round = 0; round < 2; ++round) {  // the second and then the third make way
    const int victim = 1 + round;
    clients.push_back(std::make_unique<RawClient>(h.socket_path()));
    ASSERT_TRUE(clients.back()->connected());
    const auto line = clients[victim]->read_line();
    ASSERT_TRUE(line.has_value()) << "client " << victim << " was not told";
    const json r = json::parse(*line);
    EXPECT_EQ(r.at("ok"), false);
    EXPECT_EQ(r.at("error"),
              "closed: this connection was the longest idle of 4 open ones and a new client needed its place");
    EXPECT_TRUE(clients[victim]->sees_eof());
    ASSERT_TRUE(clients.back()->send_all("{\"id\":7,\"cmd\":\"status\"}\n"));
    const auto answer = clients.back()->read_line();
    ASSERT_TRUE(answer.has_value());
    EXPECT_EQ(json::parse(*answer).at("ok"), true);
  }
  // The others were left alone and still answer.
  for (int i : {0, 3}) {
    ASSERT_TRUE(clients[i]->send_all("{\"id\":" + std::to_string(i) + ",\"cmd\":\"status\"}\n"));
    const auto line = clients[i]->read_line();
    ASSERT_TRUE(line.has_value()) << "client " << i;
    EXPECT_EQ(json::parse(*line).at("id"), i);
  }
  EXPECT_EQ(h.connections(), static_cast<std::size_t>(kLimit));
  clients.clear();
  ASSERT_TRUE(h.wait_for_connections(0));
  expect_healthy(h);
}

// A connection in the middle of a request is never closed for a newcomer:
// when every one is, the newcomer is refused with one error line, and the
// requests in progress complete.
TEST(ControlServer, WhenEveryConnectionIsMidRequestANewcomerIsRefused) {
  constexpr int kLimit = 3;
  ServerHarness h(unix_settings(65536, kLimit));
  std::vector<std::unique_ptr<RawClient>> busy;
  for (int i = 0; i < kLimit; ++i) {
    busy.push_back(std::make_unique<RawClient>(h.socket_path()));
    ASSERT_TRUE(busy.back()->connected());
    ASSERT_TRUE(h.wait_for_connections(static_cast<std::size_t>(i + 1)));
    ASSERT_TRUE(busy.back()->send_all("{\"id\":" + std::to_string(i) + ",\"cmd\":"));
  }
  // Until the server has read the partial lines (bounded).
  for (int i = 0; i < 1000 && h.idle_connections() > 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_EQ(h.idle_connections(), 0u);
  for (int attempt = 0; attempt < 5; ++attempt) {
    RawClient newcomer(h.socket_path());
    ASSERT_TRUE(newcomer.connected());
    const auto line = newcomer.read_line();
    ASSERT_TRUE(line.has_value()) << "no refusal";
    const json r = json::parse(*line);
    EXPECT_EQ(r.at("ok"), false);
    EXPECT_EQ(r.at("error"), "too many connections (the limit is 3); try again later");
    EXPECT_TRUE(newcomer.sees_eof());
  }
  for (int i = 0; i < kLimit; ++i) {
    ASSERT_TRUE(busy[i]->send_all("\"status\"}\n"));
    const auto line = busy[i]->read_line();
    ASSERT_TRUE(line.has_value()) << "busy client " << i;
    EXPECT_EQ(json::parse(*line).at("id"), i);
    EXPECT_EQ(json::parse(*line).at("ok"), true);
  }
}

// ... unless it has stalled there: half a line and then nothing for
// stalled_after. Sixteen such connections locked every client out until
// they closed; the one stalled the longest now makes way.
TEST(ControlServer, AConnectionStalledMidRequestMakesWayWhenFull) {
  constexpr int kLimit = 3;
  ServerSettings settings = unix_settings(65536, kLimit);
  settings.stalled_after = std::chrono::milliseconds(200);
  ServerHarness h(settings);
  std::vector<std::unique_ptr<RawClient>> stalled;
  for (int i = 0; i < kLimit; ++i) {
    stalled.push_back(std::make_unique<RawClient>(h.socket_path()));
    ASSERT_TRUE(stalled.back()->connected());
    ASSERT_TRUE(h.wait_for_connections(static_cast<std::size_t>(i + 1)));
    ASSERT_TRUE(stalled.back()->send_all("{\"cmd\":\"sta"));
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // distinct stall times
  }
  for (int i = 0; i < 1000 && h.idle_connections() > 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // all three past stalled_after
  RawClient newcomer(h.socket_path());
  ASSERT_TRUE(newcomer.connected());
  const auto told = stalled[0]->read_line();
  ASSERT_TRUE(told.has_value()) << "the longest stalled was not told";
  EXPECT_EQ(
      json::parse(*told).at("error"),
      "closed: this connection stalled mid-request (no byte for 200 ms) with all 3 places taken, and a new client "
      "needed its place");
  EXPECT_TRUE(stalled[0]->sees_eof());
  ASSERT_TRUE(newcomer.send_all("{\"id\":1,\"cmd\":\"status\"}\n"));
  const auto answer = newcomer.read_line();
  ASSERT_TRUE(answer.has_value());
  EXPECT_EQ(json::parse(*answer).at("ok"), true);
  // The others keep their half lines, and finish them.
  ASSERT_TRUE(stalled[1]->send_all("tus\"}\n"));
  const auto finished = stalled[1]->read_line();
  ASSERT_TRUE(finished.has_value());
  EXPECT_EQ(json::parse(*finished).at("ok"), true);
}

// ... and so does one whose request goes on too long, even with a byte now
// and then: a client trickling a space every 50 ms into a half-sent line, or
// the endless rest of a too-long line being discarded, was never idle and
// never stalled, so with every place so taken every newcomer was refused
// (tissue ctl shutdown included). Past twice stalled_after it makes way.
TEST(ControlServer, AConnectionTricklingARequestMakesWayWhenFull) {
  struct Case {
    const char* what;
    std::string first_bytes;  // the start of the endless request
    std::string trickle;      // then this every 50 ms
    const char* told_first;   // the error before the eviction, if any
  };
  const Case cases[] = {
      {"a half line and then a space at a time", "{\"cmd\":\"sta", " ", nullptr},
      {"a too-long line that never ends", std::string(300, 'a'), std::string(100, 'a'), "request line too long"},
      // Each blank line ended a line; the space after it started the
      // deadline again, for ever (blank lines are no requests).
      {"spaces with blank lines between", " ", "\n ", nullptr},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    ServerSettings settings = unix_settings(256, 1);
    // The trickle comes every 50 ms: only a scheduling gap of a whole
    // second (a loaded machine, a sanitizer) would make the connection
    // stalled rather than overdue.
    settings.stalled_after = std::chrono::milliseconds(1000);
    ServerHarness h(settings);
    RawClient trickler(h.socket_path());
    ASSERT_TRUE(trickler.connected());
    ASSERT_TRUE(h.wait_for_connections(1));
    ASSERT_TRUE(trickler.send_all(c.first_bytes));
    // Stopped and joined however the test ends (an ASSERT returns early).
    struct Sender {
      std::atomic<bool> trickling{true};
      std::thread thread;
      ~Sender() {
        trickling = false;
        if (thread.joinable()) thread.join();
      }
    } sender;
    sender.thread = std::thread([&] {
      while (sender.trickling && trickler.send_all(c.trickle))
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    });
    // A newcomer asks until it is served (bounded): refused at first, while
    // the trickled request is younger than 2 s.
    std::optional<json> served;
    std::string last_refusal;
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (!served && std::chrono::steady_clock::now() < give_up) {
      RawClient newcomer(h.socket_path());
      ASSERT_TRUE(newcomer.connected());
      // A refused newcomer may find the socket closed before it sends: its
      // refusal is there to read all the same.
      newcomer.send_all("{\"id\":\"newcomer\",\"cmd\":\"status\"}\n");
      const auto line = newcomer.read_line();
      ASSERT_TRUE(line.has_value()) << "neither served nor refused";
      const json r = json::parse(*line);
      if (r.at("ok") == true)
        served = r;
      else
        last_refusal = *line;
      if (!served) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    sender.trickling = false;
    sender.thread.join();
    EXPECT_TRUE(served.has_value()) << "still refused after 10 s: " << last_refusal;
    if (!served) continue;  // the other case may fail differently
    EXPECT_EQ(served->at("id"), "newcomer");
    // The trickler was told why, and closed.
    auto told = trickler.read_line();
    if (c.told_first) {
      ASSERT_TRUE(told.has_value());
      EXPECT_NE(told->find(c.told_first), std::string::npos) << *told;
      told = trickler.read_line();
    }
    ASSERT_TRUE(told.has_value()) << "the trickler was not told";
    EXPECT_EQ(json::parse(*told).at("error"),
              "closed: this connection took too long over a request (more than 2000 ms receiving its line) in the "
              "only place (the limit is 1), and a new client needed it");
    EXPECT_TRUE(trickler.sees_closed());  // its trickle may be unread: a reset, not an EOF
  }
}

// With max_connections 1 the closed connection is told it held the only
// place: the messages read "the longest idle of 1 open ones" and "with all 1
// places taken". With more places they count them.
TEST(ControlServer, EvictionMessagesSpeakOfTheOnlyPlaceWhenTheLimitIsOne) {
  ServerSettings settings = unix_settings(65536, 1);
  settings.stalled_after = std::chrono::milliseconds(200);
  ServerHarness h(settings);
  RawClient idle(h.socket_path());
  ASSERT_TRUE(idle.connected());
  ASSERT_TRUE(h.wait_for_connections(1));
  RawClient stalled(h.socket_path());  // takes the idle one's place
  ASSERT_TRUE(stalled.connected());
  const auto idle_told = idle.read_line();
  ASSERT_TRUE(idle_told.has_value()) << "the idle one was not told";
  EXPECT_EQ(json::parse(*idle_told).at("error"),
            "closed: this connection was idle in the only place (the limit is 1) and a new client needed it");
  EXPECT_TRUE(idle.sees_eof());
  ASSERT_TRUE(h.wait_for_connections(1));
  ASSERT_TRUE(stalled.send_all("{\"cmd\":\"sta"));
  for (int i = 0; i < 1000 && h.idle_connections() > 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // past stalled_after
  RawClient newcomer(h.socket_path());
  ASSERT_TRUE(newcomer.connected());
  const auto stalled_told = stalled.read_line();
  ASSERT_TRUE(stalled_told.has_value()) << "the stalled one was not told";
  EXPECT_EQ(json::parse(*stalled_told).at("error"),
            "closed: this connection stalled mid-request (no byte for 200 ms) in the only place (the limit is 1), and "
            "a new client needed it");
  EXPECT_TRUE(stalled.sees_eof());
  ASSERT_TRUE(newcomer.send_all("{\"id\":1,\"cmd\":\"status\"}\n"));
  const auto answer = newcomer.read_line();
  ASSERT_TRUE(answer.has_value());
  EXPECT_EQ(json::parse(*answer).at("ok"), true);
}

// A connection closed for a newcomer while its answer is half sent gets no
// farewell line: the error line went out with write_some while the answer's
// async_write was still pending, so the client read the first part of the
// answer, then the error line, then nothing: one line that is not JSON.
// To line the events up, the io thread is held while the client makes room
// in its socket and a newcomer connects; released, the server sees the
// newcomer first (epoll reports in the order things happened), so it closes
// the stalled connection before its pending write takes that room.
TEST(ControlServer, AConnectionClosedWhileItsAnswerIsHalfSentGetsNoSplicedLine) {
  ServerSettings settings = unix_settings(4u << 20, 1);
  settings.stalled_after = std::chrono::milliseconds(200);
  ServerHarness h(settings);
  RawClient slow_reader(h.socket_path());
  ASSERT_TRUE(slow_reader.connected());
  // An answer far larger than a socket's buffers (its id is echoed).
  const std::string id(1u << 20, 'x');
  ASSERT_TRUE(slow_reader.send_all("{\"id\":\"" + id + "\",\"cmd\":\"status\"}\n"));
  for (int i = 0; i < 2000 && h.handler().call_count() == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_EQ(h.handler().call_count(), 1u);
  // The handler's count rises before its answer is sent: two round trips
  // through the io thread let the answer's first write run and its next one
  // wait for room.
  h.on_io([] { return 0; });
  h.on_io([] { return 0; });
  std::string received;
  char buf[65536];
  const auto drain = [&] {  // what the socket holds now, without waiting
    for (;;) {
      const ssize_t n = ::recv(slow_reader.fd(), buf, sizeof buf, MSG_DONTWAIT);
      if (n <= 0) return;
      received.append(buf, static_cast<std::size_t>(n));
    }
  };
  {
    testing::IoThreadHold hold(h);  // the answer's write is pending: 1 MiB does not fit
    const auto held_since = std::chrono::steady_clock::now();
    RawClient newcomer(h.socket_path());  // queued at the listener
    ASSERT_TRUE(newcomer.connected());
    drain();  // room for the rest of the answer, or for the farewell line
    ASSERT_FALSE(received.empty());
    ASSERT_LT(received.size(), id.size()) << "the answer was not half sent";
    // The reader's last progress was before the hold: once past stalled_after
    // it is the one to make way.
    std::this_thread::sleep_until(held_since + 2 * settings.stalled_after);
    hold.release();
    ASSERT_TRUE(newcomer.send_all("{\"id\":\"newcomer\",\"cmd\":\"status\"}\n"));
    const auto answer = newcomer.read_line();
    ASSERT_TRUE(answer.has_value());
    EXPECT_EQ(json::parse(*answer).at("ok"), true) << *answer;
  }
  received += slow_reader.read_to_eof();
  // Only the answer's first part came: no line ended, and nothing else.
  const std::string answer_start = "{\"id\":\"" + id;
  const std::size_t after_id = std::min(received.find_first_not_of('x', 7), received.size());
  EXPECT_EQ(received.find('\n'), std::string::npos)
      << "a line ended in what the closed client read, after " << after_id << " bytes: " << received.substr(after_id);
  EXPECT_LE(received.size(), answer_start.size());
  EXPECT_EQ(answer_start.compare(0, received.size(), received), 0)
      << "not the answer's start, after " << after_id << " bytes: " << received.substr(after_id);
}

TEST(ControlServer, ManySimultaneousClientsAreAllServedWithinTheLimit) {
  constexpr int kClients = 100;
  ServerHarness h(unix_settings(65536, kClients));
  std::vector<std::thread> threads;
  std::atomic<int> ok{0};
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      std::vector<ControlClient> mine;
      for (int i = 0; i < kClients / 4; ++i) mine.push_back(ControlClient::connect_unix(h.socket_path()));
      for (std::size_t i = 0; i < mine.size(); ++i) {
        const json r = mine[i].request({{"id", t * 1000 + static_cast<int>(i)}, {"cmd", "status"}});
        if (r.at("ok") == true && r.at("id") == t * 1000 + static_cast<int>(i)) ++ok;
      }
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(ok.load(), kClients);
}

TEST(ControlServer, ClientVanishingMidLineLeavesNoTrace) {
  ServerHarness h(unix_settings());
  {
    RawClient c(h.socket_path());
    ASSERT_TRUE(c.connected());
    ASSERT_TRUE(c.send_all("{\"id\":1,\"cmd\":\"sta"));
  }  // closed mid-line
  {
    RawClient c(h.socket_path());
    ASSERT_TRUE(c.connected());
    ASSERT_TRUE(c.send_all(std::string(100000, 'x')));  // mid oversized line
  }
  ASSERT_TRUE(h.wait_for_connections(0));
  EXPECT_EQ(h.handler().call_count(), 0u);
  expect_healthy(h);
}

TEST(ControlServer, IdleConnectionsStayOpen) {
  ServerHarness h(unix_settings());
  ControlClient idle = ControlClient::connect_unix(h.socket_path());
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  expect_healthy(h);
  EXPECT_EQ(idle.call("status").at("ok"), true);
}

TEST(ControlServer, TcpListensOnLoopbackOnly) {
  ServerSettings s;  // no Unix socket
  s.tcp_port = 0;    // any free port
  ServerHarness h(s);
  const auto endpoint = h.server().tcp_endpoint();
  ASSERT_TRUE(endpoint.has_value());
  EXPECT_EQ(endpoint->address(), boost::asio::ip::make_address("127.0.0.1"));
  EXPECT_TRUE(endpoint->address().is_loopback());
  EXPECT_NE(endpoint->port(), 0);
  ControlClient c = ControlClient::connect_tcp(endpoint->port());
  EXPECT_EQ(c.call("status").at("ok"), true);
  EXPECT_TRUE(h.socket_path().empty());
}

TEST(ControlServer, ControlSpecMapsToSettings) {
  config::ControlSpec spec;
  EXPECT_FALSE(ServerSettings::from_spec(spec).tcp_port.has_value()) << "tcp_port 0 means no TCP";
  spec.tcp_port = 47801;
  spec.max_line_bytes = 4096;
  spec.max_connections = 3;
  spec.stalled_after_s = 0.25;
  const ServerSettings s = ServerSettings::from_spec(spec);
  EXPECT_EQ(s.tcp_port, 47801);
  EXPECT_EQ(s.unix_socket_path, spec.unix_socket_path);
  EXPECT_EQ(s.max_line_bytes, 4096u);
  EXPECT_EQ(s.max_connections, 3);
  EXPECT_EQ(s.stalled_after, std::chrono::milliseconds(250)) << "control.stalled_after_s did not reach the server";
  // The longest the config allows (an hour), in whole milliseconds.
  spec.stalled_after_s = 3600.0;
  EXPECT_EQ(ServerSettings::from_spec(spec).stalled_after, std::chrono::milliseconds(3'600'000));
  spec.stalled_after_s = 0.0015;  // rounded to the nearest millisecond, not truncated to 1
  EXPECT_EQ(ServerSettings::from_spec(spec).stalled_after, std::chrono::milliseconds(2));
}

// Limits of zero would refuse every request or every connection: start()
// refuses them, naming the setting, and opens nothing.
TEST(ControlServer, StartRefusesLimitsOfZeroNamingTheSetting) {
  testing::TempDir dir;
  boost::asio::io_context io;
  testing::FakeHandler handler;
  struct Case {
    std::size_t max_line_bytes;
    int max_connections;
    const char* says;
  };
  for (const Case& c : {Case{0, 16, "max_line_bytes must be >= 1"}, Case{65536, 0, "max_connections must be >= 1"}}) {
    ServerSettings s;
    s.unix_socket_path = dir / "control.sock";
    s.max_line_bytes = c.max_line_bytes;
    s.max_connections = c.max_connections;
    ControlServer server(io, s, handler);
    try {
      server.start();
      ADD_FAILURE() << "started with " << c.says;
    } catch (const ControlError& e) {
      EXPECT_NE(std::string(e.what()).find(c.says), std::string::npos) << e.what();
    }
    EXPECT_FALSE(std::filesystem::exists(s.unix_socket_path)) << c.says;
  }
}

TEST(ControlServer, SocketFileModeStaleReplacementAndRemoval) {
  testing::TempDir dir;
  const std::string path = dir / "control.sock";
  // A stale socket file, as a crash leaves it: bound, then closed.
  {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, path.data(), path.size());
    ASSERT_EQ(::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr), 0);
    ::close(fd);
  }
  boost::asio::io_context io;
  testing::FakeHandler handler;
  ServerSettings s;
  s.unix_socket_path = path;
  {
    ControlServer server(io, s, handler);
    ASSERT_NO_THROW(server.start());
    struct stat st {};
    ASSERT_EQ(::lstat(path.c_str(), &st), 0);
    EXPECT_TRUE(S_ISSOCK(st.st_mode));
    EXPECT_EQ(st.st_mode & 0777, 0660u);

    // A second server on the same path must not steal a live socket.
    boost::asio::io_context io2;
    ControlServer second(io2, s, handler);
    try {
      second.start();
      ADD_FAILURE() << "second server started on a live socket";
    } catch (const ControlError& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("another process is serving this socket"), std::string::npos) << e.what();
    }
    EXPECT_EQ(::access(path.c_str(), F_OK), 0) << "the live socket must survive";
    server.stop();
    EXPECT_NE(::access(path.c_str(), F_OK), 0) << "stop() removes the socket file";
  }
  // Not a socket: never replaced.
  std::ofstream(path) << "precious";
  ControlServer third(io, s, handler);
  try {
    third.start();
    ADD_FAILURE() << "started over a regular file";
  } catch (const ControlError& e) {
    EXPECT_NE(std::string(e.what()).find("not a socket"), std::string::npos) << e.what();
  }
  std::ifstream in(path);
  std::string content;
  in >> content;
  EXPECT_EQ(content, "precious");
  // A missing directory is named in the error.
  ServerSettings missing;
  missing.unix_socket_path = dir / "no/such/dir/control.sock";
  ControlServer fourth(io, missing, handler);
  EXPECT_THROW(fourth.start(), ControlError);
}

TEST(ControlServer, StopClosesOpenConnections) {
  ServerHarness h(unix_settings());
  RawClient idle(h.socket_path());
  ASSERT_TRUE(idle.connected());
  ASSERT_TRUE(h.wait_for_connections(1));
  h.stop();
  EXPECT_TRUE(idle.sees_eof());
  EXPECT_NE(::access(h.socket_path().c_str(), F_OK), 0);
  EXPECT_THROW(ControlClient::connect_unix(h.socket_path(), std::chrono::milliseconds(500)), ControlClientError);
}

TEST(ControlServer, ClientReportsConnectFailuresClearly) {
  testing::TempDir dir;
  try {
    ControlClient::connect_unix(dir / "absent.sock", std::chrono::milliseconds(500));
    ADD_FAILURE() << "connected to nothing";
  } catch (const ControlClientError& e) {
    EXPECT_EQ(e.kind(), ControlClientError::Kind::kConnect);
    EXPECT_NE(std::string(e.what()).find(dir / "absent.sock"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tissue::control
