#include "haptics/replay_device.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace tissue::haptics {
namespace {

std::string fmt(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.4g", v);
  return buffer;
}

// The largest speed printed as fmt() prints it (4 significant digits) at
// which the check in start() (peak * speed > max) passes: the refusal's
// advice must be accepted when followed. Rounded to nearest, the printed
// limit could be above the real one and refused in turn.
std::string fmt_speed_at_most(double max_speed_m_per_s, double peak_m_per_s) {
  const double limit = max_speed_m_per_s / peak_m_per_s;
  if (!(limit > 0.0) || !std::isfinite(limit)) return fmt(limit);
  // One unit in the 4th significant digit of the limit.
  const double unit = std::pow(10.0, std::floor(std::log10(limit)) - 3.0);
  // From a unit above the limit (the division rounds too) down a unit while
  // what is printed, read back, is still refused: the largest accepted.
  double speed = (std::floor(limit / unit) + 1.0) * unit;
  for (int step = 0; step < 4; ++step) {
    const std::string text = fmt(speed);
    if (!(peak_m_per_s * std::strtod(text.c_str(), nullptr) > max_speed_m_per_s)) return text;
    speed -= unit;
  }
  return fmt(speed);
}

}  // namespace

ReplayDevice::ReplayDevice(std::vector<double> time_s, std::vector<Vec3> position_m, double speed, bool loop,
                           double max_speed_m_per_s, std::vector<std::uint8_t> device_fresh, double device_timeout_s,
                           std::vector<std::size_t> rows_after_holes)
    : time_s_(std::move(time_s)),
      position_m_(std::move(position_m)),
      device_fresh_(std::move(device_fresh)),
      rows_after_holes_(std::move(rows_after_holes)),
      speed_(speed),
      loop_(loop),
      max_speed_m_per_s_(max_speed_m_per_s),
      device_timeout_s_(device_timeout_s) {}

bool ReplayDevice::start(std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error) *error = "replay device: " + why;
    return false;
  };
  if (time_s_.empty() || time_s_.size() != position_m_.size()) return fail("the track is empty or inconsistent");
  if (!(speed_ > 0.0) || !std::isfinite(speed_)) return fail("speed must be a positive number");
  if (!device_fresh_.empty() && device_fresh_.size() != time_s_.size())
    return fail("the track is inconsistent: " + std::to_string(device_fresh_.size()) + " device_fresh flags for " +
                std::to_string(time_s_.size()) + " rows");
  for (std::size_t k = 0; k < rows_after_holes_.size(); ++k) {
    const std::size_t row = rows_after_holes_[k];
    if (row == 0 || row >= time_s_.size() || (k > 0 && row <= rows_after_holes_[k - 1]))
      return fail("the track's recorder holes are inconsistent: hole " + std::to_string(k) + " is before row " +
                  std::to_string(row) + ", not one of rows 1 to " + std::to_string(time_s_.size() - 1) +
                  " after the hole before it");
  }
  for (std::size_t i = 0; i < time_s_.size(); ++i) {
    if (!std::isfinite(time_s_[i]) || (i > 0 && time_s_[i] < time_s_[i - 1]))
      return fail("track times must be finite and non-decreasing (row " + std::to_string(i) + ")");
    if (!position_m_[i].allFinite()) return fail("non-finite position at row " + std::to_string(i));
  }
  // With the flags, a track without one device sample is a session whose
  // device never delivered any: live the loop never had a hand. Played, the
  // rows' device origin would be a live hand for the whole track.
  if (!device_fresh_.empty()) {
    bool any_sample = false;
    for (std::size_t i = 0; i < time_s_.size() && !any_sample; ++i) any_sample = is_sample(i);
    if (!any_sample) {
      knot_time_s_.clear();  // not started: read() says so
      return fail(
          "the track has no device sample (its /haptic/device_fresh flags are all 0 and its position never "
          "changes): the device delivered none while the session recorded, so there is no hand to replay");
    }
  }
  // The loop rejects a sample faster than device.limits.max_speed_m_per_s as
  // a glitch: a replay sped up past it would lose the hand on the track's
  // fast strokes and ramp the force out mid-replay, with no word why.
  // Measured on the knots read() plays, segment by segment, so a speed is
  // refused exactly when read() would hand the loop a too-fast sample. A gap
  // played as no samples counts too, by the same formula: the loop judges
  // the sample that ends it against the last one it accepted, the sample
  // before the gap, over the wall time since (the gap / speed), whether or
  // not it lost the device meanwhile. Left out, a speed was accepted at
  // which the loop rejects that sample (and the ones after it, until the
  // time since the last accepted one has grown long enough).
  build_knots();
  double peak_m_per_s = 0.0;
  for (std::size_t k = 1; k < knot_time_s_.size(); ++k)
    peak_m_per_s = std::max(
        peak_m_per_s, (knot_position_m_[k] - knot_position_m_[k - 1]).norm() / (knot_time_s_[k] - knot_time_s_[k - 1]));
  if (peak_m_per_s * speed_ > max_speed_m_per_s_) {
    knot_time_s_.clear();  // not started: read() says so
    return fail("device.replay.speed " + fmt(speed_) + " plays the track at up to " + fmt(peak_m_per_s * speed_) +
                " m/s (its peak " + fmt(peak_m_per_s) + " m/s in the device frame, times the speed), above " +
                "device.limits.max_speed_m_per_s " + fmt(max_speed_m_per_s_) +
                ": the haptic loop would reject the hand as a glitch and ramp the force out; use a speed of at most " +
                fmt_speed_at_most(max_speed_m_per_s_, peak_m_per_s) + " for this track");
  }
  start_ns_ = -1;
  cursor_ = 0;
  gap_start_given_ = kNoKnot;
  last_read_s_ = knot_time_s_.front();
  return true;
}

void ReplayDevice::add_knot(double t_s, const Vec3& p_m, bool after_gap) {
  if (knot_time_s_.empty() || t_s > knot_time_s_.back()) {
    knot_time_s_.push_back(t_s);
    knot_position_m_.push_back(p_m);
    knot_after_gap_.push_back(after_gap ? 1 : 0);
  } else {
    knot_position_m_.back() = p_m;  // rows at the same time: the later one holds
  }
}

void ReplayDevice::build_knots() {
  knot_time_s_.clear();
  knot_position_m_.clear();
  knot_after_gap_.clear();
  starts_without_sample_ = false;
  ends_without_sample_ = false;
  if (device_fresh_.empty())
    build_knots_by_guess();
  else
    build_knots_from_flags();
}

namespace {

// The median of `gaps_s` (reordered), 0 when empty.
double median_s(std::vector<double>& gaps_s) {
  if (gaps_s.empty()) return 0.0;
  const auto middle = gaps_s.begin() + static_cast<std::ptrdiff_t>(gaps_s.size() / 2);
  std::nth_element(gaps_s.begin(), middle, gaps_s.end());
  return *middle;
}

}  // namespace

bool ReplayDevice::is_sample(std::size_t i) const noexcept {
  // A row is a new sample when its flag says so, or when its position
  // changed: the recorder drops rows when its ring overflows (a hole,
  // rows_after_holes_), and the flagged row may be among them (the step then
  // spreads from the sample before it, slower than live, never faster).
  return device_fresh_[i] != 0 || (i > 0 && position_m_[i] != position_m_[i - 1]);
}

void ReplayDevice::build_knots_from_flags() {
  const std::size_t rows = time_s_.size();
  std::size_t samples = 0, first = rows;
  for (std::size_t i = 0; i < rows; ++i) {
    if (!is_sample(i)) continue;
    ++samples;
    if (first == rows) first = i;
  }
  // For device_period_s(): the median time between flagged rows.
  std::vector<double> gaps_s;
  gaps_s.reserve(samples);
  bool have_fresh = false;
  double last_fresh_s = 0.0;
  for (std::size_t i = 0; i < rows; ++i) {
    if (device_fresh_[i] == 0) continue;
    if (have_fresh) gaps_s.push_back(time_s_[i] - last_fresh_s);
    have_fresh = true;
    last_fresh_s = time_s_[i];
  }
  device_period_s_ = median_s(gaps_s);
  // The recording's tick (a row per haptic tick): how late after a sample
  // that starts a lost gap a read may still be its tick (read()).
  std::vector<double> rows_s;
  rows_s.reserve(rows);
  for (std::size_t i = 1; i < rows; ++i) rows_s.push_back(time_s_[i] - time_s_[i - 1]);
  row_period_s_ = median_s(rows_s);

  // A knot per sample, the first and last rows, and one held over the holes
  // of each lost gap (at most one per hole).
  const std::size_t knots = samples + 2 + rows_after_holes_.size();
  knot_time_s_.reserve(knots);
  knot_position_m_.reserve(knots);
  knot_after_gap_.reserve(knots);
  // Before the first sample the loop had no hand: it read no sample (the
  // device lost from its first tick, no force), judged that sample against
  // nothing, and the rows hold the device origin. So those rows play as no
  // samples, as a lost gap whatever its length (live the loop had never had
  // the device, timeout or not), up to the first sample: a first knot that
  // is no sample (read() never plays it; at the first sample's pose, so
  // start()'s speed check measures nothing over it, as the loop judged the
  // first sample against nothing), then the first sample, reached over a
  // gap. Not held at the first sample's pose (a live hand the loop never
  // had, with forces), nor a sweep from the origin (too fast to play).
  add_knot(time_s_.front(), first < rows ? position_m_[first] : position_m_.front());
  starts_without_sample_ = first < rows && time_s_[first] > time_s_.front();
  // Each sample a knot: the step to it spreads over the time since the
  // sample before, the time the loop measured it over live (a lost sample
  // is a longer gap; a still hand whose device re-sends its pose is a run
  // of knots at that pose, held until the last one before it moves). A gap
  // in which the live loop lost the device is no step (see the header): the
  // loop declared it lost at a tick more than the device timeout after the
  // last sample, so the gap was lost iff its last row (the last tick without
  // a sample) is past the timeout. That is what happened live, so it holds
  // at any speed: judged on the playback gap (gap / speed), every sample
  // period became a lost gap at slow speeds. The row times are the loop's
  // integer-nanosecond ticks in seconds: differences of them round either
  // way, so a gap of exactly the timeout (not lost live) must not count as
  // past it by a rounding error; the slack is well under a nanosecond.
  constexpr double kRoundingSlackS = 1e-10;
  //
  // A hole the recorder left (rows_after_holes_: its ring overflowed and the
  // ticks between row h - 1 and row h are not in the file) is no time
  // without a sample: what the device sent then is unknown, and a healthy
  // device sent samples all through it. So the time between the rows on
  // either side of a hole does not count toward the timeout; only the rows
  // present are judged, so a loss beside a hole, or around it (the rows
  // present on both sides without a sample for longer than the timeout),
  // still plays as one. Counted, a 50 ms hole in a still hand's 250 Hz track
  // played as a lost device whenever a row without a sample followed it.
  // Within a gap kept, the hole glides with the rest of it (or holds a still
  // hand), as any gap between samples.
  //
  // A lost gap with holes before its loss point (the first row present past
  // the timeout, holes not counted) is held at the last sample for as long
  // as those holes last, then played as no samples: the loop loses the
  // device a timeout after the last sample read() hands over, so it does at
  // that point, as live. Played as no samples from the sample on, the loss
  // began up to a hole's length early, inside the hole, where the device
  // was fine as far as anyone knows. (The loop then judges the sample that
  // ends the gap against the held one over the rest of the gap.)
  if (first < rows) add_knot(time_s_[first], position_m_[first], starts_without_sample_);
  std::size_t hole = 0;  // the next of rows_after_holes_ to pass
  while (hole < rows_after_holes_.size() && rows_after_holes_[hole] <= first) ++hole;
  double hole_s = 0.0;   // time in holes from the last sample to row i
  double held_s = -1.0;  // hole_s at the loss point; < 0 while the gap is kept
  // Ends the gap since the last sample at a knot at row `end`: held over the
  // holes before the loss point when it was lost.
  const auto end_gap = [&](std::size_t end) {
    const bool lost = held_s >= 0.0;
    if (held_s > 0.0) add_knot(knot_time_s_.back() + held_s, knot_position_m_.back());
    add_knot(time_s_[end], position_m_[end], lost);
    hole_s = 0.0;
    held_s = -1.0;
    return lost;
  };
  for (std::size_t i = first + 1; i < rows; ++i) {
    const bool after_hole = hole < rows_after_holes_.size() && rows_after_holes_[hole] == i;
    if (after_hole) ++hole;
    if (is_sample(i)) {
      // (A hole just before a sample is outside the gap measured, which
      // ends at the row before it.)
      end_gap(i);
      continue;
    }
    // The hole before this row is inside the gap up to the next sample. The
    // time counted only grows row by row, so the first row past the timeout
    // is the loss point.
    if (after_hole) hole_s += time_s_[i] - time_s_[i - 1];
    if (held_s < 0.0 && time_s_[i] - knot_time_s_.back() - hole_s > device_timeout_s_ + kRoundingSlackS)
      held_s = hole_s;
  }
  // The rows after the last sample, by the same rule: when the track ends
  // more than the timeout after it (holes not counted), live the device had
  // stopped and the loop lost it for the rest of the track, so that tail
  // plays as no samples (to the end, and held there), not as a live hand
  // held at the last pose.
  if (time_s_.back() > knot_time_s_.back()) ends_without_sample_ = end_gap(rows - 1);
}

void ReplayDevice::build_knots_by_guess() {
  const std::size_t rows = time_s_.size();
  // The device's sample period: the median time between position changes
  // (robust to the long gaps where the hand stood still, and to jitter).
  std::vector<double> gaps_s;
  std::size_t changes = 0;
  for (std::size_t i = 1; i < rows; ++i) changes += position_m_[i] != position_m_[i - 1];
  gaps_s.reserve(changes);
  bool have_change = false;
  double last_change_s = 0.0;
  for (std::size_t i = 1; i < rows; ++i) {
    if (position_m_[i] == position_m_[i - 1]) continue;
    if (have_change) gaps_s.push_back(time_s_[i] - last_change_s);
    have_change = true;
    last_change_s = time_s_[i];
  }
  device_period_s_ = median_s(gaps_s);

  knot_time_s_.reserve(2 * changes + 2);
  knot_position_m_.reserve(2 * changes + 2);
  knot_after_gap_.reserve(2 * changes + 2);
  auto add = [&](double t_s, const Vec3& p_m) { add_knot(t_s, p_m); };
  add(time_s_.front(), position_m_.front());
  double held_since_s = time_s_.front();
  for (std::size_t i = 1; i < rows; ++i) {
    if (position_m_[i] == position_m_[i - 1]) continue;
    // The step is spread over min(gap, kSpreadPeriods periods): a gap of up
    // to that many periods (late or lost poses) over the whole gap, as the
    // loop measured it live. With no period known (fewer than two changes)
    // the hold ends at the last row that showed the old pose: row to row, as
    // a 1 kHz track plays anyway.
    const double spread_s = kSpreadPeriods * device_period_s_;
    if (time_s_[i] - held_since_s > spread_s) {
      const double hold_until_s = std::min(time_s_[i] - spread_s, time_s_[i - 1]);
      if (hold_until_s > knot_time_s_.back()) add(hold_until_s, position_m_[i - 1]);
    }
    add(time_s_[i], position_m_[i]);
    held_since_s = time_s_[i];
  }
  if (time_s_.back() > knot_time_s_.back()) add(time_s_.back(), position_m_.back());
}

std::size_t ReplayDevice::last_played_knot() const noexcept {
  // Ending on a gap played as no samples (or on a tail of rows after the
  // last sample played so), read() gives nothing from the sample before it
  // to the wrap (the last knot itself only at exactly the track's end).
  const std::size_t n = knot_time_s_.size();
  return knot_after_gap_.back() ? n - 2 : n - 1;
}

std::size_t ReplayDevice::first_played_knot() const noexcept { return starts_without_sample_ ? 1 : 0; }

double ReplayDevice::loop_wrap_jump_m() const noexcept {
  // Knot times are strictly increasing, so two knots are a track read() wraps.
  if (!loop_ || knot_time_s_.size() < 2) return 0.0;
  const std::size_t last = last_played_knot(), first = first_played_knot();
  // Nothing played before the wrap (the track's only sample on its last row):
  // the loop has nothing to judge the first sample against.
  if (last < first) return 0.0;
  return (knot_position_m_[last] - knot_position_m_[first]).norm();
}

double ReplayDevice::loop_wrap_no_sample_s() const noexcept {
  if (!loop_ || knot_time_s_.size() < 2) return 0.0;
  const std::size_t last = last_played_knot(), first = first_played_knot();
  if (last < first) return 0.0;
  // Track time from the last sample played before the wrap to its end, then
  // from the start to the first sample played after it; wall time at speed.
  const double track_s = (knot_time_s_.back() - knot_time_s_[last]) + (knot_time_s_[first] - knot_time_s_.front());
  return track_s / speed_;
}

std::size_t ReplayDevice::lost_gaps() const noexcept {
  return static_cast<std::size_t>(std::count(knot_after_gap_.begin(), knot_after_gap_.end(), std::uint8_t{1}));
}

bool ReplayDevice::read(std::int64_t now_ns, DeviceSample* out) noexcept {
  if (knot_time_s_.empty()) return false;  // not started
  if (start_ns_ < 0) start_ns_ = now_ns;
  const double first_s = knot_time_s_.front(), last_s = knot_time_s_.back();
  double t = first_s + speed_ * 1e-9 * static_cast<double>(now_ns - start_ns_);
  const double span = last_s - first_s;
  if (loop_ && span > 0.0 && t > last_s) {
    t = first_s + std::fmod(t - first_s, span);
    if (t < knot_time_s_[cursor_]) cursor_ = 0;
  }
  if (t < last_read_s_) gap_start_given_ = kNoKnot;  // wrapped: the next pass hands its samples over again
  last_read_s_ = t;
  if (t >= last_s) {
    if (ends_without_sample_) return false;  // past a tail played as no samples
    out->position_m = knot_position_m_.back();
    out->velocity_m_per_s.setZero();
    return true;
  }
  const std::size_t n = knot_time_s_.size();
  while (cursor_ + 1 < n && knot_time_s_[cursor_ + 1] <= t) ++cursor_;
  const std::size_t i = cursor_, j = std::min(cursor_ + 1, n - 1);
  // Inside a gap the device sent nothing for longer than its timeout: no
  // sample, so the loop loses the device as it did live. The sample that
  // starts the gap came at its own tick: the first read at or after it,
  // within one recorded tick, gets it (once), so the loop is not a tick
  // short of it.
  if (j > i && knot_after_gap_[j]) {
    // The first knot of a track that starts before the device's first
    // sample is no sample: nothing to hand over.
    if (i == 0 && starts_without_sample_) return false;
    if (gap_start_given_ == i || !(t - knot_time_s_[i] < row_period_s_)) return false;
    gap_start_given_ = i;
    out->position_m = knot_position_m_[i];
    out->velocity_m_per_s.setZero();
    return true;
  }
  const double dt = knot_time_s_[j] - knot_time_s_[i];
  const double u = dt > 0.0 ? std::clamp((t - knot_time_s_[i]) / dt, 0.0, 1.0) : 0.0;
  // From the knot along the step: a held pose (a step of zero) plays exactly.
  out->position_m = knot_position_m_[i] + u * (knot_position_m_[j] - knot_position_m_[i]);
  out->velocity_m_per_s = dt > 0.0 ? Vec3(speed_ * (knot_position_m_[j] - knot_position_m_[i]) / dt) : Vec3::Zero();
  return true;
}

}  // namespace tissue::haptics
