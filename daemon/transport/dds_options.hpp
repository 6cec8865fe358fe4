// How a DDS participant of ours is set up: the publisher (DdsPublisher) and
// the subscriber (DdsMeshSubscriber) take the same options, so a subscriber
// built from the daemon's publish.dds.* values matches its publisher.
#pragma once

#include <cstddef>
#include <string>

namespace tissue::transport {

struct DdsOptions {
  int domain_id = 0;                     // 0..232 (Fast DDS's default port mapping)
  std::string topic_prefix = "tissue/";  // topics: <prefix>surface_mesh, <prefix>haptic_state, <prefix>sim_stats
  // true: UDPv4 whitelisted to 127.0.0.1 + shared memory (the publisher;
  // DdsMeshSubscriber never maps shared memory, see dds_subscriber.cpp), this host only;
  // false: UDPv4 on every interface too (a peer on another host).
  bool loopback_only = true;
  // Sizes the shared-memory segment; the publisher does not send larger
  // serialized meshes (counted as failures, and as oversize_meshes).
  std::size_t max_mesh_bytes = 8u << 20;
};

}  // namespace tissue::transport
