#include "transport/dds_subscriber.hpp"

#include <fastcdr/exceptions/Exception.h>
#include <fastdds/rtps/common/InstanceHandle.h>
#include <fastdds/rtps/common/SerializedPayload.h>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <algorithm>
#include <chrono>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <limits>
#include <stdexcept>

#include "transport/dds_messages.hpp"
#include "transport/dds_publisher.hpp"

namespace tissue::transport {

#if defined(__SANITIZE_ADDRESS__)
// libfastrtps 2.9 (Debian, not built with ASan) deletes a DataReader's
// StatisticsReaderImpl with the wrong size inside RTPSReader::~RTPSReader,
// which ASan reports on every delete_datareader. Every program that reads
// DDS links this file, so the check is switched off here, for ASan builds
// only; ASAN_OPTIONS from the environment still apply on top. Weak: a test
// binary may say the same.
extern "C" __attribute__((weak)) const char* __asan_default_options() { return "new_delete_type_mismatch=0"; }
#endif

namespace dds = eprosima::fastdds::dds;

// A publication handle is the writer's 16-byte GUID.
static_assert(std::tuple_size_v<eprosima::fastrtps::rtps::KeyHash_t> ==
              std::tuple_size_v<PublisherSequences::PublisherId>);

bool SurfaceMeshReaderType::deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) {
  last_call_refused_ = false;
  const auto refuse = [&](const char* why) {
    ++refused_;
    last_call_refused_ = true;
    last_refusal_ = "DDS sample of " + std::to_string(payload->length) + " bytes not decodable: " + why;
    return false;
  };
  try {
    // false: the generated code caught a NotEnoughMemoryException.
    if (!surface_meshPubSubType::deserialize(payload, data)) return refuse("it ends inside the mesh");
    return true;
  } catch (const eprosima::fastcdr::exception::Exception& e) {
    return refuse(e.what());  // BadParamException: not a plain CDR encapsulation
  } catch (const std::exception& e) {
    return refuse(e.what());
  }
}

struct DdsMeshSubscriber::Impl {
  dds::DomainParticipant* participant = nullptr;
  dds::Subscriber* subscriber = nullptr;
  dds::TypeSupport type{new SurfaceMeshReaderType()};
  // What `type` holds (the participant keeps a copy of the same pointer).
  const SurfaceMeshReaderType& reader_type() const { return static_cast<const SurfaceMeshReaderType&>(*type); }
  dds::Topic* topic = nullptr;
  dds::DataReader* reader = nullptr;
  ::tissue::surface_mesh sample;  // reused storage

  ~Impl() {
    if (!participant) return;
    if (reader) subscriber->delete_datareader(reader);
    if (subscriber) participant->delete_subscriber(subscriber);
    if (topic) participant->delete_topic(topic);
    participant->delete_contained_entities();
    dds::DomainParticipantFactory::get_instance()->delete_participant(participant);
  }
};

DdsMeshSubscriber::DdsMeshSubscriber(const DdsOptions& o) : options_(o), impl_(std::make_unique<Impl>()) {
  const std::string where = "DDS subscribing on domain " + std::to_string(o.domain_id);
  if (o.domain_id < 0 || o.domain_id > 232) throw std::runtime_error(where + ": domain id must be within 0..232");
  // UDP only, no shared memory, on the subscriber side. A reader that dies
  // by SIGKILL leaves its shared-memory ports behind; the next subscriber
  // gets the same participant id, hence the same port names, and Fast DDS
  // 2.9.1 recreates those ports, but a publisher that had opened the old
  // ones keeps writing into them (unlinked, nobody listening) whenever the
  // dead listener was not blocked in its wait: every later subscriber on
  // that id then gets nothing until the publisher restarts. UDP leaves no
  // such state. The publisher keeps both transports and uses UDP for us.
  dds::DomainParticipantQos pq = dds_participant_qos(o.loopback_only, o.max_mesh_bytes, "tissue");
  auto& transports = pq.transport().user_transports;
  transports.erase(
      std::remove_if(transports.begin(), transports.end(),
                     [](const auto& t) {
                       return std::dynamic_pointer_cast<eprosima::fastdds::rtps::SharedMemTransportDescriptor>(t) !=
                              nullptr;
                     }),
      transports.end());
  // Room for every fragment of a full-size mesh (the kernel caps it at
  // net.core.rmem_max; reliable repairs cover the rest).
  const std::size_t rcvbuf =
      std::min<std::size_t>(o.max_mesh_bytes + (1u << 20), std::numeric_limits<std::uint32_t>::max() / 2);
  for (auto& t : transports)
    if (auto udp = std::dynamic_pointer_cast<eprosima::fastdds::rtps::UDPv4TransportDescriptor>(t))
      udp->receiveBufferSize = static_cast<std::uint32_t>(rcvbuf);
  impl_->participant =
      dds::DomainParticipantFactory::get_instance()->create_participant(static_cast<dds::DomainId_t>(o.domain_id), pq);
  if (!impl_->participant) throw std::runtime_error(where + ": cannot create the domain participant");
  if (impl_->type.register_type(impl_->participant) != ReturnCode_t::RETCODE_OK)
    throw std::runtime_error(where + ": cannot register type " + impl_->type.get_type_name());
  impl_->subscriber = impl_->participant->create_subscriber(dds::SUBSCRIBER_QOS_DEFAULT);
  if (!impl_->subscriber) throw std::runtime_error(where + ": cannot create the subscriber");
  const std::string topic = o.topic_prefix + kSurfaceMeshTopic;
  impl_->topic = impl_->participant->create_topic(topic, impl_->type.get_type_name(), dds::TOPIC_QOS_DEFAULT);
  if (!impl_->topic) throw std::runtime_error(where + ": cannot create topic '" + topic + "'");
  dds::DataReaderQos q = dds::DATAREADER_QOS_DEFAULT;
  q.reliability().kind = dds::RELIABLE_RELIABILITY_QOS;
  q.durability().kind = dds::TRANSIENT_LOCAL_DURABILITY_QOS;
  q.history().kind = dds::KEEP_LAST_HISTORY_QOS;
  // A few meshes of slack between next_frame() calls (an animation reads
  // each one as it comes); older ones are replaced, never waited for.
  q.history().depth = 8;
  // fastddsgen's size estimate bounds sequences at 100 elements: payloads
  // must grow to the real size (STACK.md), as on the writer.
  q.endpoint().history_memory_policy = eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
  q.data_sharing().off();
  impl_->reader = impl_->subscriber->create_datareader(impl_->topic, q);
  if (!impl_->reader) throw std::runtime_error(where + ": cannot create a reader on topic '" + topic + "'");
}

DdsMeshSubscriber::~DdsMeshSubscriber() = default;

std::string DdsMeshSubscriber::name() const {
  return "DDS topic " + options_.topic_prefix + kSurfaceMeshTopic + " (domain " + std::to_string(options_.domain_id) +
         ")";
}

void DdsMeshSubscriber::count_refusals() {
  const SurfaceMeshReaderType& t = impl_->reader_type();
  for (; refusals_counted_ < t.refused(); ++refusals_counted_) {
    ++counts_.received;
    count_rejection(counts_, MeshRejected("decode", t.last_refusal()));
  }
}

std::optional<x3d::SurfaceFrame> DdsMeshSubscriber::next_frame(double timeout_s) {
  using Clock = std::chrono::steady_clock;
  const auto deadline =
      Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(timeout_s));
  for (;;) {
    dds::SampleInfo info;
    while (impl_->reader->take_next_sample(&impl_->sample, &info) == ReturnCode_t::RETCODE_OK) {
      count_refusals();
      if (!info.valid_data) continue;  // a disposal or unregistration, not a mesh
      // Fast DDS 2.9 skips a sample it could not decode and hands out the
      // next one; should a take ever return the refused one instead, its
      // storage holds no mesh (counted as refused above).
      if (impl_->reader_type().last_call_refused()) continue;
      ++counts_.received;
      const ::tissue::surface_mesh& m = impl_->sample;
      PublisherSequences::PublisherId writer;
      const eprosima::fastrtps::rtps::octet* handle = info.publication_handle.value;
      std::copy(handle, handle + writer.size(), writer.begin());
      sequences_.count(counts_, writer, m.sequence_number());
      try {
        x3d::SurfaceFrame f = frame_from_mesh_arrays(m.time_s(), m.vertex_m(), m.vertex_refinement_level(),
                                                     m.triangle_vertex(), m.triangle_strain_energy_density_J_per_m3());
        ++counts_.accepted;
        return f;
      } catch (const MeshRejected& e) {
        count_rejection(counts_, e);
      }
    }
    count_refusals();  // refused samples a take skipped before finding none
    const auto left = deadline - Clock::now();
    if (left <= Clock::duration::zero()) return std::nullopt;
    // Wakes on a new sample; at most 100 ms at a time.
    const double wait_s = std::min(0.1, std::chrono::duration<double>(left).count());
    impl_->reader->wait_for_unread_message(eprosima::fastrtps::Duration_t(wait_s));
  }
}

}  // namespace tissue::transport
