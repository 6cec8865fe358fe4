// Every reader of a session file against damaged copies of a small valid
// session: random byte and bit flips (anywhere, in the metadata, in the raw
// data, in the superblock), 8-byte values that break numbers (NaN, inf, huge
// counts) and truncations. Each reader must either read it, with finite and
// consistent output, or throw its error type naming the file; never crash,
// hang, allocate what the file cannot hold or pass a NaN on. Then the
// semantic damage the fuzzing found a bug for, one test each.
#include <gtest/gtest.h>
#include <hdf5.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "export/frame_source.hpp"
#include "export/x3d.hpp"
#include "record/record_types.hpp"
#include "record/session_layout.hpp"
#include "record/session_tools.hpp"
#include "record_test_support.hpp"
#include "replay/session_replay.hpp"

namespace tissue::record {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;

// Small enough that a few hundred copies take seconds (also under ASan),
// with every group, several frames and strain present.
testing::TestSession small_session() {
  testing::TestSession c;
  c.haptic = 50;
  c.sim = 10;
  c.frames = 4;
  c.events = 2;
  return c;
}

// Where the raw chunk data lies in the file (H5Dget_chunk_info); the rest is
// metadata (superblock, object headers, chunk indices, heaps). Mutations are
// aimed at each, since a flip in 1.3 MB of mostly raw data rarely reaches
// the structures HDF5 parses.
std::vector<bool> raw_bytes_of(const std::string& path, std::size_t size) {
  std::vector<bool> raw(size, false);
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  EXPECT_GE(file, 0) << path;
  for (const DatasetSpec& spec : kDatasets) {
    const hid_t ds = H5Dopen2(file, spec.path, H5P_DEFAULT);
    const hid_t space = H5Dget_space(ds);
    hsize_t chunks = 0;
    EXPECT_GE(H5Dget_num_chunks(ds, space, &chunks), 0) << spec.path;
    for (hsize_t i = 0; i < chunks; ++i) {
      hsize_t offset[2] = {};
      unsigned filter_mask = 0;
      haddr_t address = 0;
      hsize_t bytes = 0;
      EXPECT_GE(H5Dget_chunk_info(ds, space, i, offset, &filter_mask, &address, &bytes), 0) << spec.path;
      for (hsize_t b = address; b < address + bytes && b < size; ++b) raw[b] = true;
    }
    H5Sclose(space);
    H5Dclose(ds);
  }
  H5Fclose(file);
  return raw;
}

// "inf", "-inf" or "nan" as a value in generated text (not inside a word
// such as "info"): a token of those letters between separators.
bool has_non_finite_token(const std::string& text) {
  const auto separator = [&](std::size_t at) {
    return at >= text.size() || std::string_view(" \t\n'\"=,<>-").find(text[at]) != std::string_view::npos;
  };
  for (const std::string_view word : {"inf", "nan", "INF", "NAN", "NaN", "Inf"})
    for (std::size_t at = text.find(word); at != std::string::npos; at = text.find(word, at + 1))
      if ((at == 0 || separator(at - 1)) && separator(at + word.size())) return true;
  return false;
}

struct NullSink final : replay::ReplaySink {
  void mesh(const service::MeshSnapshot&) override {}
  void haptic(const service::SimStatus&) override {}
  void stats(const service::SimStatus&) override {}
};

// Jumps to each due time: a replay of the file runs in no wall time, and its
// span says how long a real one would wait.
struct JumpingClock final : replay::ReplayClock {
  double now = 0.0;
  double now_s() override { return now; }
  bool wait_until(double t_s, const std::atomic<bool>&) override {
    now = std::max(now, t_s);
    return true;
  }
};

bool finite3(const std::array<double, 3>& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

// What each reader gives, checked: empty when it read the file and its
// output is finite and consistent, else why not. Errors of the reader's own
// type must name `named` (the file as the caller knows it).
struct Outcome {
  int read = 0, refused = 0;
};

template <typename Fn>
void expect_reads_or_names_the_file(const char* reader, const std::string& named, const std::string& mutation,
                                    Outcome& outcome, Fn&& fn) {
  SCOPED_TRACE(std::string(reader) + " on " + mutation);
  const auto refused = [&](const std::string& what) {
    EXPECT_NE(what.find("'" + named + "'"), std::string::npos) << what;
    ++outcome.refused;
  };
  try {
    const std::string wrong = fn();
    EXPECT_EQ(wrong, "") << "accepted, with output that is not finite or consistent";
    ++outcome.read;
  } catch (const RecordError& e) {
    refused(e.what());
  } catch (const x3d::SourceError& e) {
    refused(e.what());
  } catch (const replay::ReplayError& e) {
    refused(e.what());
  } catch (const std::exception& e) {
    ADD_FAILURE() << "not the reader's error type: " << e.what();
  }
}

// Runs every reader of session files on `path`; returns whether all of them
// read it. `scratch` holds their outputs (a sidecar, a repaired copy).
bool every_reader(const std::string& path, const std::string& scratch, const std::string& mutation, Outcome& outcome) {
  const int refused_before = outcome.refused;
  expect_reads_or_names_the_file("info", path, mutation, outcome, [&] {
    const SessionInfo info = read_session_info(path);
    EXPECT_FALSE(format_session_info(info).empty());
    return std::isfinite(info.duration_s) && std::abs(info.duration_s) <= kMaxSessionTime_s
               ? ""
               : "duration " + std::to_string(info.duration_s);
  });
  expect_reads_or_names_the_file("list", path, mutation, outcome, [&] {
    // The listing reads every session of the directory: this one is either
    // a session or unreadable with a reason naming it.
    const SessionListing l = list_sessions(fs::path(path).parent_path().string());
    if (l.sessions.size() + l.unreadable.size() != 1) return std::string("not listed once");
    if (!l.unreadable.empty()) throw RecordError(l.unreadable[0].reason);
    return std::string();
  });
  expect_reads_or_names_the_file("rows", path, mutation, outcome, [&] {
    const SessionRows rows = read_session_rows(path);
    for (std::size_t i = 0; i < rows.haptic.size(); ++i) {
      const HapticRow& h = rows.haptic[i];
      if (!std::isfinite(h.time_s) || !finite3(h.device_position_m) || !finite3(h.proxy_position_m) ||
          !finite3(h.force_N) || (i > 0 && h.time_s < rows.haptic[i - 1].time_s))
        return "haptic row " + std::to_string(i);
    }
    for (std::size_t i = 0; i < rows.sim.size(); ++i) {
      const SimRow& s = rows.sim[i];
      // real_time_factor is NaN until measured (by design); otherwise a pace.
      if (!std::isfinite(s.time_s) || !std::isfinite(s.sim_time_s) || !std::isfinite(s.step_ms) ||
          !std::isfinite(s.kinetic_J) || !std::isfinite(s.elastic_J) || std::isinf(s.real_time_factor) ||
          (i > 0 && s.time_s < rows.sim[i - 1].time_s))
        return "sim row " + std::to_string(i);
    }
    return std::string();
  });
  expect_reads_or_names_the_file("track", path, mutation, outcome, [&] {
    const HapticTrack t = read_haptic_track(path);
    for (std::size_t i = 0; i < t.time_s.size(); ++i)
      if (!std::isfinite(t.time_s[i]) || !finite3(t.device_position_m[i]) || !finite3(t.force_N[i]))
        return "track row " + std::to_string(i);
    return std::string();
  });
  expect_reads_or_names_the_file("frames", path, mutation, outcome, [&] {
    const std::unique_ptr<x3d::FrameSource> source = x3d::open_session_source(path);
    std::vector<x3d::SurfaceFrame> drawable;
    for (std::size_t k = 0; k < source->frame_count(); ++k) {
      x3d::SurfaceFrame f = source->read_frame(k);
      if (f.vertices_m.empty() || f.triangles.empty()) continue;
      try {  // what `tissue x3d` and `tissue render` check before drawing (the CLI adds the file)
        x3d::validate_frame(f, source->has_strain(), "frame " + std::to_string(k));
      } catch (const x3d::X3dInputError& e) {
        throw x3d::SourceError(source->name() + ": " + e.what());
      }
      drawable.push_back(std::move(f));
    }
    if (drawable.empty()) return std::string();
    x3d::X3dOptions options;
    if (source->has_strain()) options.colour = x3d::ColourMode::kStrain;
    if (has_non_finite_token(x3d::x3d_snapshot(drawable.back(), options))) return std::string("snapshot");
    if (drawable.size() >= 2 && drawable.front().time_s < drawable.back().time_s &&
        has_non_finite_token(x3d::x3d_animation(drawable, options)))
      return std::string("animation");
    return std::string();
  });
  expect_reads_or_names_the_file("replay", path, mutation, outcome, [&] {
    const std::unique_ptr<x3d::FrameSource> frames = x3d::open_session_source(path);
    const SessionRows rows = replay::read_session_rows(path);
    if (frames->frame_count() == 0 && rows.haptic.empty() && rows.sim.empty()) return std::string();
    replay::ReplayOptions options;
    options.timeline.haptic_rate_hz = 0.0;  // every row
    options.timeline.stats_rate_hz = 0.0;
    NullSink sink;
    JumpingClock clock;
    const std::atomic<bool> stop{false};
    const replay::ReplaySummary sum = replay::replay_session(*frames, rows, options, sink, clock, stop);
    // A real replay waits this long: it must end.
    if (!std::isfinite(sum.session_span_s) || sum.session_span_s > kMaxSessionTime_s)
      return "a replay spanning " + std::to_string(sum.session_span_s) + " s";
    return std::string();
  });
  expect_reads_or_names_the_file("xdmf", path, mutation, outcome, [&] {
    const std::string out = scratch + "/out.xdmf";
    write_xdmf(path, out);
    return has_non_finite_token(testing::slurp(out)) ? std::string("sidecar") : std::string();
  });
  // Repair writes: on a copy, which is then named in its errors.
  const std::string copy = scratch + "/repair.h5";
  fs::copy_file(path, copy, fs::copy_options::overwrite_existing);
  expect_reads_or_names_the_file("repair", copy, mutation, outcome, [&] {
    repair_session(copy);
    return std::string();
  });
  return outcome.refused == refused_before;
}

TEST(SessionReadingFuzz, MutatedSessionsEitherReadConsistentlyOrNameTheFile) {
  TempDir dir;
  const std::string base = testing::write_test_session(dir / "base.h5", small_session());
  const std::string bytes = testing::slurp(base);
  ASSERT_GT(bytes.size(), 4096u);
  const std::vector<bool> raw = raw_bytes_of(base, bytes.size());
  std::vector<std::size_t> metadata, data;  // non-zero bytes of each (zeros are mostly padding)
  for (std::size_t i = 0; i < bytes.size(); ++i)
    if (bytes[i] != 0) (raw[i] ? data : metadata).push_back(i);
  ASSERT_GT(metadata.size(), 1000u);
  ASSERT_GT(data.size(), 1000u);

  // Each mutant alone in its directory (the listing reads the directory).
  fs::create_directory(dir / "m");
  const std::string path = dir / "m/session.h5";
  std::mt19937_64 rng(20261127);
  const auto pick = [&](std::size_t n) { return std::uniform_int_distribution<std::size_t>(0, n - 1)(rng); };
  // Values that break numbers and counts when they land on one.
  const std::uint64_t breakers[] = {0,
                                    1,
                                    ~std::uint64_t{0},
                                    std::uint64_t{1} << 63,
                                    std::uint64_t{1} << 32,
                                    0x7ff8000000000000,   // double NaN
                                    0x7ff0000000000000,   // double +inf
                                    0xfff0000000000000,   // double -inf
                                    0x7fc000007fc00000};  // two float NaNs
  int all_read = 0, some_refused = 0;
  Outcome outcome;
  for (int iteration = 0; iteration < 160; ++iteration) {
    std::string b = bytes;
    std::string mutation = "mutant " + std::to_string(iteration) + ":";
    const int edits = 1 + static_cast<int>(pick(3));
    for (int e = 0; e < edits && !b.empty(); ++e) {
      std::size_t at = 0;
      switch (pick(8)) {
        case 0:  // any byte, any value
          at = pick(b.size());
          b[at] = static_cast<char>(pick(256));
          mutation += " byte@" + std::to_string(at);
          break;
        case 1:  // one bit anywhere
          at = pick(b.size());
          b[at] ^= static_cast<char>(1 << pick(8));
          mutation += " bit@" + std::to_string(at);
          break;
        case 2:  // metadata byte
          at = metadata[pick(metadata.size())];
          if (at < b.size()) b[at] = static_cast<char>(pick(256));
          mutation += " metadata-byte@" + std::to_string(at);
          break;
        case 3:  // metadata bit
          at = metadata[pick(metadata.size())];
          if (at < b.size()) b[at] ^= static_cast<char>(1 << pick(8));
          mutation += " metadata-bit@" + std::to_string(at);
          break;
        case 4:  // raw data byte
          at = data[pick(data.size())];
          if (at < b.size()) b[at] = static_cast<char>(pick(256));
          mutation += " data-byte@" + std::to_string(at);
          break;
        case 5:  // superblock (version 3: 48 bytes) and what follows it
          at = pick(std::min<std::size_t>(b.size(), 96));
          b[at] = static_cast<char>(pick(256));
          mutation += " superblock@" + std::to_string(at);
          break;
        case 6: {  // an 8-byte number-breaker, on a data row or in the metadata
          const bool in_data = pick(2) == 0;
          at = in_data ? data[pick(data.size())] & ~std::size_t{7} : metadata[pick(metadata.size())];
          const std::uint64_t v = breakers[pick(std::size(breakers))];
          for (std::size_t k = 0; k < 8 && at + k < b.size(); ++k) b[at + k] = static_cast<char>((v >> (8 * k)) & 0xff);
          mutation += (in_data ? " data-u64@" : " metadata-u64@") + std::to_string(at) + "=" + std::to_string(v);
          break;
        }
        default:  // truncated
          at = pick(b.size());
          b.resize(at);
          mutation += " truncated@" + std::to_string(at);
          break;
      }
    }
    testing::write_bytes(path, b);
    if (every_reader(path, dir.path(), mutation, outcome))
      ++all_read;
    else
      ++some_refused;
  }
  // Both outcomes occur: the mutations neither always break the file nor
  // never reach what the readers check.
  EXPECT_GT(all_read, 20);
  EXPECT_GT(some_refused, 80);
  EXPECT_GT(outcome.read, 250);  // counted per reader run, 8 a copy
  EXPECT_GT(outcome.refused, 500);
}

// ---------------------------------------------------------------- damage the fuzzing found

// Sets the first-dimension extent of datasets of a closed session.
void set_rows(const std::string& path, const std::vector<DatasetId>& ids, std::uint64_t rows) {
  const hid_t file = testing::open_for_edit(path);
  ASSERT_GE(file, 0) << path;
  for (const DatasetId id : ids) {
    const hid_t ds = H5Dopen2(file, kDatasets[id].path, H5P_DEFAULT);
    ASSERT_GE(ds, 0) << kDatasets[id].path;
    const hsize_t dims[2] = {rows, static_cast<hsize_t>(kDatasets[id].columns)};
    EXPECT_GE(H5Dset_extent(ds, dims), 0) << kDatasets[id].path;
    H5Dclose(ds);
  }
  H5Fclose(file);
}

template <typename Error, typename Fn>
std::string error_of(Fn&& fn) {
  try {
    fn();
  } catch (const Error& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "not the reader's error type: " << e.what();
    return {};
  }
  ADD_FAILURE() << "read without an error";
  return {};
}

// Every haptic column claims 10^10 rows (a damaged extent; chunks never
// written read as fill values). The rows readers allocated a HapticRow per
// claimed row before reading a column (960 GB: std::bad_alloc, which the
// daemon's replay device and `tissue session replay` do not catch) instead
// of refusing rows the file cannot hold.
TEST(SessionReading, AHapticExtentTheFileCannotHoldIsAnErrorNotAnAllocation) {
  TempDir dir;
  const std::string path = testing::write_test_session(dir / "s.h5", small_session());
  set_rows(path,
           {kHapticTime, kHapticDevicePosition, kHapticProxyPosition, kHapticForce, kHapticContact, kHapticModelVersion,
            kHapticDeviceFresh},
           10'000'000'000);
  for (int reader = 0; reader < 2; ++reader) {
    const std::string what = error_of<RecordError>([&] {
      if (reader == 0) read_session_rows(path);
      if (reader == 1) read_haptic_track(path);
    });
    EXPECT_NE(what.find("'" + path + "'"), std::string::npos) << what;
    EXPECT_NE(what.find("/haptic/"), std::string::npos) << what;
    EXPECT_NE(what.find("more than the whole file"), std::string::npos) << what;
  }
}

// The same for /sim.
TEST(SessionReading, ASimExtentTheFileCannotHoldIsAnErrorNotAnAllocation) {
  TempDir dir;
  const std::string path = testing::write_test_session(dir / "s.h5", small_session());
  set_rows(path,
           {kSimTime, kSimSimTime, kSimRealTimeFactor, kSimStepMs, kSimNodes, kSimTets, kSimSprings, kSimRefines,
            kSimMerges, kSimKinetic, kSimElastic},
           10'000'000'000);
  const std::string what = error_of<RecordError>([&] { read_session_rows(path); });
  EXPECT_NE(what.find("'" + path + "'"), std::string::npos) << what;
  EXPECT_NE(what.find("/sim/"), std::string::npos) << what;
  EXPECT_NE(what.find("more than the whole file"), std::string::npos) << what;
}

// A frame time that is finite but beyond any session: replay paced by it
// waited for ever (1e300 s), and frames at -1.7e308 and 1.7e308 s made its
// span inf - inf = NaN. Rows already had this bound; frames now share it.
TEST(SessionReading, AFrameTimeBeyondAnySessionIsAnErrorNotAnEndlessReplay) {
  TempDir dir;
  struct Case {
    std::uint64_t frame;
    double time_s;
  };
  int n = 0;
  for (const Case c : {Case{3, 1e300}, Case{0, -1.7e308}, Case{3, 2 * kMaxSessionTime_s}}) {
    const std::string path = dir / ("t" + std::to_string(++n) + ".h5");
    testing::write_test_session(path, small_session());
    testing::overwrite_f64(path, kDatasets[kMeshFrameTime].path, c.frame, c.time_s);
    SCOPED_TRACE(path);
    const std::string frames = error_of<x3d::SourceError>([&] { x3d::open_session_source(path); });
    const std::string xdmf = error_of<RecordError>([&] { write_xdmf(path, dir / "out.xdmf"); });
    for (const std::string& what : {frames, xdmf}) {
      EXPECT_NE(what.find("'" + path + "'"), std::string::npos) << what;
      EXPECT_NE(what.find("/mesh/frame_time_s[" + std::to_string(c.frame) + "]"), std::string::npos) << what;
      EXPECT_NE(what.find("beyond any session"), std::string::npos) << what;
    }
  }
  // The bound is the rows' own: a frame at it still reads.
  const std::string edge = dir / "edge.h5";
  testing::write_test_session(edge, small_session());
  testing::overwrite_f64(edge, kDatasets[kMeshFrameTime].path, 3, kMaxSessionTime_s);
  EXPECT_EQ(x3d::open_session_source(edge)->frame_time_s(3), kMaxSessionTime_s);
}

// real_time_factor is NaN until the first second has been measured (by
// design, and it reads); an infinite or negative one is damage, and it went
// out to every sim_stats subscriber of a replay.
TEST(SessionReading, ARealTimeFactorIsNaNOrAPaceNeverInfiniteOrNegative) {
  TempDir dir;
  int n = 0;
  for (const double bad : {std::numeric_limits<double>::infinity(), -1.0}) {
    const std::string path = dir / ("rtf" + std::to_string(++n) + ".h5");
    testing::write_test_session(path, small_session());
    testing::overwrite_f64(path, kDatasets[kSimRealTimeFactor].path, 3, bad);
    const std::string what = error_of<RecordError>([&] { read_session_rows(path); });
    EXPECT_NE(what.find("'" + path + "'"), std::string::npos) << what;
    EXPECT_NE(what.find("/sim/real_time_factor"), std::string::npos) << what;
    EXPECT_NE(what.find("row 3"), std::string::npos) << what;
  }
  const std::string fine = dir / "nan.h5";
  testing::write_test_session(fine, small_session());
  testing::overwrite_f64(fine, kDatasets[kSimRealTimeFactor].path, 3, std::numeric_limits<double>::quiet_NaN());
  const SessionRows rows = read_session_rows(fine);
  ASSERT_EQ(rows.sim.size(), 10u);
  EXPECT_TRUE(std::isnan(rows.sim[3].real_time_factor));
  EXPECT_EQ(rows.sim[4].real_time_factor, testing::sim_row(4).real_time_factor);
}

// A frame's strain is all NaN (recorded without it) or all real values. A
// frame that starts with NaN and then holds a value was refused saying the
// value (e.g. 305 J/m^3) "is not a strain energy density (must be finite and
// >= 0)": true of neither. The error now says what is wrong: the mix.
TEST(SessionReading, AFrameMixingRecordedAndMissingStrainSaysSo) {
  TempDir dir;
  const std::string path = testing::write_test_session(dir / "s.h5", small_session());
  // Frame 1 (triangles 6 to 13 of test_frame's 6, 8, 10, 12): its first NaN.
  testing::overwrite_f32(path, kDatasets[kMeshTriangleStrain].path, 6, std::numeric_limits<float>::quiet_NaN());
  const std::unique_ptr<x3d::FrameSource> source = x3d::open_session_source(path);
  EXPECT_NO_THROW(source->read_frame(0));
  const std::string what = error_of<x3d::SourceError>([&] { source->read_frame(1); });
  EXPECT_NE(what.find("'" + path + "'"), std::string::npos) << what;
  EXPECT_NE(what.find("/mesh/triangle_strain_energy_J_per_m3 row 7 (frame 1)"), std::string::npos) << what;
  EXPECT_NE(what.find("row 6 is NaN"), std::string::npos) << what;
  EXPECT_EQ(what.find("must be finite and >= 0"), std::string::npos) << what;
}

// Links of a group with many members live in a fractal heap whose direct
// blocks carry no checksum here: a flipped byte in one makes H5Lexists fail
// (< 0), which the readers took for "no such link" and reported as
// "dataset ... is missing: not a complete tissue session file". It is
// corrupt metadata, and said so with HDF5's reason.
TEST(SessionReading, ADamagedLinkIndexIsCorruptMetadataNotAMissingDataset) {
  TempDir dir;
  const std::string path = testing::write_test_session(dir / "s.h5", small_session());
  std::string bytes = testing::slurp(path);
  // The /mesh group's heap block: "FHDB", version, then the 8-byte address
  // of its heap header (HDF5 file format spec, fractal heap direct block),
  // then the link messages naming the datasets.
  std::size_t block = std::string::npos;
  for (std::size_t at = bytes.find("FHDB"); at != std::string::npos; at = bytes.find("FHDB", at + 4))
    if (bytes.find("vertices_m", at) < at + 64) block = at;
  ASSERT_NE(block, std::string::npos) << "no heap block naming vertices_m";
  bytes[block + 9] = static_cast<char>(bytes[block + 9] ^ 0x5a);  // the heap header's address
  testing::write_bytes(path, bytes);
  const std::string what = error_of<RecordError>([&] { read_session_info(path); });
  EXPECT_NE(what.find("'" + path + "'"), std::string::npos) << what;
  EXPECT_NE(what.find("cannot look up dataset /mesh/"), std::string::npos) << what;
  EXPECT_NE(what.find("corrupt metadata"), std::string::npos) << what;
  EXPECT_EQ(what.find("is missing"), std::string::npos) << what;
}

}  // namespace
}  // namespace tissue::record
