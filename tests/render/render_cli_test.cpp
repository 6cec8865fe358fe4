// `tissue render` end to end on a small session file.
#include <gtest/gtest.h>

#include <filesystem>

#include "export/export_test_support.hpp"
#include "record/session_writer.hpp"
#include "render/png_writer.hpp"

namespace tissue::render {
namespace {

using x3d::testing::quote;
using x3d::testing::run;
using x3d::testing::RunResult;
using x3d::testing::TempDir;

std::string write_session(const TempDir& dir) {
  record::SessionMetadata meta;
  meta.scene_name = "render-test";
  const std::string path = dir / "s.h5";
  auto writer = record::SessionWriter::create(path, meta);
  for (int k = 0; k < 3; ++k) {
    const x3d::SurfaceFrame f = x3d::testing::box_frame(0.1 * k, {0, 0, 0}, {0.1, 0.05, 0.02 + 0.01 * k});
    writer->append_mesh_frame(record::MeshFrameView{f.time_s, f.vertices_m, f.triangles, f.vertex_level, {}});
  }
  writer->close();
  return path;
}

RunResult render(const TempDir& dir, const std::string& args) {
  return run(quote(TISSUE_CLI_BINARY) + " render " + args, dir);
}

TEST(RenderCli, OneFrameAndANumberedSequence) {
  TempDir dir;
  const std::string session = write_session(dir);
  RunResult r =
      render(dir, "--session " + quote(session) + " --frame 1 --width 160 --height 120 -o " + quote(dir / "one.png"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_GT(std::filesystem::file_size(dir / "one.png"), 100u);
  r = render(dir, "--session " + quote(session) + " --sequence --width 64 --height 48 -o " + quote(dir / "f.png"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* name : {"f-0000.png", "f-0001.png", "f-0002.png"}) EXPECT_TRUE(std::filesystem::exists(dir / name));
}

// A sequence keeps one camera (the union of its frames' bounds): a box that
// slides along x shows up in different places. Framed frame by frame, every
// picture of a rigidly moving body was the same.
TEST(RenderCli, ASequenceKeepsOneCameraSoMotionShows) {
  TempDir dir;
  record::SessionMetadata meta;
  meta.scene_name = "slide";
  const std::string session = dir / "slide.h5";
  auto writer = record::SessionWriter::create(session, meta);
  for (int k = 0; k < 3; ++k) {
    const x3d::SurfaceFrame f = x3d::testing::box_frame(0.1 * k, {0.1 * k, 0, 0}, {0.1 * k + 0.1, 0.05, 0.02});
    writer->append_mesh_frame(record::MeshFrameView{f.time_s, f.vertices_m, f.triangles, f.vertex_level, {}});
  }
  writer->close();
  const RunResult r = render(dir, "--session " + quote(session) +
                                      " --sequence --width 120 --height 90 --no-legend -o " + quote(dir / "f.png"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Image first = read_png(dir / "f-0000.png"), last = read_png(dir / "f-0002.png");
  ASSERT_EQ(first.rgba.size(), last.rgba.size());
  std::size_t differing = 0;
  for (std::size_t i = 0; i < first.rgba.size(); i += 4) differing += first.rgba[i] != last.rgba[i] ? 1 : 0;
  EXPECT_GT(differing, first.rgba.size() / 4 / 20) << "the box did not move in the pictures";
}

// A session may record empty surfaces (before a scene is loaded): a sequence
// skips and counts them, as x3d --animate and xdmf do (it failed with "frame
// ...: vertices_m is empty"); a window of empty frames only is an error.
TEST(RenderCli, ASequenceSkipsEmptyFrames) {
  TempDir dir;
  const std::string session = dir / "gaps.h5";
  {
    auto writer = record::SessionWriter::create(session, record::SessionMetadata{});
    const x3d::SurfaceFrame empty;
    for (int k = 0; k < 4; ++k) {
      const x3d::SurfaceFrame box = x3d::testing::box_frame(0.1 * k, {0, 0, 0}, {0.1, 0.05, 0.02});
      const x3d::SurfaceFrame& f = k == 0 || k == 2 ? empty : box;
      writer->append_mesh_frame(record::MeshFrameView{0.1 * k, f.vertices_m, f.triangles, f.vertex_level, {}});
    }
    writer->close();
  }
  RunResult r =
      render(dir, "--session " + quote(session) + " --sequence --width 64 --height 48 -o " + quote(dir / "f.png"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(dir / "f-0000.png"));
  EXPECT_TRUE(std::filesystem::exists(dir / "f-0001.png"));
  EXPECT_FALSE(std::filesystem::exists(dir / "f-0002.png"));
  EXPECT_NE(r.out.find("2 empty frames skipped"), std::string::npos) << r.out << r.err;
  r = render(dir, "--session " + quote(session) + " --sequence --from 0 --to 0.05 -o " + quote(dir / "g.png"));
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("--sequence: '" + session +
                       "': its 1 frames between 0 s and 0.05 s are all empty surfaces: "
                       "nothing to draw"),
            std::string::npos)
      << r.err;
}

// A --from/--to window that holds no frame is said with the session and the
// window, as tissue x3d --animate says it: the ends as given, an end not
// given as the frame time it stands for (to 9 digits). It said "no frame in
// the --from/--to window", naming neither.
TEST(RenderCli, AWindowWithNoFrameNamesTheSessionAndTheWindow) {
  TempDir dir;
  const std::string session = dir / "summed.h5";
  const double t0_s = 0.1 + 0.2, t1_s = t0_s + 0.3;  // 0.30000000000000004, 0.6000000000000001
  {
    auto writer = record::SessionWriter::create(session, record::SessionMetadata{});
    for (const double t_s : {t0_s, t1_s}) {
      const x3d::SurfaceFrame f = x3d::testing::box_frame(t_s, {0, 0, 0}, {0.1, 0.05, 0.02});
      writer->append_mesh_frame(record::MeshFrameView{f.time_s, f.vertices_m, f.triangles, f.vertex_level, {}});
    }
    writer->close();
  }
  const auto expect_said = [&](const std::string& window, const std::string& said) {
    const RunResult r =
        render(dir, "--session " + quote(session) + " --sequence " + window + " -o " + quote(dir / "f.png"));
    EXPECT_EQ(r.exit_code, 2) << window << "\n" << r.err;
    EXPECT_NE(r.err.find("tissue render: " + said + "\n"), std::string::npos) << window << "\n" << r.err;
    EXPECT_EQ(r.err.find("0000000"), std::string::npos) << window << "\n" << r.err;
  };
  expect_said("--from 0.4 --to 0.5", "--sequence: '" + session + "' has no frame between 0.4 s and 0.5 s");
  expect_said("--from 2 --to 3", "--sequence: '" + session + "' has no frame between 2 s and 3 s");
  expect_said("--from 1 --to 0.5", "--from 1 --to 0.5: the window is empty (--from is after --to)");
  expect_said("--to 0.2", "--to 0.2 is before the first frame of '" + session + "' (t=0.3 s)");
  expect_said("--from 0.7", "--from 0.7 is after the last frame of '" + session + "' (t=0.6 s)");
  EXPECT_FALSE(std::filesystem::exists(dir / "f-0000.png"));
}

TEST(RenderCli, ErrorsHaveExitCodes) {
  TempDir dir;
  const std::string session = write_session(dir);
  EXPECT_EQ(render(dir, "--session " + quote(dir / "missing.h5") + " -o x.png").exit_code, 1);
  const RunResult past_end = render(dir, "--session " + quote(session) + " --frame 9 -o x.png");
  EXPECT_EQ(past_end.exit_code, 2);
  EXPECT_EQ(past_end.err, "tissue render: --frame 9: '" + session + "' has 3 frames\n");
  const RunResult narrow = render(dir, "--session " + quote(session) + " --width 3 -o x.png");
  EXPECT_EQ(narrow.exit_code, 2);
  EXPECT_EQ(narrow.err.rfind("--width: Value 3 not in range 16 to 8192", 0), 0u) << narrow.err;
  const RunResult nan_time = render(dir, "--session " + quote(session) + " --time nan -o x.png");
  EXPECT_EQ(nan_time.exit_code, 2);
  EXPECT_NE(nan_time.err.find("not a finite number"), std::string::npos) << nan_time.err;
  for (const char* angle : {"--azimuth nan", "--elevation nan", "--azimuth inf"}) {
    const RunResult bad_angle = render(dir, "--session " + quote(session) + " " + angle + " -o x.png");
    EXPECT_EQ(bad_angle.exit_code, 2) << angle << ": " << bad_angle.err;
    EXPECT_NE(bad_angle.err.find("not a finite number"), std::string::npos) << bad_angle.err;
  }
  const RunResult negative = render(dir, "--session " + quote(session) + " --frame -1 -o x.png");
  EXPECT_EQ(negative.exit_code, 2);
  EXPECT_NE(negative.err.find("--frame: -1 is negative"), std::string::npos) << negative.err;
  const RunResult unwritable = render(dir, "--session " + quote(session) + " -o /nonexistent-dir/x.png");
  EXPECT_EQ(unwritable.exit_code, 1);
  EXPECT_NE(unwritable.err.find("/nonexistent-dir/x.png"), std::string::npos) << unwritable.err;
}

// A sequence numbers a file name: an OUT that is a directory (or ends in
// '/') is a bad argument naming -o. `-o DIR/` wrote DIR/-0000, DIR/-0001, ...
// with no extension. An empty -o is a bad argument too (it was found only
// when the first picture was written).
TEST(RenderCli, ASequenceOutputThatIsADirectoryOrEmptyIsABadArgument) {
  TempDir dir;
  const std::string session = write_session(dir);
  const std::string frames = dir / "frames";
  std::filesystem::create_directory(frames);
  for (const std::string& out : {frames + "/", frames, dir / "new/"}) {
    const RunResult r =
        render(dir, "--session " + quote(session) + " --sequence --width 64 --height 48 -o " + quote(out));
    EXPECT_EQ(r.exit_code, 2) << out << "\n" << r.err;
    EXPECT_EQ(r.err, "tissue render: -o " + out +
                         ": a directory; --sequence numbers a file name in it (-o DIR/frame.png writes "
                         "DIR/frame-0000.png, DIR/frame-0001.png, ...)\n")
        << out;
  }
  EXPECT_TRUE(std::filesystem::is_empty(frames));
  EXPECT_FALSE(std::filesystem::exists(dir / "new"));
  EXPECT_FALSE(std::filesystem::exists(dir / "frames-0000"));
  for (const char* sequence : {"", " --sequence"}) {
    const RunResult r = render(dir, "--session " + quote(session) + sequence + " -o ''");
    EXPECT_EQ(r.exit_code, 2) << sequence << "\n" << r.err;
    EXPECT_EQ(r.err, "tissue render: -o: the output path is empty\n") << sequence;
  }
}

// One picture to an OUT that is a directory (or ends in '/') is a bad
// argument naming -o, as for a sequence: exit 2 before any frame is read. It
// was exit 1 ("cannot write DIR: is a directory"), the code of an output
// that fails, where every other mistaken argument is 2.
TEST(RenderCli, AnOutputThatIsADirectoryIsABadArgument) {
  TempDir dir;
  const std::string session = write_session(dir);
  const std::string frames = dir / "frames";
  std::filesystem::create_directory(frames);
  for (const std::string& out : {frames, frames + "/", dir / "new/"}) {
    const RunResult r = render(dir, "--session " + quote(session) + " --width 64 --height 48 -o " + quote(out));
    EXPECT_EQ(r.exit_code, 2) << out << "\n" << r.err;
    EXPECT_EQ(r.err,
              "tissue render: -o " + out + ": a directory; name the PNG file to write in it (-o DIR/frame.png)\n")
        << out;
  }
  EXPECT_TRUE(std::filesystem::is_empty(frames));
  EXPECT_FALSE(std::filesystem::exists(dir / "new"));
}

// Every file of a sequence is checked before a frame is read: with %04d in
// a directory name each file has a directory of its own, and a file's name
// may be taken by a directory. Only the first file was checked, so a later
// one failed after the earlier pictures were written (a live collection,
// after the take).
TEST(RenderCli, EveryFileOfASequenceIsCheckedBeforeAnyIsWritten) {
  TempDir dir;
  const std::string session = write_session(dir);  // 3 frames
  std::filesystem::create_directory(dir / "run0000");
  std::filesystem::create_directory(dir / "run0001");
  const std::string numbered_dirs = dir / "run%04d/f.png";
  RunResult r =
      render(dir, "--session " + quote(session) + " --sequence --width 64 --height 48 -o " + quote(numbered_dirs));
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_EQ(r.err, "tissue render: cannot write " + (dir / "run0002/f.png") + ": cannot create a temporary file in '" +
                       (dir / "run0002") + "': No such file or directory\n");
  EXPECT_FALSE(std::filesystem::exists(dir / "run0000/f.png")) << "written before the check";
  std::filesystem::create_directory(dir / "g-0001.png");  // a file's name taken by a directory
  r = render(dir, "--session " + quote(session) + " --sequence --width 64 --height 48 -o " + quote(dir / "g.png"));
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_EQ(r.err, "tissue render: cannot write " + (dir / "g-0001.png") + ": is a directory\n");
  EXPECT_FALSE(std::filesystem::exists(dir / "g-0000.png")) << "written before the check";
  // With every directory there, each file goes to its own.
  std::filesystem::create_directory(dir / "run0002");
  r = render(dir, "--session " + quote(session) + " --sequence --width 64 --height 48 -o " + quote(numbered_dirs));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* name : {"run0000/f.png", "run0001/f.png", "run0002/f.png"})
    EXPECT_TRUE(std::filesystem::exists(dir / name)) << name;
}

// A live collection's frames are counted only once it is over, so the
// directories a %04d in a directory name would need cannot be checked before
// it: refused before LCM starts (memq://: in-process, no network either way).
TEST(RenderCli, ALiveSequenceNumbersTheFileNameOnly) {
  TempDir dir;
  const std::string out = dir / "run%04d/f.png";
  const RunResult r =
      render(dir, "--lcm memq:// --timeout 1 --seconds 1 --sequence --width 64 --height 48 -o " + quote(out));
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(r.err, "tissue render: -o " + out +
                       ": %04d in a directory name; a live --sequence numbers the file name only (the directories "
                       "its frames would need cannot be checked before the collection)\n");
}

// Errors about a frame name it by its number and say its time to 9
// digits; a --time before the first frame names the file and that frame's
// time (as tissue x3d does). They said "frame (t=0.30000000000000004 s)"
// and "--time -1: no frame that early".
TEST(RenderCli, ErrorsNameTheFrameTheFileAndTimesToNineDigits) {
  TempDir dir;
  const std::string session = dir / "summed.h5";
  const double t0_s = 0.1 + 0.2, t1_s = t0_s + 0.3;  // 0.30000000000000004, 0.6000000000000001
  {
    auto writer = record::SessionWriter::create(session, record::SessionMetadata{});
    const x3d::SurfaceFrame empty;
    writer->append_mesh_frame(record::MeshFrameView{t0_s, empty.vertices_m, empty.triangles, empty.vertex_level, {}});
    x3d::SurfaceFrame degenerate = x3d::testing::box_frame(t1_s, {0, 0, 0}, {0.1, 0.05, 0.02});
    degenerate.triangles[0] = {2, 2, 3};
    writer->append_mesh_frame(
        record::MeshFrameView{t1_s, degenerate.vertices_m, degenerate.triangles, degenerate.vertex_level, {}});
    writer->close();
  }
  const auto expect_said = [&](const std::string& args, int exit_code, const std::string& fragment) {
    const RunResult r = render(dir, "--session " + quote(session) + " " + args + " -o " + quote(dir / "x.png"));
    EXPECT_EQ(r.exit_code, exit_code) << args << "\n" << r.err;
    EXPECT_NE(r.err.find(fragment), std::string::npos) << args << "\n" << r.err;
    EXPECT_EQ(r.err.find("0000000"), std::string::npos) << args << "\n" << r.err;
  };
  expect_said("--frame 0", 1, session + ": frame 0 (t=0.3 s): vertices_m is empty: nothing to draw");
  expect_said("--frame 1", 1, session + ": frame 1 (t=0.6 s): triangles[0] repeats a vertex (2 2 3): degenerate");
  expect_said("", 1, "frame 1 (t=0.6 s): triangles[0] repeats a vertex");
  expect_said("--time -1", 2, "--time -1: '" + session + "' has no frame that early (first at 0.3 s)");
  EXPECT_FALSE(std::filesystem::exists(dir / "x.png"));
}

// -o /dev/stdout with standard output redirected to a file (as run() does):
// the picture alone goes there, the "wrote" line to standard error. (Spelled
// /dev/fd/1: had a regression renamed over it, /dev/stdout stays intact.)
TEST(RenderCli, APictureToStandardOutputIsThePictureAlone) {
  TempDir dir;
  const std::string session = write_session(dir);
  const RunResult r = render(dir, "--session " + quote(session) + " --width 64 --height 48 -o /dev/fd/1");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_GT(r.out.size(), 20u);
  EXPECT_EQ(r.out.substr(1, 3), "PNG");
  EXPECT_EQ(r.out.substr(r.out.size() - 8, 4), "IEND") << "something follows the picture";
  EXPECT_NE(r.err.find("wrote /dev/fd/1"), std::string::npos) << r.err;
}

// -o naming the session (another spelling, a symbolic link) would truncate
// the recording: refused, the session left as it was.
TEST(RenderCli, RefusesToOverwriteTheInputSession) {
  TempDir dir;
  const std::string session = write_session(dir);
  std::filesystem::create_symlink(session, dir / "link.png");
  const std::string before = x3d::testing::slurp(session);
  for (const std::string& out : {session, dir / "./s.h5", dir / "link.png"}) {
    const RunResult r = render(dir, "--session " + quote(session) + " --width 64 --height 48 -o " + quote(out));
    EXPECT_EQ(r.exit_code, 1) << out;
    EXPECT_NE(r.err.find("is the input session"), std::string::npos) << r.err;
    EXPECT_EQ(x3d::testing::slurp(session), before) << "the session was changed via " << out;
  }
}

}  // namespace
}  // namespace tissue::render
