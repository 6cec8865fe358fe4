// Receives `surface_mesh` on the LCM channel TISSUE_SURFACE_MESH as export
// frames (for `tissue x3d --lcm`, `tissue render --lcm`). Single-threaded:
// next_frame() runs LCM's handler loop on the caller's thread.
//
// LCM's generated decode trusts the length fields (it resizes its vectors to
// them before checking the buffer), so every message's layout is checked
// against the received size first (lcm_mesh_layout_error): a hostile or
// corrupt datagram is counted and dropped, never decoded.
#pragma once

#include <cstddef>
#include <deque>
#include <memory>
#include <optional>
#include <string>

#include "transport/mesh_subscriber.hpp"

namespace lcm {
class LCM;
}

namespace tissue::transport {

// The publisher's default URL plus a receive buffer large enough for a
// 2 MB+ mesh (proto/README.md): what subscribers should use.
inline constexpr const char* kLcmSubscribeUrl = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=8388608";

// Empty when `size` bytes at `data` are exactly one encoded surface_mesh
// (fingerprint, non-negative counts, coordinate count 3·V, index count 3·T,
// total size); otherwise the reason.
std::string lcm_mesh_layout_error(const void* data, std::size_t size);

class LcmMeshSubscriber final : public MeshSubscriber {
 public:
  // Throws std::runtime_error naming the URL when LCM cannot start there.
  explicit LcmMeshSubscriber(const std::string& url);
  ~LcmMeshSubscriber() override;
  LcmMeshSubscriber(const LcmMeshSubscriber&) = delete;
  LcmMeshSubscriber& operator=(const LcmMeshSubscriber&) = delete;

  std::string name() const override;
  // name() of a subscriber at `url`, for a message about one not opened
  // (a stop request during the tcpq probe).
  static std::string name_for(const std::string& url);
  std::optional<x3d::SurfaceFrame> next_frame(double timeout_s) override;
  const MeshReceiveCounts& counts() const override { return counts_; }

  // Frames kept between next_frame() calls; older ones are dropped (overflow).
  // Each next_frame() first takes every message LCM has received since the
  // last call, so the queue holds the newest of them.
  static constexpr std::size_t kMaxPending = 64;
  // Messages LCM's own receive thread holds for us between next_frame()
  // calls (LCM's default is 30). LCM drops the NEWEST beyond this, uncounted,
  // so it is larger than kMaxPending: a reader that falls up to this many
  // messages behind still gets the newest kMaxPending. A bound, because each
  // may be a multi-megabyte mesh.
  static constexpr std::size_t kLcmQueueMessages = 2 * kMaxPending;

  // One received message (called by LCM's handler; public for tests that
  // feed bytes without a network).
  void on_message(const void* data, std::size_t size);

 private:
  std::string url_;
  std::unique_ptr<lcm::LCM> lcm_;
  std::deque<x3d::SurfaceFrame> pending_;
  MeshReceiveCounts counts_;
};

}  // namespace tissue::transport
