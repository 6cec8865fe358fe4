#include "service/safety_trips.hpp"

#include <algorithm>

namespace tissue::service {

std::optional<std::string> SafetyTrips::update(const haptics::HapticStats& h, std::uint64_t side) {
  if (side != side_ || h.safety_trips < trips_seen_) {
    side_ = side;
    trips_seen_ = stale_seen_ = lost_seen_ = 0;
  }
  // Saturating: the per-kind counters are read one by one (relaxed), so one
  // may lag another for a tick; a wrapped difference read 1.8e19 trips.
  const auto since = [](std::uint64_t now, std::uint64_t seen) { return now > seen ? now - seen : 0; };
  std::optional<std::string> text;
  if (h.safety_trips > trips_seen_) {
    const std::uint64_t stale = since(h.stale_model_trips, stale_seen_), lost = since(h.device_lost_trips, lost_seen_);
    const std::uint64_t all = h.safety_trips - trips_seen_;
    std::string why;
    if (stale > 0) why += std::to_string(stale) + " stale model";
    if (lost > 0) why += (why.empty() ? "" : ", ") + std::to_string(lost) + " device lost";
    if (all > stale + lost) why += (why.empty() ? "" : ", ") + std::to_string(all - stale - lost) + " other";
    text = "haptic safety tripped (" + why + "): the force ramped to zero, and back in once clear";
  }
  trips_seen_ = h.safety_trips;
  stale_seen_ = std::max(stale_seen_, h.stale_model_trips);
  lost_seen_ = std::max(lost_seen_, h.device_lost_trips);
  return text;
}

}  // namespace tissue::service
