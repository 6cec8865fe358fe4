// LCM URLs: what is wrong with one before LCM is asked to open it, and what
// to tell the user when LCM could not. Library tissue_lcm_url (no LCM link):
// the config loader checks URLs without linking LCM, the transport explains
// LCM's failures, the clients probe a tcpq:// server before LCM waits on it.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <string_view>

namespace tissue::util {

// What is wrong with a udpm:// URL ("" when nothing, or not udpm): LCM takes
// port 99999 or ttl=-3 and fails only when it opens the URL.
std::string udpm_url_problem(const std::string& url);

// Whether the IPv4 routing table (the text of /proc/net/route) has a route
// that covers `group` (host byte order): a default route or one whose
// destination and mask contain it. That table prints each address as the
// 32-bit word of its network-order bytes, so the group is compared in the
// same form.
bool has_route_to(std::uint32_t group, std::string_view proc_net_route);

// Why lcm::LCM(url) failed, as far as can be told from outside (LCM prints
// its own reason on stderr): for a udpm:// URL whose group no route covers,
// the missing multicast route; otherwise a pointer to LCM's message.
std::string lcm_start_failure(const std::string& url, std::string_view proc_net_route);

// The same, reading this machine's routing table.
std::string lcm_start_failure(const std::string& url);

// Whether a tcpq:// URL's server answers LCM's greeting within timeout_s:
// "" when it does (or the URL is not tcpq://), else why not. LCM's own
// client waits for that greeting inside lcm_create() with no time limit, so
// a port that accepts and says nothing (a web server, a typo) hung the
// clients past their --timeout. Both sides' first words are a magic number
// and the protocol version, big-endian (LCM's lcm_tcpq.c).
std::string tcpq_server_problem(const std::string& url, double timeout_s);

// The same probe, which also gives up when *stop (when not null) turns true:
// it waits in slices of kTcpqProbeSlice_s and looks at the flag between them,
// so a Ctrl-C during `tissue x3d --timeout 600` against a silent server ends
// the wait at once (it waited up to twice --timeout, connection and greeting,
// and only then saw the request). `stopped` says the flag ended it; `problem`
// is then "" (the server's state is unknown, not wrong).
struct TcpqProbe {
  std::string problem;
  bool stopped = false;
};
inline constexpr double kTcpqProbeSlice_s = 0.05;
TcpqProbe probe_tcpq_server(const std::string& url, double timeout_s, const std::atomic<bool>* stop);

// The host and port LCM's tcpq client connects to for a tcpq:// URL, as
// lcm_tcpq.c reads it: "tcpq://" is 127.0.0.1:7700, a host without a port
// takes port 7700. False when the URL is not tcpq://.
struct TcpqServer {
  std::string host;
  std::string port;
};
bool tcpq_server(const std::string& url, TcpqServer* out);

// `timeout_s` as poll(2)'s milliseconds: rounded up (0.0001 s waits 1 ms,
// not 0), at most INT_MAX (1e7 s overflowed int to a negative timeout, which
// poll takes as "forever"); 0 for a timeout that is not > 0 (NaN included).
int poll_timeout_ms(double timeout_s);

}  // namespace tissue::util
