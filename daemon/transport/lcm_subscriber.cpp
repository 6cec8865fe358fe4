#include "transport/lcm_subscriber.hpp"

#include <chrono>
#include <cstring>
#include <lcm/lcm-cpp.hpp>
#include <stdexcept>

#include "transport/lcm_messages.hpp"
#include "util/lcm_url.hpp"

namespace tissue::transport {

namespace {

using Clock = std::chrono::steady_clock;

std::int64_t be_int(const unsigned char* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v = v << 8 | p[i];
  if (bytes == 4) return static_cast<std::int32_t>(static_cast<std::uint32_t>(v));
  return static_cast<std::int64_t>(v);
}

void handle(const lcm::ReceiveBuffer* rbuf, const std::string&, LcmMeshSubscriber* self) {
  self->on_message(rbuf->data, rbuf->data_size);
}

}  // namespace

std::string lcm_mesh_layout_error(const void* data, std::size_t size) {
  const auto* b = static_cast<const unsigned char*>(data);
  // fingerprint 8, time_s 8, sequence_number 8, vertex_count 4, vertex_coordinate_count 4
  std::size_t at = 8 + 8 + 8;
  const auto need = [&](std::size_t bytes) { return size >= at && size - at >= bytes; };
  if (size < 8) return "message of " + std::to_string(size) + " bytes is shorter than an LCM fingerprint";
  if (static_cast<std::uint64_t>(be_int(b, 8)) !=
      static_cast<std::uint64_t>(tissue_lcm::tissue::surface_mesh::getHash()))
    return "fingerprint is not surface_mesh's (another type, or another schema revision)";
  if (!need(8)) return "message of " + std::to_string(size) + " bytes ends inside the vertex counts";
  const std::int64_t nv = be_int(b + at, 4), ncoord = be_int(b + at + 4, 4);
  at += 8;
  if (nv < 0 || ncoord != 3 * nv)
    return "vertex_count " + std::to_string(nv) + " with vertex_coordinate_count " + std::to_string(ncoord) +
           " (must be 3 · vertex_count, vertex_count ≥ 0)";
  const std::size_t vertex_bytes = 4 * static_cast<std::size_t>(ncoord) + static_cast<std::size_t>(nv);
  if (!need(vertex_bytes + 8))
    return "message of " + std::to_string(size) + " bytes is too short for " + std::to_string(nv) + " vertices";
  at += vertex_bytes;
  const std::int64_t nt = be_int(b + at, 4), nindex = be_int(b + at + 4, 4);
  at += 8;
  if (nt < 0 || nindex != 3 * nt)
    return "triangle_count " + std::to_string(nt) + " with triangle_index_count " + std::to_string(nindex) +
           " (must be 3 · triangle_count, triangle_count ≥ 0)";
  const std::size_t rest = 4 * static_cast<std::size_t>(nindex) + 4 * static_cast<std::size_t>(nt) + 48;
  if (!need(rest) || size - at != rest)
    return "message of " + std::to_string(size) + " bytes does not match its counts (" + std::to_string(nv) +
           " vertices, " + std::to_string(nt) + " triangles: " + std::to_string(at + rest) + " bytes)";
  return {};
}

LcmMeshSubscriber::LcmMeshSubscriber(const std::string& url) : url_(url), lcm_(std::make_unique<lcm::LCM>(url)) {
  // A tcpq:// provider that could not connect still reports good() but has
  // no socket: waiting on it aborted the process (FD_SET of -1).
  if (!lcm_->good() || lcm_->getFileno() < 0) throw std::runtime_error("LCM: " + util::lcm_start_failure(url));
  // (The provider's receive side is up, checked above: the subscription
  // cannot fail for want of it.)
  lcm_->subscribeFunction(kSurfaceMeshChannel, &handle, this)->setQueueCapacity(static_cast<int>(kLcmQueueMessages));
}

LcmMeshSubscriber::~LcmMeshSubscriber() = default;

std::string LcmMeshSubscriber::name() const { return name_for(url_); }

std::string LcmMeshSubscriber::name_for(const std::string& url) {
  return std::string("LCM channel ") + kSurfaceMeshChannel + " on " + url;
}

void LcmMeshSubscriber::on_message(const void* data, std::size_t size) {
  ++counts_.received;
  try {
    if (const std::string why = lcm_mesh_layout_error(data, size); !why.empty()) throw MeshRejected("size", why);
    tissue_lcm::tissue::surface_mesh m;
    if (m.decode(data, 0, static_cast<int>(size)) < 0) throw MeshRejected("decode", "LCM decode failed");
    count_sequence(counts_, m.sequence_number);
    x3d::SurfaceFrame f = frame_from_mesh_arrays(
        m.time_s, m.vertex_m,
        {reinterpret_cast<const std::uint8_t*>(m.vertex_refinement_level.data()), m.vertex_refinement_level.size()},
        m.triangle_vertex, m.triangle_strain_energy_density_J_per_m3);
    ++counts_.accepted;
    if (pending_.size() == kMaxPending) {
      pending_.pop_front();
      ++counts_.overflow;
    }
    pending_.push_back(std::move(f));
  } catch (const MeshRejected& e) {
    count_rejection(counts_, e);
  }
}

std::optional<x3d::SurfaceFrame> LcmMeshSubscriber::next_frame(double timeout_s) {
  const auto deadline =
      Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(timeout_s));
  // LCM dispatches one message per handle call: without this, only the
  // message that ended the wait reached pending_, so the queue never held
  // more than one frame, a slow reader got the oldest frames LCM had kept
  // and the newer ones were dropped by LCM, uncounted. Taking everything LCM
  // holds first lets the queue keep the newest and count what it drops.
  // Bounded: a publisher faster than this loop must not keep it here.
  for (std::size_t i = 0; i < kLcmQueueMessages; ++i) {
    const int handled = lcm_->handleTimeout(0);
    if (handled < 0) throw std::runtime_error(name() + ": LCM stopped receiving");
    if (handled == 0) break;
  }
  while (pending_.empty()) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
    if (left <= 0) break;
    // Wakes at least every 100 ms (LCM returns early when a message arrives).
    if (lcm_->handleTimeout(static_cast<int>(std::min<long long>(left, 100))) < 0)
      throw std::runtime_error(name() + ": LCM stopped receiving");
  }
  if (pending_.empty()) return std::nullopt;
  x3d::SurfaceFrame f = std::move(pending_.front());
  pending_.pop_front();
  return f;
}

}  // namespace tissue::transport
