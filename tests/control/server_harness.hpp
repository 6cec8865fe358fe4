// A ControlServer on its own io thread, as the daemon runs it, for tests.
#pragma once

#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>

#include <chrono>
#include <functional>
#include <future>
#include <memory>
#include <thread>

#include "control/control_server.hpp"
#include "control/fake_handler.hpp"
#include "control/temp_dir.hpp"

namespace tissue::control::testing {

class ServerHarness {
 public:
  // Default settings: a Unix socket in a fresh temp dir, no TCP.
  ServerHarness() : ServerHarness(default_settings(nullptr)) {}
  explicit ServerHarness(ServerSettings settings) {
    if (settings.unix_socket_path == "<temp>") settings.unix_socket_path = dir_ / "control.sock";
    server_ = std::make_unique<ControlServer>(io_, settings, handler_);
    server_->start();
    thread_ = std::thread([this] { io_.run(); });
  }
  ~ServerHarness() { stop(); }

  // Settings with the Unix socket in the harness's temp dir.
  static ServerSettings default_settings(ServerSettings* base) {
    ServerSettings s = base ? *base : ServerSettings{};
    s.unix_socket_path = "<temp>";
    return s;
  }

  void stop() {
    if (!thread_.joinable()) return;
    boost::asio::post(io_, [this] { server_->stop(); });
    thread_.join();  // run() returns once every aborted handler has run
  }

  // Runs fn on the io thread and returns its result (server state lives there).
  template <class F>
  auto on_io(F fn) {
    std::packaged_task<decltype(fn())()> task(std::move(fn));
    auto result = task.get_future();
    boost::asio::post(io_, [&task] { task(); });
    return result.get();
  }

  // Queues fn on the io thread without waiting for it (fn may hold that
  // thread: IoThreadHold).
  void post(std::function<void()> fn) { boost::asio::post(io_, std::move(fn)); }

  std::size_t connections() {
    return on_io([this] { return server_->connection_count(); });
  }
  std::size_t idle_connections() {
    return on_io([this] { return server_->idle_connection_count(); });
  }
  // Waits (bounded) until the server has seen `n` connections close.
  bool wait_for_connections(std::size_t n, std::chrono::milliseconds limit = std::chrono::seconds(5)) {
    const auto until = std::chrono::steady_clock::now() + limit;
    while (std::chrono::steady_clock::now() < until) {
      if (connections() == n) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return connections() == n;
  }

  const std::string& socket_path() const { return server_->unix_socket_path(); }
  ControlServer& server() { return *server_; }
  FakeHandler& handler() { return handler_; }
  const TempDir& dir() const { return dir_; }

 private:
  TempDir dir_;
  FakeHandler handler_;
  boost::asio::io_context io_;
  std::unique_ptr<ControlServer> server_;
  std::thread thread_;
};

// Holds the server's io thread (in a handler that waits) from construction
// until release() or destruction, so that a test can line up socket events
// that the server then sees together, in the order they happened.
class IoThreadHold {
 public:
  explicit IoThreadHold(ServerHarness& harness) {
    // Shared with the handler: the promise it sets must outlive its set_value.
    auto holding = std::make_shared<std::promise<void>>();
    auto held = holding->get_future();
    harness.post([holding, released = released_.get_future().share()] {
      holding->set_value();
      released.wait();
    });
    held.wait();
  }
  ~IoThreadHold() { release(); }
  IoThreadHold(const IoThreadHold&) = delete;
  IoThreadHold& operator=(const IoThreadHold&) = delete;

  void release() {
    if (released_once_) return;
    released_once_ = true;
    released_.set_value();
  }

 private:
  std::promise<void> released_;
  bool released_once_ = false;
};

}  // namespace tissue::control::testing
