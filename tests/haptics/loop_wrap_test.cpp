#include "haptics/loop_wrap.hpp"

#include <gtest/gtest.h>

namespace tissue::haptics {
namespace {

// A looping track jumps from its last point to its first in one tick: longer
// than max_speed_m_per_s / rate_hz, the loop rejects the jump and the force
// ramps out at each wrap. Said once at start, naming the key and the numbers.
TEST(LoopWrap, AWrapLongerThanATickAllowsIsAWarningNamingTheKeyAndTheNumbers) {
  // 5 m/s at 1 kHz: 5 mm a tick. The review's 0.3 m wrap.
  const std::string w = loop_wrap_warning("device.replay.loop", 0.3, 5.0, 1000.0);
  EXPECT_EQ(w.rfind("device.replay.loop: the looping track goes from its last point back to its first in one tick, "
                    "a 0.3 m jump (device frame), more than the 0.005 m a tick the haptic loop accepts "
                    "(device.limits.max_speed_m_per_s 5 at haptics.rate_hz 1000): the force ramps out and back in "
                    "at every wrap",
                    0),
            0u)
      << w;
  EXPECT_NE(loop_wrap_warning("device.sim.waypoints", 0.006, 5.0, 1000.0).find("device.sim.waypoints: "),
            std::string::npos);
}

TEST(LoopWrap, AWrapWithinATickIsNoWarning) {
  EXPECT_EQ(loop_wrap_warning("device.replay.loop", 0.0, 5.0, 1000.0), "");  // ends where it starts
  EXPECT_EQ(loop_wrap_warning("device.replay.loop", 0.005, 5.0, 1000.0), "");
  EXPECT_EQ(loop_wrap_warning("device.sim.waypoints", 0.3, 5.0, 10.0), "");  // 0.5 m a tick at 10 Hz
}

}  // namespace
}  // namespace tissue::haptics
