// ReplayDevice: the device positions of a recorded session, played back on
// the steady clock (issue 6): a lab reruns a user's motion against a changed
// scene, or checks that the daemon reproduces a session's forces.
//
// The track is given in memory (the service reads it from the session file
// with record::read_haptic_track before the loop starts), so read() and
// write() only interpolate and never allocate, lock or block. Positions are
// in the device frame: a session records them in the scene frame, and the
// service maps them back with the config's device.offset_m and scale
// (HapticSideImpl), so the hand retraces the recorded path whatever those are.
//
// A session writes a row every haptic tick, so a device slower than the loop
// (a 250 Hz UDP device) is recorded as a pose held for a few rows, then a
// step. Played row to row, the whole motion between two poses would come in
// one tick at several times the speed the loop measured live (it saw each
// pose some time after the last), and the loop would reject the hand as too
// fast. So the hand is played through knots: the rows where a new sample
// came, each step spread over the time since the one before came, which is
// what the loop measured it over live. Sessions of format version 3 and
// later say which rows those are (/haptic/device_fresh); for older ones the
// time is guessed from the position changes, at most kSpreadPeriods of the
// recorded device's sample periods.
//
// With the flags, a gap between two samples in which the live loop lost the
// device (its last row, the last tick without a sample, is more than
// device.limits.device_timeout_s after the sample before) is not a step:
// live the device sent nothing for that long, the loop declared it lost,
// ramped the force out and judged the next sample against the last one it
// accepted over the whole gap (so start() measures that jump too). That is decided on the recorded times, so the same
// gaps are lost at any speed: on the playback gap (gap / speed), every
// sample period of a 250 Hz device was "lost" at a quarter speed. Spread
// over the gap, a minute's outage with a 0.2 m move played as a minute's
// sweep at full force (possibly through the object) and no lost device. So
// read() returns the sample that starts such a gap at the first read within
// one recorded tick of it (once), no sample over the rest of the gap, then
// the next sample, and the loop loses the device exactly as live (a tick
// early, when the first sample was withheld too). Likewise a track that ends more
// than the timeout after its last sample: live the device had stopped, so
// read() returns no sample from there to the end (not a live hand held at
// the last pose). And the rows before the device's first sample: live the
// loop had no device yet (lost from its first tick, no force), so read()
// returns no sample until that sample's time, however short (not a live hand
// held at its pose). A looping replay goes through them again at each wrap:
// the loop holds the last sample it accepted, loses the device once the
// timeout passes, and judges the first sample against that last one over the
// wall time without samples (see loop_wrap_jump_m), as after a lost gap.
// A hole the recorder left (rows it dropped when its ring overflowed, named
// by the session's hole events) is no time without a sample: the device's
// ticks there are unknown, so only the rows present are judged, and a
// stretch lost on them (beside a hole, or around it) still plays as lost,
// from where live it was: the last sample is held for as long as the holes
// before the point where the rows present pass the timeout.
#pragma once

#include <cstdint>
#include <limits>
#include <vector>

#include "haptics/device.hpp"

namespace tissue::haptics {

class ReplayDevice final : public Device {
 public:
  // time_s non-decreasing, the same length as position_m, at least one row.
  // max_speed_m_per_s: device.limits.max_speed_m_per_s (device frame, as
  // position_m): start() refuses a speed that plays the track faster (a gap
  // played as no samples included: the loop judges the sample after it over
  // the gap / speed).
  // device_fresh: the session's /haptic/device_fresh, one 0/1 per row (1:
  // a new device sample came that tick), or empty when the session did not
  // record it (format version < 3: the knots are guessed, see build_knots).
  // With flags, a track without one sample is refused at start() (the
  // device never delivered one: there is no hand to replay).
  // device_timeout_s: device.limits.device_timeout_s; with device_fresh, a
  // gap between samples whose last row is more than this after the sample
  // before plays as no samples, at any speed (see above). Infinite: every
  // gap is spread.
  // rows_after_holes: the rows that follow a hole the recorder left (its
  // ring overflowed: the ticks between row h - 1 and row h are not in the
  // file; record::HapticTrack::rows_after_holes), increasing, each in
  // [1, rows); start() refuses others. With device_fresh, the time between
  // the rows on either side of a hole does not count toward
  // device_timeout_s: only the rows present are judged (see
  // build_knots_from_flags). Without flags no gap is judged lost anyway.
  ReplayDevice(std::vector<double> time_s, std::vector<Vec3> position_m, double speed, bool loop,
               double max_speed_m_per_s = std::numeric_limits<double>::infinity(),
               std::vector<std::uint8_t> device_fresh = {},
               double device_timeout_s = std::numeric_limits<double>::infinity(),
               std::vector<std::size_t> rows_after_holes = {});

  bool start(std::string* error) override;
  void stop() noexcept override {}
  // The position at (now - first read) * speed into the track: linear between
  // the knots (see build_knots), held at the end (or wrapped when looping).
  // Velocity by the slope. False before start(), inside a gap played as no
  // samples (up to, not at, the sample that ends it), before the device's
  // first sample (with flags: up to, not at, its time), and from the last
  // sample on when the track ends more than the device timeout after it.
  bool read(std::int64_t now_ns, DeviceSample* out) noexcept override;
  void write(std::int64_t /*now_ns*/, const Vec3& force_N) noexcept override { last_force_N_ = force_N; }
  const char* name() const noexcept override { return "replay"; }

  double duration_s() const noexcept { return time_s_.back() - time_s_.front(); }
  const Vec3& last_force_N() const noexcept { return last_force_N_; }
  // The recorded device's sample period start() found: the median time
  // between the rows where a new sample came (with device_fresh flags), or
  // between the track's position changes (without); 0 with fewer than two.
  double device_period_s() const noexcept { return device_period_s_; }
  // The jump (device frame) the haptic loop judges at each wrap of a looping
  // replay: from the last sample read() plays before the wrap (the last knot,
  // or the sample before a tail or a gap that ends the track, played as no
  // samples) to the first it plays after it (the first knot, or the device's
  // first sample when the recording began before it), not the track's raw
  // last and first rows (the first may hold the device origin). With
  // loop_wrap_no_sample_s() 0 the jump comes in one tick; otherwise read()
  // gives no sample for that long across the wrap, and the loop judges the
  // first sample after it against the last before it over that time (as the
  // sample after a lost gap). 0 when read() never wraps: not looping, a track
  // of no duration (it holds its one position), or not started; and when it
  // plays no sample before the wrap (a flagged track's only sample on its
  // last row).
  double loop_wrap_jump_m() const noexcept;
  // The wall time (track time / speed) read() gives no sample across each
  // wrap of a looping replay: a tail (or a gap that ends the track) played as
  // no samples, plus the rows before the device's first sample. 0: the wrap
  // jumps in one tick, or read() never wraps (as loop_wrap_jump_m).
  // loop_wrap_warning takes both.
  double loop_wrap_no_sample_s() const noexcept;
  // The gaps played as no samples (see device_timeout_s), after start(),
  // counting a tail after the last sample played so, and the rows before the
  // device's first sample.
  std::size_t lost_gaps() const noexcept;

  // Without device_fresh flags (a session of format version < 3), each step
  // is spread over at most this many device periods. Such a recording
  // cannot tell a late or lost pose from a hand that stood still (the row
  // holds the old pose either way), and live they differ: with a pose lost,
  // UdpDevice::read returned false on the ticks without a datagram and the
  // loop measured the step over the whole gap since the last accepted
  // sample (2 periods for one lost pose, 3 for two in a row); with the hand
  // still, the device re-sent the pose and the loop measured the step over
  // one period. Spreading a gap of up to 3 periods over the whole gap plays
  // up to two lost poses in a row exactly as live, and a still hand's first
  // step no faster than live (over 3 periods instead of 1: slower is safe).
  // Squeezing every gap over 1.5 periods into one period took lost poses for
  // a still hand and played them at up to twice the speed the loop measured.
  static constexpr double kSpreadPeriods = 3.0;

 private:
  // The knots read() interpolates and start() checks the speed of (one rule
  // for both). With device_fresh flags (build_knots_from_flags): every row
  // where a new sample came, so each step is spread over the time since the
  // sample before it, as the loop measured it live (a still hand whose
  // device re-sends its pose is held, and its first step takes one period);
  // see there for the first and last rows. Without (build_knots_by_guess):
  // the first row; every row whose position differs from the row before (the
  // time a new pose came); before such a row, when the old pose was held
  // longer than kSpreadPeriods device periods, a knot holding it until
  // kSpreadPeriods periods before the change (or the last row that still
  // showed it, if earlier), so the hand stands still and then moves over
  // those periods; and the last row. A shorter hold gets no extra knot: the
  // step is spread over the whole gap. Either way a track that has a new
  // position every row keeps every row as a knot and replays row to row.
  // knot_after_gap_[k] marks a knot reached over a gap played as no samples
  // (flags only): not a segment the hand moves along, so read() has no
  // sample before it; start() still measures its speed (the loop judges the
  // knot's sample against the one before the gap over the gap / speed). The
  // device's first sample, when the recording began before it, is such a
  // knot too, after a first knot at its own pose that is no sample (the
  // loop judged it against nothing: start() measures no speed there).
  void build_knots();
  void build_knots_from_flags();
  void build_knots_by_guess();
  // With device_fresh flags: row i brought a new device sample.
  bool is_sample(std::size_t i) const noexcept;
  // Appends a knot; a row at the time of the last knot replaces its position.
  void add_knot(double t_s, const Vec3& p_m, bool after_gap = false);
  std::vector<double> time_s_;
  std::vector<Vec3> position_m_;
  std::vector<std::uint8_t> device_fresh_;  // empty: not recorded
  std::vector<std::size_t> rows_after_holes_;
  double speed_;
  bool loop_;
  double max_speed_m_per_s_;
  double device_timeout_s_;
  std::vector<double> knot_time_s_;  // strictly increasing, from time_s_.front() to time_s_.back()
  std::vector<Vec3> knot_position_m_;
  std::vector<std::uint8_t> knot_after_gap_;  // one per knot
  // The last knot is the track's end after a tail played as no samples (flags
  // only): not a sample, so read() has none there either (see build_knots).
  bool ends_without_sample_ = false;
  // The first knot is the track's start before the device's first sample
  // (flags only): not a sample, and knot 1 (that first sample) is reached
  // over a gap, so read() has none before it (see build_knots_from_flags).
  bool starts_without_sample_ = false;
  // The knots of the last sample read() plays before a wrap and of the first
  // it plays after one (see loop_wrap_jump_m); the first is after the last
  // only for a track whose one sample is on its last row.
  std::size_t last_played_knot() const noexcept;
  std::size_t first_played_knot() const noexcept;
  double device_period_s_ = 0.0;
  std::int64_t start_ns_ = -1;
  std::size_t cursor_ = 0;  // knot at or before the last time read (monotone search)
  // The knot that starts a lost gap (or tail), once read() has handed it to
  // the loop at the first read at or after its time; kNoKnot otherwise. Reset
  // when the track time goes back (a wrap).
  static constexpr std::size_t kNoKnot = static_cast<std::size_t>(-1);
  std::size_t gap_start_given_ = kNoKnot;
  double last_read_s_ = 0.0;   // track time of the last read
  double row_period_s_ = 0.0;  // the recording's tick (median time between rows; flags only)
  Vec3 last_force_N_ = Vec3::Zero();
};

}  // namespace tissue::haptics
