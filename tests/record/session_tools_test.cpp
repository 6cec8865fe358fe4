// Session tools (list / info / repair / xdmf) and the session readers (SessionFile,
// read_session_rows, read_haptic_track), as library calls and through the
// `tissue session` CLI: good files, bad arguments, and files that are not
// sessions at all. No input may crash them (the ASan tree runs this too).
#include "record/session_tools.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <filesystem>
#include <fstream>
#include <limits>

#include "record/h5_util.hpp"
#include "record/session_layout.hpp"
#include "record/session_writer.hpp"
#include "record_test_support.hpp"

namespace tissue::record {
namespace {

using testing::quote;
using testing::run;
using testing::TempDir;

void write_small_session(const std::string& path, std::uint64_t frames = 5) {
  testing::TestSession content;
  content.frames = frames;
  testing::write_test_session(path, content);
}

std::string tissue() { return quote(TISSUE_CLI_BINARY); }

// Every library tool and reader refuses `path` with a RecordError naming the
// file (and `also`, e.g. the damaged dataset, when given); xdmf writes nothing.
void expect_every_tool_refuses(const std::string& path, const TempDir& dir, const std::string& also = "") {
  SCOPED_TRACE(path);
  for (int tool = 0; tool < 5; ++tool) {
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
      const auto r = run(tissue() + " session " + tool + " " + quote(path), scratch);
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
  EXPECT_NE(r.out.find(std::string(600, 'x') + " row\n"), std::string::npos) << r.out;
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
  for (std::uint64_t i = 0; i < 1500; ++i) {
    const HapticRow r = testing::haptic_row(i);
    ASSERT_TRUE(track.time_s[i] == r.time_s && track.device_position_m[i] == r.device_position_m &&
                track.force_N[i] == r.force_N)
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

}  // namespace
}  // namespace tissue::record
