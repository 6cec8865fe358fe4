// Publishes the daemon's state over LCM (proto/README.md): surface mesh,
// haptic state and sim stats, each on its channel at its configured rate.
// Runs on the service's io thread, fed from the sim thread's snapshot and
// status channels: never on the sim or haptic thread. LCM over UDP multicast
// has no back-pressure, so a slow, crashed or absent subscriber costs nothing.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "service/sim_thread.hpp"

namespace lcm {
class LCM;
}

namespace tissue::transport {

struct LcmPublishCounts {
  std::uint64_t meshes = 0, haptic_states = 0, stats = 0, failures = 0;
};

class LcmPublisher {
 public:
  // Throws std::runtime_error naming the URL and the reason when LCM cannot
  // start there (e.g. "LCM requires a valid multicast route").
  explicit LcmPublisher(const std::string& url);
  ~LcmPublisher();
  LcmPublisher(const LcmPublisher&) = delete;
  LcmPublisher& operator=(const LcmPublisher&) = delete;

  // Each publishes one message; a new mesh only when its sequence is new.
  void publish_mesh(const service::MeshSnapshot& snapshot);
  void publish_stats(const service::SimStatus& status);
  void publish_haptic(const service::SimStatus& status);

  const LcmPublishCounts& counts() const { return counts_; }
  const std::string& url() const { return url_; }

 private:
  std::string url_;
  std::unique_ptr<lcm::LCM> lcm_;
  LcmPublishCounts counts_;
  std::uint64_t last_mesh_sequence_ = 0;
  std::int64_t mesh_seq_ = 0, haptic_seq_ = 0, stats_seq_ = 0;
  struct Buffers;
  std::unique_ptr<Buffers> buffers_;  // reused message storage
};

}  // namespace tissue::transport
