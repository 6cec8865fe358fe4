#include "haptics/udp_device.hpp"

#include <netinet/in.h>
#include <sys/socket.h>

#include <algorithm>
#include <boost/asio/buffer.hpp>
#include <boost/asio/ip/address.hpp>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "tissue_lcm/tissue/device_packet.hpp"

namespace tissue::haptics {
namespace {

using Packet = tissue_lcm::tissue::device_packet;
namespace ip = boost::asio::ip;

constexpr int kFingerprintBytes = 8;  // LCM prefixes every message with its 64-bit type hash

// The fingerprint as LCM writes it: big-endian, first on the wire.
std::int64_t fingerprint_of(const unsigned char* bytes) noexcept {
  std::uint64_t v = 0;
  for (int i = 0; i < kFingerprintBytes; ++i) v = (v << 8) | bytes[i];
  return static_cast<std::int64_t>(v);
}

bool all_finite(const double (&v)[3]) noexcept {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

}  // namespace

const char* UdpDevice::reject_name(Reject reason) noexcept {
  switch (reason) {
    case Reject::kSize:
      return "size";
    case Reject::kFingerprint:
      return "fingerprint";
    case Reject::kVersion:
      return "version";
    case Reject::kKind:
      return "kind";
    case Reject::kNonFinite:
      return "non_finite";
    case Reject::kOtherSender:
      return "other_sender";
    case Reject::kCount:
      break;
  }
  return "unknown";
}

UdpDevice::UdpDevice(const config::UdpDeviceSpec& spec) : spec_(spec), socket_(io_) {
  Packet zero{};
  packet_bytes_ = zero.getEncodedSize();
}

UdpDevice::~UdpDevice() { stop(); }

bool UdpDevice::start(std::string* error) {
  stop();
  const std::string where = spec_.bind_address + ":" + std::to_string(spec_.port);
  auto fail = [&](const std::string& why) {
    if (error) *error = "udp device: " + why;
    return false;
  };
  if (!(std::isfinite(spec_.timeout_s) && spec_.timeout_s > 0.0))
    return fail("timeout_s must be finite and > 0 (got " + std::to_string(spec_.timeout_s) + ")");
  if (spec_.port < 0 || spec_.port > 65535) return fail("port " + std::to_string(spec_.port) + " is not 0..65535");

  boost::system::error_code ec;
  const ip::address address = ip::make_address(spec_.bind_address, ec);
  if (ec) return fail("bind_address '" + spec_.bind_address + "' is not an IP address: " + ec.message());
  const ip::udp::endpoint local(address, static_cast<unsigned short>(spec_.port));

  socket_.open(local.protocol(), ec);
  if (!ec) socket_.bind(local, ec);
  if (!ec) socket_.non_blocking(true, ec);  // read()/write() must never wait
  if (ec) {
    const std::string why = "cannot bind " + where + ": " + ec.message();
    stop();
    return fail(why);
  }
  local_port_ = socket_.local_endpoint(ec).port();
  if (ec) {
    stop();
    return fail("cannot read the bound port of " + where + ": " + ec.message());
  }
  if (spec_.port == 0) {
    // Port 0 took an ephemeral port, which Linux gives back when the peer
    // filter disconnects (connect(AF_UNSPEC) keeps only a port bound by
    // number; IPv4 only, IPv6 sockets are never connected, but the same
    // steps do no harm there). Bind that number explicitly on a fresh socket.
    const ip::udp::endpoint numbered(address, local_port_);
    socket_.close(ec);
    socket_.open(numbered.protocol(), ec);
    if (!ec) socket_.bind(numbered, ec);
    if (!ec) socket_.non_blocking(true, ec);
    if (ec) {
      const std::string why = "cannot bind " + spec_.bind_address + ":" + std::to_string(local_port_) +
                              " (the ephemeral port that port 0 gave): " + ec.message();
      stop();
      return fail(why);
    }
  }

  // Bound to a wildcard address, the socket may only be connected to a sender
  // if the poses came to the address the route back to it leaves from
  // (filter_to): ask the kernel for each datagram's destination.
  wildcard_ = address.is_unspecified();
  connectable_ = address.is_v4();  // IPv6: see connectable_ in the header
  if (wildcard_) {
    const int on = 1;
    const bool v4 = address.is_v4();
    if (::setsockopt(socket_.native_handle(), v4 ? IPPROTO_IP : IPPROTO_IPV6, v4 ? IP_PKTINFO : IPV6_RECVPKTINFO, &on,
                     sizeof on) != 0) {
      const std::string why = "cannot ask for the destination address of datagrams on " + where +
                              (v4 ? " (IP_PKTINFO): " : " (IPV6_RECVPKTINFO): ") + std::strerror(errno);
      stop();
      return fail(why);
    }
  }

  timeout_ns_ = static_cast<std::int64_t>(std::llround(spec_.timeout_s * 1e9));
  // Packet::getHash() computes the fingerprint once behind a function-local
  // static; take that first-call guard here, not in the tick.
  (void)Packet::getHash();

  have_pose_ = false;
  last_accept_ns_ = 0;
  last_sequence_number_ = 0;
  last_sender_time_ns_ = 0;
  pose_ = DeviceSample{};
  force_sequence_number_ = 0;
  last_sent_zero_ = false;
  behind_count_ = 0;
  behind_last_sequence_number_ = 0;
  peer_ = ip::udp::endpoint();
  filtered_ = false;  // a new socket: not connected
  filter_refused_ = false;
  filter_route_source_ = ip::address();
  peer_to_ = ip::address();
  peer_reply_from_ = ip::address();
  reply_from_refused_ = false;
  buttons_.store(0, std::memory_order_relaxed);
  for (auto& r : rejected_) r.store(0, std::memory_order_relaxed);
  for (auto* c : {&received_, &accepted_, &out_of_order_, &resyncs_, &receive_errors_, &sent_, &send_failures_,
                  &reply_source_fallbacks_, &sessions_})
    c->store(0, std::memory_order_relaxed);
  return true;
}

void UdpDevice::stop() noexcept {
  boost::system::error_code ignored;
  if (socket_.is_open()) socket_.close(ignored);
  have_pose_ = false;
}

bool UdpDevice::sender_live(std::int64_t now_ns) const noexcept {
  return have_pose_ && now_ns - last_accept_ns_ <= timeout_ns_;
}

UdpDevice::Verdict UdpDevice::consider(std::size_t bytes, std::int64_t now_ns) noexcept {
  auto reject = [&](Reject reason) {
    bump(rejected_[static_cast<int>(reason)]);
    return Verdict::kRejected;
  };
  if (bytes != static_cast<std::size_t>(packet_bytes_)) return reject(Reject::kSize);
  if (fingerprint_of(receive_buffer_.data()) != Packet::getHash()) return reject(Reject::kFingerprint);

  Packet packet;  // fixed-size type: decode fills every field, allocates nothing
  if (packet.decode(receive_buffer_.data(), 0, packet_bytes_) != packet_bytes_) return reject(Reject::kSize);
  if (packet.version != kProtocolVersion) return reject(Reject::kVersion);
  if (packet.kind != kKindPose) return reject(Reject::kKind);
  if (!all_finite(packet.position_m) || !all_finite(packet.velocity_m_per_s)) return reject(Reject::kNonFinite);

  const bool live = sender_live(now_ns);
  if (live && from_ != peer_) return reject(Reject::kOtherSender);
  if (live && packet.sequence_number <= last_sequence_number_) {
    // kResyncPackets in a row below the last accepted number, each above the
    // one before: the sender's counter restarted (or one packet leapt ahead
    // and took the sequence with it), not a reordering. Follow the sender.
    if (behind_count_ > 0 && packet.sequence_number > behind_last_sequence_number_)
      ++behind_count_;
    else
      behind_count_ = 1;
    behind_last_sequence_number_ = packet.sequence_number;
    if (behind_count_ < kResyncPackets) {
      bump(out_of_order_);
      return Verdict::kOutOfOrder;
    }
    bump(resyncs_);
  }
  behind_count_ = 0;

  if (!live) {
    bump(sessions_);
    filter_refused_ = false;  // a new sender: it may be reached where the route back leaves from
    filter_route_source_ = ip::address();
    reply_from_refused_ = false;
  }
  // Poses that move to another local address within a session (an unconnected
  // one: a connected socket hears only its own) name a source not yet tried:
  // a device that connect()ed to the new address drops forces from the route's.
  if (reply_from_ != peer_reply_from_) reply_from_refused_ = false;
  // The same for the filter, refused because the poses came to an address
  // other than the route back's source: poses that move to that source fit
  // it (read() tries it again). Moves between other addresses do not: each
  // try would cost a connect and a disconnect in the tick, for nothing.
  if (filter_refused_ && to_ != peer_to_ && to_ == filter_route_source_) filter_refused_ = false;
  peer_ = from_;
  peer_to_ = to_;
  peer_reply_from_ = reply_from_;
  have_pose_ = true;
  last_accept_ns_ = now_ns;
  last_sequence_number_ = packet.sequence_number;
  last_sender_time_ns_ = packet.sender_time_ns;
  pose_.position_m = Vec3(packet.position_m[0], packet.position_m[1], packet.position_m[2]);
  pose_.velocity_m_per_s = Vec3(packet.velocity_m_per_s[0], packet.velocity_m_per_s[1], packet.velocity_m_per_s[2]);
  buttons_.store(packet.buttons, std::memory_order_relaxed);
  bump(accepted_);
  return Verdict::kAccepted;
}

void UdpDevice::filter_to(const ip::udp::endpoint* peer) noexcept {
  sockaddr unspecified{};
  unspecified.sa_family = AF_UNSPEC;  // connect(AF_UNSPEC) dissolves a UDP association
  const int rc = peer ? ::connect(socket_.native_handle(), peer->data(), static_cast<socklen_t>(peer->size()))
                      : ::connect(socket_.native_handle(), &unspecified, sizeof unspecified);
  filtered_ = peer != nullptr && rc == 0;
  if (!filtered_ || !wildcard_) return;
  // Connecting a wildcard-bound socket also fixes its local address, to the
  // source of the route back to the peer. If the peer's poses came to another
  // local address (a hostname on 127.0.1.1, a secondary address, broadcast),
  // the kernel would drop every one of them from now on: the sender would be
  // lost after timeout_s, taken again, lost again. Stay unconnected for this
  // session then; the other_sender check still refuses the rest, in userspace,
  // and write() names the source address of each force itself.
  boost::system::error_code ec;
  const ip::udp::endpoint local = socket_.local_endpoint(ec);
  if (!ec && local.address() == peer_to_) return;
  ::connect(socket_.native_handle(), &unspecified, sizeof unspecified);
  filtered_ = false;
  filter_refused_ = true;
  filter_route_source_ = ec ? ip::address() : local.address();
}

std::size_t UdpDevice::receive(boost::system::error_code& ec) noexcept {
  if (!wildcard_) return socket_.receive_from(boost::asio::buffer(receive_buffer_), from_, 0, ec);
  // recvmsg for the destination address (IP_PKTINFO / IPV6_PKTINFO, v4-mapped
  // on a v6 socket), which receive_from does not give. Stack buffers only.
  iovec iov{receive_buffer_.data(), receive_buffer_.size()};
  alignas(cmsghdr) unsigned char control[CMSG_SPACE(sizeof(in_pktinfo)) + CMSG_SPACE(sizeof(in6_pktinfo))];
  msghdr msg{};
  msg.msg_name = from_.data();
  msg.msg_namelen = static_cast<socklen_t>(from_.capacity());
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof control;
  const ssize_t n = ::recvmsg(socket_.native_handle(), &msg, MSG_DONTWAIT);
  if (n < 0) {
    ec = boost::system::error_code(errno, boost::asio::error::get_system_category());
    return 0;
  }
  ec = boost::system::error_code();
  from_.resize(std::min<std::size_t>(msg.msg_namelen, from_.capacity()));
  to_ = ip::address();
  reply_from_ = ip::address();
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level == IPPROTO_IP && c->cmsg_type == IP_PKTINFO) {
      in_pktinfo info;
      std::memcpy(&info, CMSG_DATA(c), sizeof info);
      to_ = ip::address_v4(ntohl(info.ipi_addr.s_addr));  // the header's destination
      reply_from_ = ip::address_v4(ntohl(info.ipi_spec_dst.s_addr));
    } else if (c->cmsg_level == IPPROTO_IPV6 && c->cmsg_type == IPV6_PKTINFO) {
      in6_pktinfo info;
      std::memcpy(&info, CMSG_DATA(c), sizeof info);
      ip::address_v6::bytes_type bytes;
      std::memcpy(bytes.data(), &info.ipi6_addr, bytes.size());
      const ip::address_v6 to(bytes);
      const ip::address_v6 scoped(bytes, to.is_link_local() ? info.ipi6_ifindex : 0);
      to_ = scoped;
      // v4-mapped (an IPv4 datagram on a dual-stack socket): 224/4 is
      // multicast, 255.255.255.255 the limited broadcast. A subnet broadcast
      // cannot be told from here: the kernel refuses it as a source, and
      // write() falls back to the route's choice for the session.
      const bool mapped_multicast = to.is_v4_mapped() && (bytes[12] & 0xF0) == 0xE0;
      const bool mapped_broadcast =
          to.is_v4_mapped() && bytes[12] == 0xFF && bytes[13] == 0xFF && bytes[14] == 0xFF && bytes[15] == 0xFF;
      if (!to.is_multicast() && !mapped_multicast && !mapped_broadcast) reply_from_ = scoped;
    }
  }
  return static_cast<std::size_t>(n);
}

UdpDevice::SendFrom UdpDevice::send_from_reply_address(std::size_t bytes, boost::system::error_code& ec) noexcept {
  // Connected (filter_to), the socket's local address already is the one the
  // poses came to; not bound to a wildcard, there is only one.
  if (!wildcard_ || filtered_ || peer_reply_from_.is_unspecified()) return SendFrom::kNotUsed;
  if (reply_from_refused_) return SendFrom::kRefusedBefore;
  iovec iov{send_buffer_.data(), bytes};
  alignas(cmsghdr) unsigned char control[CMSG_SPACE(sizeof(in6_pktinfo))] = {};
  static_assert(sizeof(in6_pktinfo) >= sizeof(in_pktinfo), "the control buffer holds either");
  msghdr msg{};
  msg.msg_name = peer_.data();
  msg.msg_namelen = static_cast<socklen_t>(peer_.size());
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  if (peer_reply_from_.is_v4()) {
    // man 7 ip: a non-zero ipi_spec_dst is the source address (ipi_ifindex 0:
    // the route to peer_ picks the interface).
    in_pktinfo info{};
    info.ipi_spec_dst.s_addr = htonl(peer_reply_from_.to_v4().to_uint());
    msg.msg_controllen = CMSG_SPACE(sizeof info);
    cmsghdr* c = CMSG_FIRSTHDR(&msg);
    c->cmsg_level = IPPROTO_IP;
    c->cmsg_type = IP_PKTINFO;
    c->cmsg_len = CMSG_LEN(sizeof info);
    std::memcpy(CMSG_DATA(c), &info, sizeof info);
  } else {
    // man 7 ipv6: ipi6_addr is the source. On a dual-stack socket a v4-mapped
    // one is taken for an IPv4 peer (the kernel's IPv4 path reads the
    // IPV6_PKTINFO of a v6 socket and wants it v4-mapped). A link-local one
    // needs its interface: the scope id it came in on.
    const ip::address_v6 from = peer_reply_from_.to_v6();
    in6_pktinfo info{};
    const ip::address_v6::bytes_type from_bytes = from.to_bytes();
    std::memcpy(&info.ipi6_addr, from_bytes.data(), from_bytes.size());
    info.ipi6_ifindex = from.scope_id();
    msg.msg_controllen = CMSG_SPACE(sizeof info);
    cmsghdr* c = CMSG_FIRSTHDR(&msg);
    c->cmsg_level = IPPROTO_IPV6;
    c->cmsg_type = IPV6_PKTINFO;
    c->cmsg_len = CMSG_LEN(sizeof info);
    std::memcpy(CMSG_DATA(c), &info, sizeof info);
  }
  if (::sendmsg(socket_.native_handle(), &msg, MSG_DONTWAIT | MSG_NOSIGNAL) >= 0) {
    ec = boost::system::error_code();
    return SendFrom::kSent;
  }
  const int error = errno;
  ec = boost::system::error_code(error, boost::asio::error::get_system_category());
  // Not a usable source, or no route from it (a v4-mapped subnet broadcast:
  // ENETUNREACH; an address removed since: EINVAL, EADDRNOTAVAIL).
  const bool source_refused = error == EINVAL || error == EADDRNOTAVAIL || error == ENETUNREACH;
  return source_refused ? SendFrom::kSourceRefused : SendFrom::kSent;
}

bool UdpDevice::read(std::int64_t now_ns, DeviceSample* out) noexcept {
  if (!socket_.is_open()) return false;
  // The kernel filters for the session: while a sender is live the socket is
  // connected to it, so datagrams from other addresses never queue (a flood
  // from elsewhere took the 64 reads of a tick and the kernel's buffer, and
  // crowded the device out); once it is lost, any address may start anew.
  // IPv4 sockets only: an IPv6 one is never connected (connectable_), and
  // consider() alone refuses other senders.
  if (filtered_ && !sender_live(now_ns)) filter_to(nullptr);
  bool fresh = false;
  for (int i = 0; i < kMaxDatagramsPerRead; ++i) {
    boost::system::error_code ec;
    const std::size_t bytes = receive(ec);
    if (ec == boost::asio::error::would_block || ec == boost::asio::error::try_again) break;
    if (ec) {
      // Nothing a tick can fix (e.g. a queued ICMP error): count it and let
      // the next tick try again rather than spin on it now.
      bump(receive_errors_);
      break;
    }
    bump(received_);
    if (consider(bytes, now_ns) == Verdict::kAccepted) fresh = true;
  }
  if (fresh && connectable_ && !filtered_ && !filter_refused_) filter_to(&peer_);
  // Only a pose that arrived during this read is a sample: handing the held
  // pose back every tick would make a 250 Hz device look like one that jumps
  // 4 ms of motion in 1 ms (the loop's speed check) and would hide a device
  // that went silent until timeout_s instead of limits.device_timeout_s.
  if (!fresh) return false;
  if (out) *out = pose_;
  return true;
}

void UdpDevice::write(std::int64_t now_ns, const Vec3& force_N) noexcept {
  // No pose yet: nobody to answer. A lost sender still gets the (ramped-out)
  // force, so a device that comes back starts from what tissued renders, until
  // one zero force has gone: then nothing more goes to an address that may
  // no longer be a device (its next pose makes it live again).
  if (!socket_.is_open() || peer_.port() == 0) return;
  const bool zero = force_N.allFinite() && force_N.isZero(0.0);
  if (zero && last_sent_zero_ && !sender_live(now_ns)) return;

  Packet packet{};
  packet.version = kProtocolVersion;
  packet.kind = kKindForce;
  packet.sequence_number = ++force_sequence_number_;
  packet.sender_time_ns = now_ns;
  packet.echo_sequence_number = last_sequence_number_;
  packet.echo_sender_time_ns = last_sender_time_ns_;
  // The loop's safety already guarantees a finite force; a motor must never
  // be sent a NaN whatever happens upstream.
  const bool finite = force_N.allFinite();
  for (int k = 0; k < 3; ++k) packet.force_N[k] = finite ? force_N[k] : 0.0;

  const int bytes = packet.encode(send_buffer_.data(), 0, static_cast<int>(send_buffer_.size()));
  if (bytes != packet_bytes_) {
    bump(send_failures_);
    return;
  }
  boost::system::error_code ec;
  const SendFrom how = send_from_reply_address(static_cast<std::size_t>(bytes), ec);
  if (how != SendFrom::kSent) {
    socket_.send_to(boost::asio::buffer(send_buffer_.data(), static_cast<std::size_t>(bytes)), peer_, 0, ec);
    // The route's own source reaches the peer where the named one did not:
    // use it while the poses keep coming to that address this session (one
    // syscall a tick again). Not when both failed: that was the network, not
    // the source. Counted: a device connect()ed to tissued drops these.
    if (how == SendFrom::kSourceRefused && !ec) reply_from_refused_ = true;
    if (how != SendFrom::kNotUsed && !ec) bump(reply_source_fallbacks_);
  }
  bump(ec ? send_failures_ : sent_);  // would_block: dropped, the next tick sends a newer force
  last_sent_zero_ = !ec && zero;
}

UdpDevice::Stats UdpDevice::stats() const noexcept {
  Stats s;
  s.received = received_.load(std::memory_order_relaxed);
  s.accepted = accepted_.load(std::memory_order_relaxed);
  for (int i = 0; i < static_cast<int>(Reject::kCount); ++i)
    s.rejected[i] = rejected_[i].load(std::memory_order_relaxed);
  s.out_of_order = out_of_order_.load(std::memory_order_relaxed);
  s.resyncs = resyncs_.load(std::memory_order_relaxed);
  s.receive_errors = receive_errors_.load(std::memory_order_relaxed);
  s.sent = sent_.load(std::memory_order_relaxed);
  s.send_failures = send_failures_.load(std::memory_order_relaxed);
  s.reply_source_fallbacks = reply_source_fallbacks_.load(std::memory_order_relaxed);
  s.sessions = sessions_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace tissue::haptics
