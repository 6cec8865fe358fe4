// A blocking stream socket read and written as lines with bounded waits: the
// misbehaving clients (control_server_test) and scripted daemons
// (control_client_test) of the control tests.
#pragma once

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace tissue::control::testing {

class LineSocket {
 public:
  using milliseconds = std::chrono::milliseconds;
  // Takes ownership of `fd` (closed with the object).
  explicit LineSocket(int fd) : fd_(fd) {}
  ~LineSocket() { close(); }
  LineSocket(const LineSocket&) = delete;
  LineSocket& operator=(const LineSocket&) = delete;

  int fd() const { return fd_; }
  // Sends everything; false once the peer is gone (no SIGPIPE).
  bool send_all(std::string_view bytes) {
    while (!bytes.empty()) {
      const ssize_t n = ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return false;
      bytes.remove_prefix(static_cast<std::size_t>(n));
    }
    return true;
  }
  // One line without its '\n'; nullopt on EOF or after `timeout`.
  std::optional<std::string> read_line(milliseconds timeout = std::chrono::seconds(10)) {
    const auto until = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      if (const auto nl = buffer_.find('\n'); nl != std::string::npos) {
        std::string line = buffer_.substr(0, nl);
        buffer_.erase(0, nl + 1);
        return line;
      }
      if (!fill(until)) return std::nullopt;
    }
  }
  // Everything the peer sends until it closes (bounded by `limit`).
  std::string read_to_eof(milliseconds limit = std::chrono::seconds(10)) {
    const auto until = std::chrono::steady_clock::now() + limit;
    while (fill(until)) {
    }
    return std::exchange(buffer_, {});
  }
  // True when the peer closed the connection (EOF) within `timeout`.
  bool sees_eof(milliseconds timeout = std::chrono::seconds(5)) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout.count())) <= 0) return false;
    char c;
    return ::recv(fd_, &c, 1, MSG_DONTWAIT) == 0;
  }
  // True when the peer closed the connection within `timeout`, by an EOF or
  // by a reset: a Unix socket closed with bytes of ours still unread in it
  // makes our recv fail with ECONNRESET instead of seeing EOF (a client
  // still sending when the server closes it).
  bool sees_closed(milliseconds timeout = std::chrono::seconds(5)) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout.count())) <= 0) return false;
    char c;
    const ssize_t n = ::recv(fd_, &c, 1, MSG_DONTWAIT);
    return n == 0 || (n < 0 && errno == ECONNRESET);
  }
  void close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

 private:
  bool fill(std::chrono::steady_clock::time_point until) {
    const auto left = std::chrono::duration_cast<milliseconds>(until - std::chrono::steady_clock::now());
    if (left.count() <= 0) return false;
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) return false;
    char buf[65536];
    const ssize_t n = ::recv(fd_, buf, sizeof buf, 0);
    if (n <= 0) return false;
    buffer_.append(buf, static_cast<std::size_t>(n));
    return true;
  }

  int fd_;
  std::string buffer_;
};

// A client connected to a Unix socket at `path` (connected() says whether
// the connect worked).
class RawClient : public LineSocket {
 public:
  explicit RawClient(const std::string& path) : LineSocket(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0)) {
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, path.data(), std::min(path.size(), sizeof addr.sun_path - 1));
    connected_ = fd() >= 0 && ::connect(fd(), reinterpret_cast<const sockaddr*>(&addr), sizeof addr) == 0;
  }
  bool connected() const { return connected_; }

 private:
  bool connected_ = false;
};

}  // namespace tissue::control::testing
