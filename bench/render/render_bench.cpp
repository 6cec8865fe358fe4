// render_bench: time per frame of `tissue render` (OSMesa, llvmpipe), issue 5.
//
//   build/dev/bench/render_bench [--benchmark_filter=...]
//
// Surfaces are real Kuhn-mesh surfaces (a flat box, one corner refined, so
// several levels show) of about 1k, 10k and 100k triangles, drawn at
// 800 x 600 with the level palette and with the strain ramp. Each iteration
// is one complete frame: upload, draw, read-back, legend, and either a new
// OpenGL context (render_frame: one picture) or a kept one (Renderer: a
// frame sequence). BM_PngWrite adds the PNG encoding of one frame.
// STACK.md quotes 35-50 ms for 100k triangles at 800 x 600 on this machine.
#include <benchmark/benchmark.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <string>

#include "mesh/kuhn_mesh.hpp"
#include "mesh/refine_ops.hpp"
#include "mesh/surface.hpp"
#include "render/png_writer.hpp"
#include "render/render.hpp"

namespace {

using tissue::x3d::SurfaceFrame;

// A box of n x n x 2 cubes of 1 cm: about 4 n^2 surface triangles at level
// 0, more around the refined corner.
SurfaceFrame surface_of_about(int triangles_wanted) {
  const int n = std::max(2, static_cast<int>(std::lround(std::sqrt(triangles_wanted / 4.4))));
  tissue::mesh::KuhnMesh m(tissue::mesh::BoxSpec{n, n, 2, 0.01, 4});
  tissue::mesh::refine_sphere(m, {{0.0, 0.0, 0.02}, 0.01 * n / 6.0}, 3, nullptr);
  tissue::mesh::SurfaceMesh s;
  tissue::mesh::extract_surface(m, &s);
  SurfaceFrame f;
  for (const tissue::mesh::NodeId node : s.vertex_nodes) {
    const auto x = m.node_position_m(node);
    f.vertices_m.push_back(x);
    f.vertex_level.push_back(m.node(node).depth);
    f.vertex_strain_energy_Pa.push_back(static_cast<float>(100.0 * (x[0] + x[1])));
  }
  f.triangles = s.triangles;
  return f;
}

const SurfaceFrame& cached_surface(int triangles_wanted) {
  static std::map<int, SurfaceFrame> cache;
  auto it = cache.find(triangles_wanted);
  if (it == cache.end()) it = cache.emplace(triangles_wanted, surface_of_about(triangles_wanted)).first;
  return it->second;
}

void BM_RenderFrame(benchmark::State& state) {
  const SurfaceFrame& f = cached_surface(static_cast<int>(state.range(0)));
  tissue::render::RenderOptions o;  // 800 x 600, legend on
  o.colour = state.range(1) ? tissue::x3d::ColourMode::kStrain : tissue::x3d::ColourMode::kLevel;
  // range(2): 1 = a Renderer kept across frames (a `tissue render` sequence),
  // 0 = render_frame, which sets up a context per frame (a single picture).
  tissue::render::Renderer renderer;
  if (state.range(2))
    for (auto _ : state) benchmark::DoNotOptimize(renderer.render(f, o));
  else
    for (auto _ : state) benchmark::DoNotOptimize(tissue::render::render_frame(f, o));
  state.counters["triangles"] = static_cast<double>(f.triangles.size());
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.SetLabel(std::string(state.range(1) ? "strain" : "level") +
                 (state.range(2) ? ", kept context" : ", new context"));
}
BENCHMARK(BM_RenderFrame)
    ->ArgsProduct({{1'000, 10'000, 100'000}, {0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(1.0);

void BM_PngWrite(benchmark::State& state) {
  const tissue::render::Image img = tissue::render::render_frame(cached_surface(100'000), {});
  const std::string path = (std::filesystem::temp_directory_path() / "render_bench.png").string();
  for (auto _ : state) tissue::render::write_png(img, path);
  std::filesystem::remove(path);
}
BENCHMARK(BM_PngWrite)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
