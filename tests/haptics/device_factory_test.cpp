#include <gtest/gtest.h>

#include "haptics/device.hpp"
#include "haptics/openhaptics_device.hpp"

namespace tissue::haptics {
namespace {

TEST(DeviceFactory, BuildsEachKindOrSaysWhyNot) {
  config::DeviceSpec spec;
  std::string error;
  spec.kind = config::DeviceSpec::Kind::kNone;
  EXPECT_EQ(make_device(spec, &error), nullptr);
  EXPECT_TRUE(error.empty());

  spec.kind = config::DeviceSpec::Kind::kSim;
  auto sim = make_device(spec, &error);
  ASSERT_NE(sim, nullptr);
  EXPECT_STREQ(sim->name(), "sim");

  // Built, not started: nothing is bound until start().
  spec.kind = config::DeviceSpec::Kind::kUdp;
  error = "left from before";
  auto udp = make_device(spec, &error);
  ASSERT_NE(udp, nullptr) << error;
  EXPECT_STREQ(udp->name(), "udp");
  EXPECT_TRUE(error.empty()) << error;

  spec.kind = config::DeviceSpec::Kind::kOpenHaptics;
  auto oh = make_device(spec, &error);
  ASSERT_NE(oh, nullptr);
  EXPECT_STREQ(oh->name(), "openhaptics");

  // The haptics library reads no files: a replay device is the service's.
  spec.kind = config::DeviceSpec::Kind::kReplay;
  EXPECT_EQ(make_device(spec, &error), nullptr);
  EXPECT_NE(error.find("replay device"), std::string::npos) << error;
}

TEST(OpenHapticsDevice, MissingVendorLibraryFailsAtStartNamingLibraryAndDlerror) {
  config::OpenHapticsSpec spec;
  spec.library = "libHD_tissued_test_missing.so";
  OpenHapticsDevice device(spec);
  std::string error;
  EXPECT_FALSE(device.start(&error));
  EXPECT_NE(error.find("openhaptics device"), std::string::npos) << error;
  EXPECT_NE(error.find("libHD_tissued_test_missing.so"), std::string::npos) << error;
  EXPECT_NE(error.find("cannot open shared object file"), std::string::npos) << error;  // dlerror's words
  DeviceSample sample;
  EXPECT_FALSE(device.read(0, &sample));  // not started: no samples
  device.write(0, Vec3(1, 0, 0));         // and writing is harmless
}

TEST(OpenHapticsDevice, ALibraryWithoutTheHdApiIsReportedBySymbol) {
  config::OpenHapticsSpec spec;
  spec.library = "libm.so.6";  // loads, but is not OpenHaptics
  OpenHapticsDevice device(spec);
  std::string error;
  EXPECT_FALSE(device.start(&error));
  EXPECT_NE(error.find("lacks HD API symbols"), std::string::npos) << error;
  EXPECT_NE(error.find("hdInitDevice"), std::string::npos) << error;
}

}  // namespace
}  // namespace tissue::haptics
