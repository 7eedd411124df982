#include "fusion/input_checks.h"

#include <Eigen/Dense>
#include <cmath>
#include <stdexcept>

namespace dispmvs::fusion::internal {

void CheckIntrinsics(const Eigen::Matrix3d& K, const std::string& what) {
  if (!K.allFinite()) throw std::invalid_argument(what + ": intrinsics K are not finite");
  if (K(2, 0) != 0.0 || K(2, 1) != 0.0 || K(2, 2) != 1.0) {
    throw std::invalid_argument(what + ": intrinsics K must have last row (0, 0, 1)");
  }
  const double det = K.determinant();
  if (!std::isfinite(det) || std::abs(det) < 1e-12) {
    throw std::invalid_argument(what + ": intrinsics K are not invertible");
  }
}

void CheckRotation(const Eigen::Matrix3d& R, const std::string& what) {
  if (!R.allFinite()) throw std::invalid_argument(what + ": rotation R is not finite");
  const double orthogonality_error = (R * R.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (orthogonality_error > 1e-6 || R.determinant() < 0.0) {
    throw std::invalid_argument(what + ": R is not a rotation matrix (orthonormal, det +1)");
  }
}

void CheckFinite(const Eigen::Vector3d& v, const std::string& what) {
  if (!v.allFinite()) throw std::invalid_argument(what + ": is not finite");
}

void CheckMap(const colmap_io::DenseArray& map, int channels, const std::string& what) {
  if (map.empty()) throw std::invalid_argument(what + ": map is empty");
  if (map.channels() != channels) {
    throw std::invalid_argument(what + ": map has " + std::to_string(map.channels()) +
                                " channels, expected " + std::to_string(channels));
  }
}

void CheckSameSize(const colmap_io::DenseArray& map, const colmap_io::DenseArray& like,
                   const std::string& what) {
  if (map.width() != like.width() || map.height() != like.height()) {
    throw std::invalid_argument(what + ": map is " + std::to_string(map.width()) + "x" +
                                std::to_string(map.height()) + ", expected " +
                                std::to_string(like.width()) + "x" + std::to_string(like.height()));
  }
}

}  // namespace dispmvs::fusion::internal
