// Session tools (info / repair / xdmf), as library calls and through the
// `tissue session` CLI: good files, bad arguments, and files that are not
// sessions at all. No input may crash them (the ASan tree runs this too).
#include "record/session_tools.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

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
  SessionMetadata m;
  m.scene_name = "probe";
  m.software_version = "test";
  auto w = SessionWriter::create(path, m);
  std::vector<HapticRow> h;
  for (std::uint64_t i = 0; i < 1500; ++i) h.push_back(testing::haptic_row(i));
  w->append_haptic(h);
  std::vector<SimRow> s;
  for (std::uint64_t i = 0; i < 40; ++i) s.push_back(testing::sim_row(i));
  w->append_sim(s);
  for (std::uint64_t f = 0; f < frames; ++f) w->append_mesh_frame(testing::test_frame(f).view());
  const Event e = testing::event_row(0);
  w->append_events({&e, 1});
  w->close();
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

std::string tissue() { return quote(TISSUE_CLI_BINARY); }

// Files every tool must refuse with a message and exit code 1.
std::vector<std::string> make_bad_files(const TempDir& dir) {
  std::vector<std::string> files;
  const std::string good = dir / "good.h5";
  write_small_session(good);
  const std::string bytes = testing::slurp(good);

  write_bytes(dir / "empty.h5", "");
  files.push_back(dir / "empty.h5");
  write_bytes(dir / "text.h5", "this is a scene file, not a session\nname: cantilever\n");
  files.push_back(dir / "text.h5");
  std::mt19937 rng(42);
  std::string noise(65536, '\0');
  for (char& c : noise) c = static_cast<char>(rng() & 0xff);
  write_bytes(dir / "random.h5", noise);
  files.push_back(dir / "random.h5");
  // A valid signature followed by garbage: HDF5 itself has to reject it.
  write_bytes(dir / "signature_then_noise.h5", bytes.substr(0, 8) + noise);
  files.push_back(dir / "signature_then_noise.h5");
  for (const std::size_t cut : {std::size_t{4}, std::size_t{11}, std::size_t{48}, std::size_t{500}, bytes.size() / 4,
                                bytes.size() / 2, bytes.size() - 100, bytes.size() - 1}) {
    const std::string name = dir / ("truncated_" + std::to_string(cut) + ".h5");
    write_bytes(name, bytes.substr(0, cut));
    files.push_back(name);
  }
  // A real HDF5 file that is not a session.
  const hid_t f = H5Fcreate((dir / "foreign.h5").c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  H5Fclose(f);
  files.push_back(dir / "foreign.h5");
  files.push_back(dir / "does_not_exist.h5");
  files.push_back(dir.path());  // a directory
  return files;
}

TEST(SessionTools, BadFilesGetAClearErrorFromEveryLibraryTool) {
  TempDir dir;
  for (const std::string& path : make_bad_files(dir)) {
    SCOPED_TRACE(path);
    for (int tool = 0; tool < 3; ++tool) {
      try {
        if (tool == 0) read_session_info(path);
        if (tool == 1) repair_session(path);
        if (tool == 2) write_xdmf(path, dir / "out.xdmf");
        ADD_FAILURE() << "tool " << tool << " accepted " << path;
      } catch (const RecordError& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
      }
    }
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "out.xdmf"));
}

TEST(SessionTools, BadFilesMakeTheCliExitOneWithItsOwnMessage) {
  TempDir dir;
  TempDir scratch;
  for (const std::string& path : make_bad_files(dir)) {
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
  write_bytes(dir / "cut.h5", bytes.substr(0, bytes.size() / 2));
  try {
    read_session_info(dir / "cut.h5");
    FAIL() << "accepted a truncated file";
  } catch (const RecordError& e) {
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
  }
  write_bytes(dir / "text.h5", "hello");
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

TEST(SessionTools, CliBadArgumentsExitTwo) {
  TempDir dir;
  for (const char* args : {"session", "session info", "session repair", "session xdmf", "session frobnicate x.h5",
                           "session info a.h5 b.h5", "session xdmf a.h5 -o"}) {
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
    SCOPED_TRACE(path);
    for (int tool = 0; tool < 3; ++tool) {
      try {
        if (tool == 0) read_session_info(path);
        if (tool == 1) repair_session(path);
        if (tool == 2) write_xdmf(path, dir / "out.xdmf");
        ADD_FAILURE() << "tool " << tool << " accepted " << path;
      } catch (const RecordError& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(strain), std::string::npos) << e.what();
      }
    }
    const auto cli = run(tissue() + " session info " + quote(path), dir);
    EXPECT_EQ(cli.exit_code, 1) << cli.err;
    EXPECT_NE(cli.err.find(strain), std::string::npos) << cli.err;
    EXPECT_EQ(cli.err.find("HDF5-DIAG"), std::string::npos) << cli.err;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "out.xdmf"));
}

}  // namespace
}  // namespace tissue::record
