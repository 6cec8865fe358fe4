// sd_notify(3) without libsystemd: state messages ("READY=1", "WATCHDOG=1",
// …) as datagrams to the AF_UNIX socket named by $NOTIFY_SOCKET (a path, or
// an abstract address written "@name"). Without $NOTIFY_SOCKET (not started
// by systemd, or Type= is not notify) every call is a cheap no-op returning
// false, so the daemon calls them unconditionally.
//
// Watchdog: systemd sets $WATCHDOG_USEC (and $WATCHDOG_PID) when the unit
// has WatchdogSec=. WatchdogFeeder sends WATCHDOG=1 only while a heartbeat
// counter advances: if the haptic loop (or the sim loop, in a scene without
// a device) stalls, the feeding stops and systemd restarts the service.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace tissue::control {

class SystemdNotifier {
 public:
  // Reads $NOTIFY_SOCKET, $WATCHDOG_USEC and $WATCHDOG_PID now (the
  // environment is not read again, nor modified).
  SystemdNotifier();
  ~SystemdNotifier();
  SystemdNotifier(const SystemdNotifier&) = delete;
  SystemdNotifier& operator=(const SystemdNotifier&) = delete;

  // True when $NOTIFY_SOCKET named a usable socket address.
  bool enabled() const noexcept { return fd_ >= 0; }

  // Each sends one datagram and returns whether it was sent. Safe to call
  // from several threads (one sendto per message).
  bool ready() const;  // READY=1 (+ STATUS= when given)
  bool ready(std::string_view status) const;
  bool status(std::string_view text) const;  // STATUS=<text>: newlines become spaces
  bool watchdog() const;                     // WATCHDOG=1
  bool reloading() const;                    // RELOADING=1 with MONOTONIC_USEC= (systemd >= 253 wants it)
  bool stopping() const;                     // STOPPING=1
  // A raw message ("KEY=value\nKEY2=value2").
  bool notify(std::string_view message) const;

  // The watchdog timeout systemd enforces, or nullopt when there is none or
  // it is meant for another process ($WATCHDOG_PID set and not ours).
  std::optional<std::chrono::microseconds> watchdog_interval() const noexcept { return watchdog_; }

  // Why $NOTIFY_SOCKET was not usable (empty when it was, or was unset).
  const std::string& setup_error() const noexcept { return setup_error_; }
  // Why $WATCHDOG_USEC was not used (empty when it was, or was unset, or is
  // meant for another process): not a number, or above kMaxWatchdogInterval.
  const std::string& watchdog_error() const noexcept { return watchdog_error_; }

 private:
  int fd_ = -1;
  std::string address_;  // sockaddr_un bytes: family + path (abstract: leading NUL)
  std::optional<std::chrono::microseconds> watchdog_;
  std::string setup_error_;
  std::string watchdog_error_;
};

// Longer than this (11.6 days) a watchdog interval is a misconfiguration,
// not a watchdog, and is not used: the feeder works in nanoseconds, which
// $WATCHDOG_USEC=10000000000000000 overflowed (UB).
inline constexpr std::chrono::microseconds kMaxWatchdogInterval{1'000'000'000'000};

// The watchdog interval $WATCHDOG_USEC gives (`usec`, the variable's text),
// or nullopt: unset or 0 (no watchdog), or not usable, said in *problem
// ("WATCHDOG_USEC=... is not a number of microseconds", "... is above ...").
std::optional<std::chrono::microseconds> parse_watchdog_usec(const char* usec, std::string* problem);

// Feeds the watchdog from a heartbeat. Call poll(now) from a periodic timer
// at least every interval/4; it sends WATCHDOG=1 when at least interval/2
// has passed since the last feed AND the heartbeat changed since then.
class WatchdogFeeder {
 public:
  using Clock = std::chrono::steady_clock;

  // Interval from the notifier; nullopt, <= 0 or above kMaxWatchdogInterval
  // disables feeding. `heartbeat` is read with relaxed loads and must
  // outlive the feeder.
  WatchdogFeeder(const SystemdNotifier& notifier, const std::atomic<std::uint64_t>& heartbeat);
  WatchdogFeeder(const SystemdNotifier& notifier, const std::atomic<std::uint64_t>& heartbeat,
                 std::optional<std::chrono::microseconds> interval);

  // True when it sent WATCHDOG=1 now.
  bool poll(Clock::time_point now);

  bool enabled() const noexcept { return period_.has_value(); }
  // interval/2 (the feed period); nullopt when disabled.
  std::optional<Clock::duration> feed_period() const noexcept { return period_; }
  // How often to call poll(): interval/4; nullopt when disabled.
  std::optional<Clock::duration> poll_period() const noexcept;

 private:
  const SystemdNotifier& notifier_;
  const std::atomic<std::uint64_t>& heartbeat_;
  std::optional<Clock::duration> period_;
  std::uint64_t last_beat_;
  std::optional<Clock::time_point> last_feed_;
};

}  // namespace tissue::control
