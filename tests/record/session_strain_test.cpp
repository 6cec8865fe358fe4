// Per-triangle strain in session files, read back through the export side's
// session FrameSource (what `tissue x3d` / `tissue render` / replay use): values of
// version-2 files, version-1 files without them, frames recorded without
// them, and damaged values.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "export/frame_source.hpp"
#include "export/x3d.hpp"
#include "record/session_layout.hpp"
#include "record_test_support.hpp"

namespace tissue::record {
namespace {

using testing::TempDir;

void write_frames(const std::string& path, std::uint64_t frames, bool with_strain) {
  testing::TestSession content;
  content.haptic = content.sim = content.events = 0;
  content.frames = frames;
  content.strain = with_strain;
  content.scene_name = "strain";
  testing::write_test_session(path, content);
}

TEST(SessionStrain, SourceGivesStoredTriangleStrainAndItsVertexMeans) {
  TempDir dir;
  write_frames(dir / "s.h5", 4, true);
  auto source = x3d::open_session_source(dir / "s.h5");
  ASSERT_TRUE(source->has_strain());
  ASSERT_EQ(source->frame_count(), 4u);
  for (std::size_t k = 0; k < 4; ++k) {
    const testing::TestFrame fr = testing::test_frame(k);
    const x3d::SurfaceFrame f = source->read_frame(k);
    const std::vector<float> expected =
        x3d::vertex_strain_from_triangles(fr.vertices_m.size(), fr.triangles, fr.triangle_strain_energy_J_per_m3);
    ASSERT_EQ(f.vertex_strain_energy_Pa.size(), fr.vertices_m.size()) << "frame " << k;
    EXPECT_EQ(f.vertex_strain_energy_Pa, expected) << "frame " << k;
    // The recorded per-triangle values too, bit for bit (replay sends them).
    EXPECT_EQ(f.triangle_strain_energy_J_per_m3, fr.triangle_strain_energy_J_per_m3) << "frame " << k;
    EXPECT_NO_THROW(x3d::validate_frame(f, true, "frame"));
  }
}

TEST(SessionStrain, VersionOneFilesAndFramesWithoutStrainHaveNone) {
  TempDir dir;
  write_frames(dir / "v1.h5", 3, true);
  testing::make_version_1(dir / "v1.h5");
  write_frames(dir / "nan.h5", 3, false);
  for (const std::string name : {"v1.h5", "nan.h5"}) {
    SCOPED_TRACE(name);
    auto source = x3d::open_session_source(dir / name);
    EXPECT_FALSE(source->has_strain());
    ASSERT_EQ(source->frame_count(), 3u);
    for (std::size_t k = 0; k < 3; ++k) {
      const x3d::SurfaceFrame f = source->read_frame(k);
      EXPECT_EQ(f.triangles, testing::test_frame(k).triangles);
      EXPECT_TRUE(f.vertex_strain_energy_Pa.empty()) << "frame " << k;
      EXPECT_TRUE(f.triangle_strain_energy_J_per_m3.empty()) << "frame " << k;
    }
  }
}

// A damaged value is an error naming the file, the dataset and the row,
// never a NaN or negative colour.
TEST(SessionStrain, ImpossibleStoredValuesAreClearErrors) {
  TempDir dir;
  const char* strain = kDatasets[kMeshTriangleStrain].path;
  const std::uint64_t row = testing::test_frame(0).triangles.size() + 1;  // frame 1, triangle 1
  for (const float bad : {-2.0f, std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    SCOPED_TRACE(bad);
    const std::string path = dir / ("bad" + std::to_string(static_cast<int>(std::fpclassify(bad))) + ".h5");
    write_frames(path, 3, true);
    testing::overwrite_f32(path, strain, row, bad);
    auto source = x3d::open_session_source(path);
    EXPECT_NO_THROW(source->read_frame(0));
    try {
      source->read_frame(1);
      ADD_FAILURE() << "read a strain of " << bad;
    } catch (const x3d::SourceError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(path), std::string::npos) << what;
      EXPECT_NE(what.find(strain), std::string::npos) << what;
      EXPECT_NE(what.find("row " + std::to_string(row)), std::string::npos) << what;
    }
  }
}

TEST(SessionStrain, AStrainDatasetOfTheWrongLengthIsRefusedAtOpen) {
  TempDir dir;
  const char* strain = kDatasets[kMeshTriangleStrain].path;
  write_frames(dir / "s.h5", 2, true);
  const hid_t file = testing::open_for_edit(dir / "s.h5");
  ASSERT_GE(file, 0);
  const hid_t ds = H5Dopen2(file, strain, H5P_DEFAULT);
  const hsize_t dims[1] = {3};
  ASSERT_GE(H5Dset_extent(ds, dims), 0);
  H5Dclose(ds);
  H5Fclose(file);
  try {
    x3d::open_session_source(dir / "s.h5");
    FAIL() << "opened a session whose strain column is cut short";
  } catch (const x3d::SourceError& e) {
    EXPECT_NE(std::string(e.what()).find(dir / "s.h5"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(strain), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tissue::record
