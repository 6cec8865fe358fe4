// The Fast DDS mesh subscriber (daemon/transport/dds_subscriber): only what
// runs before a domain participant exists. Everything past that point
// discovers peers over UDP and shared memory, so it is tested where the
// network is private: the LiveNetns / ReplayNetns ctest entries
// (tests/replay), which receive replayed sessions through it. The validation
// of what it receives is frame_from_mesh_arrays (mesh_subscriber_test.cpp).
#include "transport/dds_subscriber.hpp"

#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

namespace tissue::transport {
namespace {

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
