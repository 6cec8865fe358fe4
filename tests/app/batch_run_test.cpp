// Batch mode: the report (in-process, through run_batch) and the process
// contract of `tissued --batch` (exit codes, messages, bit-identical files).
#include "app/batch_run.hpp"
#include "util/stop_signals.hpp"

#include <gtest/gtest.h>
#include <hdf5.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "export/frame_source.hpp"
#include "record/record_test_support.hpp"
#include "record/session_layout.hpp"
#include "record/session_tools.hpp"
#include "scene/scene_yaml.hpp"
#include "support/process_support.hpp"

namespace tissue::app {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string scene_path(const std::string& name) {
  return std::string(TISSUE_SOURCE_DIR) + "/config/scenes/" + name + ".yaml";
}

std::string read_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// The cantilever with its tip load released at 0.15 s, run for 0.3 s: it
// bends (the mesh refines), springs back (the probes' peak is well above
// their final displacement) and coarsens again.
const std::vector<std::string> kCantileverOverrides = {"loads[0].profile.release_s=0.15"};
constexpr double kCantileverDuration_s = 0.3;

json run_cantilever(bool timing) {
  const scene::Scene scene = scene::load_scene_file_with_overrides(scene_path("cantilever"), kCantileverOverrides);
  BatchOptions options;
  options.duration_s = kCantileverDuration_s;
  options.timing = timing;
  return run_batch(scene, options, nullptr);
}

// One cantilever run shared by the report-content tests (it is the slow part).
const json& cantilever_report() {
  static const json report = run_cantilever(/*timing=*/true);
  return report;
}

TEST(BatchReport, SameSceneGivesIdenticalResult) {
  const json a = run_cantilever(/*timing=*/false);
  const json b = run_cantilever(/*timing=*/false);
  ASSERT_TRUE(a["result"]["error"].is_null()) << a["result"]["error"];
  EXPECT_GT(a["result"]["refines"].get<long long>(), 0);  // the adaptive path is exercised
  EXPECT_EQ(a["result"].dump(), b["result"].dump());
  EXPECT_EQ(report_text(a), report_text(b));
}

// The explicit rung in single precision: deterministic too, named in the
// report, and its probe within ~1e-6 of the double run's.
TEST(BatchReport, ExplicitFloatIsDeterministicAndNamed) {
  BatchOptions options;
  options.duration_s = 0.2;
  options.timing = false;
  const auto run = [&](const char* precision) {
    return run_batch(scene::load_scene_file_with_overrides(
                         scene_path("beam"),
                         {"integrator.kind=explicit", std::string("integrator.explicit_precision=") + precision}),
                     options, nullptr);
  };
  const json a = run("float"), b = run("float"), d = run("double");
  ASSERT_TRUE(a["result"]["error"].is_null()) << a["result"]["error"];
  EXPECT_EQ(report_text(a), report_text(b));
  EXPECT_EQ(a["scene"]["integrator"], "explicit float");
  EXPECT_EQ(d["scene"]["integrator"], "explicit");
  const double tip_f = a["result"]["probes"]["tip"]["peak_magnitude_m"].get<double>();
  const double tip_d = d["result"]["probes"]["tip"]["peak_magnitude_m"].get<double>();
  EXPECT_GT(tip_d, 0.0);
  EXPECT_NE(tip_f, tip_d);  // it did run in float
  EXPECT_NEAR(tip_f, tip_d, 1e-5 * tip_d);
}

// The report counts the explicit steps run on the offset layout: every step
// of the shipped beam (one depth), none of an implicit run, and on the
// adaptive cantilever (its 4x4x4 base fills too few lanes, then it refines)
// fewer than all.
TEST(BatchReport, CountsTheStepsRunOnTheOffsetLayout) {
  BatchOptions options;
  options.duration_s = 0.05;
  options.timing = false;
  const auto offset_steps = [&](const char* scene_name, const char* kind) {
    const json r = run_batch(
        scene::load_scene_file_with_overrides(scene_path(scene_name), {std::string("integrator.kind=") + kind}),
        options, nullptr);
    EXPECT_TRUE(r["result"]["error"].is_null()) << r["result"]["error"];
    EXPECT_EQ(r["result"]["steps"].get<long long>(), 50);
    return r["result"]["solver"]["offset_layout_steps"].get<long long>();
  };
  EXPECT_EQ(offset_steps("beam", "explicit"), 50);
  EXPECT_EQ(offset_steps("beam", "implicit"), 0);
  EXPECT_LT(offset_steps("cantilever", "explicit"), 50);
}

// The shipped beam under its tip load deforms little: once the Lanczos
// bound has tightened, its explicit steps take fewer sub-steps, proved by
// the measured deformation, with none run again; implicit steps none.
TEST(BatchReport, CountsTheStepsShortenedByTheMeasuredDeformation) {
  BatchOptions options;
  options.duration_s = 1.0;
  options.timing = false;
  const auto solver = [&](const char* kind) {
    const json r =
        run_batch(scene::load_scene_file_with_overrides(scene_path("beam"), {std::string("integrator.kind=") + kind}),
                  options, nullptr);
    EXPECT_TRUE(r["result"]["error"].is_null()) << r["result"]["error"];
    return r["result"]["solver"];
  };
  const json explicit_solver = solver("explicit");
  EXPECT_GT(explicit_solver["verified_substep_steps"].get<long long>(), 0);
  EXPECT_EQ(explicit_solver["rerun_steps"].get<long long>(), 0);
  const json implicit_solver = solver("implicit");
  EXPECT_EQ(implicit_solver["verified_substep_steps"].get<long long>(), 0);
  EXPECT_EQ(implicit_solver["rerun_steps"].get<long long>(), 0);
}

TEST(BatchReport, StepsUntilTheDurationDespiteRoundedTimeSums) {
  // Ten steps of 0.01 s sum to 0.09999999999999999 s: an eleventh would overshoot.
  const scene::Scene scene = scene::load_scene_file_with_overrides(scene_path("beam"), {"integrator.dt_s=0.01"});
  BatchOptions options;
  options.duration_s = 0.1;
  const json report = run_batch(scene, options, nullptr);
  EXPECT_EQ(report["result"]["steps"].get<long long>(), 10);
  EXPECT_NEAR(report["result"]["sim_time_s"].get<double>(), 0.1, 1e-12);
  options.duration_s = 0.0;
  EXPECT_EQ(run_batch(scene, options, nullptr)["result"]["steps"].get<long long>(), 0);
}

// A stop signal ends the run before the next step: the report covers the
// steps taken and names the signal; the run is not a failure.
TEST(BatchReport, AStopSignalEndsTheRunBeforeTheNextStep) {
  physics::Simulation sim(scene::load_scene_file(scene_path("beam")));
  BatchOptions options;
  options.duration_s = 1.0;
  std::atomic<int> stop{0};
  long long seen = 0;
  const json report = run_batch(
      sim, options, nullptr,
      [&](const physics::Simulation&, double) {
        if (++seen == 25) stop = SIGTERM;
      },
      &stop);
  const json& res = report["result"];
  EXPECT_EQ(res["steps"].get<long long>(), 25);
  EXPECT_EQ(seen, 25);
  EXPECT_NEAR(res["sim_time_s"].get<double>(), 0.025, 1e-12);
  EXPECT_EQ(res["interrupted_by"], "SIGTERM");
  EXPECT_TRUE(res["error"].is_null());
}

TEST(BatchReport, TimingPresentOnlyWhenAsked) {
  const scene::Scene scene = scene::load_scene_file(scene_path("beam"));
  BatchOptions options;
  options.duration_s = 0.01;
  options.timing = false;
  EXPECT_FALSE(run_batch(scene, options, nullptr).contains("timing"));
  options.timing = true;
  const json report = run_batch(scene, options, nullptr);
  ASSERT_TRUE(report.contains("timing"));
  const json& t = report["timing"];
  ASSERT_TRUE(t["wall_s"].is_number());
  EXPECT_GT(t["wall_s"].get<double>(), 0.0);
  for (const char* key : {"p50", "p99", "max"}) {
    ASSERT_TRUE(t["step_ms"][key].is_number()) << key;
    EXPECT_GT(t["step_ms"][key].get<double>(), 0.0) << key;
  }
  EXPECT_LE(t["step_ms"]["p50"].get<double>(), t["step_ms"]["p99"].get<double>());
  EXPECT_LE(t["step_ms"]["p99"].get<double>(), t["step_ms"]["max"].get<double>());
  ASSERT_TRUE(t["real_time_factor"].is_number());
  EXPECT_NEAR(t["real_time_factor"].get<double>(),
              report["result"]["sim_time_s"].get<double>() / t["wall_s"].get<double>(), 1e-9);
}

TEST(BatchReport, FieldsHaveTheRightTypes) {
  const json& r = cantilever_report();
  const json& s = r["scene"];
  EXPECT_TRUE(s["source"].is_string());
  EXPECT_EQ(s["source"], scene_path("cantilever"));
  EXPECT_EQ(s["name"], "cantilever");
  EXPECT_EQ(s["integrator"], "implicit");
  EXPECT_TRUE(s["dt_s"].is_number_float());
  EXPECT_EQ(s["dt_s"].get<double>(), 0.001);
  EXPECT_TRUE(s["adaptivity"].is_boolean());
  EXPECT_TRUE(s["adaptivity"].get<bool>());
  EXPECT_EQ(s["overrides"], json(kCantileverOverrides));

  const json& res = r["result"];
  EXPECT_TRUE(res["sim_time_s"].is_number_float());
  EXPECT_NEAR(res["sim_time_s"].get<double>(), kCantileverDuration_s, 1e-9);
  EXPECT_TRUE(res["steps"].is_number_integer());
  EXPECT_EQ(res["steps"].get<long long>(), 300);  // summed dts round, yet no extra step
  for (const char* key : {"nodes", "tets", "springs"}) {
    ASSERT_TRUE(res[key].is_object()) << key;
    EXPECT_TRUE(res[key]["final"].is_number_integer()) << key;
    EXPECT_TRUE(res[key]["peak"].is_number_integer()) << key;
    EXPECT_GT(res[key]["final"].get<long long>(), 0) << key;
    EXPECT_GE(res[key]["peak"].get<long long>(), res[key]["final"].get<long long>()) << key;
  }
  EXPECT_TRUE(res["refines"].is_number_integer());
  EXPECT_TRUE(res["merges"].is_number_integer());
  EXPECT_TRUE(res["energy_J"]["kinetic"].is_number_float());
  EXPECT_TRUE(res["energy_J"]["elastic"].is_number_float());
  EXPECT_TRUE(res["external_work_J"].is_number_float());
  EXPECT_GT(res["external_work_J"].get<double>(), 0.0);  // the tip load did work while it bent the beam
  // The cantilever refines while it bends: its splits change the energy.
  ASSERT_TRUE(res["adaptation_energy_J"]["net"].is_number_float());
  ASSERT_TRUE(res["adaptation_energy_J"]["added"].is_number_float());
  EXPECT_NE(res["adaptation_energy_J"]["net"].get<double>(), 0.0);
  EXPECT_GT(res["adaptation_energy_J"]["added"].get<double>(), 0.0);
  EXPECT_GE(res["adaptation_energy_J"]["added"].get<double>(), res["adaptation_energy_J"]["net"].get<double>());
  EXPECT_TRUE(res["nonfinite_events"].is_number_integer());
  EXPECT_EQ(res["nonfinite_events"].get<long long>(), 0);
  EXPECT_TRUE(res["rejected_steps"].is_number_integer());
  EXPECT_EQ(res["rejected_steps"].get<long long>(), 0);
  EXPECT_TRUE(res["error"].is_null());
  EXPECT_TRUE(res["interrupted_by"].is_null());
  // A healthy run: never more energy than it was given, nothing inside out.
  EXPECT_EQ(res["energy_audit"]["worst_excess"].get<double>(), 0.0);
  EXPECT_TRUE(res["energy_audit"]["at_t_s"].is_null());
  for (const char* key : {"final", "peak"}) EXPECT_EQ(res["inverted_tets"][key].get<long long>(), 0) << key;
  EXPECT_TRUE(res["inverted_tets"]["peak_at_t_s"].is_null());

  // What the integrator spent: implicit CG iterations, one "sub-step" per step.
  const json& solver = res["solver"];
  EXPECT_TRUE(solver["iterations"]["mean"].is_number_float());
  EXPECT_TRUE(solver["iterations"]["max"].is_number_integer());
  EXPECT_GT(solver["iterations"]["mean"].get<double>(), 0.0);
  EXPECT_GE(solver["iterations"]["max"].get<double>(), solver["iterations"]["mean"].get<double>());
  EXPECT_EQ(solver["substeps"]["mean"].get<double>(), 1.0);
  EXPECT_EQ(solver["substeps"]["max"].get<long long>(), 1);
  EXPECT_TRUE(solver["unconverged_steps"].is_number_integer());
  EXPECT_EQ(solver["unconverged_steps"].get<long long>(), 0);  // the shipped tolerance is reached
  EXPECT_EQ(solver["energy_limited"]["steps"].get<long long>(), 0);
  EXPECT_EQ(solver["energy_limited"]["removed_J"].get<double>(), 0.0);

  ASSERT_TRUE(res["probes"].is_object());
  ASSERT_EQ(res["probes"].size(), 2u);
  for (const char* name : {"tip", "tip_centre"}) {
    ASSERT_TRUE(res["probes"].contains(name)) << name;
    const json& p = res["probes"][name];
    ASSERT_TRUE(p["final_displacement_m"].is_array()) << name;
    ASSERT_EQ(p["final_displacement_m"].size(), 3u) << name;
    for (const json& c : p["final_displacement_m"]) EXPECT_TRUE(c.is_number()) << name;
    EXPECT_TRUE(p["peak_magnitude_m"].is_number_float()) << name;
  }
}

TEST(BatchReport, PeaksAreTrackedEveryStep) {
  const json& res = cantilever_report()["result"];
  for (const auto& [name, p] : res["probes"].items()) {
    const auto d = p["final_displacement_m"].get<std::vector<double>>();
    const double final_m = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    const double peak_m = p["peak_magnitude_m"].get<double>();
    EXPECT_GE(peak_m, final_m) << name;
    // Released at 0.15 s, the tip sprang back: its peak (mm of bend) is long
    // gone by 0.3 s, so only per-step tracking can have seen it.
    EXPECT_GT(peak_m, 3e-3) << name;
    EXPECT_GT(peak_m, 10.0 * final_m) << name;
  }
  EXPECT_GT(res["nodes"]["peak"].get<long long>(), res["nodes"]["final"].get<long long>());  // refined, then merged
}

TEST(BatchReport, AdaptiveCantileverRefinesWithinAThirdOfASecond) {
  const json& res = cantilever_report()["result"];
  EXPECT_GT(res["refines"].get<long long>(), 0);
  EXPECT_GT(res["tets"]["peak"].get<long long>(), 384);  // above the 4x4x4-cube level-0 mesh
}

TEST(BatchReport, ProgressLinesEveryIntervalOfSimTime) {
  const scene::Scene scene = scene::load_scene_file(scene_path("beam"));
  BatchOptions options;
  options.duration_s = 0.05;
  options.progress_every_s = 0.01;
  std::FILE* out = std::tmpfile();
  ASSERT_NE(out, nullptr);
  run_batch(scene, options, out);
  std::rewind(out);
  std::vector<std::string> lines;
  char buf[1024];
  while (std::fgets(buf, sizeof buf, out)) lines.emplace_back(buf);
  std::fclose(out);
  ASSERT_EQ(lines.size(), 1u + 5u);  // a header, then t = 0.01, 0.02, ..., 0.05
  for (std::size_t i = 1; i < lines.size(); ++i) {
    char expected_time[32];
    std::snprintf(expected_time, sizeof expected_time, "%.3f s", 0.01 * static_cast<double>(i));
    EXPECT_NE(lines[i].find(expected_time), std::string::npos) << lines[i];
    for (const char* word : {"nodes", "tets", "springs", "refines", "merges", "tip ", " mm", "kin", "el ", "real time"})
      EXPECT_NE(lines[i].find(word), std::string::npos) << word << " in " << lines[i];
  }

  options.progress_every_s = 0.0;  // quiet
  std::FILE* quiet = std::tmpfile();
  ASSERT_NE(quiet, nullptr);
  run_batch(scene, options, quiet);
  EXPECT_EQ(std::ftell(quiet), 0L);
  std::fclose(quiet);
}

// A body whose energy or budget is not a finite number has an infinite
// excess (EnergyBudget::excess; written null in the report), and the warning
// says that in words. It said "the body held inf % more energy than it
// started with plus the work done on it". A fixed node given an infinite
// mass: at rest, its kinetic energy is inf x 0 = NaN from the start, while
// the implicit rung, which never moves it, takes every step (the explicit
// rung refuses the first: a NaN energy is not within its energy bound).
TEST(BatchReport, ANonFiniteEnergyIsWarnedOfInWords) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const scene::Scene scene = scene::load_scene_file_with_overrides(
      scene_path("cantilever"), {"integrator.kind=implicit", "adaptivity.enabled=false"});
  physics::Simulation sim(scene);
  physics::Body& body = sim.mutable_body();
  physics::NodeId held = 0;
  while (body.kind[held] != physics::NodeKind::kFixed) ++held;
  body.mass_kg[held] = kInf;
  BatchOptions options;
  options.duration_s = 0.005;
  options.progress_every_s = 0.0;
  const json report = run_batch(sim, options, nullptr);
  const json& result = report["result"];
  ASSERT_TRUE(result["error"].is_null()) << result["error"];
  ASSERT_EQ(result["energy_audit"]["worst_excess"].get<double>(), kInf);
  EXPECT_TRUE(json::parse(report_text(report))["result"]["energy_audit"]["worst_excess"].is_null());

  std::FILE* err = std::tmpfile();
  ASSERT_NE(err, nullptr);
  warn_of_health(scene, sim.counters(), result, err);
  std::rewind(err);
  std::string text;
  char buf[1024];
  while (std::fgets(buf, sizeof buf, err)) text += buf;
  std::fclose(err);
  EXPECT_NE(text.find("tissued: warning: the body's energy or its budget (the energy it started with plus the work "
                      "done on it) was not a finite number at t = 0.001 s"),
            std::string::npos)
      << text;
  EXPECT_EQ(text.find("inf"), std::string::npos) << text;
  EXPECT_EQ(text.find("more energy than it started with"), std::string::npos) << text;
}

// ---- the process ---------------------------------------------------------

struct Process {
  int exit_code = -1;
  std::string out, err;
};

std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += (c == '\'') ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

class TissuedProcess : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("tissued_app_test_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  Process run(const std::vector<std::string>& args) const {
    std::string command = shell_quote(TISSUED_BINARY);
    // Appended piece by piece: GCC 12 warns falsely (-Wrestrict) on "literal" + std::string&&.
    for (const auto& a : args) command.append(" ").append(shell_quote(a));
    const fs::path out = dir_ / "stdout.txt", err = dir_ / "stderr.txt";
    command.append(" >").append(shell_quote(out.string()));
    command.append(" 2>").append(shell_quote(err.string()));
    command.append(" </dev/null");
    const int status = std::system(command.c_str());
    Process p;
    if (status != -1 && WIFEXITED(status)) p.exit_code = WEXITSTATUS(status);
    p.out = read_file(out);
    p.err = read_file(err);
    return p;
  }

  fs::path dir_;
};

using record::testing::event_messages;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST_F(TissuedProcess, NoTimingReportsAreByteIdentical) {
  const fs::path a = dir_ / "a.json", b = dir_ / "b.json";
  for (const fs::path& report : {a, b}) {
    const Process p =
        run({"--batch", "--scene", scene_path("cantilever"), "--duration", "0.1", "--set",
             "loads[0].profile.release_s=0.05", "--no-timing", "--progress", "0", "--report", report.string()});
    ASSERT_EQ(p.exit_code, 0) << p.err;
    EXPECT_EQ(p.out, "");  // --progress 0 is quiet
    EXPECT_EQ(p.err, "");
  }
  const std::string text_a = read_file(a);
  ASSERT_FALSE(text_a.empty());
  EXPECT_EQ(text_a, read_file(b));
  const json report = json::parse(text_a);
  EXPECT_FALSE(report.contains("timing"));
  EXPECT_GT(report["result"]["refines"].get<long long>(), 0);
  EXPECT_GT(report["result"]["merges"].get<long long>(), 0);
}

TEST_F(TissuedProcess, ReportsTimingAndProgressByDefault) {
  const fs::path report = dir_ / "r.json";
  const Process p = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.2", "--report", report.string()});
  ASSERT_EQ(p.exit_code, 0) << p.err;
  EXPECT_TRUE(contains(p.out, "t    0.100 s")) << p.out;  // every 0.1 s of simulated time by default
  EXPECT_TRUE(contains(p.out, "t    0.200 s")) << p.out;
  EXPECT_FALSE(contains(p.out, "t    0.300 s")) << p.out;
  EXPECT_TRUE(json::parse(read_file(report)).contains("timing"));
}

TEST_F(TissuedProcess, InvalidOverrideExits2NamingTheKey) {
  const fs::path report = dir_ / "r.json";
  const Process p = run({"--batch", "--scene", scene_path("cantilever"), "--duration", "0.1", "--set",
                         "material.youngs_modulus_Pa=-1", "--report", report.string()});
  EXPECT_EQ(p.exit_code, 2);
  EXPECT_TRUE(contains(p.err, "material.youngs_modulus_Pa")) << p.err;
  EXPECT_FALSE(fs::exists(report));  // nothing ran, nothing written
}

// A value found not to fit the mesh when the body is built (a region between
// nodes) is reported as every scene error is: file: key: reason, and the
// --set that set it.
TEST_F(TissuedProcess, ARegionSetBetweenNodesByAnOverrideIsBlamedOnIt) {
  const std::string set = "loads[0].region={sphere: {centre_m: [0.1, 0.0125, 0.0125], radius_m: 0.001}}";
  const Process p = run({"--batch", "--scene", scene_path("cantilever"), "--duration", "0.1", "--set", set});
  EXPECT_EQ(p.exit_code, 2);
  EXPECT_TRUE(contains(p.err, "cantilever.yaml: loads[0].region: selects no node of the mesh")) << p.err;
  EXPECT_TRUE(contains(p.err, "(set by the override 'loads[0].region={sphere:")) << p.err;  // cut to 40 bytes
}

TEST_F(TissuedProcess, MissingSceneExits2NamingTheFile) {
  const std::string missing = (dir_ / "no_such_scene.yaml").string();
  const Process p = run({"--batch", "--scene", missing, "--duration", "0.1"});
  EXPECT_EQ(p.exit_code, 2);
  EXPECT_TRUE(contains(p.err, missing)) << p.err;
}

TEST_F(TissuedProcess, BadCommandLineExits2) {
  EXPECT_EQ(run({"--batch", "--scene", scene_path("beam"), "--duration", "-1"}).exit_code, 2);
  EXPECT_EQ(run({"--batch", "--scene", scene_path("beam")}).exit_code, 2);  // no --duration
  EXPECT_EQ(run({"--batch", "--scene", scene_path("beam"), "--duration", "1", "--bogus"}).exit_code, 2);
  const Process no_mode = run({});
  EXPECT_EQ(no_mode.exit_code, 2);
  EXPECT_TRUE(contains(no_mode.err, "--batch")) << no_mode.err;
}

// Seconds past what a clock or a counter holds: the service's --duration
// timer converted 1e10 s to nanoseconds (UB; the service stopped at once),
// and --progress 1e-20 made the run count lines past a long long. Both are
// a bad command line naming the option and its range, before anything runs
// (the config here does not exist: the option is refused before it is read).
TEST_F(TissuedProcess, SecondsOutOfRangeAreABadCommandLine) {
  const std::string config = (dir_ / "not-read.yaml").string();
  for (const char* duration : {"1e10", "1000000001", "1e300"}) {
    const Process p = run({"--config", config, "--duration", duration});
    EXPECT_EQ(p.exit_code, 2) << duration;
    EXPECT_TRUE(contains(p.err, "--duration")) << p.err;
    EXPECT_TRUE(contains(p.err, "must be a finite number of seconds in [0, 1000000000] (got " + std::string(duration)))
        << p.err;
  }
  // (A scene that does not exist either: were the bound gone, this would
  // fail on the scene instead of running for 2e9 simulated seconds.)
  const Process long_batch = run({"--batch", "--scene", (dir_ / "no-scene.yaml").string(), "--duration", "2e9"});
  EXPECT_EQ(long_batch.exit_code, 2) << long_batch.err;
  EXPECT_TRUE(contains(long_batch.err, "--duration")) << long_batch.err;
  for (const char* progress : {"1e-20", "0.0009", "-1", "1e10"}) {
    const Process p = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.01", "--progress", progress});
    EXPECT_EQ(p.exit_code, 2) << progress << ": " << p.err;
    EXPECT_TRUE(contains(p.err, "--progress")) << p.err;
    EXPECT_TRUE(contains(p.err, "must be 0 (quiet) or a number of seconds in [0.001, 1000000000]")) << p.err;
    EXPECT_EQ(p.out, "") << "nothing ran";
  }
  // A run of more steps than a batch run keeps times for (1e8): 1e9 s at the
  // smallest dt was accepted and grew by 11 MB/s for centuries.
  const Process endless = run(
      {"--batch", "--scene", scene_path("beam"), "--duration", "1e9", "--set", "integrator.dt_s=1e-7", "--no-timing"});
  EXPECT_EQ(endless.exit_code, 2) << endless.err;
  EXPECT_TRUE(contains(endless.err, "is 1e+16 steps, more than a batch run takes (1e+08)")) << endless.err;
  EXPECT_EQ(endless.out, "") << "nothing ran";
  // The bounds themselves are fine.
  const Process finest = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.01", "--progress", "0.001"});
  EXPECT_EQ(finest.exit_code, 0) << finest.err;
  EXPECT_TRUE(contains(finest.out, "done")) << finest.out;
}

TEST_F(TissuedProcess, UnwritableReportExits4NamingThePath) {
  const std::string path = "/proc/forbidden/report.json";
  const Process p = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.01", "--report", path});
  EXPECT_EQ(p.exit_code, 4);
  EXPECT_TRUE(contains(p.err, "cannot write report " + path)) << p.err;
  EXPECT_TRUE(contains(p.err, "No such file or directory")) << p.err;  // the errno reason
}

// A run that stops before it starts (its --record file exists, and sessions
// are never overwritten) leaves the user's earlier report as it was: the
// report was opened with fopen("w"), emptying it, then removed.
TEST_F(TissuedProcess, ARunThatCannotStartKeepsTheEarlierReport) {
  const fs::path report = dir_ / "old.json", session = dir_ / "existing.h5";
  std::ofstream(report) << "{\"earlier\": true}\n";
  std::ofstream(session) << "not to be overwritten";
  const Process p = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.01", "--report", report.string(),
                         "--record", session.string()});
  EXPECT_EQ(p.exit_code, 5) << p.err;
  EXPECT_TRUE(contains(p.err, "already exists")) << p.err;
  ASSERT_TRUE(fs::exists(report)) << "the earlier report was removed";
  EXPECT_EQ(read_file(report), "{\"earlier\": true}\n");
  EXPECT_EQ(read_file(session), "not to be overwritten");
  for (const auto& e : fs::directory_iterator(dir_))
    EXPECT_NE(e.path().filename().string().front(), '.') << "a temporary file was left behind: " << e.path();
}

// The report and the session (--record) of a failed run both end with the reason.
TEST_F(TissuedProcess, RefusedExplicitStepExits3WithTheReasonInTheReport) {
  const fs::path report = dir_ / "r.json", session = dir_ / "failed.h5";
  const Process p = run({"--batch", "--scene", scene_path("cantilever"), "--duration", "0.1", "--set",
                         "integrator.kind=explicit", "--set", "integrator.max_substeps=1", "--set",
                         "integrator.dt_s=0.01", "--report", report.string(), "--record", session.string()});
  EXPECT_EQ(p.exit_code, 3);
  EXPECT_TRUE(contains(p.err, "max_substeps")) << p.err;
  EXPECT_EQ(std::count(p.err.begin(), p.err.end(), '\n'), 1) << p.err;  // one line
  ASSERT_TRUE(fs::exists(report));
  const json r = json::parse(read_file(report));
  ASSERT_TRUE(r["result"]["error"].is_string());
  EXPECT_TRUE(contains(r["result"]["error"].get<std::string>(), "max_substeps"));
  EXPECT_EQ(r["result"]["steps"].get<long long>(), 0);
  EXPECT_EQ(r["result"]["rejected_steps"].get<long long>(), 1);
  EXPECT_EQ(r["result"]["nonfinite_events"].get<long long>(), 0);
  EXPECT_EQ(r["scene"]["integrator"], "explicit");
  const record::SessionInfo info = record::read_session_info(session.string());
  EXPECT_TRUE(info.closed_cleanly);
  EXPECT_EQ(info.rows.sim_rows, 0u);
  EXPECT_EQ(info.rows.mesh_frames, 1u);  // the initial state
  const std::vector<std::string> events = event_messages(session.string());
  ASSERT_EQ(events.size(), 2u);
  EXPECT_TRUE(contains(events[1], "batch run failed at t = 0 s after 0 steps")) << events[1];
  EXPECT_TRUE(contains(events[1], "max_substeps")) << events[1];
}

// The explicit rung's energy bound refuses as its sub-step cap does: exit 3,
// one line naming the key, the report's error and rejected_steps. The
// undamped cantilever swings by up to 0.11 of its budget (at the default
// slack of 1 it runs its 2 s); a slack of 0.01 refuses it within 20 ms.
TEST_F(TissuedProcess, ExplicitStepAboveItsEnergyBoundExits3WithTheReasonInTheReport) {
  const fs::path report = dir_ / "r.json";
  const Process p = run({"--batch", "--scene", scene_path("cantilever"), "--duration", "0.1", "--set",
                         "integrator.kind=explicit", "--set", "material.rayleigh_beta_s=0", "--set",
                         "integrator.explicit_energy_slack=0.01", "--report", report.string()});
  EXPECT_EQ(p.exit_code, 3) << p.err;
  EXPECT_TRUE(contains(p.err, "more than integrator.explicit_energy_slack = 0.01 allows")) << p.err;
  EXPECT_EQ(std::count(p.err.begin(), p.err.end(), '\n'), 1) << p.err;  // one line
  ASSERT_TRUE(fs::exists(report));
  const json r = json::parse(read_file(report));
  ASSERT_TRUE(r["result"]["error"].is_string());
  EXPECT_TRUE(contains(r["result"]["error"].get<std::string>(), "step refused, previous state kept"));
  EXPECT_GT(r["result"]["steps"].get<long long>(), 0);
  EXPECT_LT(r["result"]["steps"].get<long long>(), 20);
  EXPECT_EQ(r["result"]["rejected_steps"].get<long long>(), 1);
  EXPECT_EQ(r["result"]["nonfinite_events"].get<long long>(), 0);
}

// A run whose solver stops at cg_max_iterations still succeeds (exit 0), but
// says on stderr how many steps gave up accuracy and which keys to change.
TEST_F(TissuedProcess, CappedSolverWarnsNamingTheKeys) {
  const fs::path report = dir_ / "r.json";
  const Process p = run({"--batch", "--scene", scene_path("cantilever"), "--duration", "0.05", "--set",
                         "integrator.cg_max_iterations=1", "--set", "integrator.cg_tolerance=1e-12", "--progress", "0",
                         "--report", report.string()});
  ASSERT_EQ(p.exit_code, 0) << p.err;
  EXPECT_TRUE(contains(p.err, "warning: 50 of 50 steps")) << p.err;
  EXPECT_TRUE(contains(p.err, "integrator.cg_max_iterations = 1")) << p.err;
  EXPECT_TRUE(contains(p.err, "integrator.cg_tolerance")) << p.err;
  // One line (the energy guard, which one CG iteration at 1 ms needs now and
  // then, says its own on another).
  std::istringstream lines(p.err);
  std::string line, warning;
  while (std::getline(lines, line))
    if (contains(line, "steps stopped at")) warning = line;
  EXPECT_TRUE(contains(warning, "integrator.cg_max_iterations = 1") && contains(warning, "integrator.cg_tolerance"))
      << p.err;
  const json r = json::parse(read_file(report));
  EXPECT_EQ(r["result"]["solver"]["unconverged_steps"].get<long long>(), 50);
  EXPECT_EQ(r["result"]["solver"]["iterations"]["max"].get<long long>(), 1);
  EXPECT_TRUE(r["result"]["error"].is_null());
  EXPECT_TRUE(contains(p.err, "try cg_preconditioner: two_level")) << p.err;
  // Already two-level: the hint is not repeated.
  const Process q = run({"--batch", "--scene", scene_path("cantilever"), "--duration", "0.05", "--set",
                         "integrator.cg_max_iterations=1", "--set", "integrator.cg_tolerance=1e-12", "--set",
                         "integrator.cg_preconditioner=two_level", "--progress", "0"});
  ASSERT_EQ(q.exit_code, 0) << q.err;
  EXPECT_TRUE(contains(q.err, "raise cg_max_iterations or lower dt_s")) << q.err;
  EXPECT_FALSE(contains(q.err, "two_level")) << q.err;
  // Projective has no preconditioner: no hint that changes nothing.
  const Process pd = run({"--batch", "--scene", scene_path("cantilever"), "--duration", "0.05", "--set",
                          "integrator.kind=projective", "--set", "integrator.cg_max_iterations=1", "--progress", "0"});
  ASSERT_EQ(pd.exit_code, 0) << pd.err;
  EXPECT_TRUE(contains(pd.err, "raise cg_max_iterations or lower dt_s")) << pd.err;
  EXPECT_FALSE(contains(pd.err, "two_level")) << pd.err;
}

// Runs beyond what springs model faithfully say so, in the report and on
// stderr: a 1000 N pull at dt = 1/30 s turns tets inside out and its first
// implicit step needs the energy guard; the undamped explicit cantilever's
// energy swings above what it was given (README, energy table).
TEST_F(TissuedProcess, AnExtremeRunReportsItsInvertedTetsAndItsEnergy) {
  const fs::path report = dir_ / "r.json";
  const Process p = run({"--batch", "--scene", scene_path("cantilever"), "--duration", "0.3", "--set",
                         "loads[0].total_force_N=[0,0,-1000]", "--set", "integrator.dt_s=0.0333333333333", "--progress",
                         "0", "--report", report.string()});
  ASSERT_EQ(p.exit_code, 0) << p.err;
  const json r = json::parse(read_file(report));
  const json& inverted = r["result"]["inverted_tets"];
  EXPECT_GT(inverted["peak"].get<long long>(), 0);
  EXPECT_GE(inverted["peak"].get<long long>(), inverted["final"].get<long long>());
  EXPECT_GT(inverted["peak_at_t_s"].get<double>(), 0.0);
  EXPECT_TRUE(contains(p.err, "tets were inside out")) << p.err;
  const json& limited = r["result"]["solver"]["energy_limited"];
  EXPECT_GT(limited["steps"].get<long long>(), 0);
  EXPECT_GT(limited["removed_J"].get<double>(), 0.0);
  EXPECT_TRUE(contains(p.err, "were slowed")) << p.err;
  // The guard held it, to within the room it leaves for rounding (1e-9 of
  // the budget), below what the batch warns of.
  EXPECT_LE(r["result"]["energy_audit"]["worst_excess"].get<double>(), 1e-8);
  EXPECT_FALSE(contains(p.err, "more energy than it started with")) << p.err;

  const Process q =
      run({"--batch", "--scene", scene_path("cantilever"), "--duration", "0.6", "--set", "integrator.kind=explicit",
           "--set", "material.rayleigh_beta_s=0", "--progress", "0", "--report", report.string()});
  ASSERT_EQ(q.exit_code, 0) << q.err;
  const json e = json::parse(read_file(report));
  EXPECT_GT(e["result"]["energy_audit"]["worst_excess"].get<double>(), 1e-6);
  EXPECT_GT(e["result"]["energy_audit"]["at_t_s"].get<double>(), 0.0);
  EXPECT_TRUE(contains(q.err, "more energy than it started with")) << q.err;
  EXPECT_TRUE(contains(q.err, "substep_safety")) << q.err;
  EXPECT_EQ(e["result"]["inverted_tets"]["peak"].get<long long>(), 0);
  EXPECT_FALSE(contains(q.err, "inside out")) << q.err;
}

// --record: the run as a session file the session tools read (one sim row per
// step, a surface frame every 1/30 s of simulated time from the first state to
// the last, how the run started and ended), and the report unchanged by it.
TEST_F(TissuedProcess, RecordWritesTheRunAsASessionAndLeavesTheReportAsItWas) {
  const fs::path plain = dir_ / "plain.json", recorded = dir_ / "recorded.json", session = dir_ / "run.h5";
  const std::vector<std::string> args = {"--batch",    "--scene", scene_path("cantilever"),          "--duration",
                                         "0.3",        "--set",   "loads[0].profile.release_s=0.15", "--no-timing",
                                         "--progress", "0"};
  std::vector<std::string> with_report = args;
  with_report.insert(with_report.end(), {"--report", plain.string()});
  ASSERT_EQ(run(with_report).exit_code, 0);
  std::vector<std::string> with_record = args;
  with_record.insert(with_record.end(), {"--report", recorded.string(), "--record", session.string()});
  const Process p = run(with_record);
  ASSERT_EQ(p.exit_code, 0) << p.err;
  EXPECT_EQ(read_file(plain), read_file(recorded));
  const json r = json::parse(read_file(recorded));

  const record::SessionInfo info = record::read_session_info(session.string());
  EXPECT_TRUE(info.closed_cleanly);
  EXPECT_EQ(info.scene_name, "cantilever");
  EXPECT_EQ(info.rows.haptic_rows, 0u);
  EXPECT_EQ(info.rows.sim_rows, r["result"]["steps"].get<std::uint64_t>());
  EXPECT_EQ(info.rows.mesh_frames, 10u);  // t = 0, 1/30, ..., 9/30 = 0.3 s
  EXPECT_EQ(info.rows.events, 2u);
  const std::vector<std::string> events = event_messages(session.string());
  ASSERT_EQ(events.size(), 2u);
  EXPECT_TRUE(contains(events[0], "--set 'loads[0].profile.release_s=0.15'")) << events[0];
  EXPECT_TRUE(contains(events[1], "completed at t = 0.3 s after 300 steps")) << events[1];

  // The last sim row is the report's end state; the frames span the run.
  const record::SessionRows rows = record::read_session_rows(session.string());
  ASSERT_FALSE(rows.sim.empty());
  EXPECT_EQ(rows.sim.back().sim_time_s, r["result"]["sim_time_s"].get<double>());
  EXPECT_EQ(static_cast<std::int64_t>(rows.sim.back().refines), r["result"]["refines"].get<std::int64_t>());
  EXPECT_EQ(static_cast<std::int64_t>(rows.sim.back().merges), r["result"]["merges"].get<std::int64_t>());
  EXPECT_EQ(rows.sim.back().elastic_J, r["result"]["energy_J"]["elastic"].get<double>());
  const auto frames = x3d::open_session_source(session.string());
  ASSERT_EQ(frames->frame_count(), 10u);
  EXPECT_EQ(frames->frame_time_s(0), 0.0);
  EXPECT_EQ(frames->frame_time_s(9), r["result"]["sim_time_s"].get<double>());
  EXPECT_TRUE(frames->has_strain());
  // While loaded the mesh refines: its surface has more vertices than at rest.
  EXPECT_GT(frames->read_frame(4).vertices_m.size(), frames->read_frame(0).vertices_m.size());

  // And the session tools take it as they take the service's sessions.
  const std::string x3d_out = (dir_ / "run.x3d").string();
  const int x3d_status =
      std::system((shell_quote(TISSUE_CLI_BINARY) + " x3d --session " + shell_quote(session.string()) +
                   " --time 0.3 -o " + shell_quote(x3d_out) + " >/dev/null 2>&1")
                      .c_str());
  EXPECT_EQ(x3d_status, 0);
  EXPECT_TRUE(fs::exists(x3d_out));
}

// A run that ends between frame times still records its last state.
TEST_F(TissuedProcess, RecordEndsWithTheLastState) {
  const fs::path session = dir_ / "short.h5", report = dir_ / "r.json";
  const Process p = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.05", "--progress", "0", "--record",
                         session.string(), "--report", report.string()});
  ASSERT_EQ(p.exit_code, 0) << p.err;
  const auto frames = x3d::open_session_source(session.string());
  ASSERT_EQ(frames->frame_count(), 3u);  // t = 0, 1/30 s and the end
  EXPECT_EQ(frames->frame_time_s(2), json::parse(read_file(report))["result"]["sim_time_s"].get<double>());
  EXPECT_GT(frames->frame_time_s(1), frames->frame_time_s(0));
}

// --record-interval sets the frames' spacing in simulated time; without
// --record, with --config, or at 0 it is a usage error.
TEST_F(TissuedProcess, RecordIntervalSpacesTheFrames) {
  const fs::path session = dir_ / "sparse.h5";
  const Process p = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.05", "--progress", "0", "--record",
                         session.string(), "--record-interval", "0.02"});
  ASSERT_EQ(p.exit_code, 0) << p.err;
  EXPECT_EQ(x3d::open_session_source(session.string())->frame_count(), 4u);  // 0, 0.02, 0.04 and 0.05 s
  for (const std::vector<std::string>& bad :
       {std::vector<std::string>{"--batch", "--scene", scene_path("beam"), "--duration", "0.05", "--record-interval",
                                 "0.02"},
        std::vector<std::string>{"--batch", "--scene", scene_path("beam"), "--duration", "0.05", "--record",
                                 (dir_ / "zero.h5").string(), "--record-interval", "0"},
        std::vector<std::string>{"--config", "whatever.yaml", "--record-interval", "0.02"}}) {
    const Process q = run(bad);
    EXPECT_EQ(q.exit_code, 2) << q.err;
    EXPECT_TRUE(contains(q.err, "--record-interval")) << q.err;
  }
  EXPECT_FALSE(fs::exists(dir_ / "zero.h5"));
}

// The batch run's own options were silently ignored by the service:
// `--config C --scene B` served C's scene. Each is a usage error there, before
// the config is even read, naming the option.
TEST_F(TissuedProcess, BatchOnlyOptionsAreRefusedWithConfig) {
  for (const std::vector<std::string>& extra :
       {std::vector<std::string>{"--scene", scene_path("beam")}, std::vector<std::string>{"--report", "r.json"},
        std::vector<std::string>{"--no-timing"}, std::vector<std::string>{"--progress", "0"}}) {
    std::vector<std::string> args{"--config", "whatever.yaml"};
    args.insert(args.end(), extra.begin(), extra.end());
    const Process p = run(args);
    EXPECT_EQ(p.exit_code, 2) << p.err;
    EXPECT_TRUE(contains(p.err, extra.front() + " is for --batch")) << p.err;
  }
  EXPECT_TRUE(contains(run({"--config", "whatever.yaml", "--scene", "b.yaml"}).err, "--set scene=FILE"));
}

// --duration 0 with --config meant "no limit" to the service and it never
// stopped: a usage error now, before anything starts.
TEST_F(TissuedProcess, AZeroDurationForTheServiceIsAUsageError) {
  const Process p = run({"--config", "whatever.yaml", "--duration", "0"});
  EXPECT_EQ(p.exit_code, 2) << p.err;
  EXPECT_TRUE(contains(p.err, "--duration with --config must be > 0")) << p.err;
}

TEST_F(TissuedProcess, RecordNeverOverwritesAndAnUnwritablePathExits5BeforeTheRun) {
  const fs::path session = dir_ / "taken.h5", report = dir_ / "r.json";
  std::ofstream(session) << "someone else's file";
  const Process taken = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.05", "--record",
                             session.string(), "--report", report.string()});
  EXPECT_EQ(taken.exit_code, 5);
  EXPECT_TRUE(contains(taken.err, session.string())) << taken.err;
  EXPECT_TRUE(contains(taken.err, "already exists")) << taken.err;
  EXPECT_EQ(read_file(session), "someone else's file");
  EXPECT_FALSE(fs::exists(report));  // nothing ran
  const std::string nowhere = (dir_ / "missing" / "s.h5").string();
  const Process missing = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.05", "--record", nowhere});
  EXPECT_EQ(missing.exit_code, 5);
  EXPECT_TRUE(contains(missing.err, nowhere)) << missing.err;
}

// The report replaces its path when the run ends, so it may be neither the
// scene nor the session (in any spelling): the JSON took the session's name
// and the run said "done". Refused before anything runs.
TEST_F(TissuedProcess, AReportThatWouldReplaceTheSceneOrTheSessionIsRefused) {
  const fs::path scene = dir_ / "beam.yaml";
  fs::copy_file(scene_path("beam"), scene);
  const std::string scene_text = read_file(scene);
  const Process over_scene = run(
      {"--batch", "--scene", scene.string(), "--duration", "0.05", "--report", (dir_ / "." / "beam.yaml").string()});
  EXPECT_EQ(over_scene.exit_code, 2) << over_scene.err;
  EXPECT_TRUE(contains(over_scene.err, "is the scene file (--scene)")) << over_scene.err;
  EXPECT_EQ(read_file(scene), scene_text);
  const fs::path session = dir_ / "run.h5";
  for (const std::string& report : {session.string(), (dir_ / "." / "run.h5").string()}) {
    const Process over_session = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.05", "--record",
                                      session.string(), "--report", report});
    EXPECT_EQ(over_session.exit_code, 2) << report << ": " << over_session.err;
    EXPECT_TRUE(contains(over_session.err, "is the session file (--record)")) << over_session.err;
    EXPECT_FALSE(fs::exists(session)) << "nothing ran";
  }
}

// `--report /dev/stdout` prints the report alone: the live lines and the
// closing line go to stderr (they were around the JSON on stdout).
TEST_F(TissuedProcess, AReportToStandardOutputIsTheReportAlone) {
  const Process p = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.2", "--report", "/dev/stdout"});
  ASSERT_EQ(p.exit_code, 0) << p.err;
  EXPECT_TRUE(json::parse(p.out, nullptr, false).is_object()) << p.out;
  EXPECT_TRUE(contains(p.err, "t    0.100 s")) << p.err;
  EXPECT_TRUE(contains(p.err, "done: ")) << p.err;
}

// An empty file name (an unset shell variable) is a usage error, not a run
// that records or reports nothing and says nothing.
TEST_F(TissuedProcess, AnEmptyReportOrRecordNameIsAUsageError) {
  for (const char* option : {"--report", "--record"}) {
    const Process p = run({"--batch", "--scene", scene_path("beam"), "--duration", "0.05", option, ""});
    EXPECT_EQ(p.exit_code, 2) << option << ": " << p.err;
    EXPECT_TRUE(contains(p.err, std::string(option) + " needs a file name")) << p.err;
  }
}

// Under a file-size limit the session write fails (EFBIG) instead of
// killing tissued (SIGXFSZ): the run goes on, the report is written, the
// recording error is named and the exit code says the session is incomplete.
TEST_F(TissuedProcess, AFileSizeLimitStopsTheRecordingNotTheRun) {
  const fs::path session = dir_ / "limited.h5", report = dir_ / "r.json";
  const std::string command = "ulimit -f 150; exec " + shell_quote(TISSUED_BINARY) + " --batch --scene " +
                              shell_quote(scene_path("cantilever")) + " --duration 0.2 --progress 0 --record " +
                              shell_quote(session.string()) + " --report " + shell_quote(report.string()) + " 2>" +
                              shell_quote((dir_ / "err.txt").string());
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status)) << "killed by a signal: " << (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  EXPECT_EQ(WEXITSTATUS(status), 5);
  const std::string err = read_file(dir_ / "err.txt");
  // Said once, at once, then the exit line names the incomplete session.
  EXPECT_TRUE(contains(err, "recording to " + session.string() + " stopped")) << err;
  EXPECT_TRUE(contains(err, "File too large")) << err;
  EXPECT_TRUE(contains(err, "(the run goes on)")) << err;
  EXPECT_TRUE(contains(err, "session " + session.string() + " is incomplete")) << err;
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 2) << err;
  EXPECT_EQ(json::parse(read_file(report))["result"]["steps"].get<long long>(), 200);  // the run went on
}

// Standard output on a pipe whose reader has gone (a log viewer closed): the
// run's lines fail with EPIPE instead of SIGPIPE killing it, so it finishes
// and writes its report. (If the reader were slow to go, the test would pass
// without proving anything, never fail wrongly.)
TEST_F(TissuedProcess, AClosedStdoutPipeDoesNotKillTheRun) {
  const fs::path report = dir_ / "r.json", code = dir_ / "code.txt";
  std::string command = "( " + shell_quote(TISSUED_BINARY);
  command.append(" --batch --scene ").append(shell_quote(scene_path("cantilever")));
  command.append(" --duration 0.2 --report ").append(shell_quote(report.string()));
  command.append(" 2>/dev/null; echo $? >").append(shell_quote(code.string())).append(" ) | true");
  ASSERT_EQ(std::system(command.c_str()), 0);
  EXPECT_EQ(read_file(code), "0\n") << "141 is 128 + SIGPIPE";
  EXPECT_EQ(json::parse(read_file(report))["result"]["steps"].get<long long>(), 200);
}

// A batch run of the cantilever for 1000 simulated seconds (far longer than
// any test waits) in the background, with its session, report, progress
// lines and stderr under `dir`, named after `name`: for the signal tests.
struct LongBatchRun {
  LongBatchRun(const fs::path& dir, const std::string& name, bool ignore_sigint)
      : session(dir / (name + ".h5")),
        report(dir / (name + ".json")),
        process({TISSUED_BINARY, "--batch", "--scene", scene_path("cantilever"), "--duration", "1000", "--progress",
                 "0.01", "--report", report.string(), "--record", session.string()},
                dir / (name + ".out"), dir / (name + ".err"), ignore_sigint) {}
  // A progress line seen: the run is under way, its handlers installed.
  // Up to 60 s (sanitizer builds start slowly).
  bool wait_until_stepping() const { return process.wait_for_output("\nt ", 60.0); }

  const fs::path session, report;
  testing::BackgroundProcess process;
};

// Ctrl-C (SIGINT) or SIGTERM on a long batch run: it stops after the step in
// progress, the report and the session are written for the run so far (the
// session closed cleanly, its last frame the last state, an event naming the
// signal), and the exit code is 128 + the signal's number.
TEST_F(TissuedProcess, ASignalStopsTheRunAndKeepsTheReportAndTheSession) {
  for (const int signo : {SIGINT, SIGTERM}) {
    SCOPED_TRACE(util::signal_name(signo));
    LongBatchRun run(dir_, util::signal_name(signo), /*ignore_sigint=*/false);
    ASSERT_TRUE(run.process.started());
    EXPECT_TRUE(run.wait_until_stepping()) << run.process.err();
    ASSERT_TRUE(run.process.signal(signo));
    // It stops after the step in progress: a minute means it did not.
    const std::optional<int> status = run.process.wait_for_exit(60.0);
    ASSERT_TRUE(status.has_value()) << "tissued did not stop within 60 s of " << util::signal_name(signo);
    const std::string err = run.process.err();
    ASSERT_TRUE(WIFEXITED(*status)) << "killed by signal " << (WIFSIGNALED(*status) ? WTERMSIG(*status) : 0) << err;
    EXPECT_EQ(WEXITSTATUS(*status), 128 + signo) << err;
    EXPECT_TRUE(contains(err, "interrupted by " + util::signal_name(signo))) << err;
    EXPECT_TRUE(contains(err, "report " + run.report.string())) << err;
    EXPECT_TRUE(contains(err, "session " + run.session.string())) << err;

    const json r = json::parse(read_file(run.report));
    EXPECT_EQ(r["result"]["interrupted_by"], util::signal_name(signo));
    EXPECT_TRUE(r["result"]["error"].is_null());
    const double reached_s = r["result"]["sim_time_s"].get<double>();
    EXPECT_GE(reached_s, 0.01);
    EXPECT_LT(reached_s, 1000.0);

    const record::SessionInfo info = record::read_session_info(run.session.string());
    EXPECT_TRUE(info.closed_cleanly);
    EXPECT_EQ(info.rows.sim_rows, r["result"]["steps"].get<std::uint64_t>());
    EXPECT_NEAR(info.duration_s, reached_s, 1e-12);  // simulated seconds
    const std::vector<std::string> events = event_messages(run.session.string());
    ASSERT_EQ(events.size(), 2u);
    EXPECT_TRUE(contains(events[1], "interrupted by " + util::signal_name(signo))) << events[1];
    const auto frames = x3d::open_session_source(run.session.string());
    ASSERT_GT(frames->frame_count(), 0u);
    EXPECT_EQ(frames->frame_time_s(frames->frame_count() - 1), reached_s);
  }
}

// A SIGINT the process was started ignoring (nohup, `cmd &` in a script)
// stays ignored: the run goes on; SIGTERM still stops it.
TEST_F(TissuedProcess, AnIgnoredSigintStaysIgnored) {
  LongBatchRun run(dir_, "nohup", /*ignore_sigint=*/true);
  ASSERT_TRUE(run.process.started());
  EXPECT_TRUE(run.wait_until_stepping()) << run.process.err();
  ASSERT_TRUE(run.process.signal(SIGINT));
  EXPECT_FALSE(run.process.wait_for_exit(0.5).has_value()) << run.process.err();
  ASSERT_TRUE(run.process.signal(SIGTERM));
  const std::optional<int> status = run.process.wait_for_exit(60.0);
  ASSERT_TRUE(status.has_value());
  EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 128 + SIGTERM) << run.process.err();
}

}  // namespace
}  // namespace tissue::app
