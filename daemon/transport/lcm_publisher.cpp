#include "transport/lcm_publisher.hpp"

#include <lcm/lcm-cpp.hpp>
#include <stdexcept>

#include "transport/lcm_messages.hpp"
#include "util/lcm_url.hpp"

namespace tissue::transport {

struct LcmPublisher::Buffers {
  tissue_lcm::tissue::surface_mesh mesh;
};

LcmPublisher::LcmPublisher(const std::string& url)
    : url_(url), lcm_(std::make_unique<lcm::LCM>(url)), buffers_(std::make_unique<Buffers>()) {
  // A tcpq:// provider that could not connect still reports good() but has
  // no socket: waiting on it aborted the process (FD_SET of -1).
  if (!lcm_->good() || lcm_->getFileno() < 0)
    throw std::runtime_error("LCM publishing: " + util::lcm_start_failure(url));
}

LcmPublisher::~LcmPublisher() = default;

void LcmPublisher::publish_mesh(const service::MeshSnapshot& snapshot) {
  if (snapshot.sequence == 0 || snapshot.sequence == last_mesh_sequence_) return;
  last_mesh_sequence_ = snapshot.sequence;
  to_message(snapshot, ++mesh_seq_, &buffers_->mesh);
  if (lcm_->publish(kSurfaceMeshChannel, &buffers_->mesh) == 0)
    ++counts_.meshes;
  else
    ++counts_.failures;
}

void LcmPublisher::publish_stats(const service::SimStatus& status) {
  const auto m = to_message(status, ++stats_seq_);
  if (lcm_->publish(kSimStatsChannel, &m) == 0)
    ++counts_.stats;
  else
    ++counts_.failures;
}

void LcmPublisher::publish_haptic(const service::SimStatus& status) {
  const auto m = haptic_message(status, ++haptic_seq_);
  if (lcm_->publish(kHapticStateChannel, &m) == 0)
    ++counts_.haptic_states;
  else
    ++counts_.failures;
}

}  // namespace tissue::transport
