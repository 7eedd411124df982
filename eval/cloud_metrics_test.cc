#include "eval/cloud_metrics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include <Eigen/Geometry>

namespace dispmvs::eval {
namespace {

CloudMetricOptions Options(double tau, double cutoff) {
  CloudMetricOptions options;
  options.tau = tau;
  options.cutoff = cutoff;
  return options;
}

TEST(EvalCloudMetricsTest, HandComputedDistances) {
  const PointCloud gt = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {10, 10, 10}};
  const PointCloud recon = {{0, 0, 0.1f}, {1, 0, 0.3f}, {5, 5, 5}};
  // recon -> GT: 0.1, 0.3, sqrt(66) = 8.12 (to (1,0,0) and (0,1,0)): cut.
  // GT -> recon: 0.1, 0.3, sqrt(1.01) = 1.005 (cut at 1), sqrt(75) (cut).
  const NearestNeighbourIndex gt_index(gt);
  const NearestNeighbourIndex recon_index(recon);
  EXPECT_NEAR(gt_index.NearestDistance({5, 5, 5}), std::sqrt(66.0), 1e-12);
  EXPECT_NEAR(recon_index.NearestDistance({0, 1, 0}), std::sqrt(1.0 + 0.1f * 0.1f), 1e-7);

  const CloudMetrics m = EvaluateCloud(recon_index, gt_index, Options(0.2, 1.0));
  EXPECT_EQ(m.num_points, 3);
  EXPECT_EQ(m.num_gt_points, 4);
  EXPECT_NEAR(m.accuracy, (0.1 + 0.3) / 2, 1e-7);
  EXPECT_EQ(m.accuracy_cut, 1);
  EXPECT_NEAR(m.completeness, (0.1 + 0.3) / 2, 1e-7);
  EXPECT_EQ(m.completeness_cut, 2);
  EXPECT_NEAR(m.overall, 0.2, 1e-7);
  EXPECT_DOUBLE_EQ(m.precision, 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(m.recall, 0.25);
  EXPECT_NEAR(m.fscore, 2.0 / 7.0, 1e-12);  // 2 (1/3)(1/4) / (1/3 + 1/4)
  EXPECT_EQ(m.tau, 0.2);
  EXPECT_EQ(m.cutoff, 1.0);

  // A larger cut-off keeps everything; distances equal to tau do not count.
  const CloudMetrics wide = EvaluateCloud(recon_index, gt_index, Options(0.3f, 100));
  EXPECT_EQ(wide.accuracy_cut, 0);
  EXPECT_NEAR(wide.accuracy, (0.1 + 0.3 + std::sqrt(66.0)) / 3, 1e-6);
  EXPECT_NEAR(wide.completeness, (0.1 + 0.3 + std::sqrt(1.01) + std::sqrt(75.0)) / 4, 1e-6);
  EXPECT_DOUBLE_EQ(wide.precision, 1.0 / 3.0);  // 0.3f is not < 0.3f
}

TEST(EvalCloudMetricsTest, IdenticalCloudsArePerfect) {
  const PointCloud cloud = {{0, 0, 0}, {1, 2, 3}, {-1, 0.5f, 2}};
  const NearestNeighbourIndex a(cloud), b(cloud);
  const CloudMetrics m = EvaluateCloud(a, b, Options(1e-3, 1e-2));
  EXPECT_EQ(m.accuracy, 0.0);
  EXPECT_EQ(m.completeness, 0.0);
  EXPECT_EQ(m.precision, 1.0);
  EXPECT_EQ(m.recall, 1.0);
  EXPECT_EQ(m.fscore, 1.0);
}

TEST(EvalCloudMetricsTest, EmptyReconstruction) {
  const NearestNeighbourIndex gt(PointCloud{{0, 0, 0}, {1, 0, 0}});
  const NearestNeighbourIndex empty(PointCloud{});
  EXPECT_TRUE(std::isinf(empty.NearestDistance({0, 0, 0})));
  const CloudMetrics m = EvaluateCloud(empty, gt, Options(0.1, 1));
  EXPECT_EQ(m.num_points, 0);
  EXPECT_TRUE(std::isnan(m.accuracy));
  EXPECT_TRUE(std::isnan(m.completeness));
  EXPECT_EQ(m.completeness_cut, 2);
  EXPECT_TRUE(std::isnan(m.overall));
  EXPECT_TRUE(std::isnan(m.precision));
  EXPECT_EQ(m.recall, 0.0);
  EXPECT_EQ(m.fscore, 0.0);
}

TEST(EvalCloudMetricsTest, RejectsBadInput) {
  const NearestNeighbourIndex cloud(PointCloud{{0, 0, 0}});
  const NearestNeighbourIndex empty(PointCloud{});
  EXPECT_THROW(EvaluateCloud(cloud, empty, Options(0.1, 1)), std::invalid_argument);
  EXPECT_THROW(EvaluateCloud(cloud, cloud, Options(0, 1)), std::invalid_argument);
  EXPECT_THROW(EvaluateCloud(cloud, cloud, Options(0.1, -1)), std::invalid_argument);
  EXPECT_THROW(EvaluateCloud(cloud, cloud, Options(std::nan(""), 1)), std::invalid_argument);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(NearestNeighbourIndex(PointCloud{{0, nan, 0}}), std::invalid_argument);
}

// The k-d tree against brute force on random clouds (with duplicates and a
// cluster, so that the tree has uneven leaves).
TEST(EvalCloudMetricsTest, KdTreeMatchesBruteForce) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> uniform(-1.0f, 1.0f);
  std::normal_distribution<float> cluster(0.0f, 0.01f);
  PointCloud gt, recon;
  for (int i = 0; i < 2000; ++i) {
    gt.emplace_back(uniform(rng), uniform(rng), uniform(rng));
  }
  for (int i = 0; i < 300; ++i) gt.emplace_back(0.3f + cluster(rng), cluster(rng), cluster(rng));
  for (int i = 0; i < 50; ++i) gt.push_back(gt[i]);
  for (int i = 0; i < 1500; ++i) {
    // Near GT points, plus some far away.
    const Eigen::Vector3f noise(cluster(rng), cluster(rng), cluster(rng));
    recon.push_back(i % 10 == 0 ? Eigen::Vector3f(3 * uniform(rng), 3 * uniform(rng), 2)
                                : Eigen::Vector3f(gt[(i * 7) % gt.size()] + 3 * noise));
  }
  const NearestNeighbourIndex gt_index(gt), recon_index(recon);
  const std::vector<double> distances = gt_index.NearestDistances(recon);
  ASSERT_EQ(distances.size(), recon.size());
  for (std::size_t i = 0; i < recon.size(); ++i) {
    double best = std::numeric_limits<double>::infinity();
    for (const Eigen::Vector3f& p : gt) {
      best = std::min(best, (p.cast<double>() - recon[i].cast<double>()).norm());
    }
    ASSERT_NEAR(distances[i], best, 1e-12) << "point " << i;
  }
  const CloudMetricOptions options = Options(0.02, 0.2);
  const CloudMetrics tree = EvaluateCloud(recon_index, gt_index, options);
  const CloudMetrics brute = EvaluateCloudBruteForce(recon, gt, options);
  EXPECT_NEAR(tree.accuracy, brute.accuracy, 1e-12);
  EXPECT_NEAR(tree.completeness, brute.completeness, 1e-12);
  EXPECT_EQ(tree.accuracy_cut, brute.accuracy_cut);
  EXPECT_EQ(tree.completeness_cut, brute.completeness_cut);
  EXPECT_EQ(tree.precision, brute.precision);
  EXPECT_EQ(tree.recall, brute.recall);
  EXPECT_EQ(tree.fscore, brute.fscore);
  // The clouds were built so that every kind of count is non-trivial.
  EXPECT_GT(tree.accuracy_cut, 0);
  EXPECT_GT(tree.completeness_cut, 0);
  EXPECT_GT(tree.precision, 0.1);
  EXPECT_LT(tree.precision, 1.0);
  EXPECT_GT(tree.recall, 0.1);
  EXPECT_LT(tree.recall, 1.0);
}

TEST(EvalCloudMetricsTest, BoundingBoxDiagonal) {
  EXPECT_EQ(BoundingBoxDiagonal({}), 0.0);
  EXPECT_DOUBLE_EQ(BoundingBoxDiagonal({{0, 0, 0}, {1, 2, 2}, {0.5f, 1, 1}}), 3.0);
  EXPECT_DOUBLE_EQ(BoundingBoxDiagonal({{-1, -1, -1}, {1, 1, 1}}), std::sqrt(12.0));
}

TEST(EvalBackProjectTest, RawIndexConventionAndPose) {
  // PINHOLE 8x6, fx = fy = 4, cx = 4, cy = 3. World-to-camera: 90 degrees
  // about z, t = (0, 0, 1).
  colmap_io::Camera camera;
  camera.camera_id = 1;
  camera.model_id = 1;
  camera.width = 8;
  camera.height = 6;
  camera.params = {4, 4, 4, 3};
  colmap_io::Image image;
  image.camera_id = 1;
  Eigen::Matrix3d R;
  R << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  image.SetPose(R, Eigen::Vector3d(0, 0, 1));

  // Full size: pixel (col 6, row 1), depth 2 -> X_cam = 2 ((6-4)/4, (1-3)/4, 1)
  // = (1, -1, 2); X_cam - t = (1, -1, 1); R^T (1, -1, 1) = (-1, -1, 1).
  colmap_io::DenseArray full(8, 6, 1, 0.0f);
  full.at(1, 6) = 2;
  PointCloud points;
  BackProjectDepthMap(full, camera, image, 1, &points);
  ASSERT_EQ(points.size(), 1u);
  EXPECT_NEAR((points[0] - Eigen::Vector3f(-1, -1, 1)).norm(), 0, 1e-6);

  // Half size (s = 1/2): map pixel (3, 0) is image position (6, 0) -> X_cam =
  // 2 (0.5, -0.75, 1) = (1, -1.5, 2); R^T (1, -1.5, 1) = (-1.5, -1, 1).
  colmap_io::DenseArray half(4, 3, 1, 0.0f);
  half.at(0, 3) = 2;
  points.clear();
  BackProjectDepthMap(half, camera, image, 1, &points);
  ASSERT_EQ(points.size(), 1u);
  EXPECT_NEAR((points[0] - Eigen::Vector3f(-1.5f, -1, 1)).norm(), 0, 1e-6);

  // Stride 2 keeps even columns and rows only: map pixel (2, 2), depth 1, is
  // image position (4, 4) -> X_cam = (0, 0.25, 1); R^T (0, 0.25, 0) = (0.25, 0, 0).
  half.at(2, 2) = 1;
  points.clear();
  BackProjectDepthMap(half, camera, image, 2, &points);
  ASSERT_EQ(points.size(), 1u);
  EXPECT_NEAR((points[0] - Eigen::Vector3f(0.25f, 0, 0)).norm(), 0, 1e-6);

  EXPECT_THROW(BackProjectDepthMap(colmap_io::DenseArray(6, 3, 1, 1.0f), camera, image, 1,
                                   &points),
               std::invalid_argument);
  EXPECT_THROW(BackProjectDepthMap(half, camera, image, 0, &points), std::invalid_argument);
  camera.model_id = 2;  // SIMPLE_RADIAL: not undistorted
  camera.params = {4, 4, 3, 0};
  EXPECT_THROW(BackProjectDepthMap(half, camera, image, 1, &points), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::eval
