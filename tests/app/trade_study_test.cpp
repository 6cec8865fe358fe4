// The trade study as labs run it, `tissue trade` (app/trade_study.cpp; the
// build tree's trade_bench is the same function): the sweep on a user's scene
// file (--scene-file, --set) runs the scene's own loads and probes on uniform
// levels and adaptive meshes and measures each against the uniform reference
// at the maximum depth; bad options and scenes are errors naming themselves.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "support/process_support.hpp"

namespace {

using tissue::testing::quote;
using tissue::testing::run;
using tissue::testing::RunResult;
using tissue::testing::slurp;
using tissue::testing::TempDir;
using tissue::testing::write_text;

const std::string kTrade = quote(TISSUE_CLI_BINARY) + " trade";
const std::string kCantilever = std::string(TISSUE_SOURCE_DIR) + "/config/scenes/cantilever.yaml";

// One CSV record (quoted fields may hold commas and doubled quotes).
std::vector<std::string> split_csv(const std::string& line) {
  std::vector<std::string> fields(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted && c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
      fields.back() += '"';
      ++i;
    } else if (c == '"') {
      quoted = !quoted;
    } else if (c == ',' && !quoted) {
      fields.emplace_back();
    } else {
      fields.back() += c;
    }
  }
  return fields;
}

// The CSV's rows as column name -> value.
std::vector<std::map<std::string, std::string>> read_csv(const std::string& path) {
  std::istringstream in(slurp(path));
  std::string line;
  std::vector<std::map<std::string, std::string>> rows;
  if (!std::getline(in, line)) return rows;
  const std::vector<std::string> header = split_csv(line);
  while (std::getline(in, line)) {
    const std::vector<std::string> fields = split_csv(line);
    std::map<std::string, std::string> row;
    for (std::size_t i = 0; i < header.size() && i < fields.size(); ++i) row[header[i]] = fields[i];
    rows.push_back(row);
  }
  return rows;
}

double number(const std::map<std::string, std::string>& row, const std::string& column) {
  const auto it = row.find(column);
  return it == row.end() || it->second.empty() ? NAN : std::stod(it->second);
}

// A short implicit sweep of `scene` to max depth 2; extra arguments appended.
RunResult sweep(const TempDir& dir, const std::string& scene, const std::string& csv, const std::string& extra = "") {
  return run(kTrade + " --scene-file " + quote(scene) +
                 " --quick --integrators implicit --depths 2 --duration 0.05 --csv " + quote(csv) + " " + extra,
             dir);
}

TEST(TradeStudy, SweepsASceneFileAgainstItsUniformReference) {
  TempDir dir;
  const RunResult r = sweep(dir, kCantilever, dir / "sweep.csv");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.find("Table 1"), std::string::npos) << "a scene file runs the sweep only";
  const auto rows = read_csv(dir / "sweep.csv");
  std::map<std::string, std::map<std::string, std::string>> by_mesh;  // "L0".."L2", "Th20", "Th80"
  for (const auto& row : rows) {
    EXPECT_EQ(row.at("scene"), "cantilever");
    EXPECT_EQ(row.at("status"), "ok") << row.at("message");
    const std::string key = row.at("mode") == "uniform" ? "L" + row.at("level") : "Th" + row.at("th_Pa");
    by_mesh[key] = row;
  }
  // Uniform levels from the scene's min depth (0) to 2; Th around the
  // scene's own 20 Pa (--quick: 1x and 4x).
  ASSERT_EQ(by_mesh.size(), 5u) << r.out;
  for (const std::string key : {"L0", "L1", "L2", "Th20", "Th80"}) ASSERT_EQ(by_mesh.count(key), 1u) << key;
  // The reference against itself: no error; the coarsest level: some.
  EXPECT_EQ(number(by_mesh["L2"], "rms_err_rel"), 0.0);
  EXPECT_EQ(number(by_mesh["L2"], "tip_err_rel"), 0.0);
  EXPECT_GT(number(by_mesh["L0"], "rms_err_rel"), 1e-3);
  EXPECT_GT(number(by_mesh["L0"], "tip_err_rel"), 1e-3);
  // The adaptive runs refined (their leaves reach depth 2) and have an error.
  for (const std::string key : {"Th20", "Th80"}) {
    EXPECT_EQ(number(by_mesh[key], "deepest_level"), 2.0) << key;
    EXPECT_TRUE(std::isfinite(number(by_mesh[key], "rms_err_rel"))) << key;
  }
  // The tip is the scene's first probe: it bends down under the 5 N load.
  EXPECT_LT(number(by_mesh["L2"], "tip_uz_m"), -1e-4);
  // Its path: the only uniform L2 run is the truth, so it has no path error.
  EXPECT_EQ(by_mesh["L2"].at("path_truth"), "implicit at dt 1 ms, uniform L2");
  EXPECT_EQ(number(by_mesh["L2"], "tip_path_err_rel"), 0.0);
  EXPECT_GT(number(by_mesh["L0"], "tip_path_err_rel"), 1e-3);
}

// The path error sees what the end state hides: at a 5 ms step implicit
// Euler damps the first swing, so its tip path departs from the 1 ms run's,
// though each dt's reference is error-free against itself.
TEST(TradeStudy, TheTipPathIsMeasuredAgainstTheSmallestStep) {
  TempDir dir;
  const RunResult r =
      sweep(dir, kCantilever, dir / "dts.csv", "--dts 0.001,0.005 --metric path --svg " + quote(dir / "dts.svg"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("truth = implicit at dt 1 ms, uniform L2"), std::string::npos) << r.out;
  // --metric path: the verdicts and the plot use the path error.
  EXPECT_NE(r.out.find("Adaptive vs uniform curve (path metric"), std::string::npos) << r.out;
  EXPECT_NE(slurp(dir / "dts.svg").find("tip path error"), std::string::npos);
  std::map<double, std::map<std::string, std::string>> reference_by_dt;
  for (const auto& row : read_csv(dir / "dts.csv"))
    if (row.at("mode") == "uniform" && row.at("level") == "2") reference_by_dt[number(row, "dt_s")] = row;
  ASSERT_EQ(reference_by_dt.size(), 2u);
  const auto& fine = reference_by_dt.at(0.001);
  const auto& coarse = reference_by_dt.at(0.005);
  EXPECT_EQ(number(fine, "rms_err_rel"), 0.0);
  EXPECT_EQ(number(coarse, "rms_err_rel"), 0.0);  // each dt against its own reference
  EXPECT_EQ(number(fine, "tip_path_err_rel"), 0.0);
  EXPECT_GT(number(coarse, "tip_path_err_rel"), 0.01);  // but not against the truth
}

// --clock picks the cost the plot and the verdicts use; it is each study's
// own setting, not left over from an earlier study in the same process.
TEST(TradeStudy, TheCostClockIsTheOneAskedFor) {
  TempDir dir;
  const RunResult cpu = sweep(dir, kCantilever, dir / "cpu.csv", "--clock cpu --svg " + quote(dir / "cpu.svg"));
  ASSERT_EQ(cpu.exit_code, 0) << cpu.err;
  const RunResult wall = sweep(dir, kCantilever, dir / "wall.csv", "--svg " + quote(dir / "wall.svg"));
  ASSERT_EQ(wall.exit_code, 0) << wall.err;
  const std::string cpu_svg = slurp(dir / "cpu.svg"), wall_svg = slurp(dir / "wall.svg");
  EXPECT_NE(cpu_svg.find("x: cost = thread CPU"), std::string::npos);
  EXPECT_NE(cpu_svg.find("[CPU s / simulated s]"), std::string::npos);
  EXPECT_NE(wall_svg.find("x: cost = wall"), std::string::npos);
  EXPECT_NE(wall_svg.find("[wall s / simulated s]"), std::string::npos);
  // Both costs are in the CSV whichever clock is plotted.
  for (const auto& row : read_csv(dir / "cpu.csv"))
    if (row.at("status") == "ok") {
      EXPECT_GT(number(row, "cost_cpu_per_sim"), 0.0);
      EXPECT_GT(number(row, "cost_wall_per_sim"), 0.0);
    }
}

// --set reaches the scene: half the load, half the (small) deflection.
TEST(TradeStudy, OverridesApplyToTheSceneFile) {
  TempDir dir;
  ASSERT_EQ(sweep(dir, kCantilever, dir / "full.csv").exit_code, 0);
  const RunResult half = sweep(dir, kCantilever, dir / "half.csv", "--set 'loads[0].total_force_N[2]=-2.5'");
  ASSERT_EQ(half.exit_code, 0) << half.err;
  const auto reference_tip = [&](const std::string& csv) -> double {
    for (const auto& row : read_csv(csv))
      if (row.at("mode") == "uniform" && row.at("level") == "2") return number(row, "tip_uz_m");
    return NAN;
  };
  const double ratio = reference_tip(dir / "half.csv") / reference_tip(dir / "full.csv");
  EXPECT_NEAR(ratio, 0.5, 0.02);
}

TEST(TradeStudy, ASceneWithoutProbesHasNoTipErrorButANodeError) {
  TempDir dir;
  write_text(dir / "block.yaml",
             "name: 'block, \"soft\" <A&B>'\n"  // a user's name: CSV-quoted, XML-escaped
             "object: {cubes: [3, 2, 2], cube_size_m: 0.02}\n"
             "fixed: [{region: {box: {min_m: [0, 0, 0], max_m: [0, 0.04, 0.04]}}}]\n"
             "loads: [{name: push, region: {box: {min_m: [0.06, 0, 0], max_m: [0.06, 0.04, 0.04]}},\n"
             "         total_force_N: [0, 0, -1]}]\n"
             "adaptivity: {enabled: true, refine_threshold_Pa: 10, max_depth: 2}\n");
  const RunResult r = sweep(dir, dir / "block.yaml", dir / "block.csv", "--svg " + quote(dir / "block.svg"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(slurp(dir / "block.svg").find("block, &quot;soft&quot; &lt;A&amp;B&gt;"), std::string::npos);
  EXPECT_NE(r.out.find("no probes"), std::string::npos) << r.out;
  const auto rows = read_csv(dir / "block.csv");
  ASSERT_FALSE(rows.empty());
  for (const auto& row : rows) {
    EXPECT_EQ(row.at("scene"), "block, \"soft\" <A&B>");  // one field, whatever it holds
    EXPECT_EQ(row.at("tip_err_rel"), "") << "no probe, no tip";
    if (row.at("mode") == "uniform" && row.at("level") == "0") {
      EXPECT_GT(number(row, "rms_err_rel"), 0.0);
    }
  }
}

TEST(TradeStudy, ABadSceneFileIsAnErrorNamingTheFileAndKey) {
  TempDir dir;
  write_text(dir / "bad.yaml", "object: {cubes: [2, 2, 2], cube_size_m: 0.02}\nmaterial: {density_kg_per_m3: -1}\n");
  const RunResult r = sweep(dir, dir / "bad.yaml", dir / "bad.csv");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find(dir / "bad.yaml"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("material.density_kg_per_m3"), std::string::npos) << r.err;
  // And a bad override names itself.
  const RunResult o = sweep(dir, kCantilever, dir / "o.csv", "--set 'integrator.dt_s=-1'");
  EXPECT_EQ(o.exit_code, 2);
  EXPECT_NE(o.err.find("integrator.dt_s"), std::string::npos) << o.err;
  EXPECT_NE(o.err.find("--set"), std::string::npos) << o.err;
}

TEST(TradeStudy, AMaxDepthAtTheScenesMinDepthIsRefused) {
  TempDir dir;
  const RunResult r = run(kTrade + " --scene-file " + quote(kCantilever) +
                              " --set adaptivity.min_depth=1 --depths 1 --quick --integrators implicit",
                          dir);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("adaptivity.min_depth 1"), std::string::npos) << r.err;
}

TEST(TradeStudy, HelpListsTheOptionsAndABadOptionIsAUsageError) {
  TempDir dir;
  const RunResult help = run(kTrade + " --help", dir);
  EXPECT_EQ(help.exit_code, 0) << help.err;
  EXPECT_NE(help.out.find("usage: tissue trade"), std::string::npos) << help.out;
  EXPECT_NE(help.out.find("--scene-file"), std::string::npos) << help.out;
  EXPECT_EQ(help.out.find("Table 1"), std::string::npos) << "--help runs nothing";
  const RunResult bad = run(kTrade + " --sweep --depths 2 --frobnicate", dir);
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("tissue trade: unknown argument --frobnicate"), std::string::npos) << bad.err;
  EXPECT_EQ(bad.out.find("Sweep"), std::string::npos) << "nothing ran: " << bad.out;
}

}  // namespace
