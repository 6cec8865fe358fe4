// SessionWriter: what goes in comes out, through the plain HDF5 C API.
#include "record/session_writer.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

#include "record/h5_util.hpp"
#include "record/session_layout.hpp"
#include "record/session_tools.hpp"
#include "record_test_support.hpp"

namespace tissue::record {
namespace {

using testing::TempDir;

SessionMetadata test_metadata() {
  SessionMetadata m;
  m.scene_name = "cantilever";
  m.scene_text = "scene:\n  name: cantilever\n";
  m.config_text = "record:\n  state_dir: /var/lib/tissued\n";
  m.software_version = "tissued 0.1.0-test";
  return m;
}

// Writes haptic/sim/mesh/events in several batches of uneven size (so rows
// cross chunk boundaries) and closes cleanly.
void write_session(const std::string& dir, const std::string& name, std::uint64_t haptic, std::uint64_t sim,
                   std::uint64_t frames, std::uint64_t events) {
  auto w = SessionWriter::open_in(dir, name, test_metadata());
  std::vector<HapticRow> h;
  for (std::uint64_t i = 0; i < haptic; ++i) {
    h.push_back(testing::haptic_row(i));
    if (h.size() == 333 || i + 1 == haptic) {
      w->append_haptic(h);
      h.clear();
      w->flush();
    }
  }
  std::vector<SimRow> s;
  for (std::uint64_t i = 0; i < sim; ++i) s.push_back(testing::sim_row(i));
  w->append_sim(s);
  for (std::uint64_t f = 0; f < frames; ++f) w->append_mesh_frame(testing::test_frame(f).view());
  std::vector<Event> e;
  for (std::uint64_t i = 0; i < events; ++i) e.push_back(testing::event_row(i));
  w->append_events(e);
  EXPECT_EQ(w->group_rows(), (std::array<std::uint64_t, 4>{haptic, sim, frames, events}));
  w->close();
  EXPECT_FALSE(w->failed()) << w->error();
}

TEST(SessionWriter, EveryRowReadsBackEqualWithThePlainCApi) {
  TempDir dir;
  write_session(dir.path(), "s.h5", 2500, 120, 7, 10);
  const hid_t file = H5Fopen((dir / "s.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  EXPECT_EQ(testing::expect_session_content(file, 2500, 120, 7, 10), 0);
  // Units on every dataset.
  for (const DatasetSpec& spec : kDatasets) {
    const hid_t ds = H5Dopen2(file, spec.path, H5P_DEFAULT);
    ASSERT_GE(ds, 0) << spec.path;
    EXPECT_GT(H5Aexists(ds, "units"), 0) << spec.path;
    H5Dclose(ds);
  }
  H5Fclose(file);
}

TEST(SessionWriter, LongEventMessagesAreCutAtAUtf8Boundary) {
  const std::string text = std::string(254, 'a') + "\xc3\xa9" + "tail";  // é straddles byte 255
  const Event e = Event::make(1.0, EventKind::kInfo, text);
  EXPECT_EQ(std::string(e.message), std::string(254, 'a'));
  EXPECT_EQ(std::string(Event::make(0, EventKind::kInfo, "short").message), "short");
}

// Event is a plain struct a producer may fill by hand: a message of 256
// bytes without its NUL is stored cut to 255 and NUL-terminated, as the
// format says (a reader taking the fixed string up to its NUL would read past it).
TEST(SessionWriter, AHandFilledEventMessageWithoutItsNulIsStoredCutTo255Bytes) {
  TempDir dir;
  Event e;
  e.time_s = 2.0;
  e.kind = EventKind::kWarning;
  std::fill(std::begin(e.message), std::end(e.message), 'm');
  {
    auto w = SessionWriter::open_in(dir.path(), "s.h5", test_metadata());
    w->append_events({&e, 1});
    w->close();
  }
  const hid_t file = H5Fopen((dir / "s.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const hid_t ds = H5Dopen2(file, "/events/message", H5P_DEFAULT);
  ASSERT_GE(ds, 0);
  // The stored bytes as they are: read with the file's own type, no conversion.
  const hid_t type = H5Dget_type(ds);
  ASSERT_EQ(H5Tget_size(type), kEventMessageBytes);
  std::array<char, kEventMessageBytes> stored{};
  EXPECT_GE(H5Dread(ds, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, stored.data()), 0);
  H5Tclose(type);
  H5Dclose(ds);
  H5Fclose(file);
  EXPECT_EQ(std::string(stored.data(), kEventMessageBytes - 1), std::string(kEventMessageBytes - 1, 'm'));
  EXPECT_EQ(stored.back(), '\0');
}

// close(duration): "unset, negative or not finite: the wall time" since the
// writer opened, never a NaN or negative duration_s in the file.
TEST(SessionWriter, ACloseGivenANegativeOrNonFiniteDurationRecordsTheWallTime) {
  TempDir dir;
  int n = 0;
  for (const double given : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(), -2.0}) {
    const std::string name = "d" + std::to_string(++n) + ".h5";
    const auto opened = std::chrono::steady_clock::now();
    SessionWriter::open_in(dir.path(), name, test_metadata())->close(given);
    const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - opened).count();
    const hid_t file = H5Fopen((dir / name).c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(file, 0);
    double stored = -1.0;
    EXPECT_TRUE(h5::read_f64_attribute(file, kAttrDurationS, &stored));
    H5Fclose(file);
    EXPECT_TRUE(std::isfinite(stored)) << "given " << given;
    EXPECT_GE(stored, 0.0) << "given " << given;
    EXPECT_LE(stored, wall_s) << "given " << given;
  }
  // A valid duration is stored as given (a batch run's simulated seconds).
  SessionWriter::open_in(dir.path(), "given.h5", test_metadata())->close(12.5);
  EXPECT_DOUBLE_EQ(read_session_info(dir / "given.h5").duration_s, 12.5);
}

TEST(SessionWriter, InfoReportsACleanCloseWithMetadataAndCounts) {
  TempDir dir;
  write_session(dir.path(), "s.h5", 1000, 50, 3, 4);
  const SessionInfo info = read_session_info(dir / "s.h5");
  EXPECT_TRUE(info.closed_cleanly);
  EXPECT_FALSE(info.open_for_write_flag);
  EXPECT_EQ(info.scene_name, "cantilever");
  EXPECT_EQ(info.software_version, "tissued 0.1.0-test");
  EXPECT_FALSE(info.host_name.empty());
  EXPECT_EQ(info.start_time_utc.size(), std::string("2024-01-01T00:00:00.000Z").size()) << info.start_time_utc;
  EXPECT_EQ(info.start_time_utc.back(), 'Z');
  EXPECT_EQ(info.end_time_utc.size(), info.start_time_utc.size()) << info.end_time_utc;
  EXPECT_GE(info.end_time_utc, info.start_time_utc);
  EXPECT_GT(info.duration_s, 0.0);
  EXPECT_EQ(info.rows.haptic_rows, 1000u);
  EXPECT_EQ(info.rows.sim_rows, 50u);
  EXPECT_EQ(info.rows.mesh_frames, 3u);
  EXPECT_EQ(info.rows.events, 4u);
  std::uint64_t v = 0, t = 0;
  for (int f = 0; f < 3; ++f) {
    v += testing::test_frame(f).vertices_m.size();
    t += testing::test_frame(f).triangles.size();
  }
  EXPECT_EQ(info.rows.mesh_vertices, v);
  EXPECT_EQ(info.rows.mesh_triangles, t);
  EXPECT_NE(format_session_info(info).find("closed cleanly"), std::string::npos);
}

TEST(SessionWriter, OpenInRejectsNamesThatLeaveTheStateDirectory) {
  TempDir dir;
  // Also names the daemon would take for its own temporary files (removed at
  // the next start), control characters, blanks and names with no room left
  // for the temporary suffix.
  for (const std::string& bad :
       {std::string(""), std::string("a/b.h5"), std::string("../x.h5"), std::string(".."), std::string("x..h5"),
        std::string("/etc/passwd"), std::string(".evil.creating-999999-0"), std::string(".hidden.h5"),
        std::string("a\nb.h5"), std::string("tab\t.h5"), std::string("   "), std::string("nel\xc2\x85.h5"),
        std::string("ls\xe2\x80\xa8.h5"), std::string("del\x7f.h5"), std::string("bad\xff.h5"),
        std::string(kMaxSessionNameBytes - 2, 'x') + ".h5"}) {
    try {
      SessionWriter::open_in(dir.path(), bad, test_metadata());
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const RecordError& e) {
      EXPECT_NE(std::string(e.what()).find("rejected"), std::string::npos) << e.what();
      // A name that is not clean text is not echoed into the message.
      if (bad.find_first_of("\n\t\x7f\xff\xc2\xe2") != std::string::npos) {
        EXPECT_EQ(std::string(e.what()).find(bad), std::string::npos) << e.what();
      }
    }
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
  // The longest name allowed is recorded.
  const std::string longest = std::string(kMaxSessionNameBytes - 3, 'x') + ".h5";
  SessionWriter::open_in(dir.path(), longest, test_metadata())->close();
  EXPECT_TRUE(std::filesystem::exists(dir / longest));
}

TEST(SessionWriter, NeverOverwritesAndNamesMissingStateDirectories) {
  TempDir dir;
  write_session(dir.path(), "s.h5", 10, 1, 1, 1);
  try {
    SessionWriter::open_in(dir.path(), "s.h5", test_metadata());
    ADD_FAILURE() << "overwrote an existing session";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find("already exists"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(dir / "s.h5"), std::string::npos) << e.what();
  }
  EXPECT_EQ(read_session_info(dir / "s.h5").rows.haptic_rows, 10u);
  try {
    SessionWriter::open_in(dir / "missing", "s.h5", test_metadata());
    ADD_FAILURE() << "accepted a missing state directory";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find(dir / "missing"), std::string::npos) << e.what();
  }
}

// A recorder killed while creating a session leaves its hidden file behind;
// it goes once its process is gone, never while the process lives, and
// nothing else in the directory is touched.
TEST(SessionWriter, AbandonedCreationsOfGoneProcessesAreRemoved) {
  TempDir dir;
  const int gone = tissue::testing::gone_pid();
  write_session(dir.path(), "kept.h5", 10, 1, 1, 1);
  const auto touch = [&](const std::string& name) {
    std::ofstream(dir / name) << "half-made";
    return dir / name;
  };
  const std::string abandoned = touch(".a.h5" + std::string(kCreatingInfix) + std::to_string(gone) + "-0");
  const std::vector<std::string> kept = {
      touch(".b.h5" + std::string(kCreatingInfix) + std::to_string(::getpid()) + "-3"),            // this process
      touch(".c.h5" + std::string(kCreatingInfix) + std::to_string(::getppid()) + "-0"),           // a live one
      touch(".d.h5" + std::string(kCreatingInfix) + "x1-0"),                                       // no pid
      touch(".notes"), touch("e.h5" + std::string(kCreatingInfix) + std::to_string(gone) + "-0"),  // not hidden
      // Digits no pid has (a pid_t holds 9 at most here): not a name the writer makes.
      touch(".f.h5" + std::string(kCreatingInfix) + "12345678901-0"),
      touch(".g.h5" + std::string(kCreatingInfix) + std::string(25, '9') + "-0")};
  EXPECT_EQ(remove_abandoned_creations(dir.path()), std::vector<std::string>{abandoned});
  EXPECT_FALSE(std::filesystem::exists(abandoned));
  for (const std::string& f : kept) EXPECT_TRUE(std::filesystem::exists(f)) << f;
  EXPECT_EQ(read_session_info(dir / "kept.h5").rows.haptic_rows, 10u);
  EXPECT_TRUE(remove_abandoned_creations(dir / "missing").empty());
}

// record.keep_gb removes old files named like the automatic recordings, so
// a client may not give such a name: "auto-20000101-000000.h5" from
// record_start would have been deleted at the next rotation. Any "auto-"
// name is the daemon's; other names pass as validate_session_name lets them.
TEST(SessionWriter, AClientNameStartingLikeTheAutomaticRecordingsIsRefused) {
  TempDir dir;
  for (const std::string& automatic : {std::string("auto-20000101-000000.h5"), std::string("auto-20261101-010000-2.h5"),
                                       std::string("auto-notes.h5")}) {
    try {
      validate_client_session_name(automatic);
      ADD_FAILURE() << "accepted '" << automatic << "'";
    } catch (const RecordError& e) {
      const std::string why = e.what();
      EXPECT_NE(why.find("'" + automatic + "' rejected: it starts with 'auto-'"), std::string::npos) << why;
      EXPECT_NE(why.find("record.keep_gb removes"), std::string::npos) << why;
    }
  }
  // Refused the way validate_session_name refuses, first.
  try {
    validate_client_session_name("auto-x/../y.h5");
    ADD_FAILURE() << "accepted a path";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find("contains '/'"), std::string::npos) << e.what();
  }
  for (const char* fine : {"mine.h5", "automatic.h5", "my-auto-20000101-000000.h5", "Auto-1.h5"})
    EXPECT_NO_THROW(validate_client_session_name(fine)) << fine;
  // The daemon's own name for an automatic file still records.
  SessionWriter::open_in(dir.path(), "auto-20000101-000000.h5", test_metadata())->close();
  EXPECT_TRUE(std::filesystem::exists(dir / "auto-20000101-000000.h5"));
}

// Oldest first is by the time in the name, and only then by "-K": a
// second file of an early second goes before the first file of a later one.
TEST(SessionWriter, AnOlderAutomaticRecordingGoesFirstWhateverItsSuffix) {
  TempDir dir;
  const auto file = [&](const std::string& name) {
    std::ofstream(dir / name) << std::string(100, 'x');
    return dir / name;
  };
  const std::string older = file("auto-20261101-000000-3.h5"), newer = file("auto-20261101-000001.h5"),
                    now = file("auto-20261101-000002.h5");
  EXPECT_EQ(remove_oldest_automatic_recordings(dir.path(), 200, now), std::vector<std::string>{older});
  EXPECT_TRUE(std::filesystem::exists(newer));
}

// record.keep_gb: the oldest automatic recordings go first, until those left
// (the one being written counted, never removed) fit; nothing else is touched.
TEST(SessionWriter, TheOldestAutomaticRecordingsGoFirstAndNothingElse) {
  TempDir dir;
  const auto file = [&](const std::string& name, std::size_t bytes) {
    std::ofstream(dir / name) << std::string(bytes, 'x');
    return dir / name;
  };
  const std::string a = file("auto-20261101-000000.h5", 100), b = file("auto-20261101-010000.h5", 100),
                    c = file("auto-20261101-010000-2.h5", 100), d = file("auto-20261101-010000-10.h5", 100),
                    now = file("auto-20261101-020000.h5", 100);
  const std::vector<std::string> others = {file("session-20261101-000000.h5", 1000), file("auto-notes.txt", 1000),
                                           file("mine.h5", 1000), file("auto-mine.h5", 1000),
                                           file("auto-20261101-000000-x.h5", 1000)};
  std::filesystem::create_directory(dir / "auto-dir.h5");
  EXPECT_TRUE(remove_oldest_automatic_recordings(dir.path(), 500, now).empty()) << "500 B fit";
  // Oldest first: by time, then "-K" numerically (by name, "-10" and "-2" sort before the first).
  EXPECT_EQ(remove_oldest_automatic_recordings(dir.path(), 250, now), (std::vector<std::string>{a, b, c}));
  EXPECT_EQ(remove_oldest_automatic_recordings(dir.path(), 0, now), (std::vector<std::string>{d}));
  EXPECT_TRUE(std::filesystem::exists(now)) << "the file being written stays, whatever the budget";
  for (const std::string& f : others) EXPECT_TRUE(std::filesystem::exists(f)) << f;
  EXPECT_TRUE(std::filesystem::is_directory(dir / "auto-dir.h5"));
  EXPECT_TRUE(remove_oldest_automatic_recordings(dir / "missing", 0, "").empty());
}

TEST(SessionWriter, InvalidMeshFramesAreRefusedWithoutTouchingTheFile) {
  TempDir dir;
  auto w = SessionWriter::open_in(dir.path(), "s.h5", test_metadata());
  testing::TestFrame bad_index = testing::test_frame(0);
  bad_index.triangles[1][2] = static_cast<std::uint32_t>(bad_index.vertices_m.size());
  EXPECT_THROW(w->append_mesh_frame(bad_index.view()), std::invalid_argument);
  testing::TestFrame bad_levels = testing::test_frame(0);
  bad_levels.vertex_level.pop_back();
  EXPECT_THROW(w->append_mesh_frame(bad_levels.view()), std::invalid_argument);
  testing::TestFrame bad_strain_count = testing::test_frame(0);
  bad_strain_count.triangle_strain_energy_J_per_m3.pop_back();
  EXPECT_THROW(w->append_mesh_frame(bad_strain_count.view()), std::invalid_argument);
  // NaN means "not computed" in the file: a computed NaN, an infinity or a
  // negative energy must not be stored as if it were data.
  for (const float e : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(), -1.0f}) {
    testing::TestFrame bad_strain = testing::test_frame(0);
    bad_strain.triangle_strain_energy_J_per_m3[2] = e;
    EXPECT_THROW(w->append_mesh_frame(bad_strain.view()), std::invalid_argument) << e;
  }
  // Vertices are stored as float32: a coordinate beyond its range became
  // inf in the file, silently (and the double-to-float conversion of such a
  // value is undefined behaviour).
  for (const double x :
       {1e39, -1e39, std::numeric_limits<double>::quiet_NaN(), -std::numeric_limits<double>::infinity()}) {
    testing::TestFrame bad_vertex = testing::test_frame(0);
    bad_vertex.vertices_m[3][1] = x;
    try {
      w->append_mesh_frame(bad_vertex.view());
      ADD_FAILURE() << "stored vertex coordinate " << x;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("vertex 3 coordinate 1"), std::string::npos) << e.what();
    }
  }
  w->append_mesh_frame(testing::test_frame(0).view());
  w->close();
  const hid_t file = H5Fopen((dir / "s.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  EXPECT_EQ(testing::expect_session_content(file, 0, 0, 1, 0), 0);
  H5Fclose(file);
}

TEST(SessionWriter, StrainIsStoredPerTriangleAndAFrameWithoutItHoldsNaN) {
  TempDir dir;
  auto w = SessionWriter::open_in(dir.path(), "s.h5", test_metadata());
  const testing::TestFrame with = testing::test_frame(1);
  testing::TestFrame without = testing::test_frame(2);
  without.triangle_strain_energy_J_per_m3.clear();
  w->append_mesh_frame(with.view());
  w->append_mesh_frame(without.view());
  w->close();
  const hid_t file = H5Fopen((dir / "s.h5").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const auto strain = testing::read_f32(file, "/mesh/triangle_strain_energy_J_per_m3");
  const auto tris = testing::read_i32(file, "/mesh/triangles");
  ASSERT_EQ(3 * strain.size(), tris.size()) << "one strain row per triangle row";
  ASSERT_EQ(strain.size(), with.triangles.size() + without.triangles.size());
  for (std::size_t t = 0; t < with.triangles.size(); ++t)
    EXPECT_EQ(strain[t], with.triangle_strain_energy_J_per_m3[t]) << t;
  for (std::size_t t = with.triangles.size(); t < strain.size(); ++t) EXPECT_TRUE(std::isnan(strain[t])) << t;
  H5Fclose(file);
  const SessionInfo info = read_session_info(dir / "s.h5");
  EXPECT_EQ(info.format_version, kSessionFormatVersion);
  EXPECT_TRUE(info.has_strain);
}

// flush() and close() sync the file to disk (fdatasync on HDF5's own
// descriptor): H5Dflush and H5Fclose only hand the data to the page cache,
// which a power cut loses, so "a crash loses at most one flush interval" held
// for a process crash only. The sync at close comes after the file is closed,
// so the clean-close mark and the cleared open-for-write flags are on disk
// too.
TEST(SessionWriter, EachFlushAndTheCloseSyncTheFileToDisk) {
  TempDir dir;
  const std::string path = dir / "s.h5";
  auto w = SessionWriter::open_in(dir.path(), "s.h5", test_metadata());
  struct stat session {};
  ASSERT_EQ(::stat(path.c_str(), &session), 0);
  int syncs = 0;
  bool closed_at_last_sync = false;
  w->set_sync_for_testing([&](int fd) {
    ++syncs;
    struct stat synced {};
    EXPECT_EQ(::fstat(fd, &synced), 0);
    EXPECT_EQ(synced.st_ino, session.st_ino) << "synced a descriptor that is not the session file";
    EXPECT_EQ(synced.st_dev, session.st_dev);
    // Readable as closed cleanly here only once the close has written the
    // mark and closed the file.
    const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    std::int64_t closed_cleanly = 0;
    closed_at_last_sync =
        file >= 0 && h5::read_i64_attribute(file, kAttrClosedCleanly, &closed_cleanly) && closed_cleanly == 1;
    if (file >= 0) H5Fclose(file);
    return ::fdatasync(fd) == 0 ? 0 : errno;
  });
  const std::vector<HapticRow> rows{testing::haptic_row(0), testing::haptic_row(1)};
  w->append_haptic(rows);
  w->flush();
  EXPECT_EQ(syncs, 1) << "a flush that wrote rows syncs once";
  w->append_mesh_frame(testing::test_frame(0).view());
  w->flush();
  EXPECT_EQ(syncs, 2);
  EXPECT_FALSE(closed_at_last_sync);
  w->close();
  EXPECT_EQ(syncs, 3) << "the close syncs once";
  EXPECT_TRUE(closed_at_last_sync) << "the close synced before the file was closed with its mark";
  EXPECT_FALSE(w->failed()) << w->error();
}

// A failed sync is a write error (the data may not be on disk): the writer
// fails naming the file and the reason, as for a full disk.
TEST(SessionWriter, AFailedSyncFailsTheWriterNamingTheFileAndTheReason) {
  TempDir dir;
  for (const bool at_close : {false, true}) {
    const std::string name = at_close ? "close.h5" : "flush.h5";
    auto w = SessionWriter::open_in(dir.path(), name, test_metadata());
    w->set_sync_for_testing([](int) { return EIO; });
    const std::vector<HapticRow> rows{testing::haptic_row(0)};
    w->append_haptic(rows);
    try {
      if (at_close)
        w->close();
      else
        w->flush();
      ADD_FAILURE() << name << ": a failed sync went unreported";
    } catch (const RecordError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(dir / name), std::string::npos) << what;
      EXPECT_NE(what.find("fdatasync"), std::string::npos) << what;
      EXPECT_NE(what.find(std::strerror(EIO)), std::string::npos) << what;
    }
    EXPECT_TRUE(w->failed()) << name;
  }
}

// docs/session-format.md's Python example, pasted as it stands (with only the
// file name changed), reads frame 0 of a session: what it reads is the frame
// written.
TEST(SessionWriter, TheFormatDocsPythonExampleReadsAFrame) {
  if (!testing::have_system_h5py()) GTEST_SKIP() << "/usr/bin/python3 has no h5py: the docs' example needs it";
  TempDir dir;
  const std::string path = testing::write_test_session(dir / "session.h5");
  const std::string doc = testing::slurp(std::string(TISSUE_SOURCE_DIR) + "/docs/session-format.md");
  const std::string heading = "in Python:\n\n```python\n";
  const std::size_t begin = doc.find(heading);
  ASSERT_NE(begin, std::string::npos) << "docs/session-format.md has no Python example";
  const std::size_t code = begin + heading.size();
  const std::size_t end = doc.find("```", code);
  ASSERT_NE(end, std::string::npos);
  std::string script = doc.substr(code, end - code);
  const std::size_t name = script.find("\"session.h5\"");
  ASSERT_NE(name, std::string::npos) << script;
  script.replace(name, 12, "sys.argv[1]");
  script = "import sys\n" + script +
           "print('%d %d %.6f %d' % (len(vertices), len(triangles), float(vertices.sum()), len(strain)))\n"
           "print('%d of %d ticks fresh' % (int(fresh.sum()), len(fresh)))\n";
  const testing::RunResult py =
      testing::run("/usr/bin/python3 -c " + testing::quote(script) + " " + testing::quote(path), dir);
  ASSERT_EQ(py.exit_code, 0) << py.err << script;
  const testing::TestFrame frame = testing::test_frame(0);
  double sum_m = 0.0;
  for (const auto& v : frame.vertices_m) sum_m += v[0] + v[1] + v[2];
  char expected[128];
  std::snprintf(expected, sizeof expected, "%zu %zu %.6f %zu\n375 of 1500 ticks fresh\n", frame.vertices_m.size(),
                frame.triangles.size(), sum_m, frame.triangles.size());
  EXPECT_EQ(py.out, expected) << script;
}

}  // namespace
}  // namespace tissue::record
