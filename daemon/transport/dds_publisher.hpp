// Publishes the daemon's state over Fast DDS (proto/README.md): surface mesh,
// haptic state and sim stats, each on its topic at its configured rate. The
// twin of LcmPublisher: same calls, same counts, run on the service's io
// thread from the sim thread's snapshot and status (never on the sim or
// haptic thread).
//
// Transports (both settings replace Fast DDS's builtin ones, whose 512 KB
// shared-memory segment cannot carry a 2 MB mesh, STACK.md):
//   loopback_only = true   UDPv4 whitelisted to 127.0.0.1 + shared memory:
//                          nothing leaves the machine, subscribers on this
//                          host only (the default: safe on any lab network).
//   loopback_only = false  UDPv4 on every interface + shared memory: lab
//                          subscribers on other hosts (discovery multicasts
//                          on every interface).
// The shared-memory segment is sized from max_mesh_bytes (see
// dds_participant_qos). Data sharing is off (the types are unbounded).
//
// QoS per topic (durability, reliability, history):
//   surface_mesh  TRANSIENT_LOCAL, RELIABLE, KEEP_LAST 1. Reliable so a
//                 fragment lost from a 2 MB burst is repaired (best effort
//                 would drop the whole sample), keep-last 1 so the writer
//                 replaces an unacknowledged mesh instead of waiting for a
//                 slow reader: write() never blocks on a subscriber, a slow
//                 one just sees fewer meshes. A reliable writer also matches
//                 best-effort readers. Transient-local: a viewer that joins
//                 late gets the current surface at once.
//   haptic_state  VOLATILE, BEST_EFFORT, KEEP_LAST 1 (≈100 Hz, newest wins).
//   sim_stats     VOLATILE, RELIABLE, KEEP_LAST 10.
// All writers publish synchronously (write() sends before returning).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "service/sim_thread.hpp"
#include "transport/dds_options.hpp"

namespace eprosima::fastdds::dds {
class DomainParticipantQos;
}

namespace tissue::transport {

struct DdsPublishCounts {
  std::uint64_t meshes = 0, haptic_states = 0, stats = 0, failures = 0;
  // Of the failures, meshes not sent because their serialized message was
  // over DdsOptions::max_mesh_bytes, and the size of the newest one (bytes).
  std::uint64_t oversize_meshes = 0;
  std::size_t last_oversize_bytes = 0;
};

// Readers matched right now, per topic (diagnostics, tests).
struct DdsMatchedReaders {
  int meshes = 0, haptic_states = 0, stats = 0;
};

// The participant QoS DdsPublisher uses: builtin transports replaced by
// shared memory and UDPv4 (whitelisted to 127.0.0.1 when loopback_only).
// Samples travel in fragments of at most 64 KB (UDP's limit applies to the
// whole participant); the shared-memory segment is max_sample_bytes + 1 MiB
// (9 MiB by default, in /dev/shm, all of it resident): the fragments of one
// full-size sample plus discovery and the small topics fit in flight. When a
// reader holds older buffers and the segment is full, the send of a fragment
// fails (a reliable reader gets it repaired, a best-effort one loses that
// sample): the writer never waits. Subscribers in tests and tools use the
// same QoS to match the publisher's reach; a subscriber with Fast DDS's
// default QoS (512 KB segment) also receives large meshes, since the data
// sits in the writer's segment.
eprosima::fastdds::dds::DomainParticipantQos dds_participant_qos(bool loopback_only, std::size_t max_sample_bytes,
                                                                 const std::string& name);

class DdsPublisher {
 public:
  // Throws std::runtime_error naming the domain or topic and the reason when
  // an entity cannot be created (everything created so far is deleted).
  explicit DdsPublisher(const DdsOptions& options);
  ~DdsPublisher();  // deletes writers, publisher, topics, then the participant
  DdsPublisher(const DdsPublisher&) = delete;
  DdsPublisher& operator=(const DdsPublisher&) = delete;

  // Each publishes one message; a new mesh only when its sequence is new.
  void publish_mesh(const service::MeshSnapshot& snapshot);
  void publish_stats(const service::SimStatus& status);
  void publish_haptic(const service::SimStatus& status);

  const DdsPublishCounts& counts() const { return counts_; }
  const DdsOptions& options() const { return options_; }
  DdsMatchedReaders matched_readers() const;

 private:
  DdsOptions options_;
  DdsPublishCounts counts_;
  std::uint64_t last_mesh_sequence_ = 0;
  std::int64_t mesh_seq_ = 0, haptic_seq_ = 0, stats_seq_ = 0;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tissue::transport
