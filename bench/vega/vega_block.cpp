// VegaFEM's side of the block comparison (bench/vega/README.md). Our own
// driver, written against VegaFEM's public API; it is compiled only by
// bench/vega/compare.sh, outside the repository, against a VegaFEM checkout
// (no Vega code lives here).
//
// The case matches bench/scaling_bench.cc: a 3 m block of n^3 cubic cells
// ((n+1)^3 nodes), E 1e5 Pa, nu 0.3, density 1000, Rayleigh damping 2 * M,
// bottom face (z = 0) fixed, 20 kN along +x spread evenly over the top face's
// (n+1)^2 nodes, h = 1 ms. Vega: CubicMesh (trilinear hexes), consistent
// mass matrix (GenerateMassMatrix), CorotationalLinearFEM with warping
// (warp = 1, the only corotational mode Vega has for cubes), one thread, and
// Vega's PCG build of the sparse integrators (Jacobi-preconditioned CG, the
// tolerance and iteration cap hard-coded in Vega: 1e-6, 10000).
//
//   vega_block --n=12 --integrator=central|backward_euler [--steps=40] [--warmup=5]
//
// Prints one line:
//   vega n=12 integrator=central dofs=6591 free_dofs=6084 ms_per_step=...
//   build_s=... peak_mb=... top_dx=... steps_total=45
// build_s: mesh + CorotationalLinearFEM (per-element stiffness) + force model +
// mass matrix + integrator (system matrix, solver); ms_per_step: median of the
// measured steps; peak_mb: VmHWM of this process (one size and integrator per
// process); top_dx: mean x displacement of the top face's nodes (m) after
// warmup + steps steps.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "bench/figures.h"
#include "centralDifferencesSparse.h"
#include "corotationalLinearFEM.h"
#include "corotationalLinearFEMForceModel.h"
#include "cubicMesh.h"
#include "generateMassMatrix.h"
#include "implicitBackwardEulerSparse.h"
#include "sparseMatrix.h"

namespace {

using dynsolid::bench::PeakRssMb;

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

bool Flag(const char* arg, const char* name, std::string* value) {
  const size_t len = std::strlen(name);
  if (std::strncmp(arg, name, len) != 0 || arg[len] != '=') return false;
  *value = arg + len + 1;
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  int n = 8, steps = 40, warmup = 5;
  std::string integrator = "central";
  for (int a = 1; a < argc; ++a) {
    std::string v;
    if (Flag(argv[a], "--n", &v)) n = std::atoi(v.c_str());
    else if (Flag(argv[a], "--steps", &v)) steps = std::atoi(v.c_str());
    else if (Flag(argv[a], "--warmup", &v)) warmup = std::atoi(v.c_str());
    else if (Flag(argv[a], "--integrator", &v)) integrator = v;
    else {
      std::fprintf(stderr, "usage: %s --n=N --integrator=central|backward_euler "
                   "[--steps=40] [--warmup=5]\n", argv[0]);
      return 2;
    }
  }
  if (n < 1 || steps < 1 || warmup < 0 ||
      (integrator != "central" && integrator != "backward_euler")) {
    std::fprintf(stderr, "bad arguments\n");
    return 2;
  }

  const double size = 3.0, E = 1e5, nu = 0.3, density = 1000.0;
  const double h = 1e-3, damping_mass = 2.0, total_force = 2e4;
  const int m = n + 1;  // nodes per side
  const int num_vertices = m * m * m;
  const int r = 3 * num_vertices;
  auto node = [m](int i, int j, int k) { return i + m * (j + m * k); };

  const auto t_build = Clock::now();

  // Nodes on a regular grid over [0, 3]^3; z-major so the bottom face comes first.
  std::vector<double> vertices(3 * static_cast<size_t>(num_vertices));
  const double dx = size / n;
  for (int k = 0; k < m; ++k)
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) {
        const int v = node(i, j, k);
        vertices[3 * v + 0] = i * dx;
        vertices[3 * v + 1] = j * dx;
        vertices[3 * v + 2] = k * dx;
      }
  // Vega's cube corner order: (0,0,0) (1,0,0) (1,1,0) (0,1,0), then the same at z + 1.
  const int ci[8] = {0, 1, 1, 0, 0, 1, 1, 0};
  const int cj[8] = {0, 0, 1, 1, 0, 0, 1, 1};
  const int ck[8] = {0, 0, 0, 0, 1, 1, 1, 1};
  const int num_elements = n * n * n;
  std::vector<int> elements(8 * static_cast<size_t>(num_elements));
  for (int k = 0, e = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i, ++e)
        for (int c = 0; c < 8; ++c) elements[8 * e + c] = node(i + ci[c], j + cj[c], k + ck[c]);

  CubicMesh mesh(num_vertices, vertices.data(), num_elements, elements.data(), E, nu, density);
  CorotationalLinearFEM fem(&mesh);
  CorotationalLinearFEMForceModel force_model(&fem, /*warp=*/1);
  SparseMatrix* mass = nullptr;
  GenerateMassMatrix::computeMassMatrix(&mesh, &mass, /*inflate3Dim=*/true);

  // Bottom face: nodes 0 .. m^2 - 1, all three DOFs (sorted ascending, as Vega wants).
  std::vector<int> fixed;
  for (int v = 0; v < m * m; ++v)
    for (int d = 0; d < 3; ++d) fixed.push_back(3 * v + d);

  IntegratorBaseSparse* stepper = nullptr;
  if (integrator == "central") {
    // Damping is mass-proportional only, so the system matrix M + h/2 C never
    // changes: tangentialDampingMode 0 (no per-step stiffness/damping update),
    // the fastest setting Vega offers for this case.
    stepper = new CentralDifferencesSparse(r, h, mass, &force_model, (int)fixed.size(),
                                           fixed.data(), damping_mass, 0.0,
                                           /*tangentialDampingMode=*/0, /*numSolverThreads=*/0);
  } else {
    // One Newton iteration per step (Vega's default maxIterations = 1).
    stepper = new ImplicitBackwardEulerSparse(r, h, mass, &force_model, (int)fixed.size(),
                                              fixed.data(), damping_mass, 0.0,
                                              /*maxIterations=*/1, /*epsilon=*/1e-6,
                                              /*numSolverThreads=*/0);
  }
  std::vector<double> f(r, 0.0);
  const double share = total_force / (m * m);
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < m; ++i) f[3 * node(i, j, n) + 0] = share;
  stepper->SetExternalForces(f.data());
  const double build_s = MsSince(t_build) / 1000.0;

  std::vector<double> step_ms;
  for (int s = 0; s < warmup + steps; ++s) {
    const auto t = Clock::now();
    if (stepper->DoTimestep() != 0) {
      std::printf("vega n=%d integrator=%s failed_at_step=%d\n", n, integrator.c_str(), s);
      return 1;
    }
    if (s >= warmup) step_ms.push_back(MsSince(t));
  }
  std::sort(step_ms.begin(), step_ms.end());
  const double median = step_ms[step_ms.size() / 2];

  const double* q = stepper->Getq();
  double top_dx = 0;
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < m; ++i) top_dx += q[3 * node(i, j, n) + 0];
  top_dx /= m * m;

  std::printf("vega n=%d integrator=%s dofs=%d free_dofs=%d ms_per_step=%.3f build_s=%.3f "
              "peak_mb=%.1f top_dx=%.6e steps_total=%d\n",
              n, integrator.c_str(), r, r - (int)fixed.size(), median, build_s, PeakRssMb(),
              top_dx, warmup + steps);
  delete stepper;
  delete mass;
  return 0;
}
