// The Fast DDS mesh subscriber (daemon/transport/dds_subscriber): only what
// runs before a domain participant exists, and the type its reader decodes
// samples with, fed serialized payloads directly. Everything past that point
// discovers peers over UDP and shared memory, so it is tested where the
// network is private: the LiveNetns / ReplayNetns ctest entries
// (tests/replay), which receive replayed sessions through it. The validation
// of what it receives is frame_from_mesh_arrays (mesh_subscriber_test.cpp).
#include "transport/dds_subscriber.hpp"

#include <gtest/gtest.h>

#include <fastdds/rtps/common/SerializedPayload.h>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "transport/dds_messages.hpp"
#include "transport/transport_test_support.hpp"

namespace tissue::transport {
namespace {

using eprosima::fastrtps::rtps::SerializedPayload_t;

// A bent strip as the daemon's DDS publisher serializes it.
SerializedPayload_t serialized_mesh(std::int64_t sequence = 7) {
  ::tissue::surface_mesh m;
  to_dds(testing::bent_strip(3), sequence, &m);
  ::tissue::surface_meshPubSubType type;
  SerializedPayload_t payload(type.getSerializedSizeProvider(&m)());
  EXPECT_TRUE(type.serialize(&m, &payload));
  return payload;
}

// A payload libfastcdr cannot decode is refused (false) and counted with
// libfastcdr's reason, never thrown: Fast DDS calls deserialize() from
// take_next_sample() without a try, so the generated type's BadParamException
// for an encapsulation that is not plain CDR ended `tissue x3d --dds`.
TEST(DdsSubscriber, AnUndecodablePayloadIsRefusedAndCountedNotThrown) {
  SurfaceMeshReaderType type;
  ::tissue::surface_mesh m;

  SerializedPayload_t not_plain_cdr = serialized_mesh();
  not_plain_cdr.data[0] = 0x01;  // 01 01 00 00: the first byte must be 0
  not_plain_cdr.data[1] = 0x01;
  bool decoded = true;
  EXPECT_NO_THROW(decoded = type.deserialize(&not_plain_cdr, &m));
  EXPECT_FALSE(decoded);
  EXPECT_TRUE(type.last_call_refused());
  EXPECT_EQ(type.refused(), 1u);
  EXPECT_EQ(type.last_refusal(), "DDS sample of " + std::to_string(not_plain_cdr.length) +
                                     " bytes not decodable: Unexpected non-zero initial byte received in "
                                     "Cdr::read_encapsulation");

  SerializedPayload_t other_representation = serialized_mesh();
  other_representation.data[1] = 0x07;  // 00 07: neither CDR_BE (0) nor CDR_LE (1)
  EXPECT_NO_THROW(decoded = type.deserialize(&other_representation, &m));
  EXPECT_FALSE(decoded);
  EXPECT_EQ(type.refused(), 2u);
  EXPECT_NE(type.last_refusal().find("Unexpected CDR type received in Cdr::read_encapsulation"), std::string::npos)
      << type.last_refusal();

  // Cut inside the vertex array (the generated code's own catch: false).
  SerializedPayload_t truncated = serialized_mesh();
  truncated.length = 40;
  EXPECT_NO_THROW(decoded = type.deserialize(&truncated, &m));
  EXPECT_FALSE(decoded);
  EXPECT_EQ(type.refused(), 3u);
  EXPECT_EQ(type.last_refusal(), "DDS sample of 40 bytes not decodable: it ends inside the mesh");

  // A good payload afterwards decodes as before and is not refused.
  SerializedPayload_t good = serialized_mesh(9);
  EXPECT_TRUE(type.deserialize(&good, &m));
  EXPECT_FALSE(type.last_call_refused());
  EXPECT_EQ(type.refused(), 3u);
  EXPECT_EQ(m.sequence_number(), 9);
  testing::expect_frame_is_snapshot(
      frame_from_mesh_arrays(m.time_s(), m.vertex_m(), m.vertex_refinement_level(), m.triangle_vertex(),
                             m.triangle_strain_energy_density_J_per_m3()),
      testing::bent_strip(3));
}

TEST(DdsSubscriber, ADomainOutsideFastDdsPortMappingIsAnErrorBeforeAnyNetworkUse) {
  for (const int domain : {-1, 233, 100000}) {
    SCOPED_TRACE(domain);
    DdsOptions o;
    o.domain_id = domain;
    try {
      DdsMeshSubscriber sub(o);
      FAIL() << "subscribed on domain " << domain;
    } catch (const std::runtime_error& e) {
      EXPECT_EQ(std::string(e.what()),
                "DDS subscribing on domain " + std::to_string(domain) + ": domain id must be within 0..232");
    }
  }
}

}  // namespace
}  // namespace tissue::transport
