#include "haptics/device.hpp"
#include "haptics/openhaptics_device.hpp"
#include "haptics/sim_device.hpp"
#include "haptics/udp_device.hpp"

namespace tissue::haptics {

std::unique_ptr<Device> make_device(const config::DeviceSpec& spec, std::string* error) {
  if (error) error->clear();
  switch (spec.kind) {
    case config::DeviceSpec::Kind::kNone:
      return nullptr;
    case config::DeviceSpec::Kind::kSim:
      return std::make_unique<SimDevice>(spec.sim);
    case config::DeviceSpec::Kind::kOpenHaptics:
      return std::make_unique<OpenHapticsDevice>(spec.openhaptics);
    case config::DeviceSpec::Kind::kUdp:
      return std::make_unique<UdpDevice>(spec.udp);
    case config::DeviceSpec::Kind::kReplay:
      // The track lives in a session file: the service reads it (record
      // library) and builds a ReplayDevice; the haptics library reads no files.
      if (error) *error = "replay device: built by the service from device.replay.session";
      return nullptr;
  }
  if (error) *error = "device: unknown kind";
  return nullptr;
}

}  // namespace tissue::haptics
