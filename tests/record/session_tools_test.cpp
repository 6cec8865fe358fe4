// Session tools (list / info / repair / xdmf) and the session readers (SessionFile,
// read_session_rows, read_haptic_track), as library calls and through the
// `tissue session` CLI: good files, bad arguments, and files that are not
// sessions at all. No input may crash them (the ASan tree runs this too).
#include "record/session_tools.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>
#include <system_error>

#include <grp.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>

#include "record/h5_util.hpp"
#include "record/session_layout.hpp"
#include "record/session_writer.hpp"
#include "record_test_support.hpp"
#include "util/text.hpp"

namespace tissue::record {
namespace {

using testing::quote;
using testing::run;
using testing::RunResult;
using testing::TempDir;

void write_small_session(const std::string& path, std::uint64_t frames = 5) {
  testing::TestSession content;
  content.frames = frames;
  testing::write_test_session(path, content);
}

std::string tissue() { return quote(TISSUE_CLI_BINARY); }

bool is_fifo(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISFIFO(st.st_mode);
}

// Runs `call`; on a FIFO, also fails the test if it opened it (a plain open
// blocks until a writer comes: `tissue session repair` on one hung for good).
void guarding_fifo(const std::string& path, const std::string& what, const std::function<void()>& call) {
  if (!is_fifo(path)) return call();
  EXPECT_FALSE(testing::opens_fifo_for_reading(path, call))
      << what << " opened the FIFO " << path << " (it blocks there until a writer comes)";
}

// Every library tool and reader refuses `path` with a RecordError naming the
// file (and `also`, e.g. the damaged dataset, when given); xdmf writes nothing.
void expect_every_tool_refuses(const std::string& path, const TempDir& dir, const std::string& also = "") {
  SCOPED_TRACE(path);
  for (int tool = 0; tool < 5; ++tool) {
    guarding_fifo(path, "tool " + std::to_string(tool), [&] {
      try {
        if (tool == 0) read_session_info(path);
        if (tool == 1) repair_session(path);
        if (tool == 2) write_xdmf(path, dir / "out.xdmf");
        if (tool == 3) read_session_rows(path);
        if (tool == 4) read_haptic_track(path);
        ADD_FAILURE() << "tool " << tool << " accepted " << path;
      } catch (const RecordError& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << "tool " << tool << ": " << e.what();
        EXPECT_NE(std::string(e.what()).find(also), std::string::npos) << "tool " << tool << ": " << e.what();
      }
    });
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "out.xdmf"));
}

TEST(SessionTools, BadFilesGetAClearErrorFromEveryLibraryTool) {
  TempDir dir;
  for (const std::string& path : testing::bad_session_files(dir)) expect_every_tool_refuses(path, dir);
}

TEST(SessionTools, BadFilesMakeTheCliExitOneWithItsOwnMessage) {
  TempDir dir;
  TempDir scratch;
  for (const std::string& path : testing::bad_session_files(dir)) {
    for (const char* tool : {"info", "repair", "xdmf"}) {
      SCOPED_TRACE(std::string(tool) + " " + path);
      RunResult r;
      guarding_fifo(path, std::string("tissue session ") + tool,
                    [&] { r = run(tissue() + " session " + tool + " " + quote(path), scratch); });
      EXPECT_EQ(r.exit_code, 1) << r.err;
      EXPECT_NE(r.err.find(path), std::string::npos) << r.err;
      EXPECT_EQ(r.err.find("HDF5-DIAG"), std::string::npos) << "HDF5's error stack leaked:\n" << r.err;
      EXPECT_EQ(r.err.find("Sanitizer"), std::string::npos) << r.err;
      EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    }
  }
}

TEST(SessionTools, TruncatedSessionSaysWhatIsWrong) {
  TempDir dir;
  write_small_session(dir / "good.h5");
  const std::string bytes = testing::slurp(dir / "good.h5");
  testing::write_bytes(dir / "cut.h5", bytes.substr(0, bytes.size() / 2));
  try {
    read_session_info(dir / "cut.h5");
    FAIL() << "accepted a truncated file";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
  }
  testing::write_bytes(dir / "text.h5", "hello");
  try {
    read_session_info(dir / "text.h5");
    FAIL() << "accepted a text file";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find("not an HDF5 file"), std::string::npos) << e.what();
  }
}

TEST(SessionTools, CliInfoAndRepairOnACleanSession) {
  TempDir dir;
  write_small_session(dir / "s.h5");
  const auto info = run(tissue() + " session info " + quote(dir / "s.h5"), dir);
  EXPECT_EQ(info.exit_code, 0) << info.err;
  EXPECT_NE(info.out.find("closed cleanly"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("1500 ticks"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("scene:            probe"), std::string::npos) << info.out;
  EXPECT_EQ(info.err, "");
  const auto repair = run(tissue() + " session repair " + quote(dir / "s.h5"), dir);
  EXPECT_EQ(repair.exit_code, 0) << repair.err;
  EXPECT_NE(repair.out.find("nothing to repair"), std::string::npos) << repair.out;
  EXPECT_TRUE(read_session_info(dir / "s.h5").closed_cleanly);
}

// A state directory as a lab finds it: a clean session, one still open for
// writing (a copy taken while its writer runs reads as a crash), a repaired
// one, a session file without the .h5 name, an empty .h5, an unfinished
// creation, and files that are not sessions (skipped).
TEST(SessionTools, ListShowsEachSessionsStateAndTheFilesThatAreNotSessions) {
  TempDir dir;
  const std::string d = dir / "state";
  std::filesystem::create_directories(d + "/sub");
  write_small_session(d + "/a.h5");
  {
    SessionMetadata meta;
    meta.scene_name = "live";
    auto w = SessionWriter::create(dir / "live.h5", meta);
    w->append_haptic(std::vector<HapticRow>{testing::haptic_row(0), testing::haptic_row(1)});
    w->flush();
    std::filesystem::copy_file(dir / "live.h5", d + "/b.h5");
    std::filesystem::copy_file(dir / "live.h5", d + "/c.h5");
    w->close();
  }
  repair_session(d + "/c.h5");
  testing::TestSession odd;  // a scene name no table column is made for
  odd.scene_name = std::string(600, 'x') + "\nrow";
  testing::write_test_session(d + "/e.h5", odd);
  std::filesystem::copy_file(d + "/a.h5", d + "/no_extension");
  std::ofstream(d + "/empty.h5").flush();
  std::ofstream(d + "/notes.txt") << "not a session\n";
  std::ofstream(d + "/a.x3d") << "<X3D/>\n";
  std::ofstream(d + "/.d.h5" + kCreatingInfix + "1-0").flush();

  const SessionListing l = list_sessions(d);
  ASSERT_EQ(l.sessions.size(), 5u);
  const auto name = [](const SessionInfo& s) { return std::filesystem::path(s.path).filename().string(); };
  EXPECT_EQ(name(l.sessions[0]), "a.h5");
  EXPECT_EQ(session_state(l.sessions[0]), SessionState::kClosedCleanly);
  EXPECT_EQ(l.sessions[0].rows.haptic_rows, testing::TestSession{}.haptic);
  EXPECT_EQ(name(l.sessions[1]), "b.h5");
  EXPECT_EQ(session_state(l.sessions[1]), SessionState::kOpenForWrite);
  EXPECT_EQ(l.sessions[1].rows.haptic_rows, 2u);
  EXPECT_EQ(name(l.sessions[2]), "c.h5");
  EXPECT_EQ(session_state(l.sessions[2]), SessionState::kRepaired);
  EXPECT_EQ(name(l.sessions[3]), "e.h5");
  EXPECT_EQ(name(l.sessions[4]), "no_extension");
  ASSERT_EQ(l.unreadable.size(), 1u);
  EXPECT_EQ(l.unreadable[0].path, d + "/empty.h5");
  EXPECT_NE(l.unreadable[0].reason.find("empty"), std::string::npos) << l.unreadable[0].reason;
  ASSERT_EQ(l.unfinished.size(), 1u);
  EXPECT_NE(l.unfinished[0].find(".d.h5.creating-1-0"), std::string::npos);

  const auto r = run(tissue() + " session list " + quote(d), dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("5 sessions in " + d), std::string::npos) << r.out;
  // The long, two-line scene name stays whole, on its session's row.
  EXPECT_NE(r.out.find("e.h5 "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(std::string(600, 'x') + "\\x0Arow\n"), std::string::npos) << r.out;
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1 + 1 + 5 + 1 + 1 + 1)
      << "title, header, 5 sessions, 1 unreadable, 1 unfinished, the OPEN hint\n"
      << r.out;
  for (const char* expected : {"a.h5", "closed cleanly", "b.h5", "OPEN", "c.h5", "repaired", "no_extension",
                               "unreadable: '" /* the path follows */, "unfinished: ", "tissue session repair"})
    EXPECT_NE(r.out.find(expected), std::string::npos) << expected << "\n" << r.out;
  for (const char* skipped : {"notes.txt", "a.x3d", "sub"})
    EXPECT_EQ(r.out.find(skipped), std::string::npos) << skipped;

  const auto missing = run(tissue() + " session list " + quote(dir / "missing"), dir);
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.err.find(dir / "missing"), std::string::npos) << missing.err;
}

constexpr const char* kCannotDropRoot = "cannot drop root";

// list_sessions(d)'s error ("" when it lists d) as a user permissions apply
// to: root bypasses them, so as root it runs in a child process that has
// become nobody (kCannotDropRoot when that is not allowed).
std::string list_error_as_unprivileged_user(const std::string& d) {
  const auto error_of = [&d]() -> std::string {
    try {
      list_sessions(d);
      return "";
    } catch (const RecordError& e) {
      return e.what();
    }
  };
  if (::geteuid() != 0) return error_of();
  int fds[2];
  if (::pipe(fds) != 0) return std::string("pipe: ") + std::strerror(errno);
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::close(fds[0]);
    constexpr uid_t kNobody = 65534;
    const std::string what =
        ::setgroups(0, nullptr) == 0 && ::setgid(kNobody) == 0 && ::setuid(kNobody) == 0 ? error_of() : kCannotDropRoot;
    const bool sent = ::write(fds[1], what.data(), what.size()) == static_cast<ssize_t>(what.size());
    ::_exit(sent ? 0 : 1);
  }
  ::close(fds[1]);
  std::string what;
  char buf[512];
  for (ssize_t n; (n = ::read(fds[0], buf, sizeof buf)) > 0;) what.append(buf, static_cast<std::size_t>(n));
  ::close(fds[0]);
  int status = 0;
  if (pid < 0 || ::waitpid(pid, &status, 0) != pid || !WIFEXITED(status) || WEXITSTATUS(status) != 0)
    return "the unprivileged child failed: " + what;
  return what;
}

// A directory `list` cannot reach is refused with the reason, not called
// "not a directory" (found by the review of the session tools): a symbolic
// link loop (ELOOP), and a parent without search permission (EACCES).
TEST(SessionTools, ListOfADirectoryItCannotReachSaysWhy) {
  TempDir dir;
  const std::string loop = dir / "loop";
  std::filesystem::create_directory_symlink(dir / "loop", loop);
  const auto expect_refused = [](const std::string& d, const std::string& reason) {
    try {
      list_sessions(d);
      ADD_FAILURE() << "listed " << d;
    } catch (const RecordError& e) {
      EXPECT_NE(std::string(e.what()).find("cannot list sessions in '" + d + "': " + reason), std::string::npos)
          << e.what();
    }
  };
  expect_refused(loop, std::error_code(ELOOP, std::generic_category()).message());
  // Still: a file is not a directory, and a missing one is missing.
  std::ofstream(dir / "file") << "x\n";
  expect_refused(dir / "file", "not a directory");
  expect_refused(dir / "missing", "no such directory");
  expect_refused(dir / "file/sub", "no such directory");  // ENOTDIR: nothing there

  // EACCES: a parent without search permission.
  const std::string closed = dir / "closed";
  std::filesystem::create_directories(closed + "/state");
  ASSERT_EQ(::chmod(closed.c_str(), 0), 0);
  const std::string what = list_error_as_unprivileged_user(closed + "/state");
  ::chmod(closed.c_str(), 0700);  // so TempDir can remove it
  if (what == kCannotDropRoot) GTEST_SKIP() << "running as root without the right to become another user";
  EXPECT_NE(what.find("cannot list sessions in '" + closed +
                      "/state': " + std::error_code(EACCES, std::generic_category()).message()),
            std::string::npos)
      << what;
}

// Lines of `text` that are not clean text (a control character, or bytes
// that are not UTF-8), each with the reason.
std::string unclean_lines(const std::string& text) {
  std::string bad;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);)
    if (const std::string why = util::why_not_clean_text(line); !why.empty()) bad += why + ": " + line + "\n";
  return bad;
}

std::size_t lines_starting_with(const std::string& text, const std::string& start) {
  std::size_t n = 0;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) n += line.rfind(start, 0) == 0;
  return n;
}

// A session file may hold anything in its strings (a foreign writer, an
// edit, damage), and a directory any file name: `info` and `list` printed
// them raw, so an escape sequence reached the terminal and a line break
// forged a line of the report. Every such byte now shows as \xNN; clean
// UTF-8 (the ü) stays as it is.
TEST(SessionTools, InfoAndListShowControlCharactersFromTheFileAsEscapes) {
  TempDir dir;
  const std::string d = dir / "state";
  std::filesystem::create_directories(d);
  SessionMetadata meta;
  meta.scene_name = "probe\x1b]0;owned\x07\nstate:            closed cleanly";
  meta.host_name = "lab\x1b[2Jhost";
  meta.software_version = "1.0\r\xc2\x9b";  // CR, then C1 CSI as UTF-8
  meta.start_time_utc = "2026-11-27T10:00:00Z\x1b[1A";
  const std::string path = d + "/run\x1b[31m\xffü.h5";  // ESC, a byte that is not UTF-8, clean UTF-8
  {
    auto w = SessionWriter::create(dir / "s.h5", meta);
    w->append_haptic(std::vector<HapticRow>{testing::haptic_row(0), testing::haptic_row(1)});
    w->close();
  }
  {
    // Repaired (not closed cleanly, flags clear), so repaired_utc is shown too.
    const hid_t file = testing::open_for_edit(dir / "s.h5");
    ASSERT_GE(file, 0);
    for (const char* name : {kAttrClosedCleanly, kAttrEndTime}) EXPECT_GE(H5Adelete(file, name), 0) << name;
    h5::write_u8_attribute(file, kAttrClosedCleanly, 0);
    h5::write_string_attribute(file, kAttrEndTime, "\x1b[8mend");
    h5::write_string_attribute(file, kAttrRepairedTime,
                               "2026-11-27\x9b"
                               "2J");  // a lone C1 byte
    H5Fclose(file);
  }
  std::filesystem::rename(dir / "s.h5", path);
  testing::write_bytes(d + "/empty\x1b[5m.h5", "");
  std::ofstream(d + "/.x.h5" + kCreatingInfix + "1-0\x1b[7m").flush();

  const std::string info = format_session_info(read_session_info(path));
  EXPECT_EQ(unclean_lines(info), "") << info;
  EXPECT_EQ(lines_starting_with(info, "state:"), 1u) << info;
  for (const char* expected : {"file:             " /* path follows */, "run\\x1B[31m\\xFFü.h5\n",
                               "scene:            probe\\x1B]0;owned\\x07\\x0Astate:            closed cleanly\n",
                               "host:             lab\\x1B[2Jhost\n", "software version: 1.0\\x0D\\xC2\\x9B\n",
                               "start time (UTC): 2026-11-27T10:00:00Z\\x1B[1A\n", "end time (UTC):   \\x1B[8mend\n",
                               "repaired 2026-11-27\\x9B2J\n"})
    EXPECT_NE(info.find(expected), std::string::npos) << expected << "\n" << info;

  const std::string list = format_session_listing(list_sessions(d));
  EXPECT_EQ(unclean_lines(list), "") << list;
  EXPECT_EQ(std::count(list.begin(), list.end(), '\n'), 1 + 1 + 1 + 1 + 1)
      << "title, header, 1 session, 1 unreadable, 1 unfinished\n"
      << list;
  for (const char* expected : {"run\\x1B[31m\\xFFü.h5 ", "2026-11-27T10:00:00Z\\x1B[1A ",
                               "probe\\x1B]0;owned\\x07\\x0Astate:", "empty\\x1B[5m.h5", "1-0\\x1B[7m"})
    EXPECT_NE(list.find(expected), std::string::npos) << expected << "\n" << list;

  // The CLI prints what the library formats: nothing raw reaches the terminal.
  const auto cli_info = run(tissue() + " session info " + quote(path), dir);
  EXPECT_EQ(cli_info.exit_code, 0) << cli_info.err;
  EXPECT_EQ(cli_info.out, info);
  const auto cli_list = run(tissue() + " session list " + quote(d), dir);
  EXPECT_EQ(cli_list.exit_code, 0) << cli_list.err;
  EXPECT_EQ(unclean_lines(cli_list.out), "") << cli_list.out;
}

TEST(SessionTools, CliBadArgumentsExitTwo) {
  TempDir dir;
  for (const char* args : {"session", "session info", "session repair", "session xdmf", "session frobnicate x.h5",
                           "session info a.h5 b.h5", "session xdmf a.h5 -o", "session list a b"}) {
    const auto r = run(tissue() + " " + args, dir);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.err;
  }
}

// Parses the sidecar with Python's XML parser and checks every HDF DataItem
// against the real dataset shape (h5py) and every hyperslab against it.
TEST(SessionTools, XdmfSidecarIsWellFormedAndMatchesTheDatasets) {
  TempDir dir;
  write_small_session(dir / "s.h5", 6);
  const XdmfReport report = write_xdmf(dir / "s.h5", "");
  EXPECT_EQ(report.out_path, dir / "s.xdmf");
  EXPECT_EQ(report.frames, 6u);
  const std::string xml = testing::slurp(report.out_path);
  EXPECT_NE(xml.find(">s.h5:/mesh/vertices_m<"), std::string::npos) << "HDF path should be relative to the sidecar";

  const std::string script = R"PY(
import sys, xml.etree.ElementTree as ET
root = ET.parse(sys.argv[1]).getroot()
assert root.tag == 'Xdmf', root.tag
coll = root.find('Domain/Grid')
assert coll.get('CollectionType') == 'Temporal'
grids = coll.findall('Grid')
times = [float(g.find('Time').get('Value')) for g in grids]
assert times == sorted(times), times
try:
    import h5py
except ImportError:
    h5py = None
checked = 0
for g in grids:
    ntri = int(g.find('Topology').get('NumberOfElements'))
    for slab in g.iter('DataItem'):
        if slab.get('ItemType') != 'HyperSlab':
            continue
        sel, data = slab.findall('DataItem')
        dims = [int(x) for x in data.get('Dimensions').split()]
        nums = [int(x) for x in sel.text.split()]
        rank = len(dims)
        start, stride, count = nums[:rank], nums[rank:2*rank], nums[2*rank:]
        assert [int(x) for x in slab.get('Dimensions').split()] == count, (slab.get('Dimensions'), count)
        assert all(s + c <= d for s, c, d in zip(start, count, dims)), (start, count, dims)
        fname, dpath = data.text.strip().rsplit(':', 1)
        if h5py is not None:
            import os
            with h5py.File(os.path.join(os.path.dirname(sys.argv[1]), fname), 'r') as f:
                assert list(f[dpath].shape) == dims, (dpath, f[dpath].shape, dims)
                if dpath == '/mesh/triangle_strain_energy_J_per_m3':
                    assert count[0] == ntri, (count, ntri)
                    strain = f[dpath][start[0]:start[0] + count[0]]
                    assert (strain >= 0).all(), strain
                if dpath == '/mesh/triangles':
                    assert count[0] == ntri
                    tri = f[dpath][start[0]:start[0] + count[0]]
                    nvert = int(g.find('Geometry/DataItem').get('Dimensions').split()[0])
                    assert tri.min() >= 0 and tri.max() < nvert
        checked += 1
for g in grids:
    cells = [a for a in g.findall('Attribute') if a.get('Name') == 'strain_energy_density_J_per_m3']
    assert len(cells) == 1 and cells[0].get('Center') == 'Cell', [a.attrib for a in g.findall('Attribute')]
print('ok', len(grids), checked, 'h5py' if h5py else 'no-h5py')
)PY";
  std::ofstream(dir / "check.py") << script;
  const auto r = run("/usr/bin/python3 " + quote(dir / "check.py") + " " + quote(report.out_path), dir);
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_EQ(r.out.substr(0, 10), "ok 6 24 h5") << r.out;  // 6 grids x 4 hyperslabs, checked against h5py

  const auto cli =
      run(tissue() + " session xdmf " + quote(dir / "s.h5") + " -o " + quote(dir / "out" + std::string(".xdmf")), dir);
  EXPECT_EQ(cli.exit_code, 0) << cli.err;
  EXPECT_NE(cli.out.find("6 mesh frames"), std::string::npos) << cli.out;
  EXPECT_EQ(testing::slurp(dir / "out.xdmf"), xml);
}

using testing::make_version_1;
using testing::open_for_edit;

TEST(SessionTools, InfoReportsThePerTriangleStrain) {
  TempDir dir;
  write_small_session(dir / "s.h5");
  const SessionInfo info = read_session_info(dir / "s.h5");
  EXPECT_EQ(info.format_version, kSessionFormatVersion);
  EXPECT_TRUE(info.has_strain);
  EXPECT_NE(format_session_info(info).find("strain energy density per triangle"), std::string::npos)
      << format_session_info(info);
}

TEST(SessionTools, VersionOneFilesWithoutStrainStillWork) {
  TempDir dir;
  write_small_session(dir / "s.h5", 4);
  make_version_1(dir / "s.h5");
  const SessionInfo info = read_session_info(dir / "s.h5");
  EXPECT_EQ(info.format_version, 1);
  EXPECT_FALSE(info.has_strain);
  EXPECT_EQ(info.rows.mesh_frames, 4u);
  EXPECT_GT(info.rows.mesh_triangles, 0u);
  EXPECT_NE(format_session_info(info).find("no strain (format version 1)"), std::string::npos);
  const RepairReport repair = repair_session(dir / "s.h5");
  EXPECT_FALSE(repair.repair_needed);
  const XdmfReport x = write_xdmf(dir / "s.h5", "");
  EXPECT_EQ(x.frames, 4u);
  const std::string xml = testing::slurp(x.out_path);
  EXPECT_EQ(xml.find("strain"), std::string::npos) << "a version-1 file has no strain to point at";
  EXPECT_NE(xml.find("vertex_level"), std::string::npos);
  const auto cli = run(tissue() + " session info " + quote(dir / "s.h5"), dir);
  EXPECT_EQ(cli.exit_code, 0) << cli.err;
  EXPECT_NE(cli.out.find("format version:   1"), std::string::npos) << cli.out;
}

TEST(SessionTools, AFutureFormatVersionIsRefusedByName) {
  TempDir dir;
  write_small_session(dir / "s.h5", 1);
  const hid_t file = open_for_edit(dir / "s.h5");
  ASSERT_GE(file, 0);
  ASSERT_GE(H5Adelete(file, kAttrFormatVersion), 0);
  h5::write_i64_attribute(file, kAttrFormatVersion, kSessionFormatVersion + 1);
  H5Fclose(file);
  try {
    read_session_info(dir / "s.h5");
    FAIL() << "accepted a newer format";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find("version " + std::to_string(kSessionFormatVersion + 1)), std::string::npos)
        << e.what();
  }
}

// The writer stores format_version as int64 and closed_cleanly as uint8
// (docs/session-format.md). HDF5 converts a floating-point attribute to an
// integer on read, truncating: format_version 2.5 read as 2, closed_cleanly
// 1.5 as 1 (clean). Another kind of value is refused by every tool, naming
// the file and the attribute; an integer of another width still reads.
TEST(SessionTools, RootIntegerAttributesHoldingAnotherKindOfValueAreRefusedByName) {
  TempDir dir;
  struct Case {
    const char* attribute;
    int kind;  // 0 float64, 1 string, 2 int64
    double value;
    const char* says;
  };
  int n = 0;
  for (const Case& c :
       {Case{kAttrFormatVersion, 0, 2.5, "root attribute format_version is a floating-point value (2.5), expected"},
        Case{kAttrFormatVersion, 0, 2.0, "root attribute format_version is a floating-point value (2), expected"},
        Case{kAttrFormatVersion, 1, 2.0, "root attribute format_version is a string, expected an integer"},
        Case{kAttrClosedCleanly, 0, 1.5, "root attribute closed_cleanly is a floating-point value (1.5), expected"},
        Case{kAttrClosedCleanly, 1, 1.0, "root attribute closed_cleanly is a string, expected an integer"},
        Case{kAttrClosedCleanly, 2, 7.0, "root attribute closed_cleanly is 7, expected 0 or 1"}}) {
    const std::string path = dir / ("attr" + std::to_string(++n) + ".h5");
    write_small_session(path, 2);
    const hid_t file = open_for_edit(path);
    ASSERT_GE(file, 0);
    ASSERT_GE(H5Adelete(file, c.attribute), 0);
    if (c.kind == 0) h5::write_f64_attribute(file, c.attribute, c.value);
    if (c.kind == 1) h5::write_string_attribute(file, c.attribute, std::to_string(static_cast<int>(c.value)));
    if (c.kind == 2) h5::write_i64_attribute(file, c.attribute, static_cast<std::int64_t>(c.value));
    H5Fclose(file);
    expect_every_tool_refuses(path, dir, c.says);
    const auto cli = run(tissue() + " session info " + quote(path), dir);
    EXPECT_EQ(cli.exit_code, 1) << cli.out;
    EXPECT_NE(cli.err.find("'" + path + "': " + c.says), std::string::npos) << cli.err;
  }
  // Integers of other widths are integers.
  const std::string narrow = dir / "narrow.h5";
  write_small_session(narrow, 2);
  const hid_t file = open_for_edit(narrow);
  ASSERT_GE(file, 0);
  ASSERT_GE(H5Adelete(file, kAttrFormatVersion), 0);
  h5::write_u8_attribute(file, kAttrFormatVersion, 2);
  H5Fclose(file);
  const SessionInfo info = read_session_info(narrow);
  EXPECT_EQ(info.format_version, 2);
  EXPECT_TRUE(info.closed_cleanly);
}

// A closed file whose strain column does not have one row per triangle is
// damaged: every tool says so, naming the file and the dataset.
TEST(SessionTools, StrainDatasetOfTheWrongLengthIsAClearError) {
  TempDir dir;
  const std::string strain = kDatasets[kMeshTriangleStrain].path;
  std::vector<std::string> files;
  for (const int delta : {-1, +3}) {
    const std::string path = dir / ("strain" + std::to_string(delta) + ".h5");
    write_small_session(path, 3);
    const hid_t file = open_for_edit(path);
    ASSERT_GE(file, 0);
    const hid_t ds = H5Dopen2(file, strain.c_str(), H5P_DEFAULT);
    ASSERT_GE(ds, 0);
    const std::int64_t rows = h5::rows(ds);
    ASSERT_GT(rows, 1);
    const hsize_t dims[1] = {static_cast<hsize_t>(rows + delta)};
    ASSERT_GE(H5Dset_extent(ds, dims), 0);
    H5Dclose(ds);
    H5Fclose(file);
    files.push_back(path);
  }
  {  // rank 2 instead of a column
    const std::string path = dir / "strain_rank2.h5";
    write_small_session(path, 3);
    const hid_t file = open_for_edit(path);
    ASSERT_GE(file, 0);
    ASSERT_GE(H5Ldelete(file, strain.c_str(), H5P_DEFAULT), 0);
    const hsize_t dims[2] = {4, 2};
    const hid_t space = H5Screate_simple(2, dims, nullptr);
    const hid_t ds = H5Dcreate2(file, strain.c_str(), H5T_IEEE_F32LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    ASSERT_GE(ds, 0);
    H5Dclose(ds);
    H5Sclose(space);
    H5Fclose(file);
    files.push_back(path);
  }
  for (const std::string& path : files) {
    expect_every_tool_refuses(path, dir, strain);
    const auto cli = run(tissue() + " session info " + quote(path), dir);
    EXPECT_EQ(cli.exit_code, 1) << cli.err;
    EXPECT_NE(cli.err.find(strain), std::string::npos) << cli.err;
    EXPECT_EQ(cli.err.find("HDF5-DIAG"), std::string::npos) << cli.err;
  }
}

// ---------------------------------------------------------------- readers

TEST(SessionReader, ReadsBackEveryRecordedRow) {
  TempDir dir;
  testing::TestSession content;
  content.sim = 75;
  const SessionRows rows = read_session_rows(testing::write_test_session(dir / "s.h5", content));
  ASSERT_EQ(rows.haptic.size(), 1500u);
  ASSERT_EQ(rows.sim.size(), 75u);
  for (std::uint64_t i = 0; i < rows.haptic.size(); ++i)
    ASSERT_TRUE(testing::same_row(rows.haptic[i], testing::haptic_row(i))) << "haptic row " << i;
  for (std::uint64_t i = 0; i < rows.sim.size(); ++i)
    ASSERT_TRUE(testing::same_row(rows.sim[i], testing::sim_row(i))) << "sim row " << i;
}

TEST(SessionReader, HapticTrackIsTheRecordedHandMotion) {
  TempDir dir;
  const HapticTrack track = read_haptic_track(testing::write_test_session(dir / "s.h5"));
  ASSERT_EQ(track.time_s.size(), 1500u);
  ASSERT_EQ(track.device_position_m.size(), 1500u);
  ASSERT_EQ(track.force_N.size(), 1500u);
  ASSERT_EQ(track.device_fresh.size(), 1500u) << "format version 3 records which ticks had a new device sample";
  for (std::uint64_t i = 0; i < 1500; ++i) {
    const HapticRow r = testing::haptic_row(i);
    ASSERT_TRUE(track.time_s[i] == r.time_s && track.device_position_m[i] == r.device_position_m &&
                track.force_N[i] == r.force_N && track.device_fresh[i] == r.device_fresh)
        << "row " << i;
  }
  testing::TestSession no_hand;
  no_hand.haptic = 0;
  const std::string empty = testing::write_test_session(dir / "no_haptic.h5", no_hand);
  try {
    read_haptic_track(empty);
    FAIL() << "a session without haptic rows gave a track";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find(empty), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("no haptic rows"), std::string::npos) << e.what();
  }
}

// /haptic/device_fresh (format version 3) says on which ticks the device
// delivered a new sample: written from each row's flag and read back as
// written, by the row readers and the replay device's track; info says the
// file has it.
TEST(SessionReader, TheDeviceFreshFlagRoundTrips) {
  TempDir dir;
  const std::string path = testing::write_test_session(dir / "s.h5");
  const SessionInfo info = read_session_info(path);
  EXPECT_EQ(info.format_version, 3);
  EXPECT_TRUE(info.has_device_fresh);
  EXPECT_NE(format_session_info(info).find("1500 ticks, each flagged when a new device sample came"), std::string::npos)
      << format_session_info(info);
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  const std::vector<std::uint8_t> stored = testing::read_u8(file, kDatasets[kHapticDeviceFresh].path);
  H5Fclose(file);
  ASSERT_EQ(stored.size(), 1500u);
  const SessionRows rows = read_session_rows(path);
  const HapticTrack track = read_haptic_track(path);
  ASSERT_EQ(rows.haptic.size(), 1500u);
  ASSERT_EQ(track.device_fresh.size(), 1500u);
  std::uint64_t fresh = 0;
  for (std::uint64_t i = 0; i < 1500; ++i) {
    const std::uint8_t want = testing::haptic_row(i).device_fresh;
    ASSERT_EQ(stored[i], want) << "row " << i;
    ASSERT_EQ(rows.haptic[i].device_fresh, want) << "row " << i;
    ASSERT_EQ(track.device_fresh[i], want) << "row " << i;
    fresh += want;
  }
  EXPECT_EQ(fresh, 375u) << "every fourth row: the flag is not all 0 or all 1";
}

// A session of format version 2 (or 1) has no /haptic/device_fresh: it
// still reads, its track says the flags are unknown (empty: the replay
// device keeps its old rule for it), and info says what it lacks.
TEST(SessionReader, AFileWithoutTheDeviceFreshColumnStillReads) {
  TempDir dir;
  for (const int version : {1, 2}) {
    SCOPED_TRACE(version);
    const std::string path = dir / ("v" + std::to_string(version) + ".h5");
    testing::write_test_session(path);
    if (version == 1) testing::make_version_1(path);
    if (version == 2) testing::make_version_2(path);
    const SessionInfo info = read_session_info(path);
    EXPECT_EQ(info.format_version, version);
    EXPECT_FALSE(info.has_device_fresh);
    EXPECT_EQ(info.rows.haptic_rows, 1500u);
    EXPECT_NE(format_session_info(info).find("1500 ticks, no device_fresh flags (format version " +
                                             std::to_string(version) + ")"),
              std::string::npos)
        << format_session_info(info);
    const SessionRows rows = read_session_rows(path);
    ASSERT_EQ(rows.haptic.size(), 1500u);
    for (const HapticRow& r : rows.haptic) ASSERT_EQ(r.device_fresh, 0) << "not recorded: 0";
    const HapticTrack track = read_haptic_track(path);
    ASSERT_EQ(track.time_s.size(), 1500u);
    EXPECT_TRUE(track.device_fresh.empty()) << "unknown, not 'never fresh'";
    for (std::uint64_t i = 0; i < 1500; ++i)
      ASSERT_EQ(track.device_position_m[i], testing::haptic_row(i).device_position_m) << "row " << i;
    EXPECT_FALSE(repair_session(path).repair_needed);
  }
}

// A damaged /haptic/device_fresh is an error naming the file and the dataset
// (and the row, for a value): stored as floating point, as a table instead
// of a column, missing from a version-3 file, or holding a value that is not
// a flag. A replay must not guess from a column it cannot trust.
TEST(SessionReader, ADamagedDeviceFreshColumnIsAClearError) {
  TempDir dir;
  const std::string fresh = kDatasets[kHapticDeviceFresh].path;
  struct Case {
    const char* name;
    const char* says;
    bool every_tool;  // or only the row readers (info and repair do not read values)
  };
  for (const Case& c :
       {Case{"float", "dataset /haptic/device_fresh stores floating-point values, expected integer", true},
        Case{"table", "dataset /haptic/device_fresh has shape (1500 x 2), rank 2, expected rank 1", true},
        Case{"missing", "dataset /haptic/device_fresh is missing", true},
        Case{"value", "/haptic/device_fresh is 7 at row 42: a flag is 0 or 1", false}}) {
    SCOPED_TRACE(c.name);
    const std::string path = dir / (std::string(c.name) + ".h5");
    testing::write_test_session(path);
    if (std::string(c.name) == "value") {
      const std::uint8_t seven = 7;
      testing::overwrite_element(path, fresh.c_str(), 42, 0, H5T_NATIVE_UINT8, &seven);
    } else {
      const hid_t file = testing::open_for_edit(path);
      ASSERT_GE(file, 0);
      ASSERT_GE(H5Ldelete(file, fresh.c_str(), H5P_DEFAULT), 0);
      if (std::string(c.name) != "missing") {
        const bool table = std::string(c.name) == "table";
        const hsize_t dims[2] = {1500, 2};
        const hid_t space = H5Screate_simple(table ? 2 : 1, dims, nullptr);
        const hid_t ds = H5Dcreate2(file, fresh.c_str(), table ? H5T_STD_U8LE : H5T_IEEE_F64LE, space, H5P_DEFAULT,
                                    H5P_DEFAULT, H5P_DEFAULT);
        ASSERT_GE(ds, 0);
        H5Dclose(ds);
        H5Sclose(space);
      }
      H5Fclose(file);
    }
    if (c.every_tool) {
      expect_every_tool_refuses(path, dir, c.says);
      const auto cli = run(tissue() + " session info " + quote(path), dir);
      EXPECT_EQ(cli.exit_code, 1) << cli.out;
      EXPECT_NE(cli.err.find("'" + path + "': " + c.says), std::string::npos) << cli.err;
      EXPECT_EQ(cli.err.find("HDF5-DIAG"), std::string::npos) << cli.err;
    }
    for (int reader = 0; reader < 2; ++reader) {
      try {
        if (reader == 0) read_session_rows(path);
        if (reader == 1) read_haptic_track(path);
        ADD_FAILURE() << "reader " << reader << " accepted it";
      } catch (const RecordError& e) {
        EXPECT_NE(std::string(e.what()).find("'" + path + "': " + c.says), std::string::npos) << e.what();
      }
    }
  }
}

// Replay paces by the session times and the replay device interpolates
// between them: a NaN or a step back is an error naming the file, the
// dataset and the row.
TEST(SessionReader, TimesThatAreNotFiniteOrGoBackAreClearErrors) {
  TempDir dir;
  struct Damage {
    DatasetId id;
    std::uint64_t row;
    double value;
  };
  for (const Damage d : {Damage{kHapticTime, 10, std::numeric_limits<double>::quiet_NaN()},
                         Damage{kHapticTime, 700, 0.5}, Damage{kSimTime, 5, -1.0}}) {
    const char* dataset = kDatasets[d.id].path;
    // (No "literal" + std::string here: GCC 12 warns falsely, -Wrestrict, on that at -O3.)
    const std::string path = dir / (std::to_string(d.id) + "_" + std::to_string(d.row) + ".h5");
    SCOPED_TRACE(path);
    testing::write_test_session(path);
    testing::overwrite_f64(path, dataset, d.row, d.value);
    for (int reader = 0; reader < 2; ++reader) {
      if (reader == 1 && d.id != kHapticTime) continue;  // the track reads only /haptic
      try {
        if (reader == 0) read_session_rows(path);
        if (reader == 1) read_haptic_track(path);
        ADD_FAILURE() << "reader " << reader << " accepted " << dataset << "[" << d.row << "] = " << d.value;
      } catch (const RecordError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(path), std::string::npos) << what;
        EXPECT_NE(what.find(dataset), std::string::npos) << what;
        EXPECT_NE(what.find("row " + std::to_string(d.row)), std::string::npos) << what;
      }
    }
  }
}

TEST(SessionReader, RowsOutsideADatasetAreAClearErrorNotAReadPastItsEnd) {
  TempDir dir;
  const std::string path = testing::write_test_session(dir / "s.h5");
  const SessionFile file(path);
  EXPECT_EQ(file.info().rows.haptic_rows, 1500u);
  EXPECT_EQ(file.rows<double>(kHapticTime, 1490, 10).back(), testing::haptic_row(1499).time_s);
  const std::vector<double> force = file.rows<double>(kHapticForce, 2, 1);  // N x 3: one row is 3 values
  ASSERT_EQ(force.size(), 3u);
  EXPECT_EQ((std::array<double, 3>{force[0], force[1], force[2]}), testing::haptic_row(2).force_N);
  try {
    file.rows<double>(kHapticTime, 1490, 20);
    FAIL() << "read rows 1490 to 1510 of a 1500-row dataset";
  } catch (const RecordError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path), std::string::npos) << what;
    EXPECT_NE(what.find("/haptic/time_s"), std::string::npos) << what;
    EXPECT_NE(what.find("rows 1490 to 1510"), std::string::npos) << what;
  }
}

// ---------------------------------------------------------------- damaged files

// Overwrites row `row` of a 1-D uint64 dataset of a closed session.
void overwrite_u64(const std::string& path, const char* dataset, std::uint64_t row, std::uint64_t value) {
  const hid_t file = testing::open_for_edit(path);
  ASSERT_GE(file, 0) << path;
  const hid_t ds = H5Dopen2(file, dataset, H5P_DEFAULT);
  ASSERT_GE(ds, 0) << dataset;
  const hid_t space = H5Dget_space(ds);
  const hsize_t start[1] = {row}, one[1] = {1};
  H5Sselect_hyperslab(space, H5S_SELECT_SET, start, nullptr, one, nullptr);
  const hid_t mem = H5Screate_simple(1, one, nullptr);
  EXPECT_GE(H5Dwrite(ds, H5T_NATIVE_UINT64, mem, space, H5P_DEFAULT, &value), 0);
  H5Sclose(mem);
  H5Sclose(space);
  H5Dclose(ds);
  H5Fclose(file);
}

// Replaces `dataset` by an empty-valued one of the given type and shape.
void recreate(const std::string& path, const char* dataset, hid_t type, std::vector<hsize_t> dims) {
  const hid_t file = testing::open_for_edit(path);
  ASSERT_GE(file, 0) << path;
  ASSERT_GE(H5Ldelete(file, dataset, H5P_DEFAULT), 0);
  const hid_t space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr);
  const hid_t ds = H5Dcreate2(file, dataset, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(ds, 0) << dataset;
  H5Dclose(ds);
  H5Sclose(space);
  H5Fclose(file);
}

// A SWMR reader retries a metadata read whose checksum fails, doubling its
// sleep each time; with HDF5's default number of attempts one bad byte in a
// crashed session hung every reader for good. Now it is an error naming the
// file, well within a generous deadline (the reader runs under `timeout`, so
// a hang fails the test instead of stalling it).
TEST(SessionTools, CorruptMetadataInACrashedSessionIsAnErrorNotAHang) {
  TempDir dir;
  const std::string crashed = dir / "crashed.h5";
  testing::write_crashed_session(crashed, 300, 3);
  ASSERT_TRUE(read_session_info(crashed).open_for_write_flag);
  std::string bytes = testing::slurp(crashed);
  // Version-2 object headers ("OHDR") end in a checksum over the whole block;
  // 40 bytes in is past the longest prefix (34 bytes), inside the messages.
  std::vector<std::size_t> headers;
  for (std::size_t at = bytes.find("OHDR"); at != std::string::npos; at = bytes.find("OHDR", at + 4))
    headers.push_back(at);
  ASSERT_GE(headers.size(), 10u);
  // The root group's header (read by the open) and a dataset's (read by info).
  for (const std::size_t header : {headers[0], headers[9]}) {
    const std::string path = dir / ("bad_" + std::to_string(header) + ".h5");
    std::string damaged = bytes;
    damaged[header + 40] = static_cast<char>(damaged[header + 40] ^ 0x5a);
    testing::write_bytes(path, damaged);
    for (const std::string& cmd : {std::string("session info"), "x3d -o " + quote(dir / "o.x3d") + " --session"}) {
      SCOPED_TRACE(cmd + " " + path);
      const auto start = std::chrono::steady_clock::now();
      // detect_leaks=0 (ASan tree only): after a checksum failure HDF5 cannot
      // evict the entry it failed to load ("HDF5: infinite loop closing
      // library" at exit) and keeps 424 bytes of its own; the failure is
      // HDF5's, the error path ours is what this test checks.
      const auto r = run("ASAN_OPTIONS=\"${ASAN_OPTIONS:-}:detect_leaks=0\" timeout -s KILL 60 " + tissue() + " " +
                             cmd + " " + quote(path),
                         dir);
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      EXPECT_EQ(r.exit_code, 1) << "took " << seconds << " s (killed after 60 s: a hang)\n" << r.err;
      EXPECT_LT(seconds, 50.0);
      EXPECT_NE(r.err.find("'" + path + "'"), std::string::npos) << r.err;
      EXPECT_NE(r.err.find("checksum"), std::string::npos) << r.err;
    }
  }
}

// Row `row` of frame-index dataset `id` overwritten with `value`; what the
// tools must then say.
struct Damage {
  DatasetId id;
  std::uint64_t row, value;
  const char* says;
};

// In a closed file every frame's index row was written with its data: a
// broken one is damage every tool reports (naming the dataset and row),
// not a shorter session (10 of 46 frames, exit 0).
TEST(SessionTools, ABrokenFrameIndexInAClosedFileIsAnErrorNamingTheRow) {
  TempDir dir;
  for (const Damage d :
       {Damage{kMeshVertexOffset, 2, std::uint64_t{1} << 40, "/mesh/vertex_offset[2] is 1099511627776"},
        Damage{kMeshTriangleOffset, 3, 1, "/mesh/triangle_offset[3] is 1, expected"},
        Damage{kMeshVertexCount, 4, 1000000, "/mesh/vertex_count[4] is 1000000: past the end"},
        Damage{kMeshTriangleCount, 1, 1000000, "/mesh/triangle_count[1] is 1000000: past the end"}}) {
    const std::string path = dir / ("index" + std::to_string(d.id) + ".h5");
    write_small_session(path, 5);
    overwrite_u64(path, kDatasets[d.id].path, d.row, d.value);
    expect_every_tool_refuses(path, dir, d.says);
    const auto cli = run(tissue() + " session info " + quote(path), dir);
    EXPECT_EQ(cli.exit_code, 1) << cli.out;
    EXPECT_NE(cli.err.find(d.says), std::string::npos) << cli.err;
  }
}

// Overwrites row `row` of the 1-D uint64 dataset `id` of a session still
// marked open for writing (HDF5 opens such a file for reading only), in the
// raw bytes of its chunk, as a flipped byte on disk would change it.
void overwrite_u64_in_crashed(const std::string& path, DatasetId id, std::uint64_t row, std::uint64_t value) {
  const hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY | H5F_ACC_SWMR_READ, fapl);
  H5Pclose(fapl);
  ASSERT_GE(file, 0) << path;
  const hid_t ds = H5Dopen2(file, kDatasets[id].path, H5P_DEFAULT);
  ASSERT_GE(ds, 0) << kDatasets[id].path;
  const hid_t space = H5Dget_space(ds);
  hsize_t offset[1] = {};
  unsigned filter_mask = 0;
  haddr_t address = 0;
  hsize_t bytes = 0;
  const herr_t got = H5Dget_chunk_info(ds, space, 0, offset, &filter_mask, &address, &bytes);
  H5Sclose(space);
  H5Dclose(ds);
  H5Fclose(file);
  ASSERT_GE(got, 0) << kDatasets[id].path;
  ASSERT_EQ(offset[0], 0u) << "the first chunk holds row 0";
  ASSERT_GE(bytes, (row + 1) * sizeof value);
  std::string content = testing::slurp(path);
  ASSERT_LE(address + bytes, content.size());
  std::memcpy(content.data() + address + row * sizeof value, &value, sizeof value);  // little-endian, as stored
  testing::write_bytes(path, content);
}

// A crash can only leave the last index rows ahead of their data (the writer
// flushes the data first), so a crashed file's index that breaks off with
// rows after the break is damage: every tool said "2 frames" and repair cut
// every mesh dataset to them, deleting the later frames for good. Now each
// reader names the row, and repair refuses before it opens the file for
// writing: the file keeps every byte.
TEST(SessionTools, ABrokenFrameIndexWithFramesAfterItInACrashedFileIsRefusedAndKept) {
  TempDir dir;
  for (const Damage d :
       {Damage{kMeshTriangleOffset, 2, 7, "/mesh/triangle_offset[2] is 7, expected"},
        Damage{kMeshVertexOffset, 2, std::uint64_t{1} << 40, "/mesh/vertex_offset[2] is 1099511627776, expected"},
        // A count past the data is a crash tail only when it is the last
        // frame's: the next frame's offset does not continue it.
        Damage{kMeshVertexCount, 2, 1000000, "/mesh/vertex_offset[3] is "},
        Damage{kMeshTriangleCount, 2, 1000000, "after /mesh/triangle_count[2], which is 1000000: past the end"},
        // The last frame's, yet no writer's: no file holds that many rows.
        Damage{kMeshVertexCount, 5, UINT64_MAX - 1, "/mesh/vertex_count[5] is 18446744073709551614: more rows"},
        // Nor this many vertices: the writer refuses a frame its int32
        // triangle indices cannot reach (read as a crash tail: 5 frames).
        Damage{kMeshVertexCount, 5, kMaxMeshFrameVertices + 1,
               "/mesh/vertex_count[5] is 2147483648: more vertices than"}}) {
    const std::string path =
        dir / ("crashed" + std::to_string(d.id) + "_" + std::to_string(d.row) + "_" + std::to_string(d.value) + ".h5");
    testing::write_crashed_session(path, 100, 6);
    ASSERT_EQ(read_session_info(path).rows.mesh_frames, 6u);
    overwrite_u64_in_crashed(path, d.id, d.row, d.value);
    const std::string before = testing::slurp(path);
    SCOPED_TRACE(kDatasets[d.id].path);
    for (const auto& [tool, call] : std::vector<std::pair<const char*, std::function<void()>>>{
             {"info", [&] { read_session_info(path); }}, {"repair", [&] { repair_session(path); }}}) {
      try {
        call();
        ADD_FAILURE() << tool << " accepted " << path << ": " << read_session_info(path).rows.mesh_frames << " frames";
      } catch (const RecordError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("'" + path + "'"), std::string::npos) << tool << ": " << what;
        EXPECT_NE(what.find(d.says), std::string::npos) << tool << ": " << what;
        EXPECT_NE(what.find("corrupt frame index"), std::string::npos) << tool << ": " << what;
      }
    }
    EXPECT_TRUE(testing::slurp(path) == before) << "repair changed the file";
    const auto cli = run(tissue() + " session repair " + quote(path), dir);
    EXPECT_EQ(cli.exit_code, 1) << cli.out;
    EXPECT_NE(cli.err.find(d.says), std::string::npos) << cli.err;
    EXPECT_TRUE(testing::slurp(path) == before) << "`tissue session repair` changed the file";
  }
}

// Triangles index their frame's vertices with int32, so no writer makes a
// frame of more than 2^31 - 1 vertices; a count beyond that is damage even
// where the data extents (damaged too, chunks never written) make room for
// it. Only the frame source bounded it, as it read the frame; info, repair
// and the row readers took the file, and xdmf went on to read the frame.
// Now the one reader refuses it at open, naming the index row, before
// anything is read for the frame.
TEST(SessionTools, AVertexCountPastWhatTriangleIndicesReachIsRefusedNamingTheRow) {
  TempDir dir;
  const std::string path = dir / "huge_frame.h5";
  write_small_session(path, 5);
  std::uint64_t v4 = 0;  // where frame 4 starts
  for (std::uint64_t f = 0; f < 4; ++f) v4 += testing::test_frame(f).vertices_m.size();
  const std::uint64_t count = kMaxMeshFrameVertices + 1;
  overwrite_u64(path, kDatasets[kMeshVertexCount].path, 4, count);
  {
    const hid_t file = testing::open_for_edit(path);
    ASSERT_GE(file, 0);
    for (const DatasetId id : {kMeshVertices, kMeshVertexLevel}) {
      const hid_t ds = H5Dopen2(file, kDatasets[id].path, H5P_DEFAULT);
      const hsize_t dims[2] = {v4 + count, static_cast<hsize_t>(kDatasets[id].columns)};
      EXPECT_GE(H5Dset_extent(ds, dims), 0) << kDatasets[id].path;
      H5Dclose(ds);
    }
    H5Fclose(file);
  }
  ASSERT_LT(std::filesystem::file_size(path), 10u << 20);
  const std::string says = "/mesh/vertex_count[4] is 2147483648: more vertices than a frame's int32 triangle indices";
  expect_every_tool_refuses(path, dir, says);
  const auto cli = run(tissue() + " session xdmf " + quote(path), dir);
  EXPECT_EQ(cli.exit_code, 1) << cli.out;
  EXPECT_NE(cli.err.find(says), std::string::npos) << cli.err;
}

// Cuts dataset `id` of a closed session to `rows` rows (its other columns
// keep theirs), as a crash between two column writes leaves it.
void shorten(const std::string& path, DatasetId id, std::uint64_t rows) {
  const hid_t file = testing::open_for_edit(path);
  ASSERT_GE(file, 0) << path;
  const hid_t ds = H5Dopen2(file, kDatasets[id].path, H5P_DEFAULT);
  ASSERT_GE(ds, 0) << kDatasets[id].path;
  const hsize_t dims[2] = {rows, static_cast<hsize_t>(kDatasets[id].columns)};
  EXPECT_GE(H5Dset_extent(ds, dims), 0);
  H5Dclose(ds);
  H5Fclose(file);
}

// docs/session-format.md: readers use the shortest column of a group as its
// row count, whichever column it is (the event kind is written first, the
// time last).
TEST(SessionTools, EachGroupCountsTheRowsOfItsShortestColumn) {
  TempDir dir;
  testing::TestSession content;
  content.events = 4;
  struct Cut {
    DatasetId id;
    std::uint64_t rows;
    std::uint64_t GroupCounts::*count;
  };
  for (const Cut& c : {Cut{kHapticForce, 1200, &GroupCounts::haptic_rows}, Cut{kSimNodes, 30, &GroupCounts::sim_rows},
                       Cut{kEventMessage, 3, &GroupCounts::events}, Cut{kEventTime, 2, &GroupCounts::events}}) {
    const std::string path = dir / ("short" + std::to_string(c.id) + ".h5");
    testing::write_test_session(path, content);
    shorten(path, c.id, c.rows);
    EXPECT_EQ(read_session_info(path).rows.*c.count, c.rows) << kDatasets[c.id].path;
  }
}

// A frame is complete when offset + count fits inside every data column of
// the vertices: a /mesh/vertex_level one row short makes the last frame's
// count run past it, which a closed file reports as damage naming the row
// (a frame read with it would read levels that are not there).
TEST(SessionTools, AVertexLevelColumnShorterThanTheFramesIsAnErrorNamingTheFrame) {
  TempDir dir;
  const std::string path = dir / "levels.h5";
  write_small_session(path, 5);
  const std::uint64_t vertices = read_session_info(path).rows.mesh_vertices;
  shorten(path, kMeshVertexLevel, vertices - 1);
  expect_every_tool_refuses(path, dir, "/mesh/vertex_count[4] is ");
  expect_every_tool_refuses(path, dir, "(/mesh/vertices_m, /mesh/vertex_level)");
}

// A closed session as `h5clear -s` leaves a crashed one: closed_cleanly 0,
// flags clear, no repaired_utc ("NOT closed cleanly").
void mark_not_closed_cleanly(const std::string& path) {
  const hid_t file = testing::open_for_edit(path);
  ASSERT_GE(file, 0) << path;
  ASSERT_GE(H5Adelete(file, kAttrClosedCleanly), 0);
  h5::write_u8_attribute(file, kAttrClosedCleanly, 0);
  H5Fclose(file);
}

// `h5clear -s --increment` on a crashed session clears the superblock's
// flags but leaves its columns as the crash did: closed_cleanly 0, no
// repaired_utc ("NOT closed cleanly"). Repair does what h5clear does and
// more, so it trims such a file too, by the crash rules: it refused one
// whose strain column was a write short of the triangles (a crash between
// the two writes) as corrupt, though every frame before the last is whole.
TEST(SessionTools, RepairTrimsAFileLeftNotClosedCleanlyToItsLastCompleteFrame) {
  TempDir dir;
  struct Crash {
    const char* name;
    std::vector<DatasetId> cut;  // each loses its rows of the frames from `kept` on
    std::uint64_t kept;          // complete frames left
  };
  for (const Crash& c : {Crash{"strain a write short", {kMeshTriangleStrain}, 4},
                         Crash{"the last two frames' vertices missing", {kMeshVertices, kMeshVertexLevel}, 3}}) {
    SCOPED_TRACE(c.name);
    const std::string path = dir / (std::to_string(c.kept) + ".h5");
    write_small_session(path, 5);
    const SessionInfo whole = read_session_info(path);
    std::uint64_t vertices = 0, triangles = 0;  // of frames 0 .. kept-1
    for (std::uint64_t f = 0; f < c.kept; ++f) {
      vertices += testing::test_frame(f).vertices_m.size();
      triangles += testing::test_frame(f).triangles.size();
    }
    for (const DatasetId id : c.cut) shorten(path, id, id == kMeshTriangleStrain ? triangles : vertices);
    mark_not_closed_cleanly(path);

    const RepairReport report = repair_session(path);
    EXPECT_TRUE(report.repair_needed);
    EXPECT_EQ(report.before.mesh_frames, c.kept);
    EXPECT_EQ(report.after.rows.mesh_frames, c.kept);
    EXPECT_EQ(report.after.rows.mesh_vertices, vertices);
    EXPECT_EQ(report.after.rows.mesh_triangles, triangles);
    EXPECT_EQ(report.after.rows.haptic_rows, whole.rows.haptic_rows) << "other groups keep every row";
    EXPECT_EQ(report.after.rows.sim_rows, whole.rows.sim_rows);
    EXPECT_EQ(session_state(report.after), SessionState::kRepaired);
    for (const std::uint64_t n : report.after.unreferenced_rows) EXPECT_EQ(n, 0u);
    // The frames kept are whole: their strain reads back as written.
    const SessionFile file(path);
    std::uint64_t t0 = 0;
    for (std::uint64_t f = 0; f < c.kept; ++f) {
      const testing::TestFrame frame = testing::test_frame(f);
      EXPECT_EQ(file.rows<float>(kMeshTriangleStrain, t0, frame.triangles.size()),
                frame.triangle_strain_energy_J_per_m3)
          << "frame " << f;
      t0 += frame.triangles.size();
    }
  }
}

// What `tissue session info` and `list` say of a file a crash left uneven
// (columns or mesh data past the complete rows, or the last frames' index
// rows ahead of their data): `repair` trims it, and they now say so, for a
// file still marked open (left by a crash) and for one whose flags were
// cleared without a repair ("NOT closed cleanly"; its readers refuse a
// frame index ahead of the data, and the refusal says so). Before, a file
// in the second state read as "NOT closed cleanly" with "unreferenced rows"
// or as "corrupt frame index", with no word of repair. Not for damage
// repair refuses, nor for a clean or even file.
TEST(SessionTools, InfoAndListSayThatRepairTrimsASessionACrashLeftUneven) {
  TempDir dir;
  const std::string d = dir / "state";
  std::filesystem::create_directories(d);
  const std::string hint = "`tissue session repair FILE` trims it to its last complete frame";
  std::uint64_t v3 = 0;  // vertices of frames 0 .. 2
  for (std::uint64_t f = 0; f < 3; ++f) v3 += testing::test_frame(f).vertices_m.size();

  // Open for writing, no recorder: the last frame's count past the data.
  const std::string crashed = d + "/crashed.h5";
  testing::write_crashed_session(crashed, 100, 6);
  overwrite_u64_in_crashed(crashed, kMeshVertexCount, 5, testing::test_frame(5).vertices_m.size() + 1);
  // Flags cleared, not repaired: a column past its group (rows read fine).
  const std::string uneven = d + "/uneven.h5";
  write_small_session(uneven, 5);
  shorten(uneven, kHapticForce, 1200);
  mark_not_closed_cleanly(uneven);
  // Flags cleared, not repaired: the last two frames' index ahead of the data.
  const std::string tail = d + "/tail.h5";
  write_small_session(tail, 5);
  shorten(tail, kMeshVertices, v3);
  shorten(tail, kMeshVertexLevel, v3);
  mark_not_closed_cleanly(tail);
  // Not for these: even, closed cleanly (its extra rows are not a crash's),
  // and damage repair refuses.
  const std::string even = d + "/even.h5";
  write_small_session(even, 5);
  mark_not_closed_cleanly(even);
  const std::string closed = d + "/closed.h5";
  write_small_session(closed, 5);
  shorten(closed, kHapticForce, 1200);
  const std::string damaged = d + "/damaged.h5";
  write_small_session(damaged, 5);
  overwrite_u64(damaged, kDatasets[kMeshTriangleOffset].path, 2, 7);
  mark_not_closed_cleanly(damaged);

  for (const std::string& path : {crashed, uneven}) {
    SCOPED_TRACE(path);
    const auto cli = run(tissue() + " session info " + quote(path), dir);
    EXPECT_EQ(cli.exit_code, 0) << cli.err;
    EXPECT_NE(cli.out.find(hint), std::string::npos) << cli.out;
  }
  EXPECT_EQ(read_session_info(crashed).rows.mesh_frames, 5u);
  const auto refused = run(tissue() + " session info " + quote(tail), dir);
  EXPECT_EQ(refused.exit_code, 1) << refused.out;
  EXPECT_NE(refused.err.find("/mesh/vertex_count[3] is "), std::string::npos) << refused.err;
  EXPECT_NE(refused.err.find(hint), std::string::npos) << refused.err;
  for (const std::string& path : {even, closed, damaged}) {
    SCOPED_TRACE(path);
    const auto cli = run(tissue() + " session info " + quote(path), dir);
    EXPECT_EQ(cli.exit_code, path == damaged ? 1 : 0) << cli.out << cli.err;
    EXPECT_EQ((cli.out + cli.err).find("session repair"), std::string::npos) << cli.out << cli.err;
  }

  const auto list = run(tissue() + " session list " + quote(d), dir);
  EXPECT_EQ(list.exit_code, 0) << list.err;
  const auto line_of = [&](const std::string& start) {
    const std::size_t at = ("\n" + list.out).find("\n" + start);  // at the start of a line
    return at == std::string::npos ? std::string() : list.out.substr(at, list.out.find('\n', at) - at);
  };
  EXPECT_NE(line_of("crashed.h5 ").find("OPEN (crashed)"), std::string::npos) << list.out;
  EXPECT_NE(line_of("uneven.h5 ").find("NOT closed (crash tail)"), std::string::npos) << list.out;
  EXPECT_NE(line_of("even.h5 ").find("NOT closed cleanly"), std::string::npos) << list.out;
  EXPECT_NE(line_of("unreadable: '" + tail + "'").find(hint), std::string::npos) << list.out;
  EXPECT_NE(line_of("unreadable: '" + damaged + "'"), "") << list.out;
  EXPECT_EQ(line_of("unreadable: '" + damaged + "'").find("repair"), std::string::npos) << list.out;
  EXPECT_NE(line_of("OPEN (crashed): ").find(hint), std::string::npos) << list.out;
  EXPECT_NE(line_of("NOT closed (crash tail): ").find(hint), std::string::npos) << list.out;
}

// Extents of 2^36 rows (chunks never written, so the file stays small) must
// be refused before a read allocates for them (a bare std::bad_alloc, or
// gigabytes and a minute for 1e8 rows).
TEST(SessionTools, AnIndexExtentTheFileCannotHoldIsAnErrorNotAnAllocation) {
  TempDir dir;
  const std::string path = dir / "huge.h5";
  write_small_session(path, 5);
  {
    const hid_t file = testing::open_for_edit(path);
    ASSERT_GE(file, 0);
    for (const DatasetId id :
         {kMeshVertexOffset, kMeshVertexCount, kMeshTriangleOffset, kMeshTriangleCount, kMeshFrameTime}) {
      const hid_t ds = H5Dopen2(file, kDatasets[id].path, H5P_DEFAULT);
      const hsize_t dims[1] = {hsize_t{1} << 36};
      EXPECT_GE(H5Dset_extent(ds, dims), 0);
      H5Dclose(ds);
    }
    H5Fclose(file);
  }
  ASSERT_LT(std::filesystem::file_size(path), 10u << 20);
  expect_every_tool_refuses(path, dir, "more than the whole file");
  const auto cli = run(tissue() + " session info " + quote(path), dir);
  EXPECT_EQ(cli.exit_code, 1) << cli.out;
  EXPECT_NE(cli.err.find("'" + path + "': dataset /mesh/vertex_offset"), std::string::npos) << cli.err;
}

// Every reader checks the shape and type class of the columns it reads, not
// only the rank: a V x 2 vertex table read 3 values a row is garbage.
TEST(SessionTools, ColumnsOfTheWrongShapeOrTypeAreRefusedNamingTheDataset) {
  TempDir dir;
  struct Damage {
    DatasetId id;
    hid_t type;
    std::vector<hsize_t> dims;
    const char* says;
  };
  const hid_t text = H5Tcopy(H5T_C_S1);
  H5Tset_size(text, 16);
  const std::uint64_t v = 4, t = 6;
  int n = 0;
  for (const Damage& d : {Damage{kMeshVertices, H5T_IEEE_F32LE, {v, 2}, "has shape (4 x 2)"},
                          Damage{kMeshVertices, H5T_IEEE_F32LE, {v, 4}, "has shape (4 x 4)"},
                          Damage{kMeshVertices, H5T_IEEE_F32LE, {v}, "has shape (4), rank 1, expected N x 3"},
                          Damage{kMeshTriangles, text, {t, 3}, "stores string values, expected integer"},
                          Damage{kMeshVertexLevel, H5T_STD_U8LE, {v, 3}, "has shape (4 x 3), rank 2, expected rank 1"},
                          Damage{kMeshVertexOffset, H5T_IEEE_F64LE, {5}, "stores floating-point values"},
                          Damage{kMeshFrameTime, text, {5}, "stores string values, expected floating-point"},
                          Damage{kHapticForce, H5T_IEEE_F64LE, {1500, 2}, "has shape (1500 x 2)"}}) {
    const std::string path = dir / ("shape" + std::to_string(++n) + ".h5");
    write_small_session(path, 5);
    recreate(path, kDatasets[d.id].path, d.type, d.dims);
    expect_every_tool_refuses(path, dir, std::string("dataset ") + kDatasets[d.id].path + " " + d.says);
  }
  H5Tclose(text);
}

// What replay publishes as it is read must be finite (a damaged file's NaN
// force went out in every haptic message), and times must be plausible (1e308
// s kept a replay waiting with no end). Each is named with its dataset and row.
TEST(SessionTools, RowsReplayWouldPublishMustBeFiniteAndTheirTimesPlausible) {
  TempDir dir;
  struct Case {
    DatasetId id;
    std::uint64_t row, column;  // column 0 for a 1-D dataset
    double value;
    const char* says;
  };
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  int n = 0;
  for (const Case& c : {Case{kHapticForce, 7, 2, nan, "/haptic/force_N is not finite at row 7"},
                        Case{kHapticProxyPosition, 2, 0, inf, "/haptic/proxy_position_m is not finite at row 2"},
                        Case{kSimKinetic, 1, 0, nan, "/sim/kinetic_J is not finite at row 1"},
                        Case{kSimElastic, 3, 0, -inf, "/sim/elastic_J is not finite at row 3"},
                        Case{kSimStepMs, 0, 0, nan, "/sim/step_ms is not finite at row 0"},
                        Case{kSimSimTime, 2, 0, inf, "/sim/sim_time_s is not finite at row 2"},
                        Case{kSimTime, 39, 0, 1e308, "beyond any session"}}) {  // the last sim row
    const std::string path = dir / ("rows" + std::to_string(++n) + ".h5");
    write_small_session(path, 5);
    testing::overwrite_f64_at(path, kDatasets[c.id].path, c.row, c.column, c.value);
    try {
      read_session_rows(path);
      ADD_FAILURE() << "read " << kDatasets[c.id].path << " holding " << c.value;
    } catch (const RecordError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(path), std::string::npos) << what;
      EXPECT_NE(what.find(c.says), std::string::npos) << what;
    }
  }
  // A real_time_factor of NaN is what the recorder writes before the first
  // measured second: it reads.
  const std::string fine = dir / "rtf.h5";
  write_small_session(fine, 5);
  testing::overwrite_f64(fine, kDatasets[kSimRealTimeFactor].path, 0, nan);
  EXPECT_NO_THROW(read_session_rows(fine));
}

// "Session times finite and non-decreasing": rows recorded in the same clock
// tick (equal times) are a session like any other.
TEST(SessionReader, EqualConsecutiveTimesAreReadNotRefused) {
  TempDir dir;
  const std::string path = dir / "equal.h5";
  write_small_session(path, 5);
  const double t4 = read_session_rows(path).haptic[4].time_s;
  testing::overwrite_f64(path, kDatasets[kHapticTime].path, 5, t4);
  testing::overwrite_f64(path, kDatasets[kSimTime].path, 1, read_session_rows(path).sim[0].time_s);
  const SessionRows rows = read_session_rows(path);
  EXPECT_EQ(rows.haptic[5].time_s, rows.haptic[4].time_s);
  EXPECT_EQ(rows.sim[1].time_s, rows.sim[0].time_s);
  EXPECT_EQ(read_haptic_track(path).time_s[5], t4);
}

// A cleanly closed file whose duration_s is not a session's length (not
// finite, negative or beyond kMaxSessionTime_s: damaged, or a foreign
// writer's) reports the last time stamp recorded, and says so; never a NaN
// or absurd duration (1e300 was printed as the duration).
TEST(SessionTools, ARecordedDurationThatIsNotALengthFallsBackToTheLastTimeStamp) {
  TempDir dir;
  const std::string path = dir / "nan-duration.h5";
  write_small_session(path, 5);
  const double last = read_session_rows(path).haptic.back().time_s;
  EXPECT_TRUE(read_session_info(path).duration_recorded);
  for (const double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(), 1e300,
                           2 * kMaxSessionTime_s, -1.0}) {
    const hid_t file = testing::open_for_edit(path);
    ASSERT_GE(file, 0);
    h5::write_f64_attribute(file, kAttrDurationS, bad);
    H5Fclose(file);
    const SessionInfo info = read_session_info(path);
    EXPECT_TRUE(info.closed_cleanly);
    EXPECT_FALSE(info.duration_recorded) << bad;
    EXPECT_EQ(info.duration_s, last) << bad;
    EXPECT_NE(format_session_info(info).find(" s (last time stamp recorded)"), std::string::npos)
        << bad << "\n"
        << format_session_info(info);
  }
}

// Without a recorded duration, info and list report the last time stamp of
// any group: each is a session time like those replay checks. A last frame
// time of +inf was skipped (the duration silently the haptic rows'), and a
// last haptic time of 1e300 s was printed as the duration. Now every reader
// refuses the file, naming the dataset and row.
TEST(SessionTools, ALastTimeStampThatIsNotASessionTimeIsRefusedNotTheDuration) {
  TempDir dir;
  struct Case {
    DatasetId id;
    std::uint64_t row;  // the group's last
    double value;
  };
  const double inf = std::numeric_limits<double>::infinity();
  int n = 0;
  for (const Case& c : {Case{kMeshFrameTime, 4, inf}, Case{kMeshFrameTime, 4, 1e300}, Case{kHapticTime, 1499, 1e300},
                        Case{kSimTime, 39, -inf}, Case{kEventTime, 0, 2 * kMaxSessionTime_s}}) {
    const std::string path = dir / ("last" + std::to_string(++n) + ".h5");
    write_small_session(path, 5);
    {  // not closed cleanly: the duration is the last time stamp
      const hid_t file = testing::open_for_edit(path);
      ASSERT_GE(file, 0);
      h5::write_u8_attribute(file, kAttrClosedCleanly, 0);
      H5Fclose(file);
    }
    testing::overwrite_f64(path, kDatasets[c.id].path, c.row, c.value);
    const std::string says = std::string(kDatasets[c.id].path) + "[" + std::to_string(c.row) + "] is " +
                             (std::isinf(c.value) ? "not finite" : std::to_string(c.value) + " s, beyond any session");
    expect_every_tool_refuses(path, dir, says);
    const auto cli = run(tissue() + " session info " + quote(path), dir);
    EXPECT_EQ(cli.exit_code, 1) << cli.out;
    EXPECT_NE(cli.err.find("'" + path + "': " + says), std::string::npos) << cli.err;
    const SessionListing listing = list_sessions(dir.path());
    EXPECT_TRUE(listing.sessions.empty()) << "listed with duration " << listing.sessions[0].duration_s;
    ASSERT_EQ(listing.unreadable.size(), 1u);
    EXPECT_NE(listing.unreadable[0].reason.find(says), std::string::npos) << listing.unreadable[0].reason;
    std::filesystem::remove(path);
  }
}

// Rows past what a closed session's readers use (past the shortest column
// of a group, or mesh data in no frame of the index) were ignored without a
// word. The writer leaves none in a closed file: info now lists them per
// dataset, and the rows and frames that are read read as before.
TEST(SessionTools, InfoReportsRowsOfAClosedSessionThatNoReaderUses) {
  TempDir dir;
  const std::string path = dir / "trailing.h5";
  write_small_session(path, 5);
  const SessionInfo before = read_session_info(path);
  for (const std::uint64_t n : before.unreferenced_rows) EXPECT_EQ(n, 0u);
  EXPECT_EQ(format_session_info(before).find("unreferenced"), std::string::npos) << format_session_info(before);
  const std::vector<std::pair<DatasetId, std::uint64_t>> extra = {{kMeshVertices, 12}, {kMeshVertexLevel, 5},
                                                                  {kMeshTriangles, 3}, {kMeshTriangleStrain, 3},
                                                                  {kMeshFrameTime, 1}, {kHapticForce, 2}};
  {
    const hid_t file = testing::open_for_edit(path);
    ASSERT_GE(file, 0);
    for (const auto& [id, more] : extra) {
      const hid_t ds = H5Dopen2(file, kDatasets[id].path, H5P_DEFAULT);
      ASSERT_GE(ds, 0) << kDatasets[id].path;
      const hsize_t dims[2] = {static_cast<hsize_t>(h5::rows(ds)) + more, static_cast<hsize_t>(kDatasets[id].columns)};
      ASSERT_GE(H5Dset_extent(ds, dims), 0) << kDatasets[id].path;
      H5Dclose(ds);
    }
    H5Fclose(file);
  }
  const SessionInfo info = read_session_info(path);
  EXPECT_EQ(info.rows, before.rows) << "the rows read are the same";
  for (std::size_t i = 0; i < kDatasetCount; ++i) {
    const auto it = std::find_if(extra.begin(), extra.end(), [&](const auto& e) { return e.first == i; });
    EXPECT_EQ(info.unreferenced_rows[i], it == extra.end() ? 0u : it->second) << kDatasets[i].path;
  }
  const auto cli = run(tissue() + " session info " + quote(path), dir);
  EXPECT_EQ(cli.exit_code, 0) << cli.err;
  EXPECT_NE(cli.out.find("unreferenced rows"), std::string::npos) << cli.out;
  for (const auto& [id, more] : extra) {
    const std::string line = std::string(kDatasets[id].path) + " ";
    const std::size_t at = cli.out.find("  " + line);
    ASSERT_NE(at, std::string::npos) << line << "\n" << cli.out;
    const std::string row = cli.out.substr(at, cli.out.find('\n', at) - at);
    EXPECT_NE(row.find(" " + std::to_string(more) + (more == 1 ? " row" : " rows")), std::string::npos) << row;
  }
  // What is read reads as before.
  EXPECT_EQ(read_session_rows(path).haptic.size(), before.rows.haptic_rows);
  EXPECT_EQ(write_xdmf(path, "").frames, 5u);

  // A crashed file's last write is ahead of its group by design: repair
  // trims it, and nothing is reported as unreferenced before or after.
  const std::string crashed = dir / "crashed.h5";
  testing::write_crashed_session(crashed, 300, 3);
  for (const std::uint64_t n : read_session_info(crashed).unreferenced_rows) EXPECT_EQ(n, 0u);
  for (const std::uint64_t n : repair_session(crashed).after.unreferenced_rows) EXPECT_EQ(n, 0u);
}

// `session xdmf` checks frame times as every other frame reader does:
// ParaView would get <Time Value="nan"/> or grids out of order.
TEST(SessionTools, XdmfRefusesFrameTimesThatAreNotFiniteOrGoBack) {
  TempDir dir;
  for (const double bad : {std::numeric_limits<double>::quiet_NaN(), -1.0}) {
    const std::string path = dir / (std::isnan(bad) ? "nan.h5" : "back.h5");
    write_small_session(path, 5);
    testing::overwrite_f64(path, kDatasets[kMeshFrameTime].path, 3, bad);
    try {
      write_xdmf(path, "");
      ADD_FAILURE() << "wrote a sidecar with frame time " << bad;
    } catch (const RecordError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("'" + path + "'"), std::string::npos) << what;
      EXPECT_NE(what.find(std::isnan(bad) ? "/mesh/frame_time_s[3] is not finite"
                                          : "/mesh/frame_time_s goes backwards at frame 3"),
                std::string::npos)
          << what;
    }
    EXPECT_FALSE(std::filesystem::exists(dir / (std::isnan(bad) ? "nan.xdmf" : "back.xdmf")));
  }
}

// `session xdmf` checks every frame's data as the frame source (x3d, render,
// replay) does: found by the review of the session tools, it wrote a sidecar
// over an index past the frame's vertices (VTK does not bounds-check) or a
// NaN coordinate. Refused naming the file, dataset and row; nothing written.
TEST(SessionTools, XdmfRefusesFrameDataEveryOtherFrameReaderRefuses) {
  TempDir dir;
  // Rows where frame 1 starts (frame 0 comes first in the flat datasets).
  const std::uint64_t v1 = testing::test_frame(0).vertices_m.size();
  const std::uint64_t t1 = testing::test_frame(0).triangles.size();
  const std::int32_t far_index = 1000000;
  const float nan = std::numeric_limits<float>::quiet_NaN(), energy = 5.0f;
  struct Case {
    const char* name;
    DatasetId id;
    hsize_t row, column;
    hid_t type;
    const void* value;
    std::string expected;
  };
  const Case cases[] = {
      {"index", kMeshTriangles, 0, 0, H5T_NATIVE_INT32, &far_index,
       "/mesh/triangles row 0 (frame 0) holds the index 1000000, past the frame's " + std::to_string(v1) + " vertices"},
      {"coordinate", kMeshVertices, v1 + 1, 2, H5T_NATIVE_FLOAT, &nan,
       "/mesh/vertices_m row " + std::to_string(v1 + 1) + " (frame 1) holds the coordinate nan"},
      // Frame 1 "recorded without strain" but for one value.
      {"strain", kMeshTriangleStrain, t1, 0, H5T_NATIVE_FLOAT, &nan,
       "row " + std::to_string(t1 + 1) + " (frame 1) holds"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = dir / (std::string(c.name) + ".h5");
    write_small_session(path, 3);
    if (c.id == kMeshTriangleStrain) {  // every value of frame 1 NaN but the one after the first
      for (std::uint64_t t = t1; t < t1 + testing::test_frame(1).triangles.size(); ++t)
        testing::overwrite_element(path, kDatasets[c.id].path, t, 0, c.type, t == t1 + 1 ? &energy : c.value);
    } else {
      testing::overwrite_element(path, kDatasets[c.id].path, c.row, c.column, c.type, c.value);
    }
    try {
      const XdmfReport report = write_xdmf(path, "");
      ADD_FAILURE() << "wrote " << report.out_path << " (" << report.frames << " grids)";
    } catch (const RecordError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("'" + path + "': "), std::string::npos) << what;
      EXPECT_NE(what.find(c.expected), std::string::npos) << what;
    }
    EXPECT_FALSE(std::filesystem::exists(dir / (std::string(c.name) + ".xdmf")));
  }
  // The command line too: exit 1, the reason on stderr, no sidecar.
  const auto cli = run(tissue() + " session xdmf " + quote(dir / "index.h5"), dir);
  EXPECT_EQ(cli.exit_code, 1) << cli.out;
  EXPECT_NE(cli.err.find("/mesh/triangles row 0 (frame 0) holds the index 1000000"), std::string::npos) << cli.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "index.xdmf"));
}

// Frame times need only be non-decreasing: two frames of the same instant
// are two grids at one time, not an error.
TEST(SessionTools, XdmfTakesTwoFramesOfTheSameTime) {
  TempDir dir;
  const std::string path = dir / "same.h5";
  write_small_session(path, 5);
  testing::overwrite_f64(path, kDatasets[kMeshFrameTime].path, 3, testing::test_frame(2).time_s);
  const XdmfReport report = write_xdmf(path, "");
  EXPECT_EQ(report.frames, 5u);
  EXPECT_EQ(report.skipped_empty, 0u);
}

// XDMF cannot express a grid without cells: a frame with vertices but no
// triangles (or neither) is skipped and counted, the others are written.
TEST(SessionTools, XdmfSkipsAndCountsFramesWithoutTriangles) {
  TempDir dir;
  const std::string path = dir / "empty-frames.h5";
  {
    auto w = SessionWriter::create(path, SessionMetadata{});
    const testing::TestFrame full = testing::test_frame(0);
    testing::TestFrame points = testing::test_frame(1);  // vertices only
    points.triangles.clear();
    points.triangle_strain_energy_J_per_m3.clear();
    const testing::TestFrame nothing{2.0, {}, {}, {}, {}};
    w->append_mesh_frame(full.view());
    w->append_mesh_frame(points.view());
    w->append_mesh_frame(nothing.view());
    w->close();
  }
  const XdmfReport report = write_xdmf(path, "");
  EXPECT_EQ(report.frames, 1u);
  EXPECT_EQ(report.skipped_empty, 2u);
  const std::string xml = testing::slurp(report.out_path);
  EXPECT_NE(xml.find("frame_0"), std::string::npos) << xml;
  EXPECT_EQ(xml.find("frame_1"), std::string::npos) << xml;
}

// A format-2 session recorded without strain stores NaN for every triangle:
// its sidecar had the strain Cell attribute anyway, and ParaView coloured
// every frame by NaN. Now the attribute is there only when a frame of the
// session has strain; then every grid has it (ParaView's list of arrays
// stays the same across the time steps) and a frame recorded without
// strain reads as NaN there.
TEST(SessionTools, XdmfOfASessionRecordedWithoutStrainHasNoStrainAttribute) {
  TempDir dir;
  const auto strain_attributes = [](const std::string& xml) {
    std::size_t n = 0;
    for (std::size_t at = xml.find("\"strain_energy_density_J_per_m3\""); at != std::string::npos;
         at = xml.find("\"strain_energy_density_J_per_m3\"", at + 1))
      ++n;
    return n;
  };
  testing::TestSession without;
  without.frames = 4;
  without.strain = false;
  const std::string none = testing::write_test_session(dir / "none.h5", without);
  ASSERT_TRUE(read_session_info(none).has_strain) << "format version 2 and later: the dataset is there, all NaN";
  const XdmfReport report = write_xdmf(none, "");
  EXPECT_EQ(report.frames, 4u);
  const std::string xml = testing::slurp(report.out_path);
  EXPECT_EQ(strain_attributes(xml), 0u) << xml;
  EXPECT_NE(xml.find("vertex_level"), std::string::npos);

  // Frame 0 recorded without strain, the others with it: every grid keeps
  // the attribute.
  const std::string some = dir / "some.h5";
  write_small_session(some, 4);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (std::uint64_t t = 0; t < testing::test_frame(0).triangles.size(); ++t)
    testing::overwrite_element(some, kDatasets[kMeshTriangleStrain].path, t, 0, H5T_NATIVE_FLOAT, &nan);
  EXPECT_EQ(strain_attributes(testing::slurp(write_xdmf(some, "").out_path)), 4u);
}

// A session still marked open for writing (crashed, or being recorded) is
// refused by `xdmf` with what to do: ParaView's ordinary open would refuse it.
TEST(SessionTools, XdmfOfACrashedSessionIsRefusedSayingToRepairItFirst) {
  TempDir dir;
  const std::string crashed = dir / "crashed.h5";
  testing::write_crashed_session(crashed, 100, 2);
  try {
    write_xdmf(crashed, "");
    ADD_FAILURE() << "wrote a sidecar for a session still open for writing";
  } catch (const RecordError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("'" + crashed + "'"), std::string::npos) << what;
    EXPECT_NE(what.find("run `tissue session repair` first"), std::string::npos) << what;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "crashed.xdmf"));
}

// Repair trims only what a crash left incomplete: every flushed frame keeps
// all its vertices, levels, triangles and strain values.
// A live recording and a crashed one both keep the open-for-write flags;
// repair trimmed and re-flagged a file its recorder was still writing. The
// writer's mark tells them apart: repair refuses a live one, info and list
// say it is being recorded, and once closed it is an ordinary session.
TEST(SessionTools, ALiveRecordingIsNotRepairedAndSaysItIsBeingRecorded) {
  TempDir dir;
  const std::string path = dir / "live.h5";
  auto writer = SessionWriter::create(path, SessionMetadata{});
  writer->append_mesh_frame(testing::test_frame(0).view());
  writer->flush();
  const SessionInfo live = read_session_info(path);
  EXPECT_TRUE(live.open_for_write_flag);
  EXPECT_TRUE(live.being_recorded);
  EXPECT_NE(format_session_info(live).find("being recorded"), std::string::npos) << format_session_info(live);
  EXPECT_NE(format_session_listing(list_sessions(dir.path())).find("being recorded"), std::string::npos);
  try {
    repair_session(path);
    ADD_FAILURE() << "repaired a session that is being recorded";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find("is being recorded"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  const RunResult cli = run(quote(TISSUE_CLI_BINARY) + " session repair " + quote(path), dir);
  EXPECT_EQ(cli.exit_code, 1) << cli.out << cli.err;
  EXPECT_NE(cli.err.find("is being recorded"), std::string::npos) << cli.err;
  // The writer goes on, unharmed, and closes cleanly.
  writer->append_mesh_frame(testing::test_frame(1).view());
  writer->close();
  const SessionInfo closed = read_session_info(path);
  EXPECT_TRUE(closed.closed_cleanly);
  EXPECT_FALSE(closed.being_recorded);
  EXPECT_EQ(closed.rows.mesh_frames, 2u);
}

// A crashed recorder's mark went with its process: its session says so.
TEST(SessionTools, ACrashedSessionIsNotMarkedAsBeingRecorded) {
  TempDir dir;
  const std::string path = dir / "crashed.h5";
  testing::write_crashed_session(path, 10, 1);
  const SessionInfo info = read_session_info(path);
  EXPECT_TRUE(info.open_for_write_flag);
  EXPECT_FALSE(info.being_recorded);
  EXPECT_NE(format_session_info(info).find("left by a crash"), std::string::npos) << format_session_info(info);
}

TEST(SessionTools, RepairOfACrashedSessionKeepsEveryFlushedFrameWhole) {
  TempDir dir;
  const std::string crashed = dir / "crashed.h5";
  testing::write_crashed_session(crashed, 200, 4);
  const RepairReport report = repair_session(crashed);
  EXPECT_TRUE(report.repair_needed);
  EXPECT_EQ(report.after.rows, report.before);
  EXPECT_EQ(report.after.rows.mesh_frames, 4u);
  const SessionFile file(crashed);
  std::uint64_t v0 = 0, t0 = 0;
  for (std::uint64_t f = 0; f < 4; ++f) {
    const testing::TestFrame frame = testing::test_frame(f);
    const std::uint64_t nv = frame.vertices_m.size(), nt = frame.triangles.size();
    const std::vector<double> xyz = file.rows<double>(kMeshVertices, v0, nv);
    for (std::uint64_t v = 0; v < nv; ++v)
      for (int k = 0; k < 3; ++k) EXPECT_EQ(xyz[3 * v + k], frame.vertices_m[v][k]) << "frame " << f;
    EXPECT_EQ(file.rows<std::uint8_t>(kMeshVertexLevel, v0, nv), frame.vertex_level) << "frame " << f;
    EXPECT_EQ(file.rows<float>(kMeshTriangleStrain, t0, nt), frame.triangle_strain_energy_J_per_m3) << "frame " << f;
    v0 += nv;
    t0 += nt;
  }
  EXPECT_EQ(report.after.rows.mesh_vertices, v0);
  EXPECT_EQ(report.after.rows.mesh_triangles, t0);
}

// "--" may not appear inside an XML comment: the sidecar of run--2.h5 must
// still be well-formed.
TEST(SessionTools, XdmfOfASessionNamedWithDoubleHyphensIsWellFormed) {
  TempDir dir;
  const std::string path = dir / "run--2.h5";
  write_small_session(path, 3);
  write_xdmf(path, "");
  const std::string xml = testing::slurp(dir / "run--2.xdmf");
  ASSERT_FALSE(xml.empty());
  std::size_t comments = 0;
  for (std::size_t at = xml.find("<!--"); at != std::string::npos; at = xml.find("<!--", at + 4)) {
    const std::size_t end = xml.find("-->", at + 4);
    ASSERT_NE(end, std::string::npos) << xml;
    const std::string body = xml.substr(at + 4, end - at - 4);
    EXPECT_EQ(body.find("--"), std::string::npos) << body;
    EXPECT_FALSE(!body.empty() && body.back() == '-') << body;
    ++comments;
  }
  EXPECT_GT(comments, 0u);
  EXPECT_NE(xml.find("run--2.h5:/mesh/vertices_m"), std::string::npos) << "the DataItems still name the file";
}

// XDMF 3 takes a data reference's file name up to its first ':' and splits
// references on '|', and the XML is UTF-8: found by the review of the
// session tools, a session path it cannot name gave a sidecar ParaView could
// not open (exit 0). Refused naming the file and the reason; no sidecar.
TEST(SessionTools, XdmfOfASessionPathAReferenceCannotNameIsRefused) {
  TempDir dir;
  const struct {
    std::string name, expected;
  } cases[] = {
      {"a:b.h5", "contains ':'"},
      {"a|b.h5", "contains '|'"},
      {"caf\xe9.h5", "is not UTF-8 text"},
      {"line\nbreak.h5", "holds a control character"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = dir / c.name;
    write_small_session(path, 2);
    const std::string sidecar = std::filesystem::path(path).replace_extension(".xdmf").string();
    try {
      write_xdmf(path, "");
      ADD_FAILURE() << "wrote a sidecar referencing " << c.name;
    } catch (const RecordError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("'" + path + "': "), std::string::npos) << what;
      EXPECT_NE(what.find(c.expected), std::string::npos) << what;
      EXPECT_NE(what.find("which an XDMF data reference cannot name; rename it"), std::string::npos) << what;
    }
    EXPECT_FALSE(std::filesystem::exists(sidecar));
  }
  // A ':' in a directory the reference passes through is refused too; one
  // the relative reference does not name is no problem.
  std::filesystem::create_directories(dir / "x:y");
  const std::string inside = dir / "x:y/s.h5";
  write_small_session(inside, 2);
  EXPECT_NO_THROW(write_xdmf(inside, ""));
  EXPECT_TRUE(std::filesystem::exists(dir / "x:y/s.xdmf"));
  try {
    write_xdmf(inside, dir / "s.xdmf");
    ADD_FAILURE() << "wrote a sidecar referencing x:y/s.h5";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find("('x:y/s.h5') contains ':'"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "s.xdmf"));
  // The command line: exit 1, the reason on stderr.
  const auto cli = run(tissue() + " session xdmf " + quote(dir / "a:b.h5"), dir);
  EXPECT_EQ(cli.exit_code, 1) << cli.out;
  EXPECT_NE(cli.err.find("contains ':'"), std::string::npos) << cli.err;
}

// -o naming the session itself would replace the recording with its sidecar.
TEST(SessionTools, XdmfRefusesToOverwriteItsInput) {
  TempDir dir;
  const std::string path = dir / "same.h5";
  write_small_session(path, 3);
  const std::string before = testing::slurp(path);
  for (const std::string& out : {path, dir / "./same.h5"}) {
    const auto cli = run(tissue() + " session xdmf " + quote(path) + " -o " + quote(out), dir);
    EXPECT_EQ(cli.exit_code, 1) << cli.out;
    EXPECT_NE(cli.err.find("writing it would destroy the recording"), std::string::npos) << cli.err;
    EXPECT_EQ(testing::slurp(path), before) << "the session was changed";
  }
  // A session named like its default sidecar.
  const std::string xdmf_named = dir / "s.xdmf";
  std::filesystem::copy_file(path, xdmf_named);
  const auto cli = run(tissue() + " session xdmf " + quote(xdmf_named), dir);
  EXPECT_EQ(cli.exit_code, 1) << cli.out;
  EXPECT_EQ(testing::slurp(xdmf_named), before);
}

// An existing FIFO or device is written in place, never replaced by a
// regular file (the old temporary + rename turned /dev/full into a file).
TEST(SessionTools, XdmfToAFifoWritesIntoItAndKeepsIt) {
  TempDir dir;
  const std::string path = dir / "s.h5";
  write_small_session(path, 3);
  const std::string fifo = dir / "sidecar.fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  // The reader gives up after 30 s, so a writer that never opens the FIFO
  // cannot stall the test; the writer is bounded the same way.
  const auto cli = run("(timeout 30 cat " + quote(fifo) + " > " + quote(dir / "got.xdmf") + " &) ; timeout 60 " +
                           tissue() + " session xdmf " + quote(path) + " -o " + quote(fifo),
                       dir);
  EXPECT_EQ(cli.exit_code, 0) << cli.err;
  struct stat st {};
  ASSERT_EQ(::stat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode)) << "the FIFO was replaced";
  EXPECT_FALSE(std::filesystem::exists(fifo + ".tmp"));
  std::string got;
  for (int i = 0; i < 100 && got.find("</Xdmf>") == std::string::npos; ++i) {
    got = testing::slurp(dir / "got.xdmf");
    if (got.find("</Xdmf>") == std::string::npos) ::usleep(50000);
  }
  EXPECT_NE(got.find("</Xdmf>"), std::string::npos) << got;
}

// The reason a sidecar cannot be written, not "Success".
TEST(SessionTools, XdmfIntoADirectorySaysWhy) {
  TempDir dir;
  const std::string path = dir / "s.h5";
  write_small_session(path, 3);
  std::filesystem::create_directory(dir / "out");
  const auto cli = run(tissue() + " session xdmf " + quote(path) + " -o " + quote(dir / "out"), dir);
  EXPECT_EQ(cli.exit_code, 1);
  EXPECT_NE(cli.err.find("cannot write XDMF sidecar '" + (dir / "out") + "': is a directory"), std::string::npos)
      << cli.err;
  EXPECT_EQ(cli.err.find("Success"), std::string::npos) << cli.err;
}

// The holes the recorder left in /haptic (warning events naming the rows on
// either side, HapticHole) are read back by every reader that needs them:
// info counts them, the replay device's track gets the rows after the holes
// between two of its rows. Only warnings in exactly that form are holes. A
// hole event whose rows are not at the times it gives is damage (the replay
// would skip the device's judgement in the wrong place): refused, naming the
// file and the event row.
TEST(SessionReader, HoleEventsAreReadBackAndCheckedAgainstTheRows) {
  TempDir dir;
  const auto write = [&](const std::string& path, const std::vector<Event>& events) {
    auto w = SessionWriter::create(path, SessionMetadata{});
    std::vector<HapticRow> rows;
    for (std::uint64_t i = 0; i < 100; ++i) rows.push_back(testing::haptic_row(i < 50 ? i : i + 30));
    w->append_haptic(rows);
    w->append_events(events);
    w->close();
    return path;
  };
  const auto hole_event = [](EventKind kind, const HapticHole& hole) {
    return Event::make(hole.has_row_before() ? hole.time_before_s : 0.0, kind, haptic_hole_message(hole));
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const HapticHole between{30, 50, testing::haptic_row(49).time_s, testing::haptic_row(80).time_s};
  const HapticHole at_end{4, 100, testing::haptic_row(129).time_s, nan};
  const std::string path =
      write(dir / "holes.h5", {testing::event_row(0), hole_event(EventKind::kWarning, at_end),
                               hole_event(EventKind::kInfo, between),  // not a warning: no hole
                               hole_event(EventKind::kWarning, between),
                               Event::make(0.5, EventKind::kWarning, std::string(kHapticHolePrefix) + "a few ticks")});
  const SessionInfo info = read_session_info(path);
  EXPECT_EQ(info.haptic_holes, 2u);
  EXPECT_EQ(info.haptic_ticks_lost, 34u);
  EXPECT_NE(format_session_info(info).find("haptic holes:     2 holes, 34 ticks the recorder dropped"),
            std::string::npos)
      << format_session_info(info);
  const std::vector<HapticHole> holes = read_haptic_holes(SessionFile(path));
  ASSERT_EQ(holes.size(), 2u);
  EXPECT_EQ(holes[0].row_after, 50u);
  EXPECT_EQ(holes[0].ticks_lost, 30u);
  EXPECT_EQ(holes[1].row_after, 100u);
  EXPECT_FALSE(holes[1].has_row_after());
  EXPECT_EQ(read_haptic_track(path).rows_after_holes, (std::vector<std::size_t>{50}));
  // The CLI prints it.
  const RunResult cli = run(quote(TISSUE_CLI_BINARY) + " session info " + quote(path), dir);
  EXPECT_EQ(cli.exit_code, 0) << cli.err;
  EXPECT_NE(cli.out.find("haptic holes:     2 holes, 34 ticks"), std::string::npos) << cli.out;
  // A session without holes says nothing of them.
  EXPECT_EQ(format_session_info(read_session_info(testing::write_test_session(dir / "plain.h5"))).find("holes"),
            std::string::npos);

  // Rows 49 and 50 are at 49 and 80 ms, not at 49 and 50.
  const HapticHole misplaced{1, 50, testing::haptic_row(49).time_s, testing::haptic_row(50).time_s};
  const std::string bad = write(dir / "bad.h5", {testing::event_row(0), hole_event(EventKind::kWarning, misplaced),
                                                 hole_event(EventKind::kWarning, at_end)});
  try {
    read_haptic_track(bad);
    ADD_FAILURE() << "the replay took a hole that is not where its rows are";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("/events/message[1]"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("/haptic row 50"), std::string::npos) << e.what();
  }
}

// One damaged hole event does not make the rest of a session unreadable to
// `info` and `list`: they report that event and show everything else (the
// good hole too). `repair` does not touch events, so a refusal there left
// the file's summary out of reach for good. Only the replay, which would
// skip the device's judgement in the wrong place, refuses it
// (HoleEventsAreReadBackAndCheckedAgainstTheRows).
TEST(SessionReader, InfoAndListReportADamagedHoleEventAndShowTheRest) {
  TempDir dir;
  {
    auto w = SessionWriter::create(dir / "bad.h5", SessionMetadata{});
    std::vector<HapticRow> rows;
    for (std::uint64_t i = 0; i < 100; ++i) rows.push_back(testing::haptic_row(i < 50 ? i : i + 30));
    w->append_haptic(rows);
    // Rows 49 and 50 are at 49 and 80 ms: the first names 50 ms.
    const HapticHole misplaced{1, 50, testing::haptic_row(49).time_s, testing::haptic_row(50).time_s};
    const HapticHole at_end{4, 100, testing::haptic_row(129).time_s, std::numeric_limits<double>::quiet_NaN()};
    const std::vector<Event> events = {
        testing::event_row(0),
        Event::make(misplaced.time_before_s, EventKind::kWarning, haptic_hole_message(misplaced)),
        Event::make(at_end.time_before_s, EventKind::kWarning, haptic_hole_message(at_end))};
    w->append_events(events);
    w->close();
  }
  const std::string bad = dir / "bad.h5";
  const SessionInfo info = read_session_info(bad);
  EXPECT_EQ(info.rows.haptic_rows, 100u);
  EXPECT_EQ(info.haptic_holes, 1u);
  EXPECT_EQ(info.haptic_ticks_lost, 4u);
  ASSERT_EQ(info.damaged_hole_events.size(), 1u);
  EXPECT_NE(info.damaged_hole_events[0].find("/events/message[1]"), std::string::npos) << info.damaged_hole_events[0];
  EXPECT_NE(info.damaged_hole_events[0].find("/haptic row 50"), std::string::npos) << info.damaged_hole_events[0];
  const std::string text = format_session_info(info);
  EXPECT_NE(text.find("hole event 1 does not match its rows (damaged)"), std::string::npos) << text;
  EXPECT_NE(text.find("haptic holes:     1 hole, 4 ticks"), std::string::npos) << text;
  const RunResult cli = run(quote(TISSUE_CLI_BINARY) + " session info " + quote(bad), dir);
  EXPECT_EQ(cli.exit_code, 0) << cli.err;
  EXPECT_NE(cli.out.find("hole event 1 does not match its rows (damaged)"), std::string::npos) << cli.out;

  const SessionListing listing = list_sessions(dir.path());
  EXPECT_TRUE(listing.unreadable.empty()) << ::testing::PrintToString(listing.unreadable.size());
  ASSERT_EQ(listing.sessions.size(), 1u);
  const std::string listed = format_session_listing(listing);
  EXPECT_NE(listed.find("bad.h5: hole event 1 does not match its rows (damaged)"), std::string::npos) << listed;
}

// `tissue session list` shows which sessions have recorder holes, so a lab
// user scanning a directory sees them without `info` on every file: a holes
// column with the count and the session time they span (the jumps in
// /haptic/time_s between the rows on either side; a hole at the end has no
// row after it and spans nothing), "-" for none, and a damaged hole event
// flagged on its session's row as well as on its own line. Before, list
// showed holes nowhere, only a damaged event.
TEST(SessionTools, ListShowsEachSessionsHolesAndTheTimeTheySpan) {
  TempDir dir;
  const std::string d = dir / "state";
  std::filesystem::create_directories(d);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const auto write = [&](const std::string& name, const std::vector<HapticHole>& holes) {
    auto w = SessionWriter::create(d + "/" + name, SessionMetadata{});
    std::vector<HapticRow> rows;
    // Rows 49 and 50 are at 49 and 80 ms: 30 ticks lost between them.
    for (std::uint64_t i = 0; i < 100; ++i) rows.push_back(testing::haptic_row(i < 50 ? i : i + 30));
    w->append_haptic(rows);
    std::vector<Event> events = {testing::event_row(0)};
    for (const HapticHole& h : holes)
      events.push_back(
          Event::make(h.has_row_before() ? h.time_before_s : 0.0, EventKind::kWarning, haptic_hole_message(h)));
    w->append_events(events);
    w->close();
  };
  const HapticHole between{30, 50, testing::haptic_row(49).time_s, testing::haptic_row(80).time_s};
  const HapticHole at_end{4, 100, testing::haptic_row(129).time_s, nan};
  // Names 50 ms for row 50, which is at 80 ms.
  const HapticHole misplaced{1, 50, testing::haptic_row(49).time_s, testing::haptic_row(50).time_s};
  write("holes.h5", {between, at_end});
  write("end-only.h5", {at_end});
  write("damaged.h5", {misplaced, at_end});
  testing::write_test_session(d + "/plain.h5");

  const SessionListing l = list_sessions(d);
  ASSERT_EQ(l.sessions.size(), 4u);
  const auto session = [&](const std::string& name) -> const SessionInfo& {
    for (const SessionInfo& s : l.sessions)
      if (std::filesystem::path(s.path).filename() == name) return s;
    throw std::runtime_error("no session " + name);
  };
  EXPECT_EQ(session("holes.h5").haptic_holes, 2u);
  EXPECT_NEAR(session("holes.h5").haptic_hole_time_s, 0.031, 1e-9);
  EXPECT_EQ(session("end-only.h5").haptic_hole_time_s, 0.0);
  EXPECT_EQ(session("plain.h5").haptic_hole_time_s, 0.0);

  const auto r = run(tissue() + " session list " + quote(d), dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  // Each session's own row of the table.
  const auto row_of = [&](const std::string& name) {
    std::istringstream lines(r.out);
    for (std::string line; std::getline(lines, line);)
      if (line.rfind(name + " ", 0) == 0) return line;
    return std::string("(no row for " + name + ")");
  };
  std::istringstream lines(r.out);
  std::string title, header;
  std::getline(lines, title);
  std::getline(lines, header);
  EXPECT_NE(header.find(" holes "), std::string::npos) << r.out;
  EXPECT_NE(row_of("holes.h5").find(" 2 (0.031 s) "), std::string::npos) << r.out;
  EXPECT_NE(row_of("end-only.h5").find(" 1 "), std::string::npos) << r.out;
  EXPECT_EQ(row_of("end-only.h5").find(" s) "), std::string::npos) << r.out;
  EXPECT_NE(row_of("damaged.h5").find(" 1 +1 damaged "), std::string::npos) << r.out;
  EXPECT_NE(row_of("plain.h5").find(" - "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("damaged: damaged.h5: hole event 1 does not match its rows (damaged)"), std::string::npos)
      << r.out;

  // info says the time too.
  const std::string info = format_session_info(session("holes.h5"));
  EXPECT_NE(info.find("haptic holes:     2 holes, 34 ticks the recorder dropped (its ring was full), 0.031 s of "
                      "session time between the rows on either side"),
            std::string::npos)
      << info;
}

// The holes column is as wide as its widest cell: "1 (0.031 s) +1 damaged"
// is wider than the 12 characters it had, and pushed that row's scene out
// of line with every other row's.
TEST(SessionTools, ListLinesUpItsColumnsAroundAWideHolesCell) {
  TempDir dir;
  const std::string d = dir / "state";
  std::filesystem::create_directories(d);
  const auto write = [&](const std::string& name, const std::vector<HapticHole>& holes) {
    SessionMetadata m;
    m.scene_name = "scene-" + name;
    auto w = SessionWriter::create(d + "/" + name, m);
    std::vector<HapticRow> rows;
    // Rows 49 and 50 are at 49 and 80 ms: 30 ticks lost between them.
    for (std::uint64_t i = 0; i < 100; ++i) rows.push_back(testing::haptic_row(i < 50 ? i : i + 30));
    w->append_haptic(rows);
    std::vector<Event> events;
    for (const HapticHole& h : holes)
      events.push_back(Event::make(h.time_before_s, EventKind::kWarning, haptic_hole_message(h)));
    w->append_events(events);
    w->close();
  };
  const HapticHole between{30, 50, testing::haptic_row(49).time_s, testing::haptic_row(80).time_s};
  // Names 50 ms for row 50, which is at 80 ms: damaged.
  const HapticHole misplaced{1, 50, testing::haptic_row(49).time_s, testing::haptic_row(50).time_s};
  write("a.h5", {});
  write("b.h5", {between, misplaced});
  write("c.h5", {between});

  const std::string text = format_session_listing(list_sessions(d));
  std::istringstream lines(text);
  std::string title, header;
  std::getline(lines, title);
  std::getline(lines, header);
  const std::size_t scene_column = header.rfind("  scene");
  ASSERT_NE(scene_column, std::string::npos) << text;
  // The header's "holes" is right-aligned like the cells.
  EXPECT_EQ(header.rfind("holes") + 5, scene_column) << text;
  for (const char* name : {"a.h5", "b.h5", "c.h5"}) {
    std::string line;
    ASSERT_TRUE(std::getline(lines, line)) << text;
    ASSERT_EQ(line.rfind(std::string(name) + " ", 0), 0u) << text;
    EXPECT_EQ(line.rfind("  scene-" + std::string(name)), scene_column) << name << "\n" << text;
  }
  EXPECT_NE(text.find(" 1 (0.031 s) +1 damaged  scene-b.h5\n"), std::string::npos) << text;
}

// Hole events whose ticks add up past what a count holds (damage, or a forged
// file) show the largest count, not a small number that wrapped.
TEST(SessionReader, TheTicksLostInHolesSaturate) {
  TempDir dir;
  auto w = SessionWriter::create(dir / "s.h5", SessionMetadata{});
  const std::vector<HapticRow> rows = {testing::haptic_row(0)};
  w->append_haptic(rows);
  const std::string huge = std::string(kHapticHolePrefix) + std::to_string(std::numeric_limits<std::uint64_t>::max()) +
                           " ticks before any /haptic row was recorded";
  const std::vector<Event> events = {Event::make(0.0, EventKind::kWarning, huge),
                                     Event::make(0.0, EventKind::kWarning, huge)};
  w->append_events(events);
  w->close();
  const SessionInfo info = read_session_info(dir / "s.h5");
  EXPECT_EQ(info.haptic_holes, 2u);
  EXPECT_EQ(info.haptic_ticks_lost, std::numeric_limits<std::uint64_t>::max());
}

}  // namespace
}  // namespace tissue::record
