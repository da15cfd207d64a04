// Subdivision benchmark: a 20 x 20 x 20 control block subdivided
// to level 2 (512,000 cells) and its elements classified. Prints the time of
// each phase and the process's peak resident memory. Target on the 2-core
// reference machine: under 3 s and under 2 GB.
//
//   subdivide_bench [n=20] [levels=2] [repeats=3]
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <vector>

#include "solver/fem/element_set.h"
#include "solver/mesh/cell_complex.h"
#include "solver/scene/generators.h"
#include "solver/subdivision/mcj.h"

namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

double PeakRssMiB() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

}  // namespace

int main(int argc, char** argv) {
  const int n = argc > 1 ? std::atoi(argv[1]) : 20;
  const int levels = argc > 2 ? std::atoi(argv[2]) : 2;
  const int repeats = argc > 3 ? std::atoi(argv[3]) : 3;
  dynsolid::BlockGenerator block;
  block.set_nx(n);
  block.set_ny(n);
  block.set_nz(n);
  auto input = dynsolid::scene::GenerateBlock(block);
  if (!input.ok()) {
    std::fprintf(stderr, "%s\n", std::string(input.status().message()).c_str());
    return 2;
  }
  std::printf("subdivide_bench: %dx%dx%d control block, %d levels, best of %d\n", n, n, n,
              levels, repeats);
  std::vector<double> build, subdiv, classify, total;
  int64_t cells = 0, nodes = 0, nnz = 0, cubic = 0, linear = 0;
  for (int r = 0; r < repeats; ++r) {
    const double t0 = Now();
    auto control = dynsolid::mesh::CellComplex::FromInput(*input);
    if (!control.ok()) return 2;
    const double t1 = Now();
    auto h = dynsolid::subdivision::Subdivide(
        std::make_shared<const dynsolid::mesh::CellComplex>(*std::move(control)), levels, {});
    if (!h.ok()) return 2;
    const double t2 = Now();
    const dynsolid::fem::ElementSet e = dynsolid::fem::ClassifyElements(*h->fine);
    const double t3 = Now();
    build.push_back(t1 - t0);
    subdiv.push_back(t2 - t1);
    classify.push_back(t3 - t2);
    total.push_back(t3 - t0);
    cells = h->fine->num_cells();
    nodes = e.num_nodes();
    nnz = h->a.nonZeros();
    cubic = e.num_cubic();
    linear = e.num_linear();
  }
  auto best = [](const std::vector<double>& v) { return *std::min_element(v.begin(), v.end()); };
  std::printf("  fine cells          %lld\n", static_cast<long long>(cells));
  std::printf("  FEM nodes           %lld\n", static_cast<long long>(nodes));
  std::printf("  elements            %lld cubic, %lld linear\n", static_cast<long long>(cubic),
              static_cast<long long>(linear));
  std::printf("  nonzeros of A       %lld (%.1f per row)\n", static_cast<long long>(nnz),
              static_cast<double>(nnz) / static_cast<double>(nodes));
  std::printf("  control validation  %8.3f s\n", best(build));
  std::printf("  subdivision         %8.3f s\n", best(subdiv));
  std::printf("  classification      %8.3f s\n", best(classify));
  std::printf("  total               %8.3f s   (target < 3 s)\n", best(total));
  std::printf("  peak memory         %8.1f MiB (target < 2048 MiB)\n", PeakRssMiB());
  return 0;
}
