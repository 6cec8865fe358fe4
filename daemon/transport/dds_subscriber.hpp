// Receives `surface_mesh` on the Fast DDS topic <prefix>surface_mesh as export
// frames (for `tissue x3d --dds`, `tissue render --dds`). The participant uses
// the publisher's transports (dds_participant_qos: loopback UDP + shared
// memory unless !loopback_only), the reader is RELIABLE and TRANSIENT_LOCAL, so it
// gets the publisher's current mesh as soon as it matches (the writer keeps
// the newest one for late joiners) and then every new one it can keep up with.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "tissue_dds/surface_meshPubSubTypes.h"
#include "transport/dds_options.hpp"
#include "transport/mesh_subscriber.hpp"

namespace tissue::transport {

// The surface_mesh type the subscriber's reader decodes with: the generated
// one, except that a payload it cannot decode makes deserialize() return
// false and is counted, never an exception. The generated deserializer
// catches only libfastcdr's NotEnoughMemoryException (a sequence running past
// the end), but read_encapsulation throws BadParamException for a header that
// is not plain CDR (a first byte other than 0, or another representation),
// and Fast DDS calls deserialize() from take_next_sample() without a try: one
// such sample on the topic ended `tissue x3d --dds` and lost every frame it
// had collected. Fast DDS drops a sample whose deserialize() is false.
class SurfaceMeshReaderType final : public ::tissue::surface_meshPubSubType {
 public:
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override;

  // Payloads refused so far, the reason for the newest one ("DDS sample of N
  // bytes not decodable: <libfastcdr's message>"), and whether the newest
  // deserialize() call refused its payload.
  std::uint64_t refused() const { return refused_; }
  const std::string& last_refusal() const { return last_refusal_; }
  bool last_call_refused() const { return last_call_refused_; }

 private:
  std::uint64_t refused_ = 0;
  std::string last_refusal_;
  bool last_call_refused_ = false;
};

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
  std::uint64_t refusals_counted_ = 0;  // of the reader type's refused(), already in counts_
  PublisherSequences sequences_;        // gaps counted per writer
  struct Impl;
  // Counts the payloads the reader type refused since the last call as
  // received and rejected ("decode").
  void count_refusals();
  std::unique_ptr<Impl> impl_;
};

}  // namespace tissue::transport
