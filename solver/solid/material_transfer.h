// A painted solid's material carried over a topology edit (Solid::Remeshed)
// onto the new mesh's elements: an element whose rest nodes are, bit for
// bit, those of an old element in its source cell keeps that element's
// samples (the edit left it alone); any other sample takes the material of
// the nearest old sample in its source cell. A source cell of one material
// throughout gives every element of its new cells that material at every
// point; a new cell (no source) takes the scene's base material.
//
// The element layout asks from its pool threads (Sample, Whole): what they
// read is made by the constructor, for the source cells the new cells name
// (a cell of one material needs no keys nor bins), but for a cell's sample
// bins, made once when first needed (std::call_once: most cells never need
// them). Reads only plain data of the old solid.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Dense>

#include "solver/common/hash128.h"
#include "solver/fem/element_set.h"
#include "solver/mesh/points.h"
#include "solver/models/element_blocks.h"

namespace dynsolid::solid {

class CellSamples;  // material_transfer.cc

class MaterialTransfer {
 public:
  // The old solid's layout, its elements' rest nodes as the edit keeps
  // them (`old_nodes`: A P of a bake, else its rest nodes) and as they were
  // (`rest_nodes`), the control cell of each of its level-L cells
  // (`control_cell`, over `old_cells` control cells); the new cells'
  // sources (`cell_source`, -1: new) and the scene's base material.
  MaterialTransfer(const models::ElementLayout& layout, const Points& old_nodes,
                   const Points& rest_nodes, const std::vector<int32_t>& control_cell,
                   int32_t old_cells, const std::vector<int32_t>& cell_source,
                   models::MaterialPoint base);
  ~MaterialTransfer();

  // The material at rest position x of new control cell `cell`
  // (models::MaterialSampler).
  models::MaterialPoint Sample(const Eigen::Vector3d& x, int32_t cell);
  // The whole array of an element of `kind` with rest nodes x in new cell
  // `cell`, when it has one (models::ElementMaterials); else null.
  const std::vector<models::MaterialPoint>* Whole(int kind, const fem::NodeMatrixX3& x,
                                                  int32_t cell) const;

 private:
  const models::ElementLayout& layout_;
  const Points& old_nodes_;
  const Points& rest_nodes_;
  const std::vector<int32_t>& control_cell_;
  const std::vector<int32_t>& cell_source_;
  const models::MaterialPoint base_;
  // Per old cell: its elements (kind, index).
  std::vector<std::vector<std::pair<int, int32_t>>> old_elements_;
  // Old elements of the named cells not of one material, by their rest
  // nodes' key.
  std::unordered_map<Key128, std::pair<int, int32_t>, Key128Hash> by_nodes_;
  std::vector<CellSamples> by_cell_;
  std::unique_ptr<std::once_flag[]> binned_;
  // Per old cell: its arrays of one material (by kind), when it is of one
  // (else empty).
  std::vector<std::array<std::vector<models::MaterialPoint>, fem::kElementKinds>> uniform_arrays_;
};

}  // namespace dynsolid::solid
