#include "control/systemd_notify.hpp"

#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstddef>
#include <cstdlib>
#include <cstring>

namespace tissue::control {

namespace {

std::optional<std::uint64_t> parse_u64(const char* text) {
  if (text == nullptr || *text == '\0') return std::nullopt;
  const std::string_view s(text);
  std::uint64_t v = 0;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || ptr != s.data() + s.size()) return std::nullopt;
  return v;
}

}  // namespace

std::optional<std::chrono::microseconds> parse_watchdog_usec(const char* usec, std::string* problem) {
  problem->clear();
  if (usec == nullptr || *usec == '\0') return std::nullopt;
  const std::optional<std::uint64_t> value = parse_u64(usec);
  if (!value) {
    *problem = "WATCHDOG_USEC=" + std::string(usec).substr(0, 40) + " is not a number of microseconds";
    return std::nullopt;
  }
  if (*value == 0) return std::nullopt;
  if (*value > static_cast<std::uint64_t>(kMaxWatchdogInterval.count())) {
    *problem = "WATCHDOG_USEC=" + std::to_string(*value) + " is above " + std::to_string(kMaxWatchdogInterval.count()) +
               " (11.6 days): not a watchdog (check WatchdogSec=)";
    return std::nullopt;
  }
  return std::chrono::microseconds(static_cast<std::chrono::microseconds::rep>(*value));
}

SystemdNotifier::SystemdNotifier() {
  // The watchdog settings are independent of the notify socket: systemd
  // sets them for Type=notify units with WatchdogSec=.
  const char* pid_text = std::getenv("WATCHDOG_PID");
  const auto pid = parse_u64(pid_text);
  const bool ours = pid_text == nullptr || (pid && *pid == static_cast<std::uint64_t>(::getpid()));
  if (ours) watchdog_ = parse_watchdog_usec(std::getenv("WATCHDOG_USEC"), &watchdog_error_);

  const char* socket_env = std::getenv("NOTIFY_SOCKET");
  if (socket_env == nullptr || *socket_env == '\0') return;
  const std::string_view name(socket_env);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (name.size() > sizeof addr.sun_path || (name[0] != '/' && name[0] != '@') ||
      (name[0] == '/' && name.size() == sizeof addr.sun_path)) {
    setup_error_ = "NOTIFY_SOCKET is not an absolute socket path or an @abstract name";
    return;
  }
  std::memcpy(addr.sun_path, name.data(), name.size());
  if (name[0] == '@') addr.sun_path[0] = '\0';  // abstract namespace: no terminating NUL, exact length
  const std::size_t length = offsetof(sockaddr_un, sun_path) + name.size() + (name[0] == '/' ? 1 : 0);
  address_.assign(reinterpret_cast<const char*>(&addr), length);

  // Non-blocking: a full queue at systemd's end must not stall the io
  // thread (a missed WATCHDOG=1 or STATUS= is dropped, not waited for).
  fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (fd_ < 0) setup_error_ = std::string("cannot create a datagram socket: ") + std::strerror(errno);
}

SystemdNotifier::~SystemdNotifier() {
  if (fd_ >= 0) ::close(fd_);
}

bool SystemdNotifier::notify(std::string_view message) const {
  if (fd_ < 0 || message.empty()) return false;
  const auto* addr = reinterpret_cast<const sockaddr*>(address_.data());
  const auto length = static_cast<socklen_t>(address_.size());
  for (;;) {
    const ssize_t sent = ::sendto(fd_, message.data(), message.size(), MSG_NOSIGNAL | MSG_DONTWAIT, addr, length);
    if (sent >= 0) return static_cast<std::size_t>(sent) == message.size();
    if (errno != EINTR) return false;
  }
}

bool SystemdNotifier::ready() const { return notify("READY=1"); }

bool SystemdNotifier::ready(std::string_view text) const {
  std::string message = "READY=1\nSTATUS=";
  for (const char c : text) message += (c == '\n' || c == '\r') ? ' ' : c;
  return notify(message);
}

bool SystemdNotifier::status(std::string_view text) const {
  std::string message = "STATUS=";
  for (const char c : text) message += (c == '\n' || c == '\r') ? ' ' : c;
  return notify(message);
}

bool SystemdNotifier::watchdog() const { return notify("WATCHDOG=1"); }

bool SystemdNotifier::reloading() const {
  // systemd 253's Type=notify-reload matches RELOADING=1 with the
  // CLOCK_MONOTONIC time of the reload request; older ones ignore the field.
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  const auto usec = static_cast<std::uint64_t>(ts.tv_sec) * 1000000u + static_cast<std::uint64_t>(ts.tv_nsec) / 1000u;
  return notify("RELOADING=1\nMONOTONIC_USEC=" + std::to_string(usec));
}

bool SystemdNotifier::stopping() const { return notify("STOPPING=1"); }

WatchdogFeeder::WatchdogFeeder(const SystemdNotifier& notifier, const std::atomic<std::uint64_t>& heartbeat)
    : WatchdogFeeder(notifier, heartbeat, notifier.watchdog_interval()) {}

WatchdogFeeder::WatchdogFeeder(const SystemdNotifier& notifier, const std::atomic<std::uint64_t>& heartbeat,
                               std::optional<std::chrono::microseconds> interval)
    : notifier_(notifier), heartbeat_(heartbeat), last_beat_(heartbeat.load(std::memory_order_relaxed)) {
  if (interval && interval->count() > 0 && *interval <= kMaxWatchdogInterval)
    period_ = std::chrono::duration_cast<Clock::duration>(*interval) / 2;
}

std::optional<WatchdogFeeder::Clock::duration> WatchdogFeeder::poll_period() const noexcept {
  if (!period_) return std::nullopt;
  return *period_ / 2;
}

bool WatchdogFeeder::poll(Clock::time_point now) {
  if (!period_) return false;
  if (last_feed_ && now - *last_feed_ < *period_) return false;
  const std::uint64_t beat = heartbeat_.load(std::memory_order_relaxed);
  // A heartbeat that has not moved since the last feed means the loop it
  // counts is stuck: starve the watchdog so systemd notices.
  if (beat == last_beat_) return false;
  if (!notifier_.watchdog()) return false;
  last_beat_ = beat;
  last_feed_ = now;
  return true;
}

}  // namespace tissue::control
