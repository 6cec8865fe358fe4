// The trade study as labs run it, `tissue trade` (app/trade_study.cpp; the
// build tree's trade_bench is the same function): the sweep on a user's scene
// file (--scene-file, --set) runs the scene's own loads and probes on uniform
// levels and adaptive meshes and measures each against the uniform reference
// at the maximum depth; bad options and scenes are errors naming themselves.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <csignal>
#include <map>
#include <optional>
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

// A sweep in which no run gave a figure (explicit at 1 GPa needs far more
// sub-steps than its cap) says so and exits 3; its table and CSV still come
// out with each refusal.
TEST(TradeStudy, ASweepWithNoRunThatGaveFiguresExits3) {
  TempDir dir;
  const RunResult r = run(kTrade + " --scene-file " + quote(kCantilever) +
                              " --quick --integrators explicit --depths 1 --th 20 --duration 0.05 --csv " +
                              quote(dir / "none.csv") + " --set material.youngs_modulus_Pa=1e9",
                          dir);
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("every run failed or was refused"), std::string::npos) << r.err;
  const auto rows = read_csv(dir / "none.csv");
  ASSERT_FALSE(rows.empty());
  for (const auto& row : rows) EXPECT_NE(row.at("status"), "ok");
  // One run with figures is a success.
  EXPECT_EQ(sweep(dir, kCantilever, dir / "some.csv").exit_code, 0);
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
  EXPECT_NE(o.err.find("(set by the override 'integrator.dt_s=-1')"), std::string::npos) << o.err;
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

// Every number is taken whole and in range, or the option says why (exit 2,
// nothing run): NaN or zero steps ran 0-step "ok" rows, "20abc" was 20, a
// negative duration silently became the default, "," said only "stod".
TEST(TradeStudy, BadNumbersAreUsageErrorsNamingTheOption) {
  TempDir dir;
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--dts nan", "--dts: nan must be a finite number > 0"},
      {"--dts 0", "--dts: 0 must be a finite number > 0"},
      {"--dts 0.001,-0.005", "--dts: -0.005 must be a finite number > 0"},
      {"--th nan", "--th: nan must be a finite number > 0"},
      {"--th -5", "--th: -5 must be a finite number > 0"},
      {"--th 20abc", "--th: '20abc' is not a number"},
      {"--th ,", "--th: '' is not a number"},
      {"--duration -1", "--duration: -1 must be a finite number > 0"},
      {"--duration 1e400", "--duration: 1e400 must be a finite number > 0"},  // read as inf, as every CLI here
      {"--run-cap nan", "--run-cap: nan must be a finite number > 0"},
      {"--depths 3.9", "--depths: '3.9' is not an integer"},
      {"--beam-depth -3", "--beam-depth: -3 must be a depth in [0, 30]"},
      {"--csv " + quote(dir / "same.out") + " --svg " + quote(dir / "same.out"), "name the same file"},
  };
  for (const auto& [args, expected] : cases) {
    const RunResult r = run(kTrade + " --sweep --quick " + args, dir);
    EXPECT_EQ(r.exit_code, 2) << args << ": " << r.err;
    EXPECT_NE(r.err.find(expected), std::string::npos) << args << ": " << r.err;
    EXPECT_EQ(r.out.find("Sweep"), std::string::npos) << args << ": nothing runs";
  }
}

// The sweep's setup (integrators, scene file, depths, every run's scene) is
// checked before any mode runs: a bad integrator name waited through Table 1
// (minutes) before exit 2.
TEST(TradeStudy, ABadSweepSetupFailsBeforeTable1Runs) {
  TempDir dir;
  const RunResult r = run(kTrade + " --table1 --sweep --quick --integrators bogus", dir);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("unknown integrator bogus"), std::string::npos) << r.err;
  EXPECT_EQ(r.out.find("## Table 1"), std::string::npos) << "nothing ran: " << r.out;
  // A scene file that does not load, likewise (its name in the message).
  const RunResult f = run(kTrade + " --table1 --sweep --quick --scene-file " + quote(dir / "absent.yaml"), dir);
  EXPECT_EQ(f.exit_code, 2) << f.err;
  EXPECT_NE(f.err.find(dir / "absent.yaml"), std::string::npos) << f.err;
  EXPECT_EQ(f.out.find("## Table 1"), std::string::npos) << "nothing ran: " << f.out;
}

// The sweep's files are created before any run: a path that cannot be
// written is exit 4 naming it, with nothing run; and they belong to the sweep.
TEST(TradeStudy, AnUnwritableOutputFailsBeforeAnyRun) {
  TempDir dir;
  const std::string nowhere = dir / "missing/plot.svg";
  const RunResult r = sweep(dir, kCantilever, dir / "ok.csv", "--svg " + quote(nowhere));
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_NE(r.err.find("cannot write --svg " + nowhere), std::string::npos) << r.err;
  EXPECT_EQ(r.out.find("Sweep"), std::string::npos) << "nothing ran: " << r.out;
  const RunResult t = run(kTrade + " --table1 --quick --csv " + quote(dir / "t.csv"), dir);
  EXPECT_EQ(t.exit_code, 2) << t.err;
  EXPECT_NE(t.err.find("--csv and --svg are the sweep's files"), std::string::npos) << t.err;
}

// Ctrl-C during a sweep stops it after the step in progress: the run it
// stopped is "interrupted", the rest "skipped" (not run), and the tables,
// CSV and SVG still come out for what ran; exit 130.
TEST(TradeStudy, CtrlCStopsTheSweepAndKeepsWhatItMeasured) {
  TempDir dir;
  const std::string csv = dir / "s.csv", svg = dir / "s.svg";
  // Uniform L0..L3 and one adaptive run for 20 simulated seconds each: L0
  // takes ~1 s (release build), the others longer, so the signal lands in
  // L1 or later.
  tissue::testing::BackgroundProcess trade(
      {TISSUE_CLI_BINARY, "trade", "--scene-file", kCantilever, "--integrators", "implicit", "--depths", "3", "--th",
       "20", "--duration", "20", "--run-cap", "600", "--csv", csv, "--svg", svg},
      dir / "trade.out", dir / "trade.err");
  ASSERT_TRUE(trade.started());
  ASSERT_TRUE(trade.wait_for_output("uniform L0: ok", 120.0, /*in_stderr=*/true)) << trade.err();
  ASSERT_TRUE(trade.signal(SIGINT));
  const std::optional<int> status = trade.wait_for_exit(60.0);
  ASSERT_TRUE(status.has_value()) << "did not stop within 60 s of SIGINT: " << trade.err();
  ASSERT_TRUE(WIFEXITED(*status)) << trade.err();
  EXPECT_EQ(WEXITSTATUS(*status), 130) << trade.err();
  EXPECT_NE(trade.err().find("interrupted by SIGINT"), std::string::npos) << trade.err();
  EXPECT_NE(trade.out().find("| implicit |"), std::string::npos) << "the table is printed: " << trade.out();

  const auto rows = read_csv(csv);
  ASSERT_EQ(rows.size(), 5u);  // L0..L3 and the adaptive run
  EXPECT_EQ(rows[0].at("status"), "ok");
  EXPECT_EQ(number(rows[0], "steps"), 20000);
  int interrupted = 0, not_run = 0;
  for (const auto& row : rows) {
    if (row.at("status") == "interrupted") {
      ++interrupted;
      EXPECT_EQ(row.at("message"), "interrupted by SIGINT");
      EXPECT_LT(number(row, "steps"), 20000);
    } else if (row.at("status") == "skipped") {
      ++not_run;
      EXPECT_EQ(row.at("message"), "not run: interrupted by SIGINT");
    }
  }
  EXPECT_EQ(interrupted, 1);
  EXPECT_EQ(rows.back().at("status"), "skipped");  // the adaptive run comes after every uniform level
  EXPECT_EQ(interrupted + not_run + 1 + (rows[1].at("status") == "ok") + (rows[2].at("status") == "ok"), 5);
  EXPECT_NE(slurp(svg).find("</svg>"), std::string::npos);
}

}  // namespace
