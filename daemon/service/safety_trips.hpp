// What the service records when the haptic loop's safety ramps the force
// out: one warning event per rise of the loop's trip counters, by kind. The
// counters are cumulative per haptic side, and a restarted side (a reload
// that changes haptics.* or device.limits, a scene with a tool loaded after
// one without) counts from zero again.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "haptics/haptic_loop.hpp"

namespace tissue::service {

class SafetyTrips {
 public:
  // Called with the current side's stats and that side's number (a new
  // number for every side started, never reused: an address is, so a side
  // started where the last one was freed looked like the same side and its
  // counts were taken as the old side's). Returns the event text when trips
  // happened since the last call for this side.
  std::optional<std::string> update(const haptics::HapticStats& stats, std::uint64_t side);

 private:
  std::uint64_t side_ = 0;  // 0: none seen yet (sides are numbered from 1)
  std::uint64_t trips_seen_ = 0, stale_seen_ = 0, lost_seen_ = 0;
};

}  // namespace tissue::service
