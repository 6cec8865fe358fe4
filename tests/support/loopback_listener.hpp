// A loopback TCP listener for tests of clients that must not hang on a
// server that accepts and stays silent (or answers a fixed greeting).
// Header-only: the util and replay suites use it. Loopback only.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdint>
#include <string>
#include <thread>
#include <utility>

namespace tissue::testing {

// A loopback TCP listener on a port the kernel picks; `answer` (if not
// empty) is written to each connection once accepted, then the connection is
// held open until the listener goes.
class LoopbackListener {
 public:
  explicit LoopbackListener(std::string answer) : answer_(std::move(answer)) {
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t length = sizeof a;
    ok_ = fd_ >= 0 && ::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 && ::listen(fd_, 4) == 0 &&
          ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &length) == 0;
    port_ = ntohs(a.sin_port);
    if (ok_)
      thread_ = std::thread([this] {
        const int c = ::accept(fd_, nullptr, nullptr);
        if (c < 0) return;
        if (!answer_.empty()) (void)!::send(c, answer_.data(), answer_.size(), MSG_NOSIGNAL);
        char sink[64];
        while (::recv(c, sink, sizeof sink, 0) > 0) {
        }
        ::close(c);
      });
  }
  ~LoopbackListener() {
    ::shutdown(fd_, SHUT_RDWR);
    if (thread_.joinable()) {
      // The test's client is gone; one more connection unblocks accept().
      const int poke = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
      sockaddr_in a{};
      a.sin_family = AF_INET;
      a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      a.sin_port = htons(port_);
      (void)::connect(poke, reinterpret_cast<sockaddr*>(&a), sizeof a);
      ::close(poke);
      thread_.join();
    }
    ::close(fd_);
  }
  bool ok() const { return ok_; }
  std::string url() const { return "tcpq://127.0.0.1:" + std::to_string(port_); }

 private:
  std::string answer_;
  int fd_ = -1;
  bool ok_ = false;
  std::uint16_t port_ = 0;
  std::thread thread_;
};

}  // namespace tissue::testing
