// Receives `surface_mesh` on the Fast DDS topic <prefix>surface_mesh as export
// frames (for `tissue x3d --dds`, `tissue render --dds`). The participant uses
// the publisher's transports (dds_participant_qos: loopback UDP + shared
// memory unless !loopback_only), the reader is RELIABLE and TRANSIENT_LOCAL, so it
// gets the publisher's current mesh as soon as it matches (the writer keeps
// the newest one for late joiners) and then every new one it can keep up with.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include "transport/dds_options.hpp"
#include "transport/mesh_subscriber.hpp"

namespace tissue::transport {

class DdsMeshSubscriber final : public MeshSubscriber {
 public:
  // Throws std::runtime_error naming the domain or topic and the reason.
  explicit DdsMeshSubscriber(const DdsOptions& options);
  ~DdsMeshSubscriber() override;
  DdsMeshSubscriber(const DdsMeshSubscriber&) = delete;
  DdsMeshSubscriber& operator=(const DdsMeshSubscriber&) = delete;

  std::string name() const override;
  std::optional<x3d::SurfaceFrame> next_frame(double timeout_s) override;
  const MeshReceiveCounts& counts() const override { return counts_; }

 private:
  DdsOptions options_;
  MeshReceiveCounts counts_;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tissue::transport
