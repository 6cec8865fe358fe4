#include "haptics/loop_wrap.hpp"

#include <cstdio>

namespace tissue::haptics {

std::string loop_wrap_warning(const std::string& key, double jump_m, double max_speed_m_per_s, double rate_hz) {
  const double per_tick_m = max_speed_m_per_s / rate_hz;
  if (!(jump_m > per_tick_m)) return {};
  char text[512];
  std::snprintf(text, sizeof text,
                "%s: the looping track goes from its last point back to its first in one tick, a %.3g m jump "
                "(device frame), more than the %.3g m a tick the haptic loop accepts (device.limits.max_speed_m_per_s "
                "%g at haptics.rate_hz %g): the force ramps out and back in at every wrap (inputs rejected as too "
                "fast, then device lost); end the track where it starts for a seamless loop",
                key.c_str(), jump_m, per_tick_m, max_speed_m_per_s, rate_hz);
  return text;
}

}  // namespace tissue::haptics
