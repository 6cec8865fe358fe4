// transport_latency_bench: sim-to-subscriber latency of the surface mesh.
//
// Measures the time from handing a MeshSnapshot (default 100k triangles) to
// the daemon's publisher (LcmPublisher / DdsPublisher: encode + send) until
// the subscriber (LcmMeshSubscriber / DdsMeshSubscriber: receive + decode +
// validate + convert to an x3d::SurfaceFrame, what `tissue x3d --lcm|--dds`
// uses) holds the frame. One mesh in flight at a time (the next is published
// once the previous arrived), so the figures are the unloaded latency, not a
// throughput limit. Subscriber in the same process (a second thread) or in a
// forked child (2 processes); both use CLOCK_MONOTONIC (steady_clock), which
// is the same clock across processes. Prints p50 / p99 / max of the latency
// and of the publish call alone, and the message size.
//
// Loopback only. LCM multicast needs a route and DDS discovery multicasts, so
// run it in a private network namespace with a private /dev/shm for Fast
// DDS's shared memory. -r (a new user namespace, the caller root in it) is
// what lets a user who is not root create both and mount the tmpfs:
//
//   unshare -rn -m sh -c 'mount -t tmpfs -o size=512m bench_shm /dev/shm &&
//     ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo &&
//     build/dev/bench/transport/transport_latency_bench --samples 200'
//
// Options: --samples N (200), --warmup N (10), --triangles T (100000),
// --transport lcm|dds|both, --processes 1|2|both,
// --lcm-url URL (udpm://239.255.76.67:7667?ttl=0&recv_buf_size=8388608), --dds-domain N (42),
// --dds-max-mesh-bytes B (default: room for the mesh sent, at least the daemon's 8 MiB),
// --lost-after-ms MS (default: 250 ms + 50 ms per MB of the message).
// A publish_mesh() that fails ends its row with the reason; a latency column
// with no sample (every mesh lost) prints "-". A mesh not received within
// --lost-after-ms is counted lost and the next one published; a row with
// lost meshes is followed by the timeout used and how many of them arrived
// after it (a timeout too short for this machine, rather than a loss).
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "tissue_dds/surface_mesh.h"
#include "transport/dds_messages.hpp"
#include "transport/dds_publisher.hpp"
#include "transport/dds_subscriber.hpp"
#include "transport/lcm_messages.hpp"
#include "transport/lcm_publisher.hpp"
#include "transport/lcm_subscriber.hpp"

namespace {

using namespace tissue;
using Clock = std::chrono::steady_clock;

double now_s() { return std::chrono::duration<double>(Clock::now().time_since_epoch()).count(); }

struct Options {
  int samples = 200, warmup = 10, triangles = 100000;
  std::string transport = "both", processes = "both";
  std::string lcm_url = transport::kLcmSubscribeUrl;
  int dds_domain = 42;
  // Publisher and subscriber both: the publisher refuses a serialized mesh
  // above it and sizes its shared-memory segment from it. 0 until main()
  // sizes it for the mesh (the daemon's fixed 8 MiB default made every
  // publish of a mesh over ~370k triangles fail).
  std::size_t dds_max_mesh_bytes = 0;
  // A mesh not received within this long is lost. 0: lost_after_s() below.
  double lost_after_ms = 0.0;
};

// How long to wait for a mesh before counting it lost. Each lost mesh used to
// cost a fixed 2 s, so a run whose messages the kernel dropped (a receive
// buffer too small for the mesh) took 2 s a sample and measured nothing the
// while. The default is 250 ms plus 50 ms per MB (20 MB/s): the per-MB part
// alone is some 25 times the loopback's 4.3 ms for 2.26 MB
// (docs/replay-and-live.md), however large the mesh, and the 250 ms covers a
// scheduling gap on a shared machine (47 ms seen); yet a lost default mesh
// costs 0.36 s, not 2 s.
double lost_after_s(const Options& o, std::size_t message_bytes) {
  if (o.lost_after_ms > 0.0) return o.lost_after_ms / 1e3;
  return 0.25 + static_cast<double>(message_bytes) / 20e6;
}

// A flat n x n grid of quads (two triangles each): ~triangles/2 vertices,
// like a closed surface; levels and per-triangle strain filled as the sim
// thread fills them.
service::MeshSnapshot grid_mesh(int triangles) {
  const int n = std::max(1, static_cast<int>(std::lround(std::sqrt(triangles / 2.0))));
  service::MeshSnapshot s;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      s.vertices_m.push_back({0.1 * i / n, 0.1 * j / n, 0.001 * std::sin(i * 0.1)});
      s.vertex_level.push_back(static_cast<std::uint8_t>((i + j) % 6));
    }
  const auto at = [n](int i, int j) { return static_cast<std::uint32_t>(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      s.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      s.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  for (std::size_t t = 0; t < s.triangles.size(); ++t)
    s.triangle_strain_energy_J_per_m3.push_back(static_cast<float>(t % 1000));
  return s;
}

std::unique_ptr<transport::MeshSubscriber> make_subscriber(const std::string& kind, const Options& o) {
  if (kind == "lcm") return std::make_unique<transport::LcmMeshSubscriber>(o.lcm_url);
  transport::DdsOptions d;
  d.domain_id = o.dds_domain;
  d.max_mesh_bytes = o.dds_max_mesh_bytes;
  return std::make_unique<transport::DdsMeshSubscriber>(d);
}

// The daemon's publisher for `kind`, behind one call.
struct Publisher {
  std::unique_ptr<transport::LcmPublisher> lcm;
  std::unique_ptr<transport::DdsPublisher> dds;
  std::size_t dds_max_mesh_bytes = 0;
  Publisher(const std::string& kind, const Options& o) : dds_max_mesh_bytes(o.dds_max_mesh_bytes) {
    if (kind == "lcm") {
      lcm = std::make_unique<transport::LcmPublisher>(o.lcm_url);
    } else {
      transport::DdsOptions d;
      d.domain_id = o.dds_domain;
      d.max_mesh_bytes = o.dds_max_mesh_bytes;
      dds = std::make_unique<transport::DdsPublisher>(d);
    }
  }
  void publish(const service::MeshSnapshot& s) { lcm ? lcm->publish_mesh(s) : dds->publish_mesh(s); }
  std::uint64_t failures() const { return lcm ? lcm->counts().failures : dds->counts().failures; }
  // Why a publish of a `message_bytes` message failed: the publishers only
  // count failures, so this tells apart what the bench can tell apart.
  std::string failure_reason(std::size_t message_bytes) const {
    if (lcm) return "lcm_publish of " + std::to_string(message_bytes) + " bytes failed (see LCM's message above)";
    if (message_bytes > dds_max_mesh_bytes)
      return "the serialized mesh (" + std::to_string(message_bytes) + " bytes) is over max_mesh_bytes (" +
             std::to_string(dds_max_mesh_bytes) + ", --dds-max-mesh-bytes)";
    return "DataWriter::write of " + std::to_string(message_bytes) + " bytes failed (see Fast DDS's log above)";
  }
  bool wait_for_reader(double timeout_s) const {
    if (lcm) return true;  // no discovery
    const double until = now_s() + timeout_s;
    while (dds->matched_readers().meshes == 0)
      if (now_s() > until)
        return false;
      else
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return true;
  }
};

std::size_t message_bytes(const std::string& kind, const service::MeshSnapshot& s) {
  if (kind == "lcm") {
    tissue_lcm::tissue::surface_mesh m;
    transport::to_message(s, 1, &m);
    return static_cast<std::size_t>(m.getEncodedSize());
  }
  ::tissue::surface_mesh m;
  transport::to_dds(s, 1, &m);
  return ::tissue::surface_mesh::getCdrSerializedSize(m) + 4;  // + CDR encapsulation header
}

// Receipt time of mesh `id` (its time_s), from the subscriber thread or process.
class Receipts {
 public:
  void put(std::int64_t id, double t_s) {
    std::lock_guard lock(m_);
    got_[id] = t_s;
    cv_.notify_all();
  }
  std::optional<double> wait(std::int64_t id, double timeout_s) {
    std::unique_lock lock(m_);
    if (!cv_.wait_for(lock, std::chrono::duration<double>(timeout_s), [&] { return got_.count(id) > 0; }))
      return std::nullopt;
    return got_[id];
  }
  bool has(std::int64_t id) {
    std::lock_guard lock(m_);
    return got_.count(id) > 0;
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  std::map<std::int64_t, double> got_;
};

struct Result {
  std::vector<double> latency_s, publish_s;
  int lost = 0;
  std::vector<std::int64_t> lost_ids;  // samples not received within lost_after_s
  int late = 0;                        // of those, received after it
  double lost_after_s = 0.0;
  std::uint64_t failures = 0;
  bool ok = true;
  std::string error;
};

// Publishes warmup + samples meshes one at a time; `received` waits for the
// receipt time of mesh `id`, up to r->lost_after_s. Stops at the first failed
// publish: every later one would fail the same way, and each would wait out
// its receipt timeout.
template <typename WaitFn>
void run_samples(Publisher& pub, service::MeshSnapshot& mesh, std::size_t message_bytes, const Options& o,
                 WaitFn received, Result* r) {
  for (int i = 1; i <= o.warmup + o.samples; ++i) {
    mesh.sequence = static_cast<std::uint64_t>(i);
    mesh.sim_time_s = i;  // the id the subscriber reports back
    const std::uint64_t failures_before = pub.failures();
    const double t0 = now_s();
    pub.publish(mesh);
    const double t1 = now_s();
    if (pub.failures() != failures_before) {
      r->ok = false;
      r->error = "publish_mesh() of mesh " + std::to_string(i) + " (" + (i <= o.warmup ? "warm-up" : "sample") +
                 ") failed: " + pub.failure_reason(message_bytes);
      break;
    }
    const std::optional<double> t2 = received(i);
    if (i <= o.warmup) continue;
    if (!t2) {
      ++r->lost;
      r->lost_ids.push_back(i);
      continue;
    }
    r->latency_s.push_back(*t2 - t0);
    r->publish_s.push_back(t1 - t0);
    std::this_thread::sleep_for(std::chrono::milliseconds(5));  // let both sides go idle between samples
  }
  r->failures = pub.failures();
}

Result one_process(const std::string& kind, const Options& o, service::MeshSnapshot mesh, std::size_t bytes) {
  Result r;
  try {
    auto sub = make_subscriber(kind, o);
    Publisher pub(kind, o);
    if (!pub.wait_for_reader(10.0)) throw std::runtime_error("no DDS reader matched within 10 s");
    Receipts receipts;
    std::atomic<bool> done{false};
    std::thread reader([&] {
      while (!done)
        if (auto f = sub->next_frame(0.1)) receipts.put(std::llround(f->time_s), now_s());
    });
    r.lost_after_s = lost_after_s(o, bytes);
    run_samples(
        pub, mesh, bytes, o, [&](std::int64_t id) { return receipts.wait(id, r.lost_after_s); }, &r);
    // A lost last sample may still come: the same allowance once more.
    if (!r.lost_ids.empty()) receipts.wait(r.lost_ids.back(), r.lost_after_s);
    done = true;
    reader.join();
    for (const std::int64_t id : r.lost_ids) r.late += receipts.has(id) ? 1 : 0;
  } catch (const std::exception& e) {
    r.ok = false;
    r.error = e.what();
  }
  return r;
}

struct Receipt {
  std::int64_t id;
  double t_s;
};

Result two_processes(const std::string& kind, const Options& o, service::MeshSnapshot mesh, std::size_t bytes) {
  Result r;
  int to_parent[2];
  if (::pipe(to_parent) != 0) {
    r.ok = false;
    r.error = std::string("pipe failed: ") + std::strerror(errno);
    return r;
  }
  const pid_t child = ::fork();
  if (child < 0) {
    // No child to signal or reap: kill(-1, SIGTERM) below would signal every
    // process this user may signal.
    const int fork_errno = errno;
    ::close(to_parent[0]);
    ::close(to_parent[1]);
    r.ok = false;
    r.error = std::string("fork failed: ") + std::strerror(fork_errno);
    return r;
  }
  if (child == 0) {  // subscriber process: reports (id, receipt time) per frame
    ::close(to_parent[0]);
    try {
      auto sub = make_subscriber(kind, o);
      const Receipt ready{-1, 0.0};
      if (::write(to_parent[1], &ready, sizeof ready) != sizeof ready) ::_exit(1);
      for (;;)
        if (auto f = sub->next_frame(0.1)) {
          const Receipt rc{std::llround(f->time_s), now_s()};
          if (::write(to_parent[1], &rc, sizeof rc) != sizeof rc) ::_exit(0);  // parent gone
        }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "subscriber process: %s\n", e.what());
      ::_exit(1);
    }
  }
  ::close(to_parent[1]);
  const auto read_receipt = [&](double timeout_s) -> std::optional<Receipt> {
    pollfd p{to_parent[0], POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout_s * 1000)) <= 0) return std::nullopt;
    Receipt rc;
    if (::read(to_parent[0], &rc, sizeof rc) != sizeof rc) return std::nullopt;
    return rc;
  };
  try {
    if (!read_receipt(10.0)) throw std::runtime_error("the subscriber process did not start");
    Publisher pub(kind, o);
    if (!pub.wait_for_reader(10.0)) throw std::runtime_error("no DDS reader matched within 10 s");
    r.lost_after_s = lost_after_s(o, bytes);
    const auto count_if_late = [&](std::int64_t id) {
      if (std::find(r.lost_ids.begin(), r.lost_ids.end(), id) != r.lost_ids.end()) ++r.late;
    };
    run_samples(
        pub, mesh, bytes, o,
        [&](std::int64_t id) -> std::optional<double> {
          const double until = now_s() + r.lost_after_s;
          while (now_s() < until)
            if (auto rc = read_receipt(until - now_s())) {
              if (rc->id == id) return rc->t_s;
              count_if_late(rc->id);
            }
          return std::nullopt;
        },
        &r);
    // A lost last sample may still come: the same allowance once more.
    const double until = now_s() + (r.lost_ids.empty() ? 0.0 : r.lost_after_s);
    while (auto rc = read_receipt(std::max(0.0, until - now_s()))) count_if_late(rc->id);
  } catch (const std::exception& e) {
    r.ok = false;
    r.error = e.what();
  }
  // child > 0 here (a failed fork returned above).
  ::kill(child, SIGTERM);
  ::waitpid(child, nullptr, 0);
  ::close(to_parent[0]);
  return r;
}

// The p-quantile of `v` in milliseconds, "-" when there is no sample (every
// mesh lost): a 0.00 there read as a measured latency.
std::string percentile_ms(std::vector<double> v, double p) {
  if (v.empty()) return "-";
  std::sort(v.begin(), v.end());
  const std::size_t i = static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size()))) - 1;
  char text[32];
  std::snprintf(text, sizeof text, "%.2f", 1e3 * v[std::min(i, v.size() - 1)]);
  return text;
}

void print(const std::string& kind, int processes, std::size_t bytes, const Result& r) {
  const char* label = kind == "lcm" ? "LCM" : "DDS";
  if (!r.ok) {
    std::printf("%-4s %d proc  error: %s\n", label, processes, r.error.c_str());
    return;
  }
  std::printf("%-4s %d proc  %9.2f MB %6zu %9s %8s %8s   %8s %8s   %4d %4llu\n", label, processes, bytes / 1e6,
              r.latency_s.size(), percentile_ms(r.latency_s, 0.5).c_str(), percentile_ms(r.latency_s, 0.99).c_str(),
              percentile_ms(r.latency_s, 1.0).c_str(), percentile_ms(r.publish_s, 0.5).c_str(),
              percentile_ms(r.publish_s, 0.99).c_str(), r.lost, static_cast<unsigned long long>(r.failures));
  if (r.lost > 0)
    std::printf(
        "%-11s lost: not received within %.0f ms of publish_mesh() returning (--lost-after-ms); %d of them arrived "
        "later\n",
        "", 1e3 * r.lost_after_s, r.late);
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Sim-to-subscriber latency of the surface mesh over LCM and Fast DDS (loopback only)"};
  app.add_option("--samples", o.samples)->check(CLI::Range(1, 100000));
  app.add_option("--warmup", o.warmup)->check(CLI::Range(0, 10000));
  app.add_option("--triangles", o.triangles)->check(CLI::Range(2, 10000000));
  app.add_option("--transport", o.transport)->check(CLI::IsMember({"lcm", "dds", "both"}));
  app.add_option("--processes", o.processes)->check(CLI::IsMember({"1", "2", "both"}));
  app.add_option("--lcm-url", o.lcm_url);
  app.add_option("--dds-domain", o.dds_domain)->check(CLI::Range(0, 232));
  // The daemon's own bounds for publish.dds.max_mesh_bytes.
  app.add_option("--dds-max-mesh-bytes", o.dds_max_mesh_bytes,
                 "DDS max_mesh_bytes (default: room for the mesh sent, at least the daemon's 8 MiB)")
      ->check(CLI::Range(std::size_t{64} << 10, std::size_t{1} << 30));
  app.add_option("--lost-after-ms", o.lost_after_ms,
                 "a mesh not received within this long counts as lost (default: 250 ms + 50 ms per MB of message)")
      ->check(CLI::Range(1.0, 600000.0));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help prints and succeeds; every other parse problem is a usage error.
    return app.exit(e) == 0 ? 0 : 2;
  }

  const service::MeshSnapshot mesh = grid_mesh(o.triangles);
  const std::size_t dds_bytes = message_bytes("dds", mesh);
  if (o.dds_max_mesh_bytes == 0) o.dds_max_mesh_bytes = std::max(transport::DdsOptions{}.max_mesh_bytes, dds_bytes);
  std::printf(
      "mesh: %zu vertices, %zu triangles; %d samples after %d warm-up, one mesh in flight; DDS max_mesh_bytes %zu\n",
      mesh.vertices_m.size(), mesh.triangles.size(), o.samples, o.warmup, o.dds_max_mesh_bytes);
  std::printf(
      "latency = publish_mesh() called -> subscriber holds the decoded, validated frame;\n"
      "pub. = the publish_mesh() call alone (encode + send)\n\n");
  std::printf("%-11s %12s %6s %9s %8s %8s   %8s %8s   %4s %4s\n", "", "message", "count", "lat. p50", "p99", "max",
              "pub. p50", "p99", "lost", "fail");
  std::printf("%-11s %12s %6s %9s %8s %8s   %8s %8s\n", "", "", "", "ms", "ms", "ms", "ms", "ms");
  for (const std::string kind : {"lcm", "dds"}) {
    if (o.transport != "both" && o.transport != kind) continue;
    const std::size_t bytes = kind == "dds" ? dds_bytes : message_bytes(kind, mesh);
    // The two-process case goes first: it forks, and a child must not
    // inherit middleware threads (LCM's end with its objects; Fast DDS's
    // factory starts on first use, after the last fork).
    if (o.processes != "1") print(kind, 2, bytes, two_processes(kind, o, mesh, bytes));
    if (o.processes != "2") print(kind, 1, bytes, one_process(kind, o, mesh, bytes));
  }
  return 0;
}
