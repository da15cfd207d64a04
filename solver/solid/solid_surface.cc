// The solid's boundary surface: its triangles, their rows of the node
// matrix, positions, bounds and the per-vertex fields clients colour it by.
#include <algorithm>
#include <vector>

#include "solver/mesh/boundary.h"
#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"

namespace dynsolid::solid {

void Solid::BuildSurface() {
  Impl& im = *impl_;
  const mesh::CellComplex& fine = d_.fine();
  const mesh::BoundarySurface b = mesh::ExtractBoundary(fine);
  surface_ = Surface();
  surface_.nodes = b.mesh_vertex;
  for (int32_t f = 0; f < b.faces.rows(); ++f) {
    const std::span<const int32_t> loop = b.faces.row(f);
    const int32_t cell = fine.face_cells(b.mesh_face[f])[0];
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int32_t v : loop) centroid += im.rest_nodes.row(surface_.nodes[v]).transpose();
    centroid /= static_cast<double>(loop.size());
    auto emit = [&](int32_t a, int32_t b1, int32_t c, int32_t e) {
      surface_.quads.push_back({a, b1, c, e});
      im.quad_cell.push_back(cell);
      im.quad_centroid.push_back(centroid);
    };
    const int n = static_cast<int>(loop.size());
    if (n == 4) {
      emit(loop[0], loop[1], loop[2], loop[3]);
    } else {
      // A fan of quads (and a last triangle as a degenerate quad) from loop[0].
      for (int k = 1; k + 1 < n; k += 2) {
        emit(loop[0], loop[k], loop[k + 1], k + 2 < n ? loop[k + 2] : loop[k + 1]);
      }
    }
  }
  // The surface rows of A, for positions and pressure forces.
  std::vector<Eigen::Triplet<double, int32_t>> t;
  for (size_t i = 0; i < surface_.nodes.size(); ++i) {
    for (SparseMatrix::InnerIterator it(d_.node_matrix, surface_.nodes[i]); it; ++it) {
      t.emplace_back(static_cast<int32_t>(i), static_cast<int32_t>(it.col()), it.value());
    }
  }
  im.surface_rows.resize(static_cast<Eigen::Index>(surface_.nodes.size()), d_.node_matrix.cols());
  im.surface_rows.setFromTriplets(t.begin(), t.end());
  im.surface_rows.makeCompressed();
  im.surface_rest = im.surface_rows * im.rest_control;
}


// ---- Boundary surface.

Points Solid::SurfacePositions() const { return impl_->surface_rows * p_; }

Solid::Bounds Solid::SurfaceBounds() const {
  const Points x = SurfacePositions();
  Bounds b;
  if (x.rows() == 0) return b;
  b.min = x.colwise().minCoeff().transpose();
  b.max = x.colwise().maxCoeff().transpose();
  return b;
}

Solid::SurfaceFields Solid::ComputeSurfaceFields() const {
  const Impl& im = *impl_;
  const Points x = SurfacePositions();
  const int64_t nv = x.rows();
  SurfaceFields out;
  out.displacement.resize(nv);
  for (int64_t i = 0; i < nv; ++i) {
    out.displacement[i] = static_cast<float>((x.row(i) - im.surface_rest.row(i)).norm());
  }
  // Strain: the largest |l / l0 - 1| over the edges and diagonals at a vertex.
  std::vector<double> strain(nv, 0.0);
  auto stretch = [&](int32_t a, int32_t b) {
    const double l0 = (im.surface_rest.row(a) - im.surface_rest.row(b)).norm();
    if (a == b || l0 <= 0) return;
    const double e = std::abs((x.row(a) - x.row(b)).norm() / l0 - 1.0);
    strain[a] = std::max(strain[a], e);
    strain[b] = std::max(strain[b], e);
  };
  for (const auto& q : surface_.quads) {
    for (int k = 0; k < 4; ++k) stretch(q[k], q[(k + 1) % 4]);
    stretch(q[0], q[2]);
    stretch(q[1], q[3]);
  }
  out.strain.assign(strain.begin(), strain.end());
  // Stiffness and mass: mean Young's modulus and density of the boundary
  // cells' elements' quadrature points, then the mean over the cells of the
  // quads around each vertex.
  const int32_t ncells = d_.fine().num_cells();
  std::vector<double> cell_young(ncells, 0.0), cell_density(ncells, 0.0);
  std::vector<int32_t> cell_count(ncells, 0);
  std::vector<uint8_t> boundary_cell(ncells, 0);
  for (int32_t c : im.quad_cell) boundary_cell[c] = 1;
  for (const models::ElementBlock& block : im.layout->blocks) {
    for (int32_t e = 0; e < block.size(); ++e) {
      const int32_t c = block.cell[e];
      if (!boundary_cell[c]) continue;
      for (const models::MaterialPoint& m :
           im.layout->materials[block.groups[block.group[e]].material]) {
        cell_young[c] += m.young;
        cell_density[c] += m.density;
        ++cell_count[c];
      }
    }
  }
  std::vector<double> vyoung(nv, 0.0), vdensity(nv, 0.0);
  std::vector<int32_t> vcount(nv, 0);
  for (size_t q = 0; q < surface_.quads.size(); ++q) {
    const int32_t c = im.quad_cell[q];
    if (cell_count[c] == 0) continue;
    const double young = cell_young[c] / cell_count[c];
    const double density = cell_density[c] / cell_count[c];
    const auto& v = surface_.quads[q];
    for (int k = 0; k < 4; ++k) {
      if (k == 3 && v[3] == v[2]) continue;  // degenerate quad: a triangle
      vyoung[v[k]] += young;
      vdensity[v[k]] += density;
      ++vcount[v[k]];
    }
  }
  out.stiffness.resize(nv);
  out.mass.resize(nv);
  for (int64_t i = 0; i < nv; ++i) {
    out.stiffness[i] = vcount[i] > 0 ? static_cast<float>(vyoung[i] / vcount[i]) : 0.0f;
    out.mass[i] = vcount[i] > 0 ? static_cast<float>(vdensity[i] / vcount[i]) : 0.0f;
  }
  return out;
}

}  // namespace dynsolid::solid
