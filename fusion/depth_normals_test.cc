#include "fusion/depth_normals.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

namespace dispmvs::fusion {
namespace {

constexpr int kWidth = 40;
constexpr int kHeight = 30;

// Non-square pixels and an off-centre principal point, so that a wrong pixel
// convention (e.g. +0.5) or a swapped axis bends the back-projected plane.
Eigen::Matrix3d TestK() {
  Eigen::Matrix3d K;
  K << 42.0, 0, 21.3, 0, 38.0, 13.6, 0, 0, 1;
  return K;
}

Eigen::Vector3d NormalAt(const colmap_io::DenseArray& normals, int row, int col) {
  return Eigen::Vector3d(normals.at(row, col, 0), normals.at(row, col, 1), normals.at(row, col, 2));
}

// The depth map of the plane {X : n . X = n . p} in the camera frame, with
// COLMAP's convention: X = depth * K^-1 (col, row, 1).
colmap_io::DenseArray PlaneDepth(const Eigen::Vector3d& n, const Eigen::Vector3d& p) {
  const Eigen::Matrix3d K_inv = TestK().inverse();
  colmap_io::DenseArray depth(kWidth, kHeight, 1);
  for (int row = 0; row < kHeight; ++row) {
    for (int col = 0; col < kWidth; ++col) {
      const Eigen::Vector3d ray = K_inv * Eigen::Vector3d(col, row, 1.0);
      depth.at(row, col) = static_cast<float>(n.dot(p) / n.dot(ray));
    }
  }
  return depth;
}

// The plane normal oriented towards the camera at the origin.
Eigen::Vector3d TowardsCamera(const Eigen::Vector3d& n, const Eigen::Vector3d& p) {
  return n.dot(p) > 0 ? Eigen::Vector3d(-n) : n;
}

TEST(DepthNormalsTest, PlanesGiveTheExactNormalTowardsTheCamera) {
  const Eigen::Vector3d p(0.2, -0.1, 4.0);
  // Tilted left, right, up, down, steep, fronto-parallel; each given once with
  // the normal facing the camera and once facing away (same plane).
  const std::vector<Eigen::Vector3d> normals = {
      Eigen::Vector3d(0.3, -0.2, -1), Eigen::Vector3d(-0.4, 0.1, -1),
      Eigen::Vector3d(0.05, 0.5, -1), Eigen::Vector3d(0.1, -0.45, -1),
      Eigen::Vector3d(0.5, 0.3, -0.8), Eigen::Vector3d(0, 0, -1)};
  for (const Eigen::Vector3d& raw : normals) {
    for (double sign : {1.0, -1.0}) {
      const Eigen::Vector3d n = sign * raw.normalized();
      const colmap_io::DenseArray result = NormalMapFromDepth(PlaneDepth(n, p), TestK());
      ASSERT_EQ(result.width(), kWidth);
      ASSERT_EQ(result.height(), kHeight);
      ASSERT_EQ(result.channels(), 3);
      const Eigen::Vector3d expected = TowardsCamera(n, p);
      double max_error = 0;
      for (int row = 0; row < kHeight; ++row) {
        for (int col = 0; col < kWidth; ++col) {
          max_error = std::max(max_error, (NormalAt(result, row, col) - expected).norm());
        }
      }
      EXPECT_LT(max_error, 1e-5) << "plane normal " << n.transpose();
    }
  }
}

TEST(DepthNormalsTest, DepthJumpLeavesZerosOnBothSides) {
  colmap_io::DenseArray depth(kWidth, kHeight, 1, 4.0f);
  for (int row = 0; row < kHeight; ++row) {
    for (int col = kWidth / 2; col < kWidth; ++col) depth.at(row, col) = 6.0f;
  }
  const colmap_io::DenseArray result = NormalMapFromDepth(depth, TestK());
  for (int row = 0; row < kHeight; ++row) {
    for (int col = 0; col < kWidth; ++col) {
      const Eigen::Vector3d n = NormalAt(result, row, col);
      if (col == kWidth / 2 - 1 || col == kWidth / 2) {
        EXPECT_EQ(n, Eigen::Vector3d::Zero()) << row << "," << col;
      } else {
        EXPECT_LT((n - Eigen::Vector3d(0, 0, -1)).norm(), 1e-5) << row << "," << col;
      }
    }
  }
}

TEST(DepthNormalsTest, JumpThresholdIsRelativeAndConfigurable) {
  colmap_io::DenseArray depth(kWidth, kHeight, 1, 4.0f);
  for (int row = 0; row < kHeight; ++row) {
    for (int col = kWidth / 2; col < kWidth; ++col) depth.at(row, col) = 4.16f;  // +4 %
  }
  const int edge = kWidth / 2;
  // Below the default 5 %: the edge pixels get a (tilted) normal.
  const colmap_io::DenseArray loose = NormalMapFromDepth(depth, TestK());
  EXPECT_NEAR(NormalAt(loose, 5, edge).norm(), 1.0, 1e-5);
  EXPECT_LT(NormalAt(loose, 5, edge).z(), 0.0);
  // Above a 3 % threshold: zeros.
  const colmap_io::DenseArray strict = NormalMapFromDepth(depth, TestK(), 0.03);
  EXPECT_EQ(NormalAt(strict, 5, edge), Eigen::Vector3d::Zero());
  EXPECT_EQ(NormalAt(strict, 5, edge - 1), Eigen::Vector3d::Zero());
}

TEST(DepthNormalsTest, InvalidPixelsGetZerosAndNeighboursStayExact) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.3, -0.2, -1).normalized();
  const Eigen::Vector3d p(0.2, -0.1, 4.0);
  colmap_io::DenseArray depth = PlaneDepth(n, p);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  depth.at(5, 5) = 0.0f;
  depth.at(10, 12) = nan;
  depth.at(15, 20) = -3.0f;
  depth.at(20, 30) = inf;
  // A whole column missing: the pixels beside it use one-sided differences.
  for (int row = 0; row < kHeight; ++row) depth.at(row, 35) = 0.0f;
  // An isolated pixel (all 4 neighbours missing) has no normal.
  depth.at(24, 7) = 4.0f;
  depth.at(23, 7) = depth.at(25, 7) = depth.at(24, 6) = depth.at(24, 8) = 0.0f;

  const colmap_io::DenseArray result = NormalMapFromDepth(depth, TestK());
  for (const auto& [row, col] : std::vector<std::pair<int, int>>{
           {5, 5}, {10, 12}, {15, 20}, {20, 30}, {0, 35}, {17, 35}, {24, 7}}) {
    EXPECT_EQ(NormalAt(result, row, col), Eigen::Vector3d::Zero()) << row << "," << col;
  }
  const Eigen::Vector3d expected = TowardsCamera(n, p);
  for (const auto& [row, col] : std::vector<std::pair<int, int>>{
           {5, 4}, {5, 6}, {4, 5}, {6, 5}, {10, 11}, {9, 12}, {3, 34}, {3, 36}, {29, 39}, {0, 0}}) {
    EXPECT_LT((NormalAt(result, row, col) - expected).norm(), 1e-5) << row << "," << col;
  }
  for (float v : result.values()) EXPECT_TRUE(std::isfinite(v));
}

TEST(DepthNormalsTest, SingleRowHasNoVerticalNeighbourAndNoNormal) {
  const colmap_io::DenseArray depth(10, 1, 1, 3.0f);
  const colmap_io::DenseArray result = NormalMapFromDepth(depth, TestK());
  for (float v : result.values()) EXPECT_EQ(v, 0.0f);
}

TEST(DepthNormalsTest, RejectsBadArguments) {
  EXPECT_THROW(NormalMapFromDepth(colmap_io::DenseArray(), TestK()), std::invalid_argument);
  EXPECT_THROW(NormalMapFromDepth(colmap_io::DenseArray(4, 4, 3, 1.0f), TestK()),
               std::invalid_argument);
  Eigen::Matrix3d bad_K = TestK();
  bad_K(2, 2) = 2.0;
  EXPECT_THROW(NormalMapFromDepth(colmap_io::DenseArray(4, 4, 1, 1.0f), bad_K),
               std::invalid_argument);
  EXPECT_THROW(NormalMapFromDepth(colmap_io::DenseArray(4, 4, 1, 1.0f), Eigen::Matrix3d::Zero()),
               std::invalid_argument);
  EXPECT_THROW(NormalMapFromDepth(colmap_io::DenseArray(4, 4, 1, 1.0f), TestK(), 0.0),
               std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::fusion
