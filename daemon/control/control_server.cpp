#include "control/control_server.hpp"

#include <fcntl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <boost/asio/local/stream_protocol.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/write.hpp>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <unordered_map>
#include <utility>
#include <vector>

namespace tissue::control {

namespace asio = boost::asio;
using asio::ip::tcp;
using unix_stream = asio::local::stream_protocol;

namespace {

// Bytes taken from the socket per read; a request line may span many reads.
constexpr std::size_t kReadChunkBytes = 16384;
// After an accept error other than cancellation (e.g. EMFILE), retry after
// this pause instead of spinning on a connection we cannot take.
constexpr std::chrono::milliseconds kAcceptRetryDelay{100};

std::string errno_text(int err) { return std::strerror(err); }

}  // namespace

ServerSettings ServerSettings::from_spec(const config::ControlSpec& spec) {
  ServerSettings s;
  s.unix_socket_path = spec.unix_socket_path;
  if (spec.tcp_port != 0) s.tcp_port = static_cast<std::uint16_t>(spec.tcp_port);
  s.max_line_bytes = spec.max_line_bytes;
  s.max_connections = spec.max_connections;
  // Validated to [0.001, 3600] s (daemon_config_yaml.cpp): whole milliseconds
  // fit, and rounding keeps 0.0015 s from becoming 1 ms.
  s.stalled_after = std::chrono::milliseconds(std::llround(spec.stalled_after_s * 1000.0));
  return s;
}

// A connection, seen by the server state without its socket type.
class SessionBase {
 public:
  virtual ~SessionBase() = default;
  virtual void close() = 0;
  // Waiting for a request with nothing of one received and no response
  // being written: closing it loses nothing.
  virtual bool idle() const = 0;
  // Closes the connection after a best-effort error line (a short write to
  // an idle socket fits its buffer), or without one while an answer is
  // being sent.
  virtual void evict(const std::string& line) = 0;
  // Mid-request and no progress for `stalled_after`: part of a line received
  // and no byte since, or an answer not all taken that long after it was
  // ready (its write counts as progress only once whole): a client that sent
  // half a line and went quiet, or stopped reading. 16 of them locked every client
  // out (tissue ctl shutdown included) until they closed.
  bool stalled(std::chrono::steady_clock::time_point now, std::chrono::milliseconds stalled_after) const {
    return !idle() && now - last_progress >= stalled_after;
  }
  // Mid-request, with the stage in progress (receiving its line, or
  // discarding a too-long one) begun more than kRequestDeadlineStalls *
  // stalled_after ago (an answer is stalled before that):
  // a client trickling a byte every few seconds (a space, or the rest of an
  // over-long line being discarded) is never stalled, and 16 of them locked
  // every client out just the same.
  bool overdue(std::chrono::steady_clock::time_point now, std::chrono::milliseconds stalled_after) const {
    return !idle() && now - request_stage_started >= kRequestDeadlineStalls * stalled_after;
  }
  // When a full server may first close it for a newcomer (once stalled or
  // overdue); the earliest goes first. Meaningless while idle.
  std::chrono::steady_clock::time_point evictable_from(std::chrono::milliseconds stalled_after) const {
    return std::min(last_progress + stalled_after, request_stage_started + kRequestDeadlineStalls * stalled_after);
  }
  // The request deadline in units of stalled_after: twice the stall time, so
  // a client that keeps its bytes moving gets longer than a silent one, and
  // no setting of its own.
  static constexpr int kRequestDeadlineStalls = 2;

  std::chrono::steady_clock::time_point last_active = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point last_progress = std::chrono::steady_clock::now();
  // When the request in progress began its current stage: the first byte of
  // its line taken, or its answer (or a too-long line's error, after which
  // the rest of that line is discarded) started to be sent.
  std::chrono::steady_clock::time_point request_stage_started = std::chrono::steady_clock::now();
};

struct ControlServer::State : std::enable_shared_from_this<ControlServer::State> {
  State(asio::io_context& io_context, ServerSettings s, ControlHandler& h)
      : io(io_context),
        settings(std::move(s)),
        handler(h),
        unix_acceptor(io_context),
        tcp_acceptor(io_context),
        unix_retry(io_context),
        tcp_retry(io_context) {}

  asio::io_context& io;
  const ServerSettings settings;
  ControlHandler& handler;
  unix_stream::acceptor unix_acceptor;
  tcp::acceptor tcp_acceptor;
  asio::steady_timer unix_retry, tcp_retry;  // one per acceptor: a retry of one must not cancel the other's
  std::optional<tcp::endpoint> bound_tcp;
  bool started = false;
  bool stopped = false;
  // The socket file start() created, so stop() removes that one and not a
  // file some other process put there since.
  bool own_socket_file = false;
  dev_t socket_dev = 0;
  ino_t socket_ino = 0;
  std::unordered_map<SessionBase*, std::shared_ptr<SessionBase>> sessions;

  void forget(SessionBase* s) { sessions.erase(s); }

  template <class Socket>
  void admit(Socket socket);
  template <class Acceptor>
  void accept_next(Acceptor& acceptor, asio::steady_timer& retry);
  void open_unix();
  void open_tcp();
  void remove_socket_file();
  void stop();
};

namespace {

template <class Socket>
class Session final : public SessionBase, public std::enable_shared_from_this<Session<Socket>> {
 public:
  Session(std::shared_ptr<ControlServer::State> state, Socket socket)
      : state_(std::move(state)), socket_(std::move(socket)) {}

  void start() { read_more(); }

  void close() override {
    if (closed_) return;
    closed_ = true;
    boost::system::error_code ignored;
    socket_.shutdown(asio::socket_base::shutdown_both, ignored);
    socket_.close(ignored);
  }

  bool idle() const override { return awaiting_request_ && !closed_; }

  void evict(const std::string& line) override {
    // While an answer's async_write is pending, part of the answer may be
    // out and the rest waiting for room: an error line written now would
    // land in the middle of it, and the client would read one line that is
    // not JSON. Such a connection is closed without a word.
    if (out_.empty()) {
      boost::system::error_code ignored;
      socket_.non_blocking(true, ignored);
      socket_.write_some(asio::buffer(line), ignored);
    }
    close();
  }

 private:
  void read_more() {
    auto self = this->shared_from_this();
    awaiting_request_ = line_.empty() && !discarding_ && out_.empty();
    if (awaiting_request_) stage_running_ = false;  // idle: the next byte begins a request
    socket_.async_read_some(asio::buffer(chunk_), [self](const boost::system::error_code& ec, std::size_t n) {
      self->awaiting_request_ = false;
      self->last_progress = std::chrono::steady_clock::now();
      // closed_: evicted as idle after this read had already taken a line
      // (asio reads speculatively when the read starts); the client was told
      // it was closed, so its request must not run unanswered.
      if (ec || self->closed_ || self->state_->stopped) {
        self->finish();  // EOF (maybe mid-line: nothing to answer), reset, or stop()
        return;
      }
      self->pending_.assign(self->chunk_.data(), n);
      self->pos_ = 0;
      self->process();
    });
  }

  // Consumes pending_ from pos_. A complete line is answered and processing
  // resumes after the response is written; when pending_ runs out, reads more.
  void process() {
    const std::size_t max_line = state_->settings.max_line_bytes;
    while (pos_ < pending_.size()) {
      // A line's first byte starts its stage, unless a stage is already
      // running: a blank line (no request) does not end one, or a client
      // sending " " then "\n " for ever would never be overdue.
      if (!stage_running_ && line_.empty() && !discarding_) {
        request_stage_started = std::chrono::steady_clock::now();
        stage_running_ = true;
      }
      const std::size_t nl = pending_.find('\n', pos_);
      const std::size_t end = nl == std::string::npos ? pending_.size() : nl;
      if (discarding_) {
        // The rest of an oversized line, already answered: drop it up to its '\n'.
        pos_ = end;
        if (nl != std::string::npos) {
          discarding_ = false;
          ++pos_;
        }
        continue;
      }
      const std::size_t take = end - pos_;
      if (line_.size() + take > max_line) {
        line_.clear();
        line_.shrink_to_fit();  // a long line must not keep its memory
        pos_ = end;
        if (nl != std::string::npos)
          ++pos_;
        else
          discarding_ = true;
        respond(error_response("request line too long (more than " + std::to_string(max_line) +
                               " bytes); the rest of that line is discarded"));
        return;
      }
      line_.append(pending_, pos_, take);
      pos_ = end;
      if (nl == std::string::npos) break;
      ++pos_;
      std::string line = std::move(line_);
      line_.clear();
      if (!line.empty() && line.back() == '\r') line.pop_back();         // telnet / nc -C line endings
      if (line.find_first_not_of(" \t") == std::string::npos) continue;  // blank lines are no requests
      respond(handle_request_line(line, state_->handler));
      return;
    }
    read_more();
  }

  void respond(std::string response) {
    // Activity is a request answered: blank lines (ignored) do not count.
    // The answer's stage starts now, not when its line began: the handler's
    // own time is not the client's.
    last_active = last_progress = request_stage_started = std::chrono::steady_clock::now();
    stage_running_ = false;  // the answer's own stage; the next line's first byte begins a new one
    out_ = std::move(response);
    out_ += '\n';
    auto self = this->shared_from_this();
    asio::async_write(socket_, asio::buffer(out_), [self](const boost::system::error_code& ec, std::size_t) {
      if (ec || self->closed_ || self->state_->stopped) {
        self->finish();
        return;
      }
      self->out_.clear();
      // Discarding the rest of a too-long line is a stage of its own.
      self->last_progress = self->request_stage_started = std::chrono::steady_clock::now();
      self->process();
    });
  }

  void finish() {
    close();
    if (!state_->stopped) state_->forget(this);
  }

  std::shared_ptr<ControlServer::State> state_;
  Socket socket_;
  std::array<char, kReadChunkBytes> chunk_{};
  std::string pending_;  // the bytes of the last read
  std::size_t pos_ = 0;  // next unprocessed byte of pending_
  std::string line_;     // the request line so far
  std::string out_;      // the response being written
  bool discarding_ = false;
  bool closed_ = false;
  bool awaiting_request_ = false;
  bool stage_running_ = false;  // request_stage_started holds a line's stage still going on
};

}  // namespace

template <class Socket>
void ControlServer::State::admit(Socket socket) {
  if (sessions.size() >= static_cast<std::size_t>(settings.max_connections)) {
    // Full: the connection idle the longest (nothing asked since its last
    // answer) makes way, so forgotten connections (a script that never
    // closed its socket) cannot lock every client out; failing that, the one
    // that first became stalled (no byte for stalled_after: half a line, then
    // silence) or overdue (a request going on for twice that: a line
    // trickled in a byte at a time). Only when every connection is busy with
    // a request that is neither is the newcomer refused.
    const auto now = std::chrono::steady_clock::now();
    const std::chrono::milliseconds stalled_after = settings.stalled_after;
    SessionBase* longest_idle = nullptr;
    SessionBase* first_evictable = nullptr;
    for (const auto& [session, owner] : sessions) {
      if (session->idle() && (!longest_idle || session->last_active < longest_idle->last_active))
        longest_idle = session;
      if ((session->stalled(now, stalled_after) || session->overdue(now, stalled_after)) &&
          (!first_evictable || session->evictable_from(stalled_after) < first_evictable->evictable_from(stalled_after)))
        first_evictable = session;
    }
    // With a limit of 1 the connection closed held the only place: "the
    // longest idle of 1 open ones" and "all 1 places taken" misled.
    const bool only_place = settings.max_connections == 1;
    const std::string places = std::to_string(settings.max_connections);
    if (longest_idle) {
      longest_idle->evict(
          error_response(only_place ? "closed: this connection was idle in the only place (the limit is 1) and a new "
                                      "client needed it"
                                    : "closed: this connection was the longest idle of " + places +
                                          " open ones and a new client needed its place") +
          "\n");
      sessions.erase(longest_idle);
    } else if (first_evictable) {
      const std::string why = first_evictable->stalled(now, stalled_after)
                                  ? "stalled mid-request (no byte for " + std::to_string(stalled_after.count()) + " ms)"
                                  : "took too long over a request (more than " +
                                        std::to_string(SessionBase::kRequestDeadlineStalls * stalled_after.count()) +
                                        " ms receiving its line)";
      const std::string full = only_place ? " in the only place (the limit is 1), and a new client needed it"
                                          : " with all " + places + " places taken, and a new client needed its place";
      first_evictable->evict(error_response("closed: this connection " + why + full) + "\n");
      sessions.erase(first_evictable);
    }
  }
  if (sessions.size() >= static_cast<std::size_t>(settings.max_connections)) {
    // One line, best effort: the socket is fresh, so a short write fits its
    // buffer; a client that cannot take it is closed all the same.
    const std::string line = error_response("too many connections (the limit is " +
                                            std::to_string(settings.max_connections) + "); try again later") +
                             "\n";
    boost::system::error_code ignored;
    socket.non_blocking(true, ignored);
    asio::write(socket, asio::buffer(line), ignored);
    socket.shutdown(asio::socket_base::shutdown_both, ignored);
    socket.close(ignored);
    return;
  }
  auto session = std::make_shared<Session<Socket>>(shared_from_this(), std::move(socket));
  sessions.emplace(session.get(), session);
  session->start();
}

template <class Acceptor>
void ControlServer::State::accept_next(Acceptor& acceptor, asio::steady_timer& retry) {
  using Socket = typename Acceptor::protocol_type::socket;
  auto self = shared_from_this();
  acceptor.async_accept([self, &acceptor, &retry](const boost::system::error_code& ec, Socket socket) {
    if (self->stopped || ec == asio::error::operation_aborted) return;
    if (ec) {
      retry.expires_after(kAcceptRetryDelay);
      retry.async_wait([self, &acceptor, &retry](const boost::system::error_code& wait_ec) {
        if (!wait_ec && !self->stopped) self->accept_next(acceptor, retry);
      });
      return;
    }
    self->admit(std::move(socket));
    self->accept_next(acceptor, retry);
  });
}

void ControlServer::State::open_unix() {
  const std::string& path = settings.unix_socket_path;
  const auto fail = [&](const std::string& why) -> ControlError {
    return ControlError("control socket " + path + ": " + why);
  };
  if (path.size() >= sizeof(sockaddr_un{}.sun_path)) throw fail("path too long for a Unix socket");

  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0) {
    if (!S_ISSOCK(st.st_mode)) throw fail("the path exists and is not a socket; refusing to replace it");
    // A socket file: live (another daemon) or stale (a crash). Ask it.
    const int probe = ::socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (probe < 0) throw fail("cannot create a probe socket: " + errno_text(errno));
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, path.data(), path.size());
    const int rc = ::connect(probe, reinterpret_cast<const sockaddr*>(&addr), sizeof addr);
    const int err = errno;
    ::close(probe);
    if (rc == 0 || err == EAGAIN || err == EINPROGRESS)
      throw fail("another process is serving this socket (is tissued already running?)");
    if (err == ECONNREFUSED) {
      if (::unlink(path.c_str()) != 0 && errno != ENOENT)
        throw fail("cannot remove the stale socket file: " + errno_text(errno));
    } else if (err != ENOENT) {
      throw fail("cannot check whether the existing socket is in use: " + errno_text(err));
    }
  } else if (errno != ENOENT) {
    throw fail(errno_text(errno));
  }

  boost::system::error_code ec;
  unix_acceptor.open(unix_stream(), ec);
  if (!ec) unix_acceptor.bind(unix_stream::endpoint(path), ec);
  if (ec) throw fail("cannot bind: " + ec.message());
  if (::lstat(path.c_str(), &st) == 0) {
    own_socket_file = true;
    socket_dev = st.st_dev;
    socket_ino = st.st_ino;
  }
  // The group (the service's users) may connect; nobody else. A client needs
  // write permission on the socket file to connect.
  if (::chmod(path.c_str(), 0660) != 0) {
    const int err = errno;
    remove_socket_file();
    throw fail("cannot set mode 0660: " + errno_text(err));
  }
  unix_acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) {
    remove_socket_file();
    throw fail("cannot listen: " + ec.message());
  }
}

void ControlServer::State::open_tcp() {
  const tcp::endpoint want(asio::ip::address_v4::loopback(), *settings.tcp_port);
  const auto fail = [&](const std::string& why) -> ControlError {
    return ControlError("control TCP port 127.0.0.1:" + std::to_string(*settings.tcp_port) + ": " + why);
  };
  boost::system::error_code ec;
  tcp_acceptor.open(want.protocol(), ec);
  if (!ec) tcp_acceptor.set_option(asio::socket_base::reuse_address(true), ec);
  if (!ec) tcp_acceptor.bind(want, ec);
  if (!ec) tcp_acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) throw fail("cannot listen: " + ec.message());
  bound_tcp = tcp_acceptor.local_endpoint(ec);
  if (ec) throw fail("cannot read the bound address: " + ec.message());
}

void ControlServer::State::remove_socket_file() {
  if (!own_socket_file) return;
  own_socket_file = false;
  struct stat st {};
  const std::string& path = settings.unix_socket_path;
  if (::lstat(path.c_str(), &st) == 0 && S_ISSOCK(st.st_mode) && st.st_dev == socket_dev && st.st_ino == socket_ino)
    ::unlink(path.c_str());
}

void ControlServer::State::stop() {
  if (stopped) return;
  stopped = true;
  boost::system::error_code ignored;
  unix_retry.cancel();
  tcp_retry.cancel();
  unix_acceptor.close(ignored);
  tcp_acceptor.close(ignored);
  remove_socket_file();
  // Closing cancels each session's pending operation; its handler then sees
  // `stopped` and lets go of the session.
  auto open = std::move(sessions);
  sessions.clear();
  for (auto& [raw, session] : open) session->close();
}

ControlServer::ControlServer(asio::io_context& io, ServerSettings settings, ControlHandler& handler)
    : state_(std::make_shared<State>(io, std::move(settings), handler)) {}

ControlServer::~ControlServer() { stop(); }

void ControlServer::start() {
  State& s = *state_;
  if (s.started) throw ControlError("control server: start() called twice");
  if (s.stopped) throw ControlError("control server: start() after stop()");
  if (s.settings.max_connections < 1) throw ControlError("control server: max_connections must be >= 1");
  if (s.settings.max_line_bytes < 1) throw ControlError("control server: max_line_bytes must be >= 1");
  s.started = true;
  try {
    if (!s.settings.unix_socket_path.empty()) s.open_unix();
    if (s.settings.tcp_port) s.open_tcp();
  } catch (...) {
    s.stop();
    throw;
  }
  if (s.unix_acceptor.is_open()) s.accept_next(s.unix_acceptor, s.unix_retry);
  if (s.tcp_acceptor.is_open()) s.accept_next(s.tcp_acceptor, s.tcp_retry);
}

void ControlServer::stop() { state_->stop(); }

std::optional<tcp::endpoint> ControlServer::tcp_endpoint() const { return state_->bound_tcp; }

const std::string& ControlServer::unix_socket_path() const { return state_->settings.unix_socket_path; }

std::size_t ControlServer::connection_count() const { return state_->sessions.size(); }

std::size_t ControlServer::idle_connection_count() const {
  std::size_t idle = 0;
  for (const auto& entry : state_->sessions) idle += entry.first->idle() ? 1 : 0;
  return idle;
}

}  // namespace tissue::control
