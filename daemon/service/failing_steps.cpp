#include "service/failing_steps.hpp"

#include <cmath>

namespace tissue::service {

std::optional<FailingStepsNotice> FailingSteps::update(const SimStatus& s, double now_s) {
  // failed_steps counts over the sim thread's life (every runner); a scene
  // change clears last_error, so failures followed by one before this look
  // have no reason left to give.
  const bool new_failures = s.failed_steps > failed_seen_;
  const bool stepped = s.generation != generation_ || s.steps > steps_;
  failed_seen_ = s.failed_steps;
  generation_ = s.generation;
  steps_ = s.steps;
  if (new_failures) {
    const std::string why = s.last_error[0] != '\0' ? std::string(s.last_error)
                                                    : std::string("the scene was changed since; its reason is gone");
    if (failing_ && why == reason_said_ && now_s - said_at_s_ < kRepeat_s) return std::nullopt;
    const std::int64_t count = s.failed_steps - failed_said_;
    std::string text;
    if (!failing_)
      text = std::to_string(count) + " simulation steps failed since the last status (the state before each is kept): ";
    else if (why != reason_said_)
      text = std::to_string(count) + " more simulation steps failed, now for another reason: ";
    else
      text = std::to_string(count) + " more simulation steps failed in the last " +
             std::to_string(static_cast<long long>(std::lround(now_s - said_at_s_))) + " s (still failing): ";
    failing_ = true;
    failed_said_ = s.failed_steps;
    reason_said_ = why;
    said_at_s_ = now_s;
    return FailingStepsNotice{true, text + why};
  }
  if (!failing_ || !stepped) return std::nullopt;  // paused, or no news
  failing_ = false;
  const std::int64_t unsaid = s.failed_steps - failed_said_;
  failed_said_ = s.failed_steps;
  return FailingStepsNotice{false,
                            "simulation steps succeed again" +
                                (unsaid > 0 ? " (after " + std::to_string(unsaid) + " more failed)" : std::string()) +
                                "; the last failure was: " + reason_said_};
}

}  // namespace tissue::service
