// tissued — the daemon's entry point. Until the simulation and service land
// (issues 3 and 4) its only face is a mesh demonstration that prints figures.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <exception>

#include "mesh/kuhn_mesh.hpp"
#include "mesh/refine_ops.hpp"
#include "mesh/surface.hpp"

namespace {

void print_counts(const char* label, const tissue::mesh::KuhnMesh& mesh, double ms) {
  tissue::mesh::SurfaceMesh surface;
  tissue::mesh::extract_surface(mesh, &surface);
  std::printf("%-34s nodes %7zu  edges %8zu  tets %8zu  surface tris %7zu  %8.3f ms\n", label, mesh.node_count(),
              mesh.edge_count(), mesh.tet_count(), surface.triangles.size(), ms);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"tissued: real-time haptic server for adaptive soft-tissue simulation (mesh demo)"};
  int cubes_x = 4, cubes_y = 4, cubes_z = 4, depth = 6;
  double cube_size_m = 0.025;
  app.add_option("--cubes-x", cubes_x, "cubes along x")->capture_default_str();
  app.add_option("--cubes-y", cubes_y, "cubes along y")->capture_default_str();
  app.add_option("--cubes-z", cubes_z, "cubes along z")->capture_default_str();
  app.add_option("--cube-size", cube_size_m, "coarse cube edge [m]")->capture_default_str();
  app.add_option("--depth", depth, "refinement depth near the free end (3 = one cube halving)")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  try {
    using Clock = std::chrono::steady_clock;
    auto ms_since = [](Clock::time_point t0) {
      return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    };
    tissue::mesh::BoxSpec spec{cubes_x, cubes_y, cubes_z, cube_size_m, std::max(depth, 9)};
    auto t0 = Clock::now();
    tissue::mesh::KuhnMesh mesh(spec);
    print_counts("coarse (paper's low resolution)", mesh, ms_since(t0));

    // Refine around the free end's bottom edge, where a cantilever bends most.
    const double lx = cubes_x * cube_size_m, ly = cubes_y * cube_size_m, lz = cubes_z * cube_size_m;
    t0 = Clock::now();
    tissue::mesh::MeshChangeLog log;
    const int splits = tissue::mesh::refine_sphere(mesh, {{lx, ly / 2, lz / 2}, 0.3 * lx}, depth, &log);
    print_counts("refined near the free end", mesh, ms_since(t0));
    std::printf("  %d diamond splits, %zu change events, mesh memory %.1f bytes/tet\n", splits, log.events.size(),
                static_cast<double>(mesh.memory_bytes()) / static_cast<double>(mesh.tet_count()));

    t0 = Clock::now();
    const int merges = tissue::mesh::merge_all(mesh);
    print_counts("simplified back", mesh, ms_since(t0));
    std::printf("  %d diamond merges\n", merges);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tissued: %s\n", e.what());
    return 1;
  }
}
