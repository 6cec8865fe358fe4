#include "util/lcm_url.hpp"

#include <arpa/inet.h>
#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <optional>
#include <sstream>

namespace tissue::util {

namespace {

bool all_digits(const std::string& s, std::size_t max_length) {
  return !s.empty() && s.size() <= max_length && s.find_first_not_of("0123456789") == std::string::npos;
}

// One octet of a dotted IPv4 address: 1 to 3 digits, at most 255, no sign,
// space or leading zero (inet_aton, which LCM uses, reads "010" as octal 8).
std::optional<std::uint32_t> octet(std::string_view s) {
  if (s.empty() || s.size() > 3 || s.find_first_not_of("0123456789") != std::string_view::npos) return std::nullopt;
  if (s.size() > 1 && s[0] == '0') return std::nullopt;
  std::uint32_t v = 0;
  for (const char c : s) v = v * 10 + static_cast<std::uint32_t>(c - '0');
  if (v > 255) return std::nullopt;
  return v;
}

// The multicast group of a udpm:// URL in host byte order; false when the
// URL does not start with a dotted IPv4 multicast address (four octets as
// above: sscanf's %d accepted "4294967535.255.76.67" as 239.255.76.67, signs
// and spaces, and overflowed on long numbers).
bool udpm_group(const std::string& url, std::uint32_t* group) {
  if (url.rfind("udpm://", 0) != 0) return false;
  const std::string rest = url.substr(7);
  const std::string address = rest.substr(0, rest.find('?'));
  const std::string_view host = std::string_view(address).substr(0, address.rfind(':'));
  std::uint32_t value = 0;
  std::size_t at = 0;
  for (int i = 0; i < 4; ++i) {
    const std::size_t dot = i < 3 ? host.find('.', at) : host.size();
    if (dot == std::string_view::npos) return false;
    const std::optional<std::uint32_t> o = octet(host.substr(at, dot - at));
    if (!o) return false;
    value = value << 8 | *o;
    at = dot + 1;
  }
  if (value >> 28 != 0xeu) return false;  // 224.0.0.0/4
  *group = value;
  return true;
}

}  // namespace

std::string udpm_url_problem(const std::string& url) {
  if (url.rfind("udpm://", 0) != 0) return {};
  std::uint32_t group = 0;
  if (!udpm_group(url, &group)) return "the group must be an IPv4 multicast address (224.0.0.0 to 239.255.255.255)";
  const std::string rest = url.substr(7);
  const std::string address = rest.substr(0, rest.find('?'));
  const std::size_t colon = address.rfind(':');
  if (colon != std::string::npos) {
    const std::string port = address.substr(colon + 1);
    if (!all_digits(port, 5) || std::stoi(port) < 1 || std::stoi(port) > 65535) return "the port must be in [1, 65535]";
  }
  if (const std::size_t q = rest.find('?'); q != std::string::npos) {
    const std::string options = rest.substr(q + 1) + "&";
    for (std::size_t at = 0, amp; (amp = options.find('&', at)) != std::string::npos; at = amp + 1) {
      const std::string option = options.substr(at, amp - at);
      if (option.rfind("ttl=", 0) != 0) continue;
      const std::string ttl = option.substr(4);
      if (!all_digits(ttl, 3) || std::stoi(ttl) > 255) return "ttl must be in [0, 255] (0: this host only)";
    }
  }
  return {};
}

bool has_route_to(std::uint32_t group, std::string_view proc_net_route) {
  const std::uint32_t raw = htonl(group);
  std::istringstream table{std::string(proc_net_route)};
  std::string line;
  std::getline(table, line);  // header
  while (std::getline(table, line)) {
    std::istringstream fields(line);
    std::string iface, destination, gateway, flags, refcnt, use, metric, mask;
    if (!(fields >> iface >> destination >> gateway >> flags >> refcnt >> use >> metric >> mask)) continue;
    unsigned long dest = 0, netmask = 0, route_flags = 0;
    try {
      dest = std::stoul(destination, nullptr, 16);
      netmask = std::stoul(mask, nullptr, 16);
      route_flags = std::stoul(flags, nullptr, 16);
    } catch (const std::exception&) {
      continue;
    }
    if ((route_flags & 0x1) == 0) continue;  // RTF_UP
    if ((raw & netmask) == dest) return true;
  }
  return false;
}

std::string lcm_start_failure(const std::string& url, std::string_view proc_net_route) {
  std::uint32_t group = 0;
  if (udpm_group(url, &group) && !has_route_to(group, proc_net_route))
    return "cannot start LCM at '" + url +
           "': no route covers its multicast group (add one, e.g. `ip route add 224.0.0.0/4 dev lo` for this host "
           "only)";
  return "cannot start LCM at '" + url + "' (LCM's own message above on stderr says why)";
}

std::string lcm_start_failure(const std::string& url) {
  std::ifstream in("/proc/net/route");
  std::ostringstream text;
  text << in.rdbuf();
  return lcm_start_failure(url, text.str());
}

int poll_timeout_ms(double timeout_s) {
  if (!(timeout_s > 0.0)) return 0;
  const double ms = std::ceil(timeout_s * 1000.0);
  return ms >= static_cast<double>(INT_MAX) ? INT_MAX : static_cast<int>(ms);
}

bool tcpq_server(const std::string& url, TcpqServer* out) {
  if (url.rfind("tcpq://", 0) != 0) return false;
  const std::string rest = url.substr(7);
  const std::string address = rest.substr(0, rest.find('?'));
  // LCM's default port when none is given: the probe used to skip such a
  // URL, and LCM then waited on a silent 7700 with no time limit.
  const std::size_t colon = address.rfind(':');
  out->host = address.substr(0, colon);
  out->port = colon == std::string::npos ? "7700" : address.substr(colon + 1);
  return true;
}

std::string tcpq_server_problem(const std::string& url, double timeout_s) {
  return probe_tcpq_server(url, timeout_s, nullptr).problem;
}

TcpqProbe probe_tcpq_server(const std::string& url, double timeout_s, const std::atomic<bool>* stop) {
  TcpqServer server;
  if (!tcpq_server(url, &server)) return {};
  const std::string& host = server.host;
  const std::string& port = server.port;
  if (!all_digits(port, 5) || std::stoi(port) < 1 || std::stoi(port) > 65535) return {"the port must be in [1, 65535]"};
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (::getaddrinfo(host.empty() ? "127.0.0.1" : host.c_str(), port.c_str(), &hints, &found) != 0 || !found)
    return {"cannot resolve '" + host + "'"};
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  std::string why;
  char seconds[32];
  std::snprintf(seconds, sizeof seconds, "%g s", timeout_s);
  const auto stopped = [&] { return stop && stop->load(std::memory_order_acquire); };
  // Up to timeout_s, in slices so that a stop request is seen within one.
  const auto wait_for = [&](short events) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    for (;;) {
      if (stopped()) return false;
      const double left_s = std::chrono::duration<double>(end - std::chrono::steady_clock::now()).count();
      pollfd p{fd, events, 0};
      // A timeout used up (or 0) still looks once: poll_timeout_ms gives 0.
      const int ready = ::poll(&p, 1, poll_timeout_ms(stop ? std::min(left_s, kTcpqProbeSlice_s) : left_s));
      if (ready == 1) return (p.revents & events) != 0;
      if (ready < 0 && errno != EINTR) return false;
      if (std::chrono::steady_clock::now() >= end) return false;
    }
  };
  const auto stop_result = [&] {
    if (fd >= 0) ::close(fd);
    ::freeaddrinfo(found);
    return TcpqProbe{"", true};
  };
  if (stopped()) return stop_result();
  if (fd < 0) {
    why = std::string("cannot create a socket: ") + std::strerror(errno);
  } else if (::connect(fd, found->ai_addr, found->ai_addrlen) != 0 && errno != EINPROGRESS) {
    why = std::string("cannot connect: ") + std::strerror(errno);
  } else if (!wait_for(POLLOUT)) {
    if (stopped()) return stop_result();
    why = std::string("no connection within ") + seconds;
  } else {
    int err = 0;
    socklen_t length = sizeof err;
    ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &length);
    const std::uint32_t greeting[2] = {htonl(0x287617fbu), htonl(0x0100u)};  // client magic, version
    std::uint32_t reply[2] = {0, 0};
    std::size_t got = 0;
    if (err != 0) {
      why = std::string("cannot connect: ") + std::strerror(err);
    } else if (::send(fd, greeting, sizeof greeting, MSG_NOSIGNAL) != static_cast<ssize_t>(sizeof greeting)) {
      why = std::string("cannot send LCM's greeting: ") + std::strerror(errno);
    } else {
      while (got < sizeof reply && wait_for(POLLIN)) {
        const ssize_t n = ::recv(fd, reinterpret_cast<char*>(reply) + got, sizeof reply - got, 0);
        if (n <= 0) break;
        got += static_cast<std::size_t>(n);
      }
      if (got < sizeof reply && stopped()) return stop_result();
      if (got < sizeof reply)
        why =
            std::string("the server did not answer LCM's greeting within ") + seconds + " (is it an LCM tcpq server?)";
      else if (ntohl(reply[0]) != 0x287617fau)
        why = "the server's answer is not LCM's (is it an LCM tcpq server?)";
    }
  }
  if (fd >= 0) ::close(fd);
  ::freeaddrinfo(found);
  return {why.empty() ? why : "tcpq server at '" + url + "': " + why};
}

}  // namespace tissue::util
