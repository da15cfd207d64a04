// Point arrays shared by every solver module: #N by 3, row-major, metres.
#pragma once

#include <Eigen/Core>

namespace dynsolid {

using Points = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

}  // namespace dynsolid

namespace dynsolid::mesh {
using ::dynsolid::Points;
}  // namespace dynsolid::mesh
