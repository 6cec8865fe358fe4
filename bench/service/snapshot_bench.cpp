// snapshot_bench: what handing a surface snapshot off costs the sim thread,
// next to what a step costs it (issue 5: target <= 2 % of a step).
//
//   build/dev/bench/snapshot_bench [--steps N] [--scene FILE]   (N: 3 to 10000, default 30)
//
// For the shipped cantilever (the daemon's default scene) and the same
// 0.1 m object at finer uniform lattices (up to a flat slab whose surface has
// ~100k triangles), it alternates one sim step and one hand-off and reports
// medians of thread CPU time (robust on a shared machine):
//   step        Simulation::step() (the scene's integrator, implicit cg by default)
//   hand-off    build_mesh_snapshot into a triple-buffer slot + publish, with
//               the surface reused (topology unchanged since the last one)
//   re-extract  the same after a split or merge (surface extracted again)
// and the ratios: per snapshot (hand-off / step) and as a share of the sim
// thread at the daemon's rates (30 Hz snapshots, one step per dt_s).
#include <time.h>

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include "../bench_timing.hpp"
#include "concurrency/latest_value.hpp"
#include "scene/scene_yaml.hpp"
#include "service/mesh_snapshot.hpp"

namespace {

using tissue::service::MeshSnapshot;

using tissue::bench::median;
using tissue::bench::thread_cpu_ns;

struct Case {
  std::string name;
  tissue::scene::Scene scene;
};

void run(const Case& c, int steps) {
  tissue::physics::Simulation sim(c.scene);
  tissue::concurrency::LatestValue<MeshSnapshot> channel;
  tissue::service::SnapshotScratch scratch;
  std::vector<double> step_ns, handoff_ns, extract_ns;
  for (int i = 0; i < steps + 3; ++i) {
    double t0 = thread_cpu_ns();
    if (!sim.step().ok) {
      std::fprintf(stderr, "snapshot_bench: %s: step failed\n", c.name.c_str());
      std::exit(1);
    }
    double t1 = thread_cpu_ns();
    const bool extracted = scratch.topology_version != sim.body().mesh().topology_version();
    tissue::service::build_mesh_snapshot(sim, &scratch, &channel.write_buffer());
    channel.publish();
    double t2 = thread_cpu_ns();
    // The same hand-off as after a split or merge: the surface is extracted.
    scratch.topology_version = 0;
    tissue::service::build_mesh_snapshot(sim, &scratch, &channel.write_buffer());
    channel.publish();
    double t3 = thread_cpu_ns();
    if (i < 3) continue;  // warm-up: first touches, buffer growth
    step_ns.push_back(t1 - t0);
    if (!extracted) handoff_ns.push_back(t2 - t1);
    extract_ns.push_back(t3 - t2);
  }
  const MeshSnapshot& snap = *channel.read().value;
  const double step = median(step_ns), extract = median(extract_ns);
  const double handoff = handoff_ns.empty() ? extract : median(handoff_ns);
  const double steps_per_snapshot = (1.0 / 30.0) / c.scene.integrator.dt_s;
  std::printf("%-22s %7zu %8zu %9.3f %9.3f %10.3f %8.2f%% %8.2f%% %9.3f%%\n", c.name.c_str(),
              sim.body().mesh().tet_count(), snap.triangles.size(), 1e-6 * step, 1e-6 * handoff, 1e-6 * extract,
              100.0 * handoff / step, 100.0 * extract / step, 100.0 * handoff / (steps_per_snapshot * step));
}

// The shipped scene at `scene_path` and its finer variants, one row each.
void run_cases(const std::string& scene_path, int steps) {
  const tissue::scene::Scene base = tissue::scene::load_scene_file(scene_path);
  std::vector<Case> cases{{"scene as shipped", base}};
  // The same object at finer uniform lattices: no adaptivity, so the
  // hand-off reuses its surface, and the step is the integrator's alone.
  for (const int n : {8, 16, 32}) {
    Case c{"uniform " + std::to_string(n) + "^3", base};
    c.scene.object.cubes = {n, n, n};
    c.scene.object.cube_size_m = base.object.cube_size_m * base.object.cubes[0] / n;
    c.scene.adaptivity.enabled = false;
    cases.push_back(c);
  }
  {
    // A flat slab with ~100k surface triangles, the size issue 5 names.
    Case c{"slab 160x160x2", base};
    c.scene.object.cubes = {160, 160, 2};
    c.scene.object.cube_size_m = base.object.cube_size_m * base.object.cubes[0] / 160;
    c.scene.adaptivity.enabled = false;
    c.scene.probes.clear();
    cases.push_back(c);
  }
  std::printf("snapshot_bench: %d steps per case, medians of thread CPU time, scene %s\n", steps, scene_path.c_str());
  std::printf("%-22s %7s %8s %9s %9s %10s %9s %9s %10s\n", "case", "tets", "tris", "step ms", "hand ms", "extract ms",
              "hand/step", "extr/step", "share@30Hz");
  for (const Case& c : cases) run(c, steps);
}

}  // namespace

int main(int argc, char** argv) {
  // At least 3 measured steps for a median; at most 10000, which is hours for
  // the largest case already (and keeps steps + 3 far from overflowing).
  constexpr int kMinSteps = 3, kMaxSteps = 10000;
  int steps = 30;
  std::string scene_path = std::string(TISSUE_SOURCE_DIR) + "/config/scenes/cantilever.yaml";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--steps" && i + 1 < argc) {
      // The whole argument: atoi read "abc" as 0 (then 3, silently) and
      // overflowed on the loop bound for 2147483647.
      const char* text = argv[++i];
      const char* end = text + std::strlen(text);
      const auto [stop, error] = std::from_chars(text, end, steps);
      if (error != std::errc{} || stop != end || steps < kMinSteps || steps > kMaxSteps) {
        std::fprintf(stderr, "snapshot_bench: --steps must be a whole number from %d to %d (got '%s')\n", kMinSteps,
                     kMaxSteps, text);
        return 2;
      }
    } else if (a == "--scene" && i + 1 < argc)
      scene_path = argv[++i];
    else {
      std::fprintf(stderr, "usage: %s [--steps N] [--scene FILE]\n", argv[0]);
      return 2;
    }
  }
  try {
    run_cases(scene_path, steps);
  } catch (const std::exception& e) {  // a SceneError names the file and what is wrong in it
    std::fprintf(stderr, "snapshot_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
