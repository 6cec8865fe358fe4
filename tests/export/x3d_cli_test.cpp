// `tissue x3d` end to end on session files written with the recorder's
// SessionWriter, and the session FrameSource it reads through.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "export/export_test_support.hpp"
#include "export/frame_source.hpp"
#include "export/x3d.hpp"
#include "record/record_test_support.hpp"
#include "record/session_layout.hpp"
#include "record/session_writer.hpp"

namespace tissue::x3d {
namespace {

using testing::attribute;
using testing::count_elements;
using testing::numbers;
using testing::quote;
using testing::RunResult;
using testing::TempDir;

// Coordinates are multiples of 1/64 m: exact in the session's float32.
std::vector<SurfaceFrame> session_frames() {
  std::vector<SurfaceFrame> f;
  f.push_back(testing::box_frame(0.25, {0, 0, 0}, {0.125, 0.0625, 0.03125}));
  f.push_back(testing::box_frame(0.5, {0.015625, 0, 0}, {0.140625, 0.0625, 0.03125}));
  f.push_back(testing::box_frame(0.75, {0.03125, 0, 0}, {0.15625, 0.0625, 0.046875}));
  f.push_back(testing::tetra_frame(1.0, 0.0625));
  f.push_back(testing::tetra_frame(1.25, 0.078125));
  return f;
}

std::string write_session(const TempDir& dir, const std::string& name, const std::vector<SurfaceFrame>& frames) {
  const std::string path = dir / name;
  record::SessionMetadata meta;
  meta.scene_name = "x3d export test";
  meta.software_version = "test";
  auto writer = record::SessionWriter::create(path, meta);
  for (const SurfaceFrame& f : frames)
    writer->append_mesh_frame(record::MeshFrameView{f.time_s, f.vertices_m, f.triangles, f.vertex_level, {}});
  writer->close();
  return path;
}

std::string tissue() { return quote(TISSUE_CLI_BINARY); }

class X3dCli : public ::testing::Test {
 protected:
  void SetUp() override { session_ = write_session(dir_, "s.h5", session_frames()); }
  RunResult x3d(const std::string& args) { return testing::run(tissue() + " x3d " + args, dir_); }
  TempDir dir_;
  std::string session_;
};

TEST_F(X3dCli, SessionSourceReadsFramesBack) {
  const std::vector<SurfaceFrame> expected = session_frames();
  auto source = open_session_source(session_);
  ASSERT_EQ(source->frame_count(), expected.size());
  EXPECT_FALSE(source->has_strain());
  for (std::size_t k = 0; k < expected.size(); ++k) {
    const SurfaceFrame f = source->read_frame(k);
    EXPECT_EQ(source->frame_time_s(k), expected[k].time_s);
    EXPECT_EQ(f.time_s, expected[k].time_s);
    EXPECT_EQ(f.vertices_m, expected[k].vertices_m) << "frame " << k;
    EXPECT_EQ(f.triangles, expected[k].triangles) << "frame " << k;
    EXPECT_EQ(f.vertex_level, expected[k].vertex_level) << "frame " << k;
  }
  EXPECT_THROW(source->read_frame(expected.size()), std::out_of_range);
  EXPECT_EQ(frame_at_time(*source, 0.1), std::nullopt);
  EXPECT_EQ(frame_at_time(*source, 0.25), 0u);
  EXPECT_EQ(frame_at_time(*source, 0.7), 1u);
  EXPECT_EQ(frame_at_time(*source, 99.0), 4u);
  // A time a rounding hair before a frame's (summed steps: 0.5000000000000003
  // for 0.5) picks that frame; a microsecond before does not.
  EXPECT_EQ(frame_at_time(*source, expected[1].time_s - 1e-12), 1u);
  EXPECT_EQ(frame_at_time(*source, expected[1].time_s - 1e-6), 0u);
  EXPECT_EQ(frames_in_window(*source, 0.5, 1.0), (std::vector<std::size_t>{1, 2, 3}));
}

TEST_F(X3dCli, DefaultSnapshotIsTheLastFrame) {
  const std::string out = dir_ / "last.x3d";
  const RunResult r = x3d("--session " + quote(session_) + " -o " + quote(out));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  EXPECT_NE(r.out.find("frame 4"), std::string::npos) << r.out;
  const std::string xml = testing::slurp(out);
  EXPECT_NE(xml.find("<X3D profile='Interchange' version='3.3'"), std::string::npos);
  const SurfaceFrame last = session_frames().back();
  const std::vector<double> point = numbers(attribute(xml, "Coordinate", "point"));
  ASSERT_EQ(point.size(), 3 * last.vertices_m.size());
  for (std::size_t i = 0; i < point.size(); ++i) EXPECT_EQ(point[i], last.vertices_m[i / 3][i % 3]);
  const std::vector<double> index = numbers(attribute(xml, "IndexedTriangleSet", "index"));
  ASSERT_EQ(index.size(), 3 * last.triangles.size());
  for (const double i : index) EXPECT_LT(i, static_cast<double>(last.vertices_m.size()));
  EXPECT_FALSE(std::filesystem::exists(out + ".tmp"));
}

TEST_F(X3dCli, FrameAndTimeSelectTheSnapshot) {
  const std::string out = dir_ / "f.x3d";
  RunResult r = x3d("--session " + quote(session_) + " --frame 1 -o " + quote(out));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(numbers(attribute(testing::slurp(out), "Coordinate", "point"))[0], 0.015625);
  r = x3d("--session " + quote(session_) + " --time 0.9 -o " + quote(out));  // frame 2 is on screen at 0.9 s
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string xml = testing::slurp(out);
  EXPECT_EQ(numbers(attribute(xml, "Coordinate", "point"))[0], 0.03125);
  EXPECT_EQ(numbers(attribute(xml, "Coordinate", "point")).size(), 24u);
}

TEST_F(X3dCli, AnimationOverAWindow) {
  const std::string out = dir_ / "anim.x3d";
  const RunResult r = x3d("--session " + quote(session_) + " --animate --from 0.5 --to 1.25 -o " + quote(out));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  const std::string xml = testing::slurp(out);
  EXPECT_EQ(numbers(attribute(xml, "TimeSensor", "cycleInterval")), (std::vector<double>{0.75}));
  EXPECT_EQ(count_elements(xml, "Shape"), 2u);  // box run (frames 1-2), tetra run (3-4)
  EXPECT_EQ(count_elements(xml, "CoordinateInterpolator"), 2u);
  EXPECT_EQ(numbers(attribute(xml, "IntegerSequencer", "key")), (std::vector<double>{0.0, 0.5 / 0.75}));
  const std::string tool = testing::tovrmlx3d_path();
  if (tool.empty()) GTEST_SKIP() << "tovrmlx3d not installed (apt-get install view3dscene)";
  const RunResult v = testing::run(quote(tool) + " " + quote(out) + " --encoding xml", dir_);
  EXPECT_EQ(v.exit_code, 0);
  EXPECT_EQ(v.err, "");
}

TEST_F(X3dCli, SnapshotAcceptedByTovrml) {
  const std::string tool = testing::tovrmlx3d_path();
  if (tool.empty()) GTEST_SKIP() << "tovrmlx3d not installed (apt-get install view3dscene)";
  const std::string out = dir_ / "snap.x3d";
  ASSERT_EQ(x3d("--session " + quote(session_) + " --frame 0 -o " + quote(out)).exit_code, 0);
  const RunResult v = testing::run(quote(tool) + " " + quote(out) + " --encoding xml", dir_);
  EXPECT_EQ(v.exit_code, 0);
  EXPECT_EQ(v.err, "");
}

TEST_F(X3dCli, UnreadableInputExitsOneNamingTheFile) {
  const std::string out = dir_ / "o.x3d";
  const std::string missing = dir_ / "missing.h5";
  RunResult r = x3d("--session " + quote(missing) + " -o " + quote(out));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find(missing), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("No such file"), std::string::npos) << r.err;

  const std::string junk = dir_ / "junk.h5";
  testing::write_text(junk, "this is not HDF5 at all, just text padding the header\n");
  r = x3d("--session " + quote(junk) + " -o " + quote(out));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find(junk), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("not an HDF5 file"), std::string::npos) << r.err;

  const std::string empty = write_session(dir_, "empty.h5", {});
  r = x3d("--session " + quote(empty) + " -o " + quote(out));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no complete mesh frame"), std::string::npos) << r.err;

  r = x3d("--session " + quote(session_) + " -o " + quote(dir_ / "no/such/dir/o.x3d"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("cannot write"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
}

// Overwrites /mesh/triangles row `row`, column 0, of a closed session.
void poke_triangle_index(const std::string& path, hsize_t row, std::int32_t value) {
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const hid_t d = H5Dopen2(file, "/mesh/triangles", H5P_DEFAULT);
  const hid_t space = H5Dget_space(d);
  const hsize_t start[2] = {row, 0}, count[2] = {1, 1};
  H5Sselect_hyperslab(space, H5S_SELECT_SET, start, nullptr, count, nullptr);
  const hid_t mem = H5Screate_simple(2, count, nullptr);
  EXPECT_GE(H5Dwrite(d, H5T_NATIVE_INT32, mem, space, H5P_DEFAULT, &value), 0);
  H5Sclose(mem);
  H5Sclose(space);
  H5Dclose(d);
  H5Fclose(file);
}

TEST_F(X3dCli, ImpossibleStoredFramesExitOneNamingFrameAndField) {
  const std::string out = dir_ / "o.x3d";
  // Frame 1 starts at triangle row 12 (frame 0 is a 12-triangle box).
  poke_triangle_index(session_, 12 + 3, 8);
  RunResult r = x3d("--session " + quote(session_) + " --frame 1 -o " + quote(out));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(
      r.err.find("'" + session_ + "': /mesh/triangles row 15 (frame 1) holds the index 8, past the frame's 8 vertices"),
      std::string::npos)
      << r.err;
  r = x3d("--session " + quote(session_) + " --animate -o " + quote(out));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("/mesh/triangles row 15 (frame 1) holds the index 8"), std::string::npos) << r.err;
  poke_triangle_index(session_, 12 + 3, -4);
  r = x3d("--session " + quote(session_) + " --frame 1 -o " + quote(out));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("/mesh/triangles row 15 (frame 1) holds the negative index -4"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
}

// Sets the row count of a closed session's (chunked, unlimited) dataset;
// rows past the written ones read as 0 and take no space in the file.
void set_rows(const std::string& path, const char* dataset, hsize_t rows) {
  const hid_t file = record::testing::open_for_edit(path);
  ASSERT_GE(file, 0) << path;
  const hid_t d = H5Dopen2(file, dataset, H5P_DEFAULT);
  ASSERT_GE(d, 0) << dataset;
  const hid_t space = H5Dget_space(d);
  hsize_t dims[2] = {0, 0};
  H5Sget_simple_extent_dims(space, dims, nullptr);
  dims[0] = rows;
  EXPECT_GE(H5Dset_extent(d, dims), 0) << dataset;
  H5Sclose(space);
  H5Dclose(d);
  H5Fclose(file);
}

// Overwrites every row of a closed session's one-column uint64 dataset.
void write_column(const std::string& path, const char* dataset, const std::vector<std::uint64_t>& values) {
  const hid_t file = record::testing::open_for_edit(path);
  ASSERT_GE(file, 0) << path;
  const hid_t d = H5Dopen2(file, dataset, H5P_DEFAULT);
  ASSERT_GE(d, 0) << dataset;
  EXPECT_GE(H5Dwrite(d, H5T_NATIVE_UINT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()), 0) << dataset;
  H5Dclose(d);
  H5Fclose(file);
}

// --animate without --from/--to kept every frame of the session in memory:
// an hour of a 50k-vertex surface at 30 Hz is hundreds of GB (bad_alloc or
// the OOM killer). Its window is refused from the session's index, before a
// frame is read, past the budget live collection has (1 GiB). The session
// claims 45 frames of 2^20 vertices (~29 MB each, 1.2 GiB in all) in rows
// HDF5 does not store.
TEST_F(X3dCli, AnAnimationTooLargeToHoldIsRefusedBeforeReadingAFrame) {
  using record::kDatasets;
  constexpr std::uint64_t kFrames = 45, kVertices = std::uint64_t{1} << 20;
  std::vector<SurfaceFrame> frames;
  for (std::uint64_t k = 0; k < kFrames; ++k)
    frames.push_back(testing::box_frame(static_cast<double>(k), {0, 0, 0}, {0.125, 0.0625, 0.03125}));
  const std::string big = write_session(dir_, "big.h5", frames);
  std::vector<std::uint64_t> offsets, counts(kFrames, kVertices);
  for (std::uint64_t k = 0; k < kFrames; ++k) offsets.push_back(k * kVertices);
  set_rows(big, kDatasets[record::kMeshVertices].path, kFrames * kVertices);
  set_rows(big, kDatasets[record::kMeshVertexLevel].path, kFrames * kVertices);
  write_column(big, kDatasets[record::kMeshVertexOffset].path, offsets);
  write_column(big, kDatasets[record::kMeshVertexCount].path, counts);
  // Reading a frame fails (exit 1): the session reader refuses rows past
  // what the file can hold, so an export without the check stops at frame 0
  // instead of holding 1.2 GiB here.
  const std::string out = dir_ / "big.x3d";
  const auto expect_refused = [&](const std::string& window, const std::string& said) {
    const RunResult r = x3d("--session " + quote(big) + " --animate " + window + " -o " + quote(out));
    EXPECT_EQ(r.exit_code, 2) << window << "\n" << r.err;
    EXPECT_NE(r.err.find("tissue x3d: --animate " + said), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(" GiB of frame data, more than the 1 GiB an export may hold; choose a shorter window "
                         "with --from/--to"),
              std::string::npos)
        << r.err;
  };
  expect_refused("", "(all frames): 45 frames of '" + big + "' (t=0 s to 44 s) hold 1.2");
  expect_refused("--from 0 --to 40", "--from 0 --to 40: 41 frames of '" + big + "' (t=0 s to 40 s) hold ");
  expect_refused("--to 40", "--to 40: 41 frames of '" + big + "' (t=0 s to 40 s) hold ");
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST_F(X3dCli, BadArgumentsExitTwo) {
  const std::string s = "--session " + quote(session_) + " -o " + quote(dir_ / "o.x3d");
  const auto expect_2 = [&](const std::string& args, const std::string& fragment) {
    const RunResult r = x3d(args);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.err;
    EXPECT_NE(r.err.find(fragment), std::string::npos) << args << "\n" << r.err;
  };
  expect_2(s + " --frame 5", "--frame 5: '" + session_ + "' has 5 frames (0 to 4)");
  expect_2(s + " --time 0.1", "--time 0.1: '" + session_ + "' has no frame that early");
  expect_2(s + " --frame -1", "--frame: -1 is negative: frames are numbered from 0");
  expect_2(s + " --frame 1 --time 0.5", "excludes");
  expect_2(s + " --animate --frame 1", "excludes");
  expect_2(s + " --from 0.5", "requires --animate");
  expect_2(s + " --animate --from 2 --to 3", "0 non-empty frames between 2 s and 3 s");
  expect_2(s + " --animate --from 1 --to 0.5", "the window is empty (--from is after --to)");
  expect_2(s + " --animate --from 0.5 --to 0.5", "the window has no length; an animation needs at least 2 frames");
  // One end given: the message has only that option, the other end is the
  // session's (it said "--from 0.25 --to 0.1" to a user who gave no --from).
  const auto expect_only = [&](const std::string& given, const std::string& absent, const std::string& said) {
    const RunResult r = x3d(s + " --animate " + given);
    EXPECT_EQ(r.exit_code, 2) << given << "\n" << r.err;
    EXPECT_NE(r.err.find("tissue x3d: " + said), std::string::npos) << given << "\n" << r.err;
    EXPECT_EQ(r.err.find(absent), std::string::npos) << given << "\n" << r.err;
  };
  expect_only(
      "--to 0.1", "--from",
      "--to 0.1 is before the first frame of '" + session_ + "' (t=0.25 s): an animation needs at least 2 frames");
  expect_only("--to 0.25", "--from",
              "--to 0.25 is the time of the first frame (t=0.25 s): an animation needs at least 2 frames");
  expect_only(
      "--from 2", "--to",
      "--from 2 is after the last frame of '" + session_ + "' (t=1.25 s): an animation needs at least 2 frames");
  expect_only("--from 1.25", "--to",
              "--from 1.25 is the time of the last frame (t=1.25 s): an animation needs at least 2 frames");
  expect_2(s + " --colour purple", "purple");
  expect_2(s + " --colour strain", "stores no strain energy (session format version 1, or recorded without it)");
  // Live waits: NaN passed CLI11's PositiveNumber and waited forever (no
  // publisher is needed to see the refusal: arguments are checked first).
  const std::string live = "--lcm memq:// -o " + quote(dir_ / "o.x3d");
  expect_2(live + " --timeout nan", "--timeout: nan must be a finite number > 0");
  expect_2(live + " --timeout inf", "--timeout: inf must be a finite number > 0");
  expect_2(live + " --timeout 0", "--timeout: 0 must be a finite number > 0");
  expect_2(live + " --animate --seconds nan", "--seconds: nan must be a finite number > 0");
  // A window of any length kept every frame in memory: bounded to an hour
  // (it waited out --timeout and exited 4 for want of a publisher).
  expect_2(live + " --timeout 0.1 --animate --seconds 3601",
           "--seconds: 3601 is more than 3600: live frames are held in memory");
  expect_2(live + " --timeout 5s", "--timeout: '5s' is not a number");
  expect_2("-o " + quote(dir_ / "o.x3d"), "--session is required");
  expect_2("--session " + quote(session_), "--output is required");
  // An empty -o is a bad argument, said before any work (the export was made
  // and then failed to be renamed to '').
  expect_2("--session " + quote(session_) + " -o ''", "tissue x3d: -o: the output path is empty\n");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "o.x3d"));
  // An OUT that is a directory is a mistaken argument, as in tissue render
  // (it was exit 1, "cannot write 'DIR': is a directory", the code of an
  // output that fails), and so is one ending in '/'.
  std::filesystem::create_directory(dir_ / "exports");
  expect_2("--session " + quote(session_) + " -o " + quote(dir_ / "exports"),
           "tissue x3d: -o " + (dir_ / "exports") + ": a directory; name the X3D file to write in it (-o " +
               (dir_ / "exports") + "/scene.x3d)\n");
  expect_2("--session " + quote(session_) + " -o " + quote(dir_ / "new/"), ": a directory; name the X3D file");
  expect_2("--lcm memq:// -o " + quote(dir_ / "exports"), ": a directory; name the X3D file");  // before any wait
  EXPECT_TRUE(std::filesystem::is_empty(dir_ / "exports"));
}

// Frame times in messages have 9 significant digits, as docs/x3d-export.md
// says ("t=1.5 s"): times summed from steps are a hair off (0.1 + 0.2 is
// 0.30000000000000004), and the messages said every digit of it.
TEST_F(X3dCli, FrameTimesInMessagesHaveNineSignificantDigits) {
  const double t0_s = 0.1 + 0.2, t1_s = t0_s + 0.3;  // 0.30000000000000004, 0.6000000000000001
  SurfaceFrame degenerate = testing::box_frame(t1_s, {0, 0, 0}, {0.125, 0.0625, 0.03125});
  degenerate.triangles[0] = {2, 2, 3};
  const std::string summed = write_session(dir_, "summed.h5",
                                           {testing::box_frame(t0_s, {0, 0, 0}, {0.125, 0.0625, 0.03125}), degenerate,
                                            testing::box_frame(t1_s + 0.2, {0, 0, 0}, {0.125, 0.0625, 0.03125})});
  const std::string s = "--session " + quote(summed) + " -o " + quote(dir_ / "o.x3d");
  const auto expect_said = [&](const std::string& args, int exit_code, const std::string& fragment) {
    const RunResult r = x3d(s + " " + args);
    EXPECT_EQ(r.exit_code, exit_code) << args << "\n" << r.err;
    EXPECT_NE(r.err.find(fragment), std::string::npos) << args << "\n" << r.err;
    EXPECT_EQ(r.err.find("0000000"), std::string::npos) << args << "\n" << r.err;
  };
  expect_said("--frame 1", 1, "frame 1 (t=0.6 s): triangles[0] repeats a vertex (2 2 3): degenerate");
  expect_said("--time 0.1", 2, "--time 0.1: '" + summed + "' has no frame that early (first at 0.3 s)");
  expect_said("--animate --to 0.4", 2, "has 1 non-empty frames between 0.3 s and 0.4 s; an animation needs 2");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "o.x3d"));
}

// Frames all at one time (a paused daemon's stream, recorded or live) cannot
// animate: the source's fault, said of the source (exit 1), not of
// --from/--to, which the user never gave (it said "--from 0 --to 0", exit 2).
TEST_F(X3dCli, AnAnimationOfFramesAllAtOneTimeIsTheSourcesFault) {
  const std::string paused = write_session(
      dir_, "paused.h5",
      {testing::tetra_frame(0.5, 0.0625), testing::tetra_frame(0.5, 0.0625), testing::tetra_frame(0.5, 0.0625)});
  const RunResult r = x3d("--session " + quote(paused) + " --animate -o " + quote(dir_ / "p.x3d"));
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("'" + paused + "': its 3 frames are all at t=0.5 s"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("--from"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "p.x3d"));
}

// -o naming the session would rename the export over the recording.
TEST_F(X3dCli, RefusesToOverwriteTheInputSession) {
  std::filesystem::create_symlink(session_, dir_ / "link.x3d");
  const std::string before = testing::slurp(session_);
  for (const std::string& out : {session_, dir_ / "./s.h5", dir_ / "link.x3d"}) {
    const RunResult r = x3d("--session " + quote(session_) + " -o " + quote(out));
    EXPECT_EQ(r.exit_code, 1) << out;
    EXPECT_NE(r.err.find("is the input session"), std::string::npos) << r.err;
    EXPECT_EQ(testing::slurp(session_), before) << "the session was changed via " << out;
  }
}

// -o /dev/stdout with standard output redirected to a file (as run() does):
// written in place, the document alone, the "wrote" line on standard error.
// The rename used for regular files replaced /dev/stdout itself (as root).
// Spelled /dev/fd/1 here, so a regression cannot touch /dev/stdout.
TEST_F(X3dCli, ADocumentToStandardOutputIsTheDocumentAlone) {
  const RunResult r = x3d("--session " + quote(session_) + " -o /dev/fd/1");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.rfind("<?xml", 0), 0u) << r.out.substr(0, 200);
  ASSERT_GE(r.out.size(), 7u);
  EXPECT_EQ(r.out.substr(r.out.size() - 7), "</X3D>\n") << "something follows the document";
  EXPECT_NE(r.err.find("wrote /dev/fd/1"), std::string::npos) << r.err;
}

// An existing FIFO (or device: /dev/full, /dev/null) is written in place;
// the temporary + rename used for regular files replaced such a node with a
// regular file. (A FIFO, not a real device: a broken build must not be able
// to replace a system node.)
TEST_F(X3dCli, WritesIntoAFifoAndKeepsIt) {
  const std::string fifo = dir_ / "out.fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  // Both ends bounded: a writer that never opens the FIFO leaves the reader
  // to give up after 30 s, and the other way round.
  const RunResult r =
      testing::run("(timeout 30 cat " + quote(fifo) + " > " + quote(dir_ / "got.x3d") + " &) ; timeout 60 " + tissue() +
                       " x3d --session " + quote(session_) + " -o " + quote(fifo),
                   dir_);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  struct stat st {};
  ASSERT_EQ(::stat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode)) << "the FIFO was replaced by a regular file";
  EXPECT_FALSE(std::filesystem::exists(fifo + ".tmp"));
  std::string got;
  for (int i = 0; i < 100 && got.find("</X3D>") == std::string::npos; ++i) {
    got = testing::slurp(dir_ / "got.x3d");
    if (got.find("</X3D>") == std::string::npos) ::usleep(50000);
  }
  EXPECT_NE(got.find("</X3D>"), std::string::npos) << got;
}

}  // namespace
}  // namespace tissue::x3d
