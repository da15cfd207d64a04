// The cell partials' Gram product G = W^T W (models/gram.h) on every path
// this CPU runs, beside Eigen's symmetric rank update (what the partials
// used before), at the sizes of the chair's cells: a couple of thousand
// quadrature rows by 3 S columns. One thread; figures printed, never
// asserted.
#include <cstdio>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "bench/best_ms.h"
#include "bench/cpu_name.h"
#include "solver/models/gram.h"

int main() {
  using dynsolid::models::GramPath;
  std::printf("gram_bench: G = W^T W, one thread, %s; best of 20 runs\n",
              dynsolid::bench::CpuName().c_str());
  std::printf("| rows x n | Eigen rank update ms | path | ms | Eigen / path | GFLOP/s |\n");
  std::printf("| --- | ---: | --- | ---: | ---: | ---: |\n");
  const std::pair<int, int> sizes[] = {{1408, 78}, {1856, 99}, {2304, 111}, {2304, 135}, {1632, 168}};
  for (const auto& [rows, n] : sizes) {
    std::mt19937 rng(rows + n);
    std::uniform_real_distribution<double> u(-1, 1);
    // W 64-byte aligned, as the cell partials keep it.
    std::vector<double, dynsolid::models::GramAllocator> storage(static_cast<size_t>(rows) * n);
    Eigen::Map<Eigen::MatrixXd> w(storage.data(), rows, n);
    for (int64_t i = 0; i < w.size(); ++i) w.data()[i] = u(rng);
    Eigen::MatrixXd g(n, n);
    const double eigen = dynsolid::bench::BestMs(20, 1, [&] {
      g.setZero();
      g.selfadjointView<Eigen::Lower>().rankUpdate(w.transpose());
    });
    // Flops of the lower triangle: rows n (n + 1) / 2 multiply-adds.
    const double flops = 2.0 * rows * n * (n + 1) / 2.0;
    for (GramPath path : {GramPath::kPortable, GramPath::kAvx2, GramPath::kAvx512}) {
      if (!dynsolid::models::Gram(path, w.data(), rows, n, rows, g.data(), n)) continue;
      const double ms = dynsolid::bench::BestMs(
          20, 1, [&] { dynsolid::models::Gram(path, w.data(), rows, n, rows, g.data(), n); });
      std::printf("| %d x %d | %.3f | %s | %.3f | %.2f | %.1f |\n", rows, n, eigen,
                  dynsolid::models::GramPathName(path), ms, eigen / ms, flops / ms / 1e6);
    }
  }
  return 0;
}
