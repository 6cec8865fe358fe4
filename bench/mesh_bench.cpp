// Mesh benchmarks for the paper's linear-time claim: split/merge cost per tet
// must stay constant from 10^3 to >= 10^6 tets (target <= 1 us per tet
// created) and memory must stay <= 200 bytes per leaf tet.
//
// Conventions (they matter when reading the numbers):
// - "tets created" is the net growth of the leaf-tet count. A bisection births
//   two tets and kills one, so this is the stricter of the two possible counts.
//   "tets destroyed" (merge) is the net shrinkage, likewise.
// - Building and pre-refining the box is setup: only the measured step is
//   inside the manual-time interval.
// - bytes_per_tet = memory_bytes() / tet_count(); memory_bytes counts capacity.
// - Iterations are fixed per benchmark (not from --benchmark_min_time) so the
//   whole run stays well under two minutes on a shared 2-core machine.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "mesh/kuhn_mesh.hpp"
#include "mesh/lattice.hpp"
#include "mesh/mesh_change.hpp"
#include "mesh/refine_ops.hpp"

namespace {

using namespace tissue::mesh;
using Clock = std::chrono::steady_clock;

constexpr int kMaxDepth = 9;
constexpr double kCubeSizeM = 0.01;

BoxSpec cube_box(int n) { return BoxSpec{n, n, n, kCubeSizeM, kMaxDepth}; }

double ns_between(Clock::time_point t0, Clock::time_point t1) {
  return std::chrono::duration<double, std::nano>(t1 - t0).count();
}

// Leaf tets after uniformly refining an n^3-cube box to `depth`.
std::int64_t uniform_tets(int n, int depth) { return std::int64_t{6} * n * n * n << depth; }

// Enough iterations that small meshes are timed over ~`budget` tets in total
// (one small refinement is only tens of microseconds), at least `floor`.
benchmark::IterationCount iterations_for(std::int64_t tets_per_iteration, std::int64_t budget, int floor) {
  return std::max<benchmark::IterationCount>(floor, budget / std::max<std::int64_t>(1, tets_per_iteration));
}

void set_memory_counters(benchmark::State& state, const KuhnMesh& mesh) {
  const double tets = static_cast<double>(mesh.tet_count());
  state.counters["tets"] = tets;
  state.counters["bytes_per_tet"] = static_cast<double>(mesh.memory_bytes()) / tets;
}

// Undoes the last uniform level: merges every diamond whose tets were at
// `depth`. Scans, sorts and merges like merge_all, so it mirrors
// refine_uniform's own scan + sort + split.
int merge_level(KuhnMesh& mesh, int depth) {
  std::vector<Key> keys;
  mesh.for_each_node([&](NodeId n, const Node& node) {
    if (node.edge_a != kInvalidId && node.depth == depth) keys.push_back(mesh.node_key(n));
  });
  std::sort(keys.begin(), keys.end());
  for (Key k : keys) mesh.merge(k);
  return static_cast<int>(keys.size());
}

// 1. Uniform refinement by one level, depth -> depth + 1.
void split_one_level(benchmark::State& state, int n, int depth) {
  double total_ns = 0.0;
  std::int64_t created = 0;
  for (auto _ : state) {
    KuhnMesh mesh(cube_box(n));
    refine_uniform(mesh, depth);
    const auto before = static_cast<std::int64_t>(mesh.tet_count());
    const auto t0 = Clock::now();
    refine_uniform(mesh, depth + 1);
    const auto t1 = Clock::now();
    const double ns = ns_between(t0, t1);
    state.SetIterationTime(ns * 1e-9);
    total_ns += ns;
    created += static_cast<std::int64_t>(mesh.tet_count()) - before;
    set_memory_counters(state, mesh);
  }
  state.SetItemsProcessed(created);
  state.counters["ns_per_tet_created"] = total_ns / static_cast<double>(created);
}

// 2. Merge of one uniform level, depth + 1 -> depth.
void merge_one_level(benchmark::State& state, int n, int depth) {
  double total_ns = 0.0;
  std::int64_t destroyed = 0;
  std::size_t tets_after = 0;
  for (auto _ : state) {
    KuhnMesh mesh(cube_box(n));
    refine_uniform(mesh, depth + 1);
    const auto before = static_cast<std::int64_t>(mesh.tet_count());
    const auto t0 = Clock::now();
    merge_level(mesh, depth);
    const auto t1 = Clock::now();
    const double ns = ns_between(t0, t1);
    state.SetIterationTime(ns * 1e-9);
    total_ns += ns;
    destroyed += before - static_cast<std::int64_t>(mesh.tet_count());
    tets_after = mesh.tet_count();
  }
  if (tets_after != static_cast<std::size_t>(uniform_tets(n, depth)))
    state.SkipWithError("merge_level did not restore the coarser level");
  state.SetItemsProcessed(destroyed);
  state.counters["tets"] = static_cast<double>(uniform_tets(n, depth + 1));  // size merged from
  state.counters["ns_per_tet_destroyed"] = total_ns / static_cast<double>(destroyed);
}

// Random diamonds `extra` levels below the leaves: splitting one from the
// uniform mesh needs its unsplit ancestors first, i.e. the closure.
std::vector<Key> random_deep_diamonds(const KuhnMesh& mesh, int extra, std::size_t count, std::mt19937_64& rng) {
  std::vector<Key> keys;
  std::uniform_int_distribution<TetId> pick_tet(0, static_cast<TetId>(mesh.tet_capacity() - 1));
  while (keys.size() < count) {
    const TetId t = pick_tet(rng);
    if (!mesh.tet_alive(t)) continue;
    Key key = mesh.diamond_of(t);
    DiamondInfo info = mesh.diamond_info(key);
    bool ok = true;
    for (int level = 0; level < extra && ok; ++level) {
      std::array<Key, 8> children{};
      const int c = diamond_children(mesh.domain(), info, &children);
      ok = c > 0;
      if (ok) {
        key = children[rng() % static_cast<unsigned>(c)];
        info = mesh.diamond_info(key);
      }
    }
    if (ok && mesh.can_split(key)) keys.push_back(key);
  }
  return keys;
}

// 3. The adaptive case: split one random deep diamond (closure included) and
// merge it all back, in a mesh of fixed size. Must not grow with mesh size.
void local_split_merge(benchmark::State& state, int n, int depth, int extra) {
  KuhnMesh mesh(cube_box(n));
  refine_uniform(mesh, depth);
  const auto base_tets = static_cast<std::int64_t>(mesh.tet_count());
  std::mt19937_64 rng(20240611);
  const std::vector<Key> keys = random_deep_diamonds(mesh, extra, 1024, rng);
  MeshChangeLog log;
  std::size_t next = 0;
  double split_ns = 0.0, merge_ns = 0.0;
  std::int64_t created = 0, diamonds = 0;
  for (auto _ : state) {
    const Key key = keys[next];
    next = (next + 1) % keys.size();
    log.clear();
    const auto t0 = Clock::now();
    diamonds += mesh.split(key, &log);
    const auto t1 = Clock::now();
    created += static_cast<std::int64_t>(mesh.tet_count()) - base_tets;
    // Reverse split order is a valid merge order: a diamond's children that
    // got split were split after it.
    for (auto it = log.events.rbegin(); it != log.events.rend(); ++it)
      if (it->kind == MeshEvent::Kind::kNodeAdded) mesh.merge(mesh.node_key(it->id));
    const auto t2 = Clock::now();
    split_ns += ns_between(t0, t1);
    merge_ns += ns_between(t1, t2);
    state.SetIterationTime(ns_between(t0, t2) * 1e-9);
  }
  if (static_cast<std::int64_t>(mesh.tet_count()) != base_tets) state.SkipWithError("merge did not undo the split");
  const double ops = static_cast<double>(state.iterations());
  const double tets = static_cast<double>(created);
  state.SetItemsProcessed(created);
  state.counters["tets"] = static_cast<double>(base_tets);
  state.counters["diamonds_per_op"] = static_cast<double>(diamonds) / ops;
  state.counters["tets_created_per_op"] = tets / ops;
  state.counters["split_ns_per_tet"] = split_ns / tets;
  state.counters["merge_ns_per_tet"] = merge_ns / tets;
  state.counters["ns_per_tet_split_merge"] = (split_ns + merge_ns) / tets;
}

// 4. The headline case: 32^3 cubes (196,608 tets) refined by 3 levels
// to 1,572,864 tets. `reserve` pre-sizes the pools, isolating vector slack
// from the mesh's intrinsic bytes per tet.
void uniform_32_by_3(benchmark::State& state, bool reserve) {
  double total_ns = 0.0;
  std::int64_t created = 0;
  for (auto _ : state) {
    KuhnMesh mesh(BoxSpec{32, 32, 32, kCubeSizeM, kMaxDepth});
    if (reserve) mesh.reserve_tets(static_cast<std::size_t>(uniform_tets(32, 3)));
    const auto before = static_cast<std::int64_t>(mesh.tet_count());
    const auto t0 = Clock::now();
    refine_uniform(mesh, 3);
    const auto t1 = Clock::now();
    const double ns = ns_between(t0, t1);
    state.SetIterationTime(ns * 1e-9);
    total_ns += ns;
    created += static_cast<std::int64_t>(mesh.tet_count()) - before;
    set_memory_counters(state, mesh);
    const double tets = static_cast<double>(mesh.tet_count());
    state.counters["nodes_per_tet"] = static_cast<double>(mesh.node_count()) / tets;
    state.counters["edges_per_tet"] = static_cast<double>(mesh.edge_count()) / tets;
  }
  state.SetItemsProcessed(created);
  state.counters["ns_per_tet_created"] = total_ns / static_cast<double>(created);
}

void register_all() {
  // Boxes of n^3 cubes refined 2 -> 3 levels: 48 n^3 tets after, i.e.
  // 1,296 / 10,368 / 105,456 / 384,000 / 1,053,696. A fixed depth keeps the
  // diamond mix identical, so only the size varies.
  constexpr std::array<int, 5> kCubes{3, 6, 13, 20, 28};
  constexpr int kDepth = 2;
  constexpr std::int64_t kTetBudget = 2'000'000;
  for (int n : kCubes) {
    const std::string size = "/cubes:" + std::to_string(n) + "^3/tets:" + std::to_string(uniform_tets(n, kDepth + 1));
    const auto iters = iterations_for(uniform_tets(n, kDepth + 1), kTetBudget, 3);
    benchmark::RegisterBenchmark(("SplitOneLevel_PerTetCreated" + size + "/depth:2to3").c_str(),
                                 [=](benchmark::State& s) { split_one_level(s, n, kDepth); })
        ->UseManualTime()
        ->Unit(benchmark::kMillisecond)
        ->Iterations(iters);
  }
  for (int n : kCubes) {
    const std::string size = "/cubes:" + std::to_string(n) + "^3/tets:" + std::to_string(uniform_tets(n, kDepth + 1));
    const auto iters = iterations_for(uniform_tets(n, kDepth + 1), kTetBudget, 3);
    benchmark::RegisterBenchmark(("MergeOneLevel_PerTetDestroyed" + size + "/depth:3to2").c_str(),
                                 [=](benchmark::State& s) { merge_one_level(s, n, kDepth); })
        ->UseManualTime()
        ->Unit(benchmark::kMillisecond)
        ->Iterations(iters);
  }
  // Same meshes (uniform depth 3); each op splits a random depth-6 diamond.
  constexpr int kExtra = 3;
  for (int n : kCubes) {
    const std::string size = "/cubes:" + std::to_string(n) + "^3/tets:" + std::to_string(uniform_tets(n, kDepth + 1));
    benchmark::RegisterBenchmark(("LocalSplitMerge_PerTetCreated" + size + "/diamond_depth:6").c_str(),
                                 [=](benchmark::State& s) { local_split_merge(s, n, kDepth + 1, kExtra); })
        ->UseManualTime()
        ->Unit(benchmark::kMicrosecond)
        ->Iterations(5000);
  }
  benchmark::RegisterBenchmark("UniformRefine32x32x32By3", [](benchmark::State& s) { uniform_32_by_3(s, false); })
      ->UseManualTime()
      ->Unit(benchmark::kMillisecond)
      ->Iterations(3);
  benchmark::RegisterBenchmark("UniformRefine32x32x32By3_Reserved",
                               [](benchmark::State& s) { uniform_32_by_3(s, true); })
      ->UseManualTime()
      ->Unit(benchmark::kMillisecond)
      ->Iterations(3);
}

}  // namespace

int main(int argc, char** argv) {
  register_all();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
