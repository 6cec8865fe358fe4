// UdpDevice over loopback (127.0.0.1, ephemeral ports): a fake device sends
// pose packets and reads the force packets back.
//
// Port 0 is the test-only door to an ephemeral port: the config loader
// rejects it, UdpDevice binds whatever the OS picks and reports local_port().
//
// Time: read()/write() take now_ns from the caller, so the loss/return tests
// use synthetic clocks and are exact. Loopback delivery is fast but not
// formally synchronous with send_to, so tests poll (eventually()) until the
// device has taken the datagrams they sent, with a generous deadline.
//
// Allocations are counted on the thread that calls read()/write() only
// (support/allocation_counter, count_this_thread), so the fake device may
// allocate freely meanwhile.
#include <gtest/gtest.h>
#include <net/if.h>
#include <netinet/in.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/udp.hpp>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <new>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "haptics/device.hpp"
#include "haptics/haptic_loop.hpp"
#include "haptics/udp_device.hpp"
#include "support/allocation_counter.hpp"

#include <dlfcn.h>

// connect() calls while counting is on (around reads only): the UDP device's
// tries of the kernel filter. TSan intercepts connect itself, and this binary
// runs under it: the count is taken in the other builds.
namespace {
std::atomic<bool> g_count_connects{false};
std::atomic<int> g_connects{0};
}  // namespace
#if !defined(__SANITIZE_THREAD__)
extern "C" int connect(int fd, const sockaddr* address, socklen_t length) {
  using Fn = int (*)(int, const sockaddr*, socklen_t);
  static const Fn real = reinterpret_cast<Fn>(dlsym(RTLD_NEXT, "connect"));
  if (g_count_connects.load()) g_connects.fetch_add(1);
  return real(fd, address, length);
}
#endif
#include "tissue_lcm/tissue/device_packet.hpp"
#include "tissue_lcm/tissue/haptic_state.hpp"

namespace tissue::haptics {
namespace {

namespace ip = boost::asio::ip;
using Packet = tissue_lcm::tissue::device_packet;
using Reject = UdpDevice::Reject;
constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kT0 = 5'000 * kMs;  // synthetic clock start

std::int64_t steady_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

template <typename Pred>
bool eventually(Pred done, std::chrono::milliseconds timeout = std::chrono::milliseconds(2000)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::microseconds(100));
  }
  return true;
}

Packet pose_packet(std::int64_t sequence_number, const Vec3& position_m, const Vec3& velocity_m_per_s = Vec3::Zero(),
                   std::int32_t buttons = 0) {
  Packet p{};
  p.version = UdpDevice::kProtocolVersion;
  p.kind = UdpDevice::kKindPose;
  p.sequence_number = sequence_number;
  p.sender_time_ns = 1000 + sequence_number;
  for (int k = 0; k < 3; ++k) {
    p.position_m[k] = position_m[k];
    p.velocity_m_per_s[k] = velocity_m_per_s[k];
  }
  p.buttons = buttons;
  return p;
}

template <typename T>
std::vector<unsigned char> encode(const T& msg) {
  std::vector<unsigned char> bytes(static_cast<std::size_t>(msg.getEncodedSize()));
  EXPECT_EQ(msg.encode(bytes.data(), 0, static_cast<int>(bytes.size())), static_cast<int>(bytes.size()));
  return bytes;
}

// The far side: what a device box or a vendor-SDK shim does.
class FakeDevice {
 public:
  // kConnected: connect()s its socket to tissued's address and port, as many
  // device bridges do; the kernel then hands it only datagrams from exactly
  // there, so a force from any other source address never arrives.
  enum class Link { kUnconnected, kConnected };

  // `tissued_address`: where the poses go (any local address reaches a
  // device bound to 0.0.0.0; all of 127/8 is on lo). `own_address`: where
  // the fake itself is bound.
  explicit FakeDevice(std::uint16_t tissued_port, const char* tissued_address = "127.0.0.1",
                      Link link = Link::kUnconnected, const char* own_address = "127.0.0.1")
      : socket_(io_, ip::udp::endpoint(ip::make_address(own_address), 0)),
        tissued_(ip::make_address(tissued_address), tissued_port) {
    socket_.non_blocking(true);
    socket_.set_option(ip::udp::socket::broadcast(true));  // tissued_address may be a broadcast address
    if (link == Link::kConnected) socket_.connect(tissued_);
  }

  void send_bytes(const std::vector<unsigned char>& bytes) {
    boost::system::error_code ec;
    socket_.send_to(boost::asio::buffer(bytes), tissued_, 0, ec);  // connected: the same address, allowed
    ASSERT_FALSE(ec) << ec.message();
  }
  void send(const Packet& p) { send_bytes(encode(p)); }

  // Sends to `tissued_address` from now on, from the same socket (so the
  // same sender to tissued, in the same session); kConnected also connects
  // the socket to it (from then on only datagrams from there arrive).
  void retarget(const char* tissued_address, Link link) {
    tissued_ = ip::udp::endpoint(ip::make_address(tissued_address), tissued_.port());
    if (link == Link::kConnected) socket_.connect(tissued_);
  }
  // The source of the datagram receive() returned last.
  ip::address last_source() const { return from_.address(); }

  // Next datagram tissued sent, decoded; nullopt after timeout.
  std::optional<Packet> receive(std::chrono::milliseconds timeout = std::chrono::milliseconds(2000)) {
    std::optional<Packet> out;
    eventually(
        [&] {
          boost::system::error_code ec;
          const std::size_t n = socket_.receive_from(boost::asio::buffer(buffer_), from_, 0, ec);
          if (ec) return false;
          Packet p;
          EXPECT_EQ(p.decode(buffer_.data(), 0, static_cast<int>(n)), static_cast<int>(n));
          out = p;
          return true;
        },
        timeout);
    return out;
  }

  int drain() {
    int n = 0;
    boost::system::error_code ec;
    while (socket_.receive_from(boost::asio::buffer(buffer_), from_, 0, ec), !ec) ++n;
    return n;
  }

 private:
  boost::asio::io_context io_;
  ip::udp::socket socket_;
  ip::udp::endpoint tissued_;
  ip::udp::endpoint from_;
  std::array<unsigned char, 2048> buffer_{};
};

config::UdpDeviceSpec loopback_spec(double timeout_s = 0.05) {
  config::UdpDeviceSpec spec;
  spec.bind_address = "127.0.0.1";
  spec.port = 0;
  spec.timeout_s = timeout_s;
  return spec;
}

config::UdpDeviceSpec wildcard_spec(const char* bind_address = "0.0.0.0", double timeout_s = 0.05) {
  config::UdpDeviceSpec spec = loopback_spec(timeout_s);
  spec.bind_address = bind_address;  // 0.0.0.0: what docs/daemon-config.md says for a device on another machine
  return spec;
}

struct Started {
  explicit Started(double timeout_s = 0.05) : Started(loopback_spec(timeout_s)) {}
  explicit Started(const config::UdpDeviceSpec& spec) : device(spec) {
    std::string error;
    EXPECT_TRUE(device.start(&error)) << error;
    EXPECT_NE(device.local_port(), 0);
  }
  UdpDevice device;
};

// The wildcard tests' setup: tissued bound to `bind_address` (0.0.0.0 or ::)
// and a fake device (on 127.0.0.1) that sends its poses to `to_address`.
// The route back to 127.0.0.1 leaves from 127.0.0.1, so any other to_address
// in 127/8 is "another local address" (filter_to leaves the socket unconnected).
struct WildcardBound {
  explicit WildcardBound(const char* to_address, FakeDevice::Link link = FakeDevice::Link::kUnconnected,
                         const char* bind_address = "0.0.0.0", const char* own_address = "127.0.0.1")
      : s(wildcard_spec(bind_address)), fake(s.device.local_port(), to_address, link, own_address) {}
  Started s;
  FakeDevice fake;
};

// Reads at now_ns until the device has taken `received` datagrams in total.
bool read_until_received(UdpDevice& device, std::uint64_t received, std::int64_t now_ns, DeviceSample* out,
                         bool* result = nullptr) {
  bool last = false;
  const bool ok = eventually([&] {
    last = device.read(now_ns, out);
    return device.stats().received >= received;
  });
  if (result) *result = last;
  return ok;
}

TEST(UdpDevice, StartsOnLoopbackAndReportsItsPort) {
  Started s;
  EXPECT_STREQ(s.device.name(), "udp");
  EXPECT_EQ(s.device.packet_bytes(), 121);
  DeviceSample sample;
  EXPECT_FALSE(s.device.read(kT0, &sample)) << "no sender yet";
  s.device.write(kT0, Vec3(1, 2, 3));  // nobody to answer: nothing sent
  EXPECT_EQ(s.device.stats().sent, 0u);
  s.device.stop();
  EXPECT_FALSE(s.device.read(kT0, &sample));
}

TEST(UdpDevice, BindFailuresNameTheAddressPortAndOsError) {
  Started first;
  config::UdpDeviceSpec spec = loopback_spec();
  spec.port = first.device.local_port();
  UdpDevice second(spec);
  std::string error;
  EXPECT_FALSE(second.start(&error));
  EXPECT_NE(error.find("udp device: cannot bind 127.0.0.1:" + std::to_string(spec.port) + ": "), std::string::npos)
      << error;
  EXPECT_NE(error.find("Address already in use"), std::string::npos) << error;

  spec.bind_address = "192.0.2.1";  // TEST-NET-1: never a local address; bind fails without traffic
  spec.port = 47999;
  UdpDevice foreign(spec);
  EXPECT_FALSE(foreign.start(&error));
  EXPECT_NE(error.find("cannot bind 192.0.2.1:47999: Cannot assign requested address"), std::string::npos) << error;

  spec.bind_address = "localhost-ish";
  UdpDevice bad(spec);
  EXPECT_FALSE(bad.start(&error));
  EXPECT_NE(error.find("bind_address 'localhost-ish' is not an IP address"), std::string::npos) << error;

  spec = loopback_spec(0.0);
  UdpDevice no_timeout(spec);
  EXPECT_FALSE(no_timeout.start(&error));
  EXPECT_NE(error.find("timeout_s must be finite and > 0"), std::string::npos) << error;
  DeviceSample sample;
  EXPECT_FALSE(no_timeout.read(kT0, &sample));
}

TEST(UdpDevice, FactoryBuildsItForKindUdp) {
  config::DeviceSpec spec;
  spec.kind = config::DeviceSpec::Kind::kUdp;
  spec.udp = loopback_spec();
  std::string error;
  std::unique_ptr<Device> device = make_device(spec, &error);
  ASSERT_NE(device, nullptr) << error;
  EXPECT_TRUE(error.empty());
  EXPECT_STREQ(device->name(), "udp");
  EXPECT_TRUE(device->start(&error)) << error;
}

TEST(UdpDevice, PoseInAndForceBackToTheSender) {
  Started s;
  FakeDevice fake(s.device.local_port());
  const Vec3 position_m(0.01, -0.02, 0.03), velocity_m_per_s(0.1, 0.2, -0.3);
  Packet pose = pose_packet(1, position_m, velocity_m_per_s, 0b101);
  pose.sender_time_ns = 777;
  fake.send(pose);

  DeviceSample sample;
  bool got = false;
  ASSERT_TRUE(read_until_received(s.device, 1, kT0, &sample, &got));
  ASSERT_TRUE(got);
  EXPECT_EQ(sample.position_m, position_m);  // doubles cross bit-exact
  EXPECT_EQ(sample.velocity_m_per_s, velocity_m_per_s);
  EXPECT_EQ(s.device.buttons(), 0b101);

  s.device.write(kT0 + kMs, Vec3(1.0, -2.0, 0.5));
  const std::optional<Packet> force = fake.receive();
  ASSERT_TRUE(force.has_value());
  EXPECT_EQ(force->version, UdpDevice::kProtocolVersion);
  EXPECT_EQ(force->kind, UdpDevice::kKindForce);
  EXPECT_EQ(force->sequence_number, 1);
  EXPECT_EQ(force->sender_time_ns, kT0 + kMs);
  EXPECT_EQ(force->echo_sequence_number, 1);
  EXPECT_EQ(force->echo_sender_time_ns, 777);
  EXPECT_EQ(force->force_N[0], 1.0);
  EXPECT_EQ(force->force_N[1], -2.0);
  EXPECT_EQ(force->force_N[2], 0.5);
  EXPECT_EQ(force->position_m[0], 0.0);
  EXPECT_EQ(force->buttons, 0);

  // A non-finite force never reaches the motors.
  s.device.write(kT0 + 2 * kMs, Vec3(std::numeric_limits<double>::quiet_NaN(), 1.0, 1.0));
  const std::optional<Packet> zero = fake.receive();
  ASSERT_TRUE(zero.has_value());
  EXPECT_EQ(zero->sequence_number, 2);
  EXPECT_EQ(zero->force_N[0], 0.0);
  EXPECT_EQ(zero->force_N[1], 0.0);
  EXPECT_EQ(s.device.stats().sent, 2u);
}

TEST(UdpDevice, TheNewestOfSeveralWaitingPosesWins) {
  Started s;
  FakeDevice fake(s.device.local_port());
  for (int i = 1; i <= 3; ++i) fake.send(pose_packet(i, Vec3(0.001 * i, 0, 0)));
  // Give the kernel all three before the single read that drains them.
  DeviceSample sample;
  ASSERT_TRUE(read_until_received(s.device, 3, kT0, &sample));
  EXPECT_EQ(sample.position_m.x(), 0.003);
  // Nothing new has come: the next read gives no sample (the loop holds the
  // last one), while the sender stays live.
  DeviceSample untouched;
  untouched.position_m = Vec3(7, 7, 7);
  EXPECT_FALSE(s.device.read(kT0 + kMs, &untouched));
  EXPECT_EQ(untouched.position_m, Vec3(7, 7, 7));
  EXPECT_TRUE(s.device.sender_live(kT0 + kMs));
  const UdpDevice::Stats st = s.device.stats();
  EXPECT_EQ(st.accepted, 3u);
  EXPECT_EQ(st.out_of_order, 0u);
  EXPECT_EQ(st.rejected_total(), 0u);
}

TEST(UdpDevice, RejectsAndCountsEveryKindOfBadDatagram) {
  Started s;
  FakeDevice fake(s.device.local_port());
  const Vec3 good_m(0.02, 0.02, 0.02), bad_m(0.09, 0.09, 0.09);
  fake.send(pose_packet(10, good_m));
  DeviceSample sample;
  ASSERT_TRUE(read_until_received(s.device, 1, kT0, &sample));

  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  std::uint64_t sent = 1;
  auto send = [&](const std::vector<unsigned char>& bytes) {
    fake.send_bytes(bytes);
    ++sent;
  };
  // size: short garbage, one trailing byte, an oversized datagram
  send({'h', 'e', 'l', 'l', 'o'});
  std::vector<unsigned char> longer = encode(pose_packet(11, bad_m));
  longer.push_back(0);
  send(longer);
  send(std::vector<unsigned char>(3000, 0xAB));
  // fingerprint: right-sized garbage, a corrupted fingerprint, another LCM type padded to size
  send(std::vector<unsigned char>(121, 0x5A));
  std::vector<unsigned char> corrupted = encode(pose_packet(12, bad_m));
  corrupted[3] ^= 0x10;
  send(corrupted);
  std::vector<unsigned char> other_type = encode(tissue_lcm::tissue::haptic_state{});
  other_type.resize(121, 0);
  send(other_type);
  // version, kind
  Packet wrong_version = pose_packet(13, bad_m);
  wrong_version.version = 2;
  send(encode(wrong_version));
  Packet force_kind = pose_packet(14, bad_m);
  force_kind.kind = UdpDevice::kKindForce;
  send(encode(force_kind));
  // non-finite position / velocity
  send(encode(pose_packet(15, Vec3(nan, 0, 0))));
  send(encode(pose_packet(16, bad_m, Vec3(0, -inf, 0))));
  // duplicate and reordered sequence numbers
  send(encode(pose_packet(10, bad_m)));
  send(encode(pose_packet(9, bad_m)));

  bool got = true;
  ASSERT_TRUE(read_until_received(s.device, sent, kT0, &sample, &got));
  EXPECT_FALSE(got) << "a bad datagram is no sample";
  EXPECT_TRUE(s.device.sender_live(kT0)) << "bad datagrams do not make the device lost";
  EXPECT_EQ(sample.position_m, good_m) << "no bad datagram changed the pose";
  UdpDevice::Stats st = s.device.stats();
  EXPECT_EQ(st.received, sent);
  EXPECT_EQ(st.accepted, 1u);
  EXPECT_EQ(st.rejected[static_cast<int>(Reject::kSize)], 3u);
  EXPECT_EQ(st.rejected[static_cast<int>(Reject::kFingerprint)], 3u);
  EXPECT_EQ(st.rejected[static_cast<int>(Reject::kVersion)], 1u);
  EXPECT_EQ(st.rejected[static_cast<int>(Reject::kKind)], 1u);
  EXPECT_EQ(st.rejected[static_cast<int>(Reject::kNonFinite)], 2u);
  EXPECT_EQ(st.rejected[static_cast<int>(Reject::kOtherSender)], 0u);
  EXPECT_EQ(st.rejected_total(), 10u);
  EXPECT_EQ(st.out_of_order, 2u);
  EXPECT_STREQ(UdpDevice::reject_name(Reject::kFingerprint), "fingerprint");

  // The stream continues after the bad ones.
  fake.send(pose_packet(11, Vec3(0.03, 0, 0)));
  bool live = false;
  ASSERT_TRUE(read_until_received(s.device, sent + 1, kT0 + kMs, &sample, &live));
  EXPECT_TRUE(live);
  EXPECT_EQ(sample.position_m.x(), 0.03);
  EXPECT_EQ(s.device.stats().accepted, 2u);
}

TEST(UdpDevice, LossAfterTimeoutThenReturnWithARestartedSequence) {
  Started s(0.05);
  FakeDevice fake(s.device.local_port());
  fake.send(pose_packet(100, Vec3(0.01, 0, 0)));
  DeviceSample sample;
  bool live = false;
  ASSERT_TRUE(read_until_received(s.device, 1, kT0, &sample, &live));
  EXPECT_TRUE(live);
  EXPECT_EQ(sample.position_m.x(), 0.01);
  EXPECT_FALSE(s.device.read(kT0 + 1 * kMs, &sample)) << "the pose is a sample once, not every tick";
  EXPECT_TRUE(s.device.sender_live(kT0 + 50 * kMs)) << "live for exactly timeout_s";
  EXPECT_FALSE(s.device.sender_live(kT0 + 51 * kMs)) << "lost after timeout_s";
  EXPECT_FALSE(s.device.read(kT0 + 500 * kMs, &sample));

  // The device box restarted: its sequence starts over. After the loss that
  // is a new session, not an out-of-order packet.
  fake.send(pose_packet(1, Vec3(0.02, 0, 0)));
  ASSERT_TRUE(read_until_received(s.device, 2, kT0 + 600 * kMs, &sample, &live));
  EXPECT_TRUE(live);
  EXPECT_EQ(sample.position_m.x(), 0.02);
  const UdpDevice::Stats st = s.device.stats();
  EXPECT_EQ(st.sessions, 2u);
  EXPECT_EQ(st.out_of_order, 0u);
  // Forces go to the returned sender.
  s.device.write(kT0 + 601 * kMs, Vec3(0.5, 0, 0));
  const std::optional<Packet> force = fake.receive();
  ASSERT_TRUE(force.has_value());
  EXPECT_EQ(force->echo_sequence_number, 1);
}

TEST(UdpDevice, ASecondSenderIsRejectedWhileTheFirstIsLiveAndTakesOverAfterLoss) {
  Started s(0.05);
  FakeDevice first(s.device.local_port()), second(s.device.local_port());
  first.send(pose_packet(1, Vec3(0.01, 0, 0)));
  DeviceSample sample;
  ASSERT_TRUE(read_until_received(s.device, 1, kT0, &sample));
  // While the first is live the socket is connected to it: the kernel drops
  // the second's datagrams before they queue (none is even received).
  second.send(pose_packet(50, Vec3(0.05, 0, 0)));
  first.send(pose_packet(2, Vec3(0.02, 0, 0)));
  ASSERT_TRUE(read_until_received(s.device, 2, kT0 + 10 * kMs, &sample));
  EXPECT_EQ(sample.position_m.x(), 0.02);
  for (int i = 0; i < 20; ++i) s.device.read(kT0 + 11 * kMs, &sample);
  EXPECT_EQ(s.device.stats().received, 2u) << "the other address's datagram reached the socket";
  s.device.write(kT0 + 10 * kMs, Vec3(1, 0, 0));
  EXPECT_TRUE(first.receive().has_value()) << "forces go to the live sender";
  EXPECT_FALSE(second.receive(std::chrono::milliseconds(20)).has_value());

  // The first falls silent for more than timeout_s: the next read lets every
  // address in again, and the second, still sending, takes over.
  EXPECT_FALSE(s.device.read(kT0 + 100 * kMs, &sample));
  second.send(pose_packet(51, Vec3(0.06, 0, 0)));
  bool live = false;
  ASSERT_TRUE(read_until_received(s.device, 3, kT0 + 100 * kMs, &sample, &live));
  EXPECT_TRUE(live);
  EXPECT_EQ(sample.position_m.x(), 0.06);
  s.device.write(kT0 + 101 * kMs, Vec3(2, 0, 0));
  const std::optional<Packet> force = second.receive();
  ASSERT_TRUE(force.has_value());
  EXPECT_EQ(force->force_N[0], 2.0);
}

// A flood from another address while the device is live never reaches the
// socket's queue (the kernel filters for the connected sender), so the
// device's next pose is read on the next tick. Without the filter 200 junk
// datagrams took three ticks of 64 reads first (and, faster than that, the
// kernel's buffer).
TEST(UdpDevice, AFloodFromElsewhereDoesNotDelayTheLiveDevice) {
  Started s(0.05);
  FakeDevice device(s.device.local_port()), flood(s.device.local_port());
  device.send(pose_packet(1, Vec3(0.01, 0, 0)));
  DeviceSample sample;
  ASSERT_TRUE(read_until_received(s.device, 1, kT0, &sample));
  for (int i = 0; i < 200; ++i) flood.send(pose_packet(1000 + i, Vec3(0.5, 0, 0)));
  device.send(pose_packet(2, Vec3(0.02, 0, 0)));
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // everything sent has arrived
  ASSERT_TRUE(s.device.read(kT0 + kMs, &sample)) << "the device's pose was not read on the next tick";
  EXPECT_EQ(sample.position_m.x(), 0.02);
  EXPECT_EQ(s.device.stats().received, 2u);
}

// Bound to 0.0.0.0, a sender whose poses go to a local address other than
// the one the route back to it leaves from (the hostname's 127.0.1.1 on
// Debian, a secondary address, broadcast) stays one session. Connecting the
// socket to it fixed the socket's local address to that route's source, so
// the kernel dropped every later pose: each was lost after timeout_s and
// taken again as a new session, and the force never ramped in.
TEST(UdpDevice, AWildcardBoundDeviceKeepsASenderThatSendsToAnotherLocalAddress) {
  WildcardBound w("127.0.1.1");
  UdpDevice& device = w.s.device;
  FakeDevice& fake = w.fake;
  DeviceSample sample;
  for (int i = 1; i <= 10; ++i) {
    fake.send(pose_packet(i, Vec3(0.001 * i, 0, 0)));
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    device.read(kT0 + i * kMs, &sample);
  }
  eventually([&] { return device.read(kT0 + 11 * kMs, &sample), device.stats().accepted >= 10; },
             std::chrono::milliseconds(500));
  const UdpDevice::Stats st = device.stats();
  EXPECT_EQ(st.accepted, 10u) << "poses to 127.0.1.1 were dropped after the first";
  EXPECT_EQ(st.sessions, 1u);
  EXPECT_EQ(sample.position_m.x(), 0.01);
  device.write(kT0 + 11 * kMs, Vec3(0.5, 0, 0));
  const std::optional<Packet> force = fake.receive();
  ASSERT_TRUE(force.has_value()) << "no force back to the sender";
  EXPECT_EQ(force->echo_sequence_number, 10);
}

// The fake device sends a pose, `flood` 200, the fake device another: that
// one is read on the next tick, and none of the flood reached the socket (it
// is connected to the fake device, so the kernel dropped them).
void expect_a_flood_from_elsewhere_is_filtered(WildcardBound& w, FakeDevice& flood) {
  UdpDevice& device = w.s.device;
  w.fake.send(pose_packet(1, Vec3(0.01, 0, 0)));
  DeviceSample sample;
  ASSERT_TRUE(read_until_received(device, 1, kT0, &sample));
  for (int i = 0; i < 200; ++i) flood.send(pose_packet(1000 + i, Vec3(0.5, 0, 0)));
  w.fake.send(pose_packet(2, Vec3(0.02, 0, 0)));
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // everything sent has arrived
  ASSERT_TRUE(device.read(kT0 + kMs, &sample)) << "the device's pose was not read on the next tick";
  EXPECT_EQ(sample.position_m.x(), 0.02);
  EXPECT_EQ(device.stats().received, 2u) << "the flood reached the socket";
}

// Bound to 0.0.0.0, a sender whose poses go to the address the route back
// to it leaves from (the usual case) still gets the kernel's filter: a flood
// from elsewhere does not reach the socket while it is live.
TEST(UdpDevice, AWildcardBoundDeviceStillFiltersAFloodFromElsewhere) {
  WildcardBound w("127.0.0.1");
  FakeDevice flood(w.s.device.local_port());
  expect_a_flood_from_elsewhere_is_filtered(w, flood);
}

// Bound to 0.0.0.0, a session whose poses come to a local address other than
// the route back's source stays unconnected (filter_to). When the same
// sender's poses move to another local address within the session, the
// filter is tried again for it: refused again for another such address (the
// poses keep coming, the sender is kept), taken for the route's own source
// (a flood from elsewhere no longer reaches the socket). The refusal was
// kept for the whole session: the kernel's flood defence stayed off until
// the sender was lost.
TEST(UdpDevice, AWildcardBoundDeviceTriesTheFilterAgainWhenThePosesMoveToAnotherLocalAddress) {
  WildcardBound w("127.0.0.2");
  UdpDevice& device = w.s.device;
  FakeDevice flood(device.local_port(), "127.0.0.1");
  constexpr int kFlood = 20;  // fits one read (64) and the socket's buffer: exact counts
  std::int64_t now_ns = kT0;
  std::uint64_t received = 0, refused = 0, seq = 0;
  auto poses_to = [&](const char* to_address, bool filtered) {
    SCOPED_TRACE(std::string("poses to ") + to_address);
    w.fake.retarget(to_address, FakeDevice::Link::kUnconnected);
    DeviceSample sample;
    bool live = false;
    ++seq;
    w.fake.send(pose_packet(static_cast<std::int64_t>(seq), Vec3(0.001 * static_cast<double>(seq), 0, 0)));
    ASSERT_TRUE(read_until_received(device, ++received, now_ns += kMs, &sample, &live));
    ASSERT_TRUE(live);
    for (int i = 0; i < kFlood; ++i) flood.send(pose_packet(1000 + i, Vec3(0.5, 0, 0)));
    ++seq;
    w.fake.send(pose_packet(static_cast<std::int64_t>(seq), Vec3(0.001 * static_cast<double>(seq), 0, 0)));
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // everything sent has arrived
    ASSERT_TRUE(device.read(now_ns += kMs, &sample)) << "the device's pose was not read on the next tick";
    EXPECT_EQ(sample.position_m.x(), 0.001 * static_cast<double>(seq));
    received += 1 + (filtered ? 0 : kFlood);
    refused += filtered ? 0 : kFlood;
    const UdpDevice::Stats st = device.stats();
    EXPECT_EQ(st.received, received) << (filtered ? "the flood reached the socket: not filtered"
                                                  : "the flood did not reach the socket");
    EXPECT_EQ(st.rejected[static_cast<int>(Reject::kOtherSender)], refused);
    EXPECT_EQ(st.accepted, seq);
    EXPECT_EQ(st.sessions, 1u);
  };
  poses_to("127.0.0.2", false);  // the route back leaves from 127.0.0.1: unconnected
  poses_to("127.0.0.3", false);  // tried again, refused again: the poses must keep coming
  poses_to("127.0.0.1", true);   // the route's own source: connected, filtered by the kernel
}

// A sender whose poses alternate between two local addresses, neither the
// route back's source (127.0.1.1 and a broadcast address, say), cannot be
// filtered at either: the filter is tried once for the session, not again at
// every move (each try a connect and a disconnect in the 1 kHz read, and a
// pose arriving in between dropped by the kernel). Found by the review of
// the retry that tries it again when the poses move.
TEST(UdpDevice, PosesAlternatingBetweenTwoUnfilterableAddressesTryTheFilterOnce) {
#if defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "TSan intercepts connect(): counted in the other builds";
#else
  WildcardBound w("127.0.0.2");
  UdpDevice& device = w.s.device;
  std::int64_t now_ns = kT0;
  std::uint64_t received = 0;
  g_connects = 0;
  for (int seq = 1; seq <= 20; ++seq) {
    w.fake.retarget(seq % 2 ? "127.0.0.2" : "127.0.0.3", FakeDevice::Link::kUnconnected);
    w.fake.send(pose_packet(seq, Vec3(0.001 * seq, 0, 0)));
    DeviceSample sample;
    bool live = false;
    g_count_connects = true;
    const bool read = read_until_received(device, ++received, now_ns += kMs, &sample, &live);
    g_count_connects = false;
    ASSERT_TRUE(read && live) << "pose " << seq;
  }
  EXPECT_EQ(device.stats().sessions, 1u);
  EXPECT_EQ(device.stats().accepted, 20u);
  // The session's one try: a connect to the sender and the disconnect that
  // undoes it (the route leaves from 127.0.0.1).
  EXPECT_EQ(g_connects.load(), 2);
#endif
}

// Sends a pose, reads it, writes a force: the fake device must get the force,
// also after the sender is lost (the socket is disconnected then, and the
// ramped-out force still goes).
void expect_forces_reach_the_fake_device(WildcardBound& w) {
  UdpDevice& device = w.s.device;
  w.fake.send(pose_packet(7, Vec3(0.01, 0, 0)));
  DeviceSample sample;
  bool got = false;
  ASSERT_TRUE(read_until_received(device, 1, kT0, &sample, &got));
  ASSERT_TRUE(got);
  device.write(kT0 + kMs, Vec3(0.5, 0, 0));
  const std::optional<Packet> force = w.fake.receive();
  ASSERT_TRUE(force.has_value()) << "no force reached the device";
  EXPECT_EQ(force->echo_sequence_number, 7);
  EXPECT_EQ(force->force_N[0], 0.5);

  EXPECT_FALSE(device.read(kT0 + 100 * kMs, &sample));  // lost: the filter (if any) is lifted
  device.write(kT0 + 100 * kMs, Vec3(0.25, 0, 0));
  const std::optional<Packet> ramp = w.fake.receive();
  ASSERT_TRUE(ramp.has_value()) << "no force reached the device after it was lost";
  EXPECT_EQ(ramp->force_N[0], 0.25);
  const UdpDevice::Stats st = device.stats();
  EXPECT_EQ(st.sent, 2u);
  EXPECT_EQ(st.send_failures, 0u);
}

// A device that connect()s its socket to tissued's address (common in device
// bridges) takes only datagrams from exactly that address. Bound to 0.0.0.0
// and reached at 127.0.0.2 while the route back to the device leaves from
// 127.0.0.1, tissued keeps the session unconnected (filter_to); its forces
// went out from 127.0.0.1 and the device's kernel dropped every one.
TEST(UdpDevice, AWildcardBoundDeviceAnswersFromTheAddressThePosesCameTo) {
  WildcardBound w("127.0.0.2", FakeDevice::Link::kConnected);
  expect_forces_reach_the_fake_device(w);
}

// The same on a dual-stack socket bound to ::, where the IPv4 device's poses
// arrive as v4-mapped addresses.
TEST(UdpDevice, ADualStackWildcardBoundDeviceAnswersAnIpv4DeviceFromTheAddressThePosesCameTo) {
  WildcardBound w("127.0.0.2", FakeDevice::Link::kConnected, "::");
  expect_forces_reach_the_fake_device(w);
}

// Poses sent to a broadcast address (lo's 127.255.255.255), which no force
// can come from. Bound to 0.0.0.0, the kernel names lo's own address for the
// reply (in_pktinfo.ipi_spec_dst); bound to ::, the v4-mapped broadcast is
// refused as a source and the route picks one for the session (both forces
// count as fallbacks: the second skips the refused source). Either way every
// force goes out to the (unconnected) device, from 127.0.0.1.
TEST(UdpDevice, AWildcardBoundDeviceAnswersPosesSentToABroadcastAddress) {
  for (const char* bind_address : {"0.0.0.0", "::"}) {
    SCOPED_TRACE(bind_address);
    WildcardBound w("127.255.255.255", FakeDevice::Link::kUnconnected, bind_address);
    expect_forces_reach_the_fake_device(w);
    EXPECT_EQ(w.fake.last_source(), ip::make_address("127.0.0.1"));
    const bool v6_socket = std::string(bind_address) == "::";
    EXPECT_EQ(w.s.device.stats().reply_source_fallbacks, v6_socket ? 2u : 0u)
        << (v6_socket ? "the v4-mapped broadcast was never tried (and refused) as the source"
                      : "lo's own address (ipi_spec_dst) was refused as the source");
  }
}

// `first` goes live and is lost; `second`, at another address, must then be
// heard and answered, and `first` refused while `second` is live. On a socket
// of the IPv6 family that refusal happens in userspace (the socket is never
// connected, see UdpDevice::filter_to), so its datagram is read and counted.
// Linux keeps an IPv6 socket filtering by its last peer's address after
// connect(AF_UNSPEC): connected once, such a socket never heard a device at
// another address again until restart.
void expect_a_sender_at_another_address_is_heard_after_loss(UdpDevice& device, FakeDevice& first, FakeDevice& second) {
  DeviceSample sample;
  bool live = false;
  first.send(pose_packet(1, Vec3(0.01, 0, 0)));
  ASSERT_TRUE(read_until_received(device, 1, kT0, &sample, &live));
  ASSERT_TRUE(live);
  device.write(kT0 + kMs, Vec3(0.5, 0, 0));
  ASSERT_TRUE(first.receive().has_value()) << "no force reached the first sender";

  EXPECT_FALSE(device.read(kT0 + 100 * kMs, &sample));  // lost
  EXPECT_FALSE(device.sender_live(kT0 + 100 * kMs));
  second.send(pose_packet(1, Vec3(0.06, 0, 0)));
  ASSERT_TRUE(read_until_received(device, 2, kT0 + 100 * kMs, &sample, &live))
      << "a sender at another address was never heard after the first was lost";
  EXPECT_TRUE(live);
  EXPECT_EQ(sample.position_m.x(), 0.06);
  EXPECT_EQ(device.stats().sessions, 2u);
  device.write(kT0 + 101 * kMs, Vec3(2, 0, 0));
  const std::optional<Packet> force = second.receive();
  ASSERT_TRUE(force.has_value()) << "no force reached the second sender";
  EXPECT_EQ(force->force_N[0], 2.0);

  first.send(pose_packet(2, Vec3(0.02, 0, 0)));
  ASSERT_TRUE(read_until_received(device, 3, kT0 + 102 * kMs, &sample, &live))
      << "the first sender's datagram did not reach the socket";
  EXPECT_FALSE(live);
  EXPECT_EQ(device.stats().rejected[static_cast<int>(Reject::kOtherSender)], 1u);
  EXPECT_EQ(device.stats().accepted, 2u);
}

// Bound to :: (dual-stack), an IPv4 device's session (v4-mapped) was lost
// and a native IPv6 device was never heard: the socket had been connected to
// ::ffff:127.0.0.1, and Linux filters an IPv6 socket by that address after
// the disconnect.
TEST(UdpDevice, ADualStackDeviceHearsAnIpv6SenderAfterAnIpv4SessionIsLost) {
  Started s(wildcard_spec("::"));
  FakeDevice first(s.device.local_port(), "127.0.0.1", FakeDevice::Link::kUnconnected, "127.0.0.1");
  FakeDevice second(s.device.local_port(), "::1", FakeDevice::Link::kUnconnected, "::1");
  expect_a_sender_at_another_address_is_heard_after_loss(s.device, first, second);
}

// IPv6 link-local and unique-local addresses, in a private network namespace
// where lo carries fe80::1/64 and fd00::2/128 (tests/haptics/CMakeLists.txt,
// UdpDeviceNetns.InPrivateNamespace).
bool in_link_local_netns() { return std::getenv("TISSUE_TEST_UDP_LINK_LOCAL") != nullptr; }

// Bound to ::1 or ::, a device on ::1 goes live and is lost; a device at
// another IPv6 address (unique-local, link-local) was then never heard.
TEST(UdpDeviceNetns, AnIpv6BoundDeviceHearsASenderAtAnotherAddressAfterTheFirstIsLost) {
  if (!in_link_local_netns()) GTEST_SKIP() << "run through tests/transport/in_netns.sh (ctest does)";
  for (const char* bind_address : {"::1", "::"}) {
    for (const char* second_address : {"fd00::2", "fe80::1%lo"}) {
      SCOPED_TRACE(std::string(bind_address) + " then " + second_address);
      Started s(wildcard_spec(bind_address));
      FakeDevice first(s.device.local_port(), "::1", FakeDevice::Link::kUnconnected, "::1");
      FakeDevice second(s.device.local_port(), "::1", FakeDevice::Link::kUnconnected, second_address);
      expect_a_sender_at_another_address_is_heard_after_loss(s.device, first, second);
    }
  }
}

// On a socket of the IPv6 family the flood defence is userspace only (the
// socket is never connected: Linux would keep filtering by the last peer's
// address after the disconnect, see UdpDevice::filter_to). A flood from
// another port of a live link-local sender's address reaches the socket, and
// every datagram of it is refused as other_sender; the device's next pose
// waits behind it (64 reads a tick) but is taken, and the flood never is.
// 100 datagrams: they fit the socket's default buffer, so none is lost and the
// counts are exact.
TEST(UdpDeviceNetns, AWildcardBoundDeviceRefusesAFloodWhileALinkLocalSenderIsLive) {
  if (!in_link_local_netns()) GTEST_SKIP() << "run through tests/transport/in_netns.sh (ctest does)";
  WildcardBound w("fe80::1%lo", FakeDevice::Link::kUnconnected, "::", "fe80::1%lo");
  FakeDevice flood(w.s.device.local_port(), "fe80::1%lo", FakeDevice::Link::kUnconnected, "fe80::1%lo");
  UdpDevice& device = w.s.device;
  w.fake.send(pose_packet(1, Vec3(0.01, 0, 0)));
  DeviceSample sample;
  ASSERT_TRUE(read_until_received(device, 1, kT0, &sample));
  constexpr int kFlood = 100;
  for (int i = 0; i < kFlood; ++i) flood.send(pose_packet(1000 + i, Vec3(0.5, 0, 0)));
  w.fake.send(pose_packet(2, Vec3(0.02, 0, 0)));
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // everything sent has arrived
  int ticks = 0;
  bool got = false;
  while (!got && ticks < 10) got = device.read(kT0 + (++ticks) * kMs, &sample);
  ASSERT_TRUE(got) << "the device's pose was never read";
  EXPECT_EQ(ticks, (kFlood + 1 + UdpDevice::kMaxDatagramsPerRead - 1) / UdpDevice::kMaxDatagramsPerRead)
      << "the device's pose waited longer than the flood's reads";
  EXPECT_EQ(sample.position_m.x(), 0.02);
  const UdpDevice::Stats st = device.stats();
  EXPECT_EQ(st.received, static_cast<std::uint64_t>(kFlood) + 2u);
  EXPECT_EQ(st.rejected[static_cast<int>(Reject::kOtherSender)], static_cast<std::uint64_t>(kFlood));
  EXPECT_EQ(st.accepted, 2u);
  EXPECT_EQ(st.sessions, 1u);
}

// Removes an IPv6 address from lo with the SIOCDIFADDR ioctl (no netlink,
// no shell): it is gone when the call returns. Needs CAP_NET_ADMIN in the
// network namespace (in_netns.sh's user namespace gives it).
bool remove_ipv6_address_from_lo(const char* address, std::uint32_t prefix_length, std::string* error) {
  struct {  // struct in6_ifreq of <linux/ipv6.h>, which clashes with <netinet/in.h>
    in6_addr addr;
    std::uint32_t prefix_length;
    int ifindex;
  } request{};
  const ip::address_v6::bytes_type bytes = ip::make_address_v6(address).to_bytes();
  std::memcpy(&request.addr, bytes.data(), bytes.size());
  request.prefix_length = prefix_length;
  request.ifindex = static_cast<int>(if_nametoindex("lo"));
  const int fd = ::socket(AF_INET6, SOCK_DGRAM, 0);
  const bool ok = fd >= 0 && request.ifindex > 0 && ::ioctl(fd, SIOCDIFADDR, &request) == 0;
  if (!ok) *error = std::string("removing ") + address + " from lo: " + std::strerror(errno);
  if (fd >= 0) ::close(fd);
  return ok;
}

// Bound to :: (never connected), a device on ::1 sends its poses to fd00::3,
// which is then removed from lo: the kernel refuses it as the source (EINVAL),
// the force leaves from the route's source (::1) and still reaches the
// (unconnected) device, counted as a fallback, and the next force goes there
// straight away. The same device then sends to fd00::2 and connect()s to it:
// that source is valid and must be tried again. The refusal was kept for the
// whole session, so every force left from ::1 and the device dropped it.
TEST(UdpDeviceNetns, ARefusedSourceFallsBackToTheRoutesAndIsTriedAgainWhenThePosesMove) {
  if (!in_link_local_netns()) GTEST_SKIP() << "run through tests/transport/in_netns.sh (ctest does)";
  Started s(wildcard_spec("::"));
  UdpDevice& device = s.device;
  FakeDevice fake(device.local_port(), "fd00::3", FakeDevice::Link::kUnconnected, "::1");
  DeviceSample sample;
  bool live = false;
  fake.send(pose_packet(1, Vec3(0.01, 0, 0)));
  ASSERT_TRUE(read_until_received(device, 1, kT0, &sample, &live));
  ASSERT_TRUE(live);
  device.write(kT0 + kMs, Vec3(0.5, 0, 0));
  std::optional<Packet> force = fake.receive();
  ASSERT_TRUE(force.has_value()) << "no force reached the device";
  EXPECT_EQ(fake.last_source(), ip::make_address("fd00::3"));
  EXPECT_EQ(device.stats().reply_source_fallbacks, 0u);

  std::string error;
  ASSERT_TRUE(remove_ipv6_address_from_lo("fd00::3", 128, &error)) << error;
  for (int i = 2; i <= 3; ++i) {
    SCOPED_TRACE("force " + std::to_string(i) + " after fd00::3 was removed");
    device.write(kT0 + i * kMs, Vec3(0.1 * i, 0, 0));
    force = fake.receive();
    ASSERT_TRUE(force.has_value()) << "no force reached the device after its source was removed";
    EXPECT_EQ(force->force_N[0], 0.1 * i);
    EXPECT_EQ(fake.last_source(), ip::make_address("::1"));
    EXPECT_EQ(device.stats().reply_source_fallbacks, static_cast<std::uint64_t>(i - 1));
  }

  fake.retarget("fd00::2", FakeDevice::Link::kConnected);
  fake.send(pose_packet(2, Vec3(0.02, 0, 0)));
  ASSERT_TRUE(read_until_received(device, 2, kT0 + 4 * kMs, &sample, &live));
  ASSERT_TRUE(live);
  device.write(kT0 + 5 * kMs, Vec3(0.9, 0, 0));
  force = fake.receive(std::chrono::milliseconds(500));
  ASSERT_TRUE(force.has_value()) << "no force reached the device connected to fd00::2 (sent from ::1?)";
  EXPECT_EQ(force->force_N[0], 0.9);
  EXPECT_EQ(fake.last_source(), ip::make_address("fd00::2"));
  const UdpDevice::Stats st = device.stats();
  EXPECT_EQ(st.reply_source_fallbacks, 2u);
  EXPECT_EQ(st.sent, 4u);
  EXPECT_EQ(st.send_failures, 0u);
  EXPECT_EQ(st.sessions, 1u);
}

// A connected device on ::1 that sends to fe80::1%lo (the route back to ::1
// leaves from ::1: unconnected session) gets its forces from fe80::1, which
// as a source needs its interface named (IPV6_PKTINFO's ifindex).
TEST(UdpDeviceNetns, AWildcardBoundDeviceAnswersFromTheLinkLocalAddressThePosesCameTo) {
  if (!in_link_local_netns()) GTEST_SKIP() << "run through tests/transport/in_netns.sh (ctest does)";
  WildcardBound w("fe80::1%lo", FakeDevice::Link::kConnected, "::", "::1");
  expect_forces_reach_the_fake_device(w);
}

// One pose whose sequence number leapt ahead (a glitch, a bad sender on the
// same address) is accepted, as any higher number is; the real stream below it
// is followed again after kResyncPackets poses, not locked out for timeout_s.
TEST(UdpDevice, ASequenceThatLeaptAheadIsFollowedBackAfterThreePoses) {
  Started s(0.05);
  FakeDevice fake(s.device.local_port());
  DeviceSample sample;
  std::uint64_t sent = 0;
  auto send_and_read = [&](std::int64_t sequence, double x_m, std::int64_t now_ns) {
    fake.send(pose_packet(sequence, Vec3(x_m, 0, 0)));
    ++sent;
    bool got = false;
    EXPECT_TRUE(read_until_received(s.device, sent, now_ns, &sample, &got));
    return got;
  };
  for (int i = 1; i <= 5; ++i) EXPECT_TRUE(send_and_read(i, 0.001 * i, kT0 + i * kMs));
  EXPECT_TRUE(send_and_read(std::int64_t{1} << 62, 0.5, kT0 + 6 * kMs));
  EXPECT_EQ(sample.position_m.x(), 0.5);
  EXPECT_FALSE(send_and_read(6, 0.006, kT0 + 7 * kMs));
  EXPECT_FALSE(send_and_read(7, 0.007, kT0 + 8 * kMs));
  EXPECT_TRUE(send_and_read(8, 0.008, kT0 + 9 * kMs)) << "the third in a row is followed";
  EXPECT_EQ(sample.position_m.x(), 0.008);
  EXPECT_TRUE(send_and_read(9, 0.009, kT0 + 10 * kMs));
  UdpDevice::Stats st = s.device.stats();
  EXPECT_EQ(st.out_of_order, 2u);
  EXPECT_EQ(st.resyncs, 1u);
  EXPECT_EQ(st.sessions, 1u);

  // Duplicates and a reordering never add up to a resync: each is followed by
  // a pose above the last accepted one, or repeats the same number.
  for (int i = 0; i < 5; ++i) EXPECT_FALSE(send_and_read(9, 0.1, kT0 + 11 * kMs));
  EXPECT_TRUE(send_and_read(11, 0.011, kT0 + 12 * kMs));
  EXPECT_FALSE(send_and_read(10, 0.1, kT0 + 13 * kMs));
  EXPECT_TRUE(send_and_read(12, 0.012, kT0 + 14 * kMs));
  EXPECT_FALSE(send_and_read(11, 0.1, kT0 + 15 * kMs));
  EXPECT_TRUE(send_and_read(13, 0.013, kT0 + 16 * kMs));
  st = s.device.stats();
  EXPECT_EQ(st.out_of_order, 2u + 7u);
  EXPECT_EQ(st.resyncs, 1u);
  EXPECT_EQ(sample.position_m.x(), 0.013);
}

// A lost sender gets forces until one zero force has gone, then none: its
// address may no longer be a device. Its next pose makes it live again.
TEST(UdpDevice, ALostSenderGetsForcesUntilAZeroForceThenNothing) {
  Started s(0.05);
  FakeDevice fake(s.device.local_port());
  fake.send(pose_packet(1, Vec3(0.01, 0, 0)));
  DeviceSample sample;
  ASSERT_TRUE(read_until_received(s.device, 1, kT0, &sample));
  s.device.write(kT0 + 1 * kMs, Vec3(0, 0, 0));  // live: a zero force goes
  s.device.write(kT0 + 2 * kMs, Vec3(0, 0, 0));
  s.device.write(kT0 + 60 * kMs, Vec3(0.5, 0, 0));  // lost, ramping out: goes
  s.device.write(kT0 + 61 * kMs, Vec3(0, 0, 0));    // the first zero after the loss: goes
  s.device.write(kT0 + 62 * kMs, Vec3(0, 0, 0));    // then nothing
  s.device.write(kT0 + 500 * kMs, Vec3(0, 0, 0));
  EXPECT_EQ(s.device.stats().sent, 4u);
  std::vector<double> forces_x;
  while (const std::optional<Packet> f = fake.receive(std::chrono::milliseconds(200)))
    forces_x.push_back(f->force_N[0]);
  EXPECT_EQ(forces_x, (std::vector<double>{0.0, 0.0, 0.5, 0.0}));

  fake.send(pose_packet(1, Vec3(0.02, 0, 0)));  // back: a new session
  ASSERT_TRUE(read_until_received(s.device, 2, kT0 + 600 * kMs, &sample));
  s.device.write(kT0 + 601 * kMs, Vec3(0, 0, 0));
  EXPECT_EQ(s.device.stats().sent, 5u);
  EXPECT_TRUE(fake.receive().has_value());
}

// The bridge under the haptic loop, on a synthetic clock: a device that sends
// at 250 Hz while moving at 1.5 m/s (6 mm between poses) is not "too fast"
// (the loop sees each pose once, 4 ms after the last), and when it falls
// silent the loop ramps the force out after limits.device_timeout_s (10 ms),
// not after the bridge's session timeout_s (50 ms). Before each pose was a
// sample on every tick: 6 mm in "1 ms" was rejected, silence went unseen.
TEST(UdpDeviceInTheLoop, A250HzDeviceIsNotTooFastAndItsSilenceIsSeenAfterTheDeviceTimeout) {
  Started s(0.05);
  FakeDevice fake(s.device.local_port());
  config::DeviceSpec device_spec;
  device_spec.limits.stale_model_s = 10.0;  // no model: only the device side is judged
  ASSERT_EQ(device_spec.limits.device_timeout_s, 0.01);
  ASSERT_EQ(device_spec.limits.max_speed_m_per_s, 5.0);
  config::HapticSpec haptic_spec;
  auto models = std::make_unique<LocalModelBuffer>();
  auto samples = std::make_unique<ToolSampleRing>();
  HapticLoop loop(s.device, device_spec, haptic_spec, *models, *samples);

  std::int64_t now_ns = kT0;
  constexpr int kPoses = 60;
  for (int tick = 0; tick < 4 * kPoses; ++tick) {
    if (tick % 4 == 0) {
      const int n = tick / 4 + 1;
      fake.send(pose_packet(n, Vec3(0.006 * n, 0, 0.05), Vec3(1.5, 0, 0)));
      std::this_thread::sleep_for(std::chrono::microseconds(300));  // loopback delivery, not formally synchronous
    }
    now_ns += kMs;
    loop.tick(now_ns);
    ToolSample drained;
    while (samples->try_pop(drained)) {
    }
  }
  HapticStats st = loop.stats();
  EXPECT_EQ(st.rejected_speed, 0u);
  EXPECT_EQ(st.rejected_inputs, 0u);
  EXPECT_GE(s.device.stats().accepted, static_cast<std::uint64_t>(kPoses - 2));
  EXPECT_EQ(st.device_lost_trips, 0u) << "a pose every 4 ms is within the 10 ms device timeout";

  // Silence. The last pose was read at tick 4 * kPoses - 3 (or a tick later).
  const std::int64_t last_pose_ns = kT0 + (4 * kPoses - 3) * kMs;
  std::int64_t lost_at_ns = 0;
  for (int tick = 0; tick < 60 && lost_at_ns == 0; ++tick) {
    now_ns += kMs;
    loop.tick(now_ns);
    if (loop.stats().device_lost_trips == 1) lost_at_ns = now_ns;
  }
  ASSERT_NE(lost_at_ns, 0) << "silence never seen";
  EXPECT_GE(lost_at_ns - last_pose_ns, 10 * kMs);
  EXPECT_LE(lost_at_ns - last_pose_ns, 13 * kMs);
  EXPECT_TRUE(s.device.sender_live(lost_at_ns)) << "the session outlives the force ramp";
}

// A fake device thread streams poses at ~1 kHz and checks every force that
// comes back against the pose it answered; the main thread runs read()/write()
// at ~1 kHz on the real clock. Then the device goes silent (lost after
// timeout_s) and comes back (valid again).
TEST(UdpDevice, StreamsWithAFakeDeviceThreadThroughLossAndReturn) {
  constexpr double kTimeout_s = 0.1;  // well above scheduling hiccups of a loaded 2-core box
  constexpr double kStiffness_N_per_m = 100.0;
  constexpr double kStep_m = 1e-5;  // pose n is at x = n * kStep_m
  Started s(kTimeout_s);
  const std::uint16_t port = s.device.local_port();

  std::atomic<bool> sending{true}, quit{false};
  std::atomic<std::int64_t> last_sent_sequence{0};
  std::atomic<std::int64_t> last_send_ns{0};  // when the newest pose left the fake device
  std::atomic<int> forces_received{0}, force_mismatches{0};
  std::thread fake_thread([&] {
    FakeDevice fake(port);
    std::int64_t sequence = 0;
    while (!quit.load()) {
      if (sending.load()) {
        ++sequence;
        last_sent_sequence.store(sequence);  // before the send: the reader may see the pose at once
        fake.send(pose_packet(sequence, Vec3(sequence * kStep_m, 0, 0)));
        last_send_ns.store(steady_now_ns());
      }
      while (const std::optional<Packet> force = fake.receive(std::chrono::milliseconds(0))) {
        forces_received.fetch_add(1);
        const double expected_N = -kStiffness_N_per_m * (force->echo_sequence_number * kStep_m);
        if (force->kind != UdpDevice::kKindForce || force->force_N[0] != expected_N ||
            force->echo_sequence_number > sequence)
          force_mismatches.fetch_add(1);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  });

  auto tick_for = [&](std::chrono::milliseconds duration, int* valid_reads, int* pose_mismatches) {
    const auto end = std::chrono::steady_clock::now() + duration;
    while (std::chrono::steady_clock::now() < end) {
      DeviceSample sample;
      if (s.device.read(steady_now_ns(), &sample)) {
        ++*valid_reads;
        const double n = sample.position_m.x() / kStep_m;
        if (std::abs(n - std::round(n)) > 1e-6 || std::round(n) > static_cast<double>(last_sent_sequence.load()))
          ++*pose_mismatches;
        s.device.write(steady_now_ns(), Vec3(-kStiffness_N_per_m * sample.position_m.x(), 0, 0));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  };

  int valid = 0, mismatches = 0;
  tick_for(std::chrono::milliseconds(300), &valid, &mismatches);
  EXPECT_GT(valid, 50) << "a 1 kHz stream gives valid reads on most ticks";
  EXPECT_EQ(mismatches, 0);
  EXPECT_TRUE(eventually([&] { return forces_received.load() > 50; }));

  sending.store(false);  // device lost
  DeviceSample sample;
  EXPECT_TRUE(eventually([&] {
    s.device.read(steady_now_ns(), &sample);
    return !s.device.sender_live(steady_now_ns());
  }));
  // Silence starts with the last pose sent, which a slow fake thread (TSan,
  // a loaded box) may have sent a few ms before `sending` went false.
  EXPECT_GE(steady_now_ns() - last_send_ns.load(), static_cast<std::int64_t>(kTimeout_s * 1e9) - 2 * kMs)
      << "not lost before timeout_s";

  sending.store(true);  // and back
  EXPECT_TRUE(eventually([&] { return s.device.read(steady_now_ns(), &sample); }));
  int valid_after = 0;
  tick_for(std::chrono::milliseconds(100), &valid_after, &mismatches);
  EXPECT_GT(valid_after, 20);
  EXPECT_EQ(mismatches, 0);

  quit.store(true);
  fake_thread.join();
  EXPECT_EQ(force_mismatches.load(), 0);
  const UdpDevice::Stats st = s.device.stats();
  EXPECT_EQ(st.rejected_total(), 0u);
  EXPECT_EQ(st.out_of_order, 0u);
  EXPECT_GE(st.sessions, 2u);  // 2 unless the box stalled the fake for > timeout_s
  EXPECT_GT(st.sent, 70u);
  EXPECT_EQ(st.send_failures, 0u);
}

// 10,000 ticks of read()/write() with valid poses and garbage arriving (and,
// with `other`, valid poses from another sender that the device must refuse),
// counting allocations on this thread; returns the force packets the fake
// device received.
int expect_ten_thousand_read_write_calls_allocate_nothing(UdpDevice& device, FakeDevice& fake,
                                                          FakeDevice* other = nullptr) {
  // The fake side encodes outside the counted window (counting is per thread
  // and only switched on around read()/write()).
  const std::vector<unsigned char> garbage(121, 0x5A);

  constexpr int kCalls = 10'000;
  int valid_reads = 0, forces = 0;
  std::int64_t now_ns = kT0;
  tissue::testing::reset_allocations();
  for (int i = 0; i < kCalls; ++i) {
    // Every tenth tick a fresh valid pose (its sequence keeps growing) or a
    // rejected datagram arrives, so both decode paths run in the window.
    if (i % 10 == 0) {
      fake.send(pose_packet(i + 1, Vec3(0.0001 * (i % 100), 0, 0)));
    } else if (i % 10 == 5) {
      fake.send_bytes(garbage);
    } else if (i % 10 == 3 && other) {
      other->send(pose_packet(i + 1, Vec3(0.5, 0, 0)));
    }
    if (i % 100 == 99) forces += fake.drain();
    now_ns += kMs;
    DeviceSample sample;
    tissue::testing::count_this_thread(true);
    const bool ok = device.read(now_ns, &sample);
    device.write(now_ns, Vec3(0.001 * (i % 7), 0, 0));
    tissue::testing::count_this_thread(false);
    valid_reads += ok ? 1 : 0;
  }
  EXPECT_EQ(tissue::testing::allocations(), 0u) << "read()/write() allocated";
  const UdpDevice::Stats st = device.stats();
  EXPECT_GT(st.accepted, 900u) << "the valid path ran";
  EXPECT_LE(static_cast<std::uint64_t>(valid_reads), st.accepted) << "each pose is a sample once";
  EXPECT_GT(valid_reads, 900);
  EXPECT_GT(st.rejected[static_cast<int>(Reject::kFingerprint)], 900u) << "the reject path ran";
  if (other) {
    EXPECT_GT(st.rejected[static_cast<int>(Reject::kOtherSender)], 900u) << "the other_sender path ran";
  }
  EXPECT_GT(st.sent, static_cast<std::uint64_t>(kCalls) * 9 / 10);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the last forces have arrived
  return forces + fake.drain();
}

TEST(UdpDeviceRealtime, TenThousandReadWriteCallsAllocateNothing) {
  Started s(0.05);
  FakeDevice fake(s.device.local_port());
  EXPECT_GT(expect_ten_thousand_read_write_calls_allocate_nothing(s.device, fake), 9'000);

  // The counter itself works (a check that guards against a silent zero).
  tissue::testing::count_this_thread(true);
  auto* probe = new std::vector<int>(8);
  tissue::testing::count_this_thread(false);
  delete probe;
  EXPECT_GE(tissue::testing::allocations(), 1u);
}

// The same where write() names the source address (sendmsg with IP_PKTINFO):
// bound to 0.0.0.0, poses to 127.0.0.2, a device connected there.
// On 0.0.0.0 (IP_PKTINFO) and on a dual-stack :: (a v4-mapped IPV6_PKTINFO).
TEST(UdpDeviceRealtime, AWildcardBoundDeviceAnsweringFromThePosesAddressAllocatesNothing) {
  for (const char* bind_address : {"0.0.0.0", "::"}) {
    SCOPED_TRACE(bind_address);
    WildcardBound w("127.0.0.2", FakeDevice::Link::kConnected, bind_address);
    EXPECT_GT(expect_ten_thousand_read_write_calls_allocate_nothing(w.s.device, w.fake), 9'000)
        << "the forces did not reach the device";
    EXPECT_EQ(w.s.device.stats().rejected[static_cast<int>(Reject::kOtherSender)], 0u);
  }
}

// Bound to an IPv6 address (::1, and :: where write() names ::1 as the source
// with IPV6_PKTINFO), the socket is never connected: another sender's poses
// (::1, another port) are read and refused in userspace, each tick.
TEST(UdpDeviceRealtime, AnIpv6BoundDeviceRefusingAnotherSenderAllocatesNothing) {
  for (const char* bind_address : {"::1", "::"}) {
    SCOPED_TRACE(bind_address);
    WildcardBound w("::1", FakeDevice::Link::kConnected, bind_address, "::1");
    FakeDevice other(w.s.device.local_port(), "::1", FakeDevice::Link::kUnconnected, "::1");
    EXPECT_GT(expect_ten_thousand_read_write_calls_allocate_nothing(w.s.device, w.fake, &other), 9'000)
        << "the forces did not reach the device";
    EXPECT_EQ(w.s.device.stats().sessions, 1u);
  }
}

}  // namespace
}  // namespace tissue::haptics
