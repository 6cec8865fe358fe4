// What the service says about simulation steps that fail (the sim thread
// keeps the state before each and tries the next): once when they start,
// again when the reason changes, at most once a minute while they go on, and
// once when steps succeed again. A scene that failed every step used to
// write an error event and a stderr line at every status tick (1 Hz by
// default): thousands of identical events an hour in the session file and
// the journal.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "service/sim_thread.hpp"

namespace tissue::service {

struct FailingStepsNotice {
  bool error = false;  // true: an error event (steps failing); false: an info event (they succeed again)
  std::string text;
};

class FailingSteps {
 public:
  // While failing with an unchanged reason, repeat the notice this often.
  static constexpr double kRepeat_s = 60.0;

  // Called at each status tick with the sim's status and a steady time (s).
  // Returns what to record and print, if anything.
  std::optional<FailingStepsNotice> update(const SimStatus& status, double now_s);

 private:
  std::int64_t failed_seen_ = 0;  // failed_steps at the last tick
  std::int64_t failed_said_ = 0;  // failed_steps at the last notice
  std::string reason_said_;
  double said_at_s_ = 0.0;
  bool failing_ = false;
  std::uint64_t generation_ = 0;  // of the runner that was failing
  std::int64_t steps_ = 0;        // its steps at the last tick
};

}  // namespace tissue::service
