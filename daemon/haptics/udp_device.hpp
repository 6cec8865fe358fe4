// UdpDevice: the UDP device bridge (proto/README.md, "UDP device bridge").
//
// A device on another box, or a vendor-SDK shim, streams tissue::device_packet
// datagrams (LCM encoding, proto/lcm/device_packet.lcm) with kind = pose to
// UdpDeviceSpec.bind_address:port; every write() answers the sender of the
// newest valid pose with a kind = force packet.
//
// Bound to a wildcard address (0.0.0.0, ::), forces leave from the local
// address the newest pose came to (sendmsg with IP_PKTINFO / IPV6_PKTINFO),
// not from whichever address the route back to the device prefers: a device
// that connect()s its socket to tissued's address takes datagrams only from
// exactly there. When the kernel refuses that source (an address removed
// since, a subnet broadcast on ::) the force goes from the route's source,
// counted in reply_source_fallbacks, until the poses come to another local
// address or a new session starts.
//
// Real-time: read() and write() run in the 1 kHz tick. The socket is
// non-blocking; read() drains at most kMaxDatagramsPerRead waiting datagrams
// into a preallocated buffer and keeps the newest valid pose, returning true
// only when one arrived during that read (a device slower than the loop
// gives a sample on some ticks; the loop holds it between), write() sends one
// datagram and drops it when the socket would block. Packets are decoded into
// stack objects of a fixed-size generated type, so nothing allocates, locks or
// waits. start()/stop() are the only calls that allocate or may fail.
//
// Validation, in this order (each rejection is counted by reason):
//   size          datagram length != the encoded size of device_packet
//   fingerprint   the first 8 bytes are not device_packet's LCM fingerprint
//                 (garbage, another LCM type, another schema revision)
//   version       version != kProtocolVersion
//   kind          not a pose packet (e.g. a force packet looped back)
//   non_finite    a position or velocity component is NaN or infinite
//   other_sender  while a sender is live, datagrams from any other address
//                 (only those queued before it went live: from then on the
//                 socket is connected to it and the kernel drops the rest;
//                 not so on a socket of the IPv6 family, nor when bound to
//                 0.0.0.0 and the poses come to a local address other than
//                 the route back's source, see filter_to: every datagram is
//                 then read and refused)
// and then the ordering rule: sequence_number must exceed the last accepted
// one (duplicates and reordered packets are dropped and counted as
// out_of_order), except that kResyncPackets valid poses in a row below it,
// each above the one before, are followed (counted as resyncs): one packet
// whose number leapt ahead cannot lock the real stream out until timeout_s.
// When no valid pose has arrived for timeout_s the sender is lost and the
// next valid pose from any address starts a new session with any sequence
// number (a restarted device may count from 0 again). The haptic loop ramps
// the force out sooner, after limits.device_timeout_s without a sample.
//
// Threads: start()/stop()/read()/write() from one thread at a time (the
// haptic thread while it runs); stats() and buttons() from any thread.
#pragma once

#include <array>
#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/udp.hpp>
#include <cstdint>

#include "config/daemon_config.hpp"
#include "haptics/device.hpp"

namespace tissue::haptics {

class UdpDevice final : public Device {
 public:
  static constexpr std::int32_t kProtocolVersion = 1;
  static constexpr std::uint8_t kKindPose = 1;   // device -> tissued
  static constexpr std::uint8_t kKindForce = 2;  // tissued -> device
  // Bounds the work of one read(): a flooding sender cannot stall the tick;
  // what is left waits for the next tick (or is dropped by the kernel).
  static constexpr int kMaxDatagramsPerRead = 64;
  // Larger than any valid packet, so an oversized datagram is seen (and
  // rejected by size) instead of being silently truncated to a valid length.
  static constexpr std::size_t kReceiveBufferBytes = 2048;
  // Poses in a row below the last accepted sequence number (and rising) after
  // which the sender is followed: more than a reordering produces, few
  // enough that a bad leap costs the loop ~2 ms of samples at 1 kHz.
  static constexpr int kResyncPackets = 3;

  enum class Reject : int { kSize, kFingerprint, kVersion, kKind, kNonFinite, kOtherSender, kCount };
  static const char* reject_name(Reject reason) noexcept;

  // Counters since start() (each exact, the set not one instant).
  struct Stats {
    std::uint64_t received = 0;  // datagrams taken off the socket
    std::uint64_t accepted = 0;  // valid poses (not necessarily the newest of their read())
    std::array<std::uint64_t, static_cast<int>(Reject::kCount)> rejected{};
    std::uint64_t out_of_order = 0;  // valid but sequence_number <= the last accepted one, dropped
    std::uint64_t resyncs = 0;       // times the sequence was followed below the last accepted one
    std::uint64_t receive_errors = 0;
    std::uint64_t sent = 0;
    std::uint64_t send_failures = 0;  // would block (dropped) or an OS error
    // Forces sent (counted in `sent` too) from the route's source address
    // because the local address the poses came to was refused as a source
    // this session (an address removed since, a subnet broadcast on ::): a
    // device that connect()ed its socket to tissued drops them.
    std::uint64_t reply_source_fallbacks = 0;
    std::uint64_t sessions = 0;  // times a sender was (re)acquired after silence
    std::uint64_t rejected_total() const noexcept {
      std::uint64_t n = 0;
      for (std::uint64_t r : rejected) n += r;
      return n;
    }
  };

  explicit UdpDevice(const config::UdpDeviceSpec& spec);
  ~UdpDevice() override;

  // Binds the socket. False with "udp device: cannot bind ADDRESS:PORT: OS error".
  bool start(std::string* error) override;
  void stop() noexcept override;
  bool read(std::int64_t now_ns, DeviceSample* out) noexcept override;
  void write(std::int64_t now_ns, const Vec3& force_N) noexcept override;
  const char* name() const noexcept override { return "udp"; }

  // The port bound by start(). Equals spec.port unless that is 0 (the config
  // loader forbids 0; tests use it to get an ephemeral port).
  std::uint16_t local_port() const noexcept { return local_port_; }
  // The encoded size of device_packet, bytes (every valid datagram has it).
  int packet_bytes() const noexcept { return packet_bytes_; }
  Stats stats() const noexcept;
  // A sender is live from its accepted pose until timeout_s without another:
  // meanwhile other addresses are refused and sequence numbers must rise.
  // Haptic thread only (it reads the pose state).
  bool sender_live(std::int64_t now_ns) const noexcept;
  // Buttons of the newest accepted pose (bit i = button i).
  std::int32_t buttons() const noexcept { return buttons_.load(std::memory_order_relaxed); }

 private:
  // Outcome of one datagram: accepted, rejected for a reason, or out of order.
  enum class Verdict { kAccepted, kRejected, kOutOfOrder };
  Verdict consider(std::size_t bytes, std::int64_t now_ns) noexcept;
  // Connects the socket to `peer` (the kernel then drops datagrams from
  // every other address before they queue) or, with nullptr, disconnects it
  // (any address may start the next session). One syscall, no allocation.
  // Bound to 0.0.0.0, it connects only if the local address the connect
  // picks is the one peer_'s poses came to (else disconnects again and sets
  // filter_refused_ until the poses come to the route's source or a new
  // session starts). IPv4 sockets only (connectable_).
  void filter_to(const boost::asio::ip::udp::endpoint* peer) noexcept;
  // One datagram into receive_buffer_, its source into from_ and, when bound
  // to a wildcard address, its destination into to_ and reply_from_.
  std::size_t receive(boost::system::error_code& ec) noexcept;
  // Sends send_buffer_[0, bytes) to peer_ from peer_reply_from_ (sendmsg with
  // a PKTINFO control message): kSent (ec says how it went), kNotUsed (not
  // bound to a wildcard address, connected, no such address), kRefusedBefore
  // (refused earlier this session, and the poses still come to it) or
  // kSourceRefused (the kernel would not send from it): for the last three the
  // caller sends plainly (the last two count as reply_source_fallbacks). One
  // syscall at most, stack buffers only.
  enum class SendFrom { kSent, kNotUsed, kRefusedBefore, kSourceRefused };
  SendFrom send_from_reply_address(std::size_t bytes, boost::system::error_code& ec) noexcept;
  static void bump(std::atomic<std::uint64_t>& counter) noexcept {
    counter.store(counter.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);  // one writer
  }

  config::UdpDeviceSpec spec_;
  std::int64_t timeout_ns_ = 0;
  int packet_bytes_ = 0;
  std::uint16_t local_port_ = 0;

  boost::asio::io_context io_;
  boost::asio::ip::udp::socket socket_;
  boost::asio::ip::udp::endpoint from_;  // scratch for receive_from
  boost::asio::ip::udp::endpoint peer_;  // sender of the newest accepted pose
  bool filtered_ = false;                // the socket is connected to peer_ (filter_to)
  // The socket is of the IPv4 family, so filter_to may connect it. Never one
  // of the IPv6 family (bound to ::, ::1, any IPv6 address): Linux's
  // connect(AF_UNSPEC) forgets its peer's port but not its address
  // (__udp_disconnect leaves sk_v6_daddr, which udp6's lookup still
  // compares), so after one session the kernel would drop every datagram from
  // any other address until restart (on a dual-stack ::, an IPv4 session
  // would shut out every native IPv6 device). No connect() clears it (one to
  // :: connects to ::1), and a new socket would, but the tick may not open one
  // (asio's register_descriptor takes a mutex). Such a socket refuses other
  // senders in userspace only (consider(), other_sender).
  bool connectable_ = false;
  bool wildcard_ = false;  // bound to 0.0.0.0 or ::
  // The poses come to a local address other than the route back's source:
  // no connect, until they come to that source (filter_route_source_) or a
  // new session starts. Only that address can pass filter_to's check, so a
  // sender alternating between two others costs no connect at each move.
  bool filter_refused_ = false;
  boost::asio::ip::address filter_route_source_;  // the route back's source, learnt by the refused try
  // Destination of the datagram in receive_buffer_ (wildcard_ only); an IPv6
  // link-local one carries the scope id of the interface it came in on, which
  // write() names as the source's interface (IPV6_PKTINFO).
  boost::asio::ip::address to_;
  // The local address a reply to that datagram leaves from: IPv4 the
  // kernel's own choice (in_pktinfo.ipi_spec_dst: to_, or the interface's
  // address for a broadcast); IPv6 to_, unspecified for a multicast to_ (no
  // source can be one; the route picks).
  boost::asio::ip::address reply_from_;
  boost::asio::ip::address peer_to_;          // to_ of the newest accepted pose (wildcard_ only)
  boost::asio::ip::address peer_reply_from_;  // reply_from_ of the newest accepted pose (wildcard_ only)
  // peer_reply_from_ failed as a source and the route's did not: until a new
  // session, or poses to another local address (a new peer_reply_from_).
  bool reply_from_refused_ = false;
  std::array<unsigned char, kReceiveBufferBytes> receive_buffer_{};
  std::array<unsigned char, kReceiveBufferBytes> send_buffer_{};

  // Newest accepted pose (haptic thread only).
  bool have_pose_ = false;
  std::int64_t last_accept_ns_ = 0;  // now_ns of the read() that accepted it
  std::int64_t last_sequence_number_ = 0;
  std::int64_t last_sender_time_ns_ = 0;
  DeviceSample pose_;
  std::int64_t force_sequence_number_ = 0;
  bool last_sent_zero_ = false;  // the newest force packet that went out was zero
  int behind_count_ = 0;         // poses in a row below last_sequence_number_, rising
  std::int64_t behind_last_sequence_number_ = 0;

  std::atomic<std::int32_t> buttons_{0};
  std::atomic<std::uint64_t> received_{0};
  std::atomic<std::uint64_t> accepted_{0};
  std::array<std::atomic<std::uint64_t>, static_cast<int>(Reject::kCount)> rejected_{};
  std::atomic<std::uint64_t> out_of_order_{0};
  std::atomic<std::uint64_t> resyncs_{0};
  std::atomic<std::uint64_t> receive_errors_{0};
  std::atomic<std::uint64_t> sent_{0};
  std::atomic<std::uint64_t> send_failures_{0};
  std::atomic<std::uint64_t> reply_source_fallbacks_{0};
  std::atomic<std::uint64_t> sessions_{0};
};

}  // namespace tissue::haptics
