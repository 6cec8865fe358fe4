#include "transport/dds_publisher.hpp"

#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <limits>
#include <stdexcept>

#include "tissue_dds/haptic_statePubSubTypes.h"
#include "tissue_dds/sim_statsPubSubTypes.h"
#include "tissue_dds/surface_meshPubSubTypes.h"
#include "transport/dds_messages.hpp"

namespace tissue::transport {

namespace dds = eprosima::fastdds::dds;

namespace {

constexpr int kMaxDomainId = 232;  // 7400 + 250 * domain + offsets must stay a valid port

dds::DataWriterQos writer_qos(dds::DurabilityQosPolicyKind durability, dds::ReliabilityQosPolicyKind reliability,
                              int depth) {
  dds::DataWriterQos q = dds::DATAWRITER_QOS_DEFAULT;
  q.durability().kind = durability;
  q.reliability().kind = reliability;
  q.history().kind = dds::KEEP_LAST_HISTORY_QOS;
  q.history().depth = depth;
  q.resource_limits().max_instances = 1;
  q.resource_limits().max_samples = depth;
  q.resource_limits().max_samples_per_instance = depth;
  q.resource_limits().allocated_samples = depth;
  q.publish_mode().kind = dds::SYNCHRONOUS_PUBLISH_MODE;
  // fastddsgen bounds unbounded sequences at 100 elements for its size
  // estimate: payloads must grow to the real size (STACK.md).
  q.endpoint().history_memory_policy = eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
  q.data_sharing().off();
  return q;
}

}  // namespace

dds::DomainParticipantQos dds_participant_qos(bool loopback_only, std::size_t max_sample_bytes,
                                              const std::string& name) {
  dds::DomainParticipantQos q = dds::PARTICIPANT_QOS_DEFAULT;
  q.name(name);
  q.transport().use_builtin_transports = false;
  auto shm = std::make_shared<eprosima::fastdds::rtps::SharedMemTransportDescriptor>();
  const std::size_t segment = max_sample_bytes + (1u << 20);
  if (segment > std::numeric_limits<std::uint32_t>::max() / 2)
    throw std::runtime_error("DDS: max sample size " + std::to_string(max_sample_bytes) + " bytes is too large");
  shm->segment_size(static_cast<std::uint32_t>(segment));
  q.transport().user_transports.push_back(shm);
  auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
  if (loopback_only) udp->interfaceWhiteList.emplace_back("127.0.0.1");
  q.transport().user_transports.push_back(udp);
  return q;
}

struct DdsPublisher::Impl {
  dds::DomainParticipant* participant = nullptr;
  dds::Publisher* publisher = nullptr;
  dds::TypeSupport mesh_type{new ::tissue::surface_meshPubSubType()};
  dds::TypeSupport haptic_type{new ::tissue::haptic_statePubSubType()};
  dds::TypeSupport stats_type{new ::tissue::sim_statsPubSubType()};
  dds::Topic *mesh_topic = nullptr, *haptic_topic = nullptr, *stats_topic = nullptr;
  dds::DataWriter *mesh_writer = nullptr, *haptic_writer = nullptr, *stats_writer = nullptr;
  ::tissue::surface_mesh mesh;  // reused message storage

  ~Impl() { close(); }

  // Deletes whatever exists, children before parents.
  void close() {
    if (!participant) return;
    for (dds::DataWriter** w : {&mesh_writer, &haptic_writer, &stats_writer})
      if (*w) {
        publisher->delete_datawriter(*w);
        *w = nullptr;
      }
    if (publisher) participant->delete_publisher(publisher);
    publisher = nullptr;
    for (dds::Topic** t : {&mesh_topic, &haptic_topic, &stats_topic})
      if (*t) {
        participant->delete_topic(*t);
        *t = nullptr;
      }
    // Anything left over (none expected) goes with the participant.
    participant->delete_contained_entities();
    dds::DomainParticipantFactory::get_instance()->delete_participant(participant);
    participant = nullptr;
  }

  void open(const DdsOptions& o) {
    const std::string where = "DDS publishing on domain " + std::to_string(o.domain_id);
    if (o.domain_id < 0 || o.domain_id > kMaxDomainId)
      throw std::runtime_error(where + ": domain id must be within 0.." + std::to_string(kMaxDomainId));
    if (o.max_mesh_bytes < (64u << 10))
      throw std::runtime_error(where + ": max_mesh_bytes " + std::to_string(o.max_mesh_bytes) + " is below 64 KiB");
    participant = dds::DomainParticipantFactory::get_instance()->create_participant(
        static_cast<dds::DomainId_t>(o.domain_id), dds_participant_qos(o.loopback_only, o.max_mesh_bytes, "tissued"));
    if (!participant)
      throw std::runtime_error(where + ": cannot create the domain participant (" +
                               (o.loopback_only ? "UDPv4 on 127.0.0.1" : "UDPv4 on every interface") +
                               " + shared memory; see Fast DDS's log above)");
    for (dds::TypeSupport* type : {&mesh_type, &haptic_type, &stats_type})
      if (type->register_type(participant) != ReturnCode_t::RETCODE_OK)
        throw std::runtime_error(where + ": cannot register type " + type->get_type_name());
    publisher = participant->create_publisher(dds::PUBLISHER_QOS_DEFAULT);
    if (!publisher) throw std::runtime_error(where + ": cannot create the publisher");

    auto topic = [&](const char* name, const dds::TypeSupport& type) {
      const std::string full = o.topic_prefix + name;
      dds::Topic* t = participant->create_topic(full, type.get_type_name(), dds::TOPIC_QOS_DEFAULT);
      if (!t) throw std::runtime_error(where + ": cannot create topic '" + full + "'");
      return t;
    };
    auto writer = [&](dds::Topic* t, const dds::DataWriterQos& qos) {
      dds::DataWriter* w = publisher->create_datawriter(t, qos);
      if (!w) throw std::runtime_error(where + ": cannot create a writer on topic '" + t->get_name() + "'");
      return w;
    };
    mesh_topic = topic(kSurfaceMeshTopic, mesh_type);
    haptic_topic = topic(kHapticStateTopic, haptic_type);
    stats_topic = topic(kSimStatsTopic, stats_type);

    dds::DataWriterQos mesh_qos = writer_qos(dds::TRANSIENT_LOCAL_DURABILITY_QOS, dds::RELIABLE_RELIABILITY_QOS, 1);
    // Repairs of a lost fragment within 0.1 s, not the default 3 s: meshes
    // come at ~30 Hz.
    mesh_qos.reliable_writer_qos().times.heartbeatPeriod = eprosima::fastrtps::Duration_t(0, 100'000'000);
    // Bounds the synchronous send of one mesh (fragmenting into the
    // transports), not a wait for readers: keep-last never waits for acks.
    mesh_qos.reliability().max_blocking_time = eprosima::fastrtps::Duration_t(1, 0);
    mesh_writer = writer(mesh_topic, mesh_qos);
    haptic_writer = writer(haptic_topic, writer_qos(dds::VOLATILE_DURABILITY_QOS, dds::BEST_EFFORT_RELIABILITY_QOS, 1));
    stats_writer = writer(stats_topic, writer_qos(dds::VOLATILE_DURABILITY_QOS, dds::RELIABLE_RELIABILITY_QOS, 10));
  }
};

DdsPublisher::DdsPublisher(const DdsOptions& options) : options_(options), impl_(std::make_unique<Impl>()) {
  impl_->open(options_);  // on a throw, impl_'s destructor deletes what was created
}

DdsPublisher::~DdsPublisher() = default;

void DdsPublisher::publish_mesh(const service::MeshSnapshot& snapshot) {
  if (snapshot.sequence == 0 || snapshot.sequence == last_mesh_sequence_) return;
  last_mesh_sequence_ = snapshot.sequence;
  to_dds(snapshot, mesh_seq_ + 1, &impl_->mesh);
  // + 4: the CDR encapsulation header in front of the data.
  const std::size_t bytes = ::tissue::surface_mesh::getCdrSerializedSize(impl_->mesh) + 4;
  if (bytes > options_.max_mesh_bytes) {
    ++counts_.failures;
    ++counts_.oversize_meshes;
    counts_.last_oversize_bytes = bytes;
    return;
  }
  ++mesh_seq_;
  if (impl_->mesh_writer->write(&impl_->mesh))
    ++counts_.meshes;
  else
    ++counts_.failures;
}

void DdsPublisher::publish_stats(const service::SimStatus& status) {
  ::tissue::sim_stats m = to_dds_stats(status, ++stats_seq_);
  if (impl_->stats_writer->write(&m))
    ++counts_.stats;
  else
    ++counts_.failures;
}

void DdsPublisher::publish_haptic(const service::SimStatus& status) {
  ::tissue::haptic_state m = to_dds_haptic(status, ++haptic_seq_);
  if (impl_->haptic_writer->write(&m))
    ++counts_.haptic_states;
  else
    ++counts_.failures;
}

DdsMatchedReaders DdsPublisher::matched_readers() const {
  auto count = [](dds::DataWriter* w) {
    dds::PublicationMatchedStatus s;
    return w->get_publication_matched_status(s) == ReturnCode_t::RETCODE_OK ? s.current_count : 0;
  };
  return {count(impl_->mesh_writer), count(impl_->haptic_writer), count(impl_->stats_writer)};
}

}  // namespace tissue::transport
