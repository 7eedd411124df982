// Region labels against configurations whose answer is known in closed form
// (planes seen by translated cameras), the edge distance against a brute-force
// search, and the sums on hand-made errors.

#include "eval/error_regions.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <vector>

#include "colmap_io/camera_models.h"

namespace dispmvs::eval {
namespace {

using colmap_io::DenseArray;

DenseArray Filled(int width, int height, float value) { return DenseArray(width, height, 1, value); }

float& At(DenseArray& map, int row, int col) { return map.data()[static_cast<size_t>(row) * map.width() + col]; }

colmap_io::Camera PinholeCamera64x48() {
  colmap_io::Camera camera;
  camera.camera_id = 1;
  camera.model_id = colmap_io::kPinholeModelId;
  camera.width = 64;
  camera.height = 48;
  camera.params = {50, 50, 32, 24};
  return camera;
}

// A camera looking along +z from (x, 0, 0): t = -R C with R = I.
colmap_io::Image ImageAt(double x) {
  colmap_io::Image image;
  image.camera_id = 1;
  image.tvec = Eigen::Vector3d(-x, 0, 0);
  return image;
}

int Count(const cv::Mat& labels, Visibility v) {
  return cv::countNonZero(labels == static_cast<uint8_t>(v));
}

// The reference at the origin and a source 2 units to the right both see a
// fronto-parallel plane at depth 10: reference pixel (col, row) lands on
// source position col - 50 * 2 / 10 = col - 10. Columns 0-9 fall left of the
// source (outside); the source's GT has a nearer block (depth 5) on its
// columns 20-29, rows 10-19, which hides reference columns 30-39 there.
TEST(ErrorRegionsTest, VisibilityOfAPlaneBehindABlockInOneSource) {
  const colmap_io::Camera camera = PinholeCamera64x48();
  const colmap_io::Image reference = ImageAt(0), source = ImageAt(2);
  DenseArray reference_gt = Filled(64, 48, 10), source_gt = Filled(64, 48, 10);
  for (int row = 10; row < 20; ++row) {
    for (int col = 20; col < 30; ++col) At(source_gt, row, col) = 5;
  }
  At(reference_gt, 0, 0) = 0;  // no surface: no label
  const cv::Mat labels = LabelVisibility(reference_gt, camera, reference, {{&source_gt, &camera, &source}});
  EXPECT_EQ(Count(labels, Visibility::kOutside), 10 * 48 - 1);
  EXPECT_EQ(Count(labels, Visibility::kHidden), 10 * 10);
  EXPECT_EQ(Count(labels, Visibility::kSeen), 64 * 48 - 10 * 48 - 10 * 10);
  EXPECT_EQ(labels.at<uint8_t>(0, 0), 255);
  EXPECT_EQ(labels.at<uint8_t>(15, 35), static_cast<uint8_t>(Visibility::kHidden));
  EXPECT_EQ(labels.at<uint8_t>(15, 29), static_cast<uint8_t>(Visibility::kSeen));
  EXPECT_EQ(labels.at<uint8_t>(15, 40), static_cast<uint8_t>(Visibility::kSeen));
  EXPECT_EQ(labels.at<uint8_t>(30, 9), static_cast<uint8_t>(Visibility::kOutside));
  EXPECT_EQ(labels.at<uint8_t>(30, 10), static_cast<uint8_t>(Visibility::kSeen));

  // A hole in the source's GT where the block was: nothing hides them.
  DenseArray holed = source_gt;
  for (int row = 10; row < 20; ++row) {
    for (int col = 20; col < 30; ++col) At(holed, row, col) = 0;
  }
  EXPECT_EQ(Count(LabelVisibility(reference_gt, camera, reference, {{&holed, &camera, &source}}), Visibility::kHidden),
            0);

  // The block 3 % nearer than the plane is within the tolerance: seen.
  DenseArray close_block = source_gt;
  for (int row = 10; row < 20; ++row) {
    for (int col = 20; col < 30; ++col) At(close_block, row, col) = 10 / 1.029f;
  }
  EXPECT_EQ(Count(LabelVisibility(reference_gt, camera, reference, {{&close_block, &camera, &source}}),
                  Visibility::kHidden),
            0);

  // A second source 2 units to the left sees what the first cannot: every
  // pixel is seen by one of them.
  const colmap_io::Image left = ImageAt(-2);
  const DenseArray left_gt = Filled(64, 48, 10);
  const cv::Mat both = LabelVisibility(reference_gt, camera, reference,
                                       {{&source_gt, &camera, &source}, {&left_gt, &camera, &left}});
  EXPECT_EQ(Count(both, Visibility::kSeen), 64 * 48 - 1);

  // No other view: everything outside.
  EXPECT_EQ(Count(LabelVisibility(reference_gt, camera, reference, {}), Visibility::kOutside), 64 * 48 - 1);
}

// A GT map at half the camera's size: GT pixel i is image position 2 i, so
// source position 2 i - 10, outside for i < 5; the source's GT at half size too.
TEST(ErrorRegionsTest, VisibilityOfDownScaledGroundTruth) {
  const colmap_io::Camera camera = PinholeCamera64x48();
  const colmap_io::Image reference = ImageAt(0), source = ImageAt(2);
  const DenseArray reference_gt = Filled(32, 24, 10), source_gt = Filled(32, 24, 10);
  const cv::Mat labels = LabelVisibility(reference_gt, camera, reference, {{&source_gt, &camera, &source}});
  EXPECT_EQ(Count(labels, Visibility::kOutside), 5 * 24);
  EXPECT_EQ(Count(labels, Visibility::kSeen), 27 * 24);
  const DenseArray odd = Filled(40, 24, 10);  // not one scale of 64x48
  EXPECT_THROW(LabelVisibility(odd, camera, reference, {}), std::invalid_argument);
}

// Brute force: the L1 distance to the nearest pixel of a neighbour pair whose
// depths differ by more than 5 % in log depth.
std::vector<int> BruteForceEdgeDistance(DenseArray& gt) {
  const int w = gt.width(), h = gt.height();
  std::vector<std::pair<int, int>> edges;
  const auto valid = [](float d) { return d > 0; };
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      for (const auto& [dr, dc] : {std::pair<int, int>{0, 1}, {1, 0}, {0, -1}, {-1, 0}}) {
        const int r2 = r + dr, c2 = c + dc;
        if (r2 < 0 || r2 >= h || c2 < 0 || c2 >= w) continue;
        const float a = At(gt, r, c), b = At(gt, r2, c2);
        if (valid(a) && valid(b) && std::abs(std::log(a) - std::log(b)) > kEdgeLogDepthStep) {
          edges.push_back({r, c});
          break;
        }
      }
    }
  }
  std::vector<int> distance(static_cast<size_t>(w) * h, -1);
  for (int r = 0; r < h; ++r) {
    for (int c = 0; c < w; ++c) {
      if (!valid(At(gt, r, c))) continue;
      int best = 1 << 30;
      for (const auto& [er, ec] : edges) best = std::min(best, std::abs(er - r) + std::abs(ec - c));
      distance[static_cast<size_t>(r) * w + c] = best;
    }
  }
  return distance;
}

TEST(ErrorRegionsTest, DistanceToDepthEdgeMatchesABruteForceSearch) {
  DenseArray gt = Filled(40, 30, 4);
  for (int r = 0; r < 30; ++r) {
    for (int c = 0; c < 40; ++c) {
      if (c >= 25) At(gt, r, c) = 4.1f;                      // a 2.5 % step: not an edge
      if (r >= 8 && r < 14 && c >= 5 && c < 12) At(gt, r, c) = 2;  // a nearer block: edges
      if (r >= 20 && c < 6) At(gt, r, c) = 0;                // no surface
      if (r == 25 && c >= 30) At(gt, r, c) = 8;              // a thin far line
    }
  }
  const std::vector<int> expected = BruteForceEdgeDistance(gt);
  const cv::Mat distance = DistanceToDepthEdge(gt);
  ASSERT_EQ(distance.type(), CV_32SC1);
  int mismatches = 0;
  for (int r = 0; r < 30; ++r) {
    for (int c = 0; c < 40; ++c) mismatches += distance.at<int>(r, c) != expected[static_cast<size_t>(r) * 40 + c];
  }
  EXPECT_EQ(mismatches, 0);
  EXPECT_EQ(distance.at<int>(8, 5), 0);
  EXPECT_EQ(distance.at<int>(25, 0), -1);
  EXPECT_GT(distance.at<int>(0, 39), 12);

  // No edge anywhere: every pixel in the outer ring.
  const RegionLabels flat = LabelRegions(Filled(16, 12, 3), PinholeCamera64x48(), ImageAt(0), {});
  EXPECT_EQ(cv::countNonZero(flat.edge_ring == kNumEdgeRings - 1), 16 * 12);
}

TEST(ErrorRegionsTest, EdgeRingsAreTheDocumentedRanges) {
  const int expected[] = {0, 0, 1, 1, 2, 2, 2, 3, 3, 3, 3, 3, 3, 4, 4};
  for (int d = 0; d < 15; ++d) EXPECT_EQ(EdgeRing(d), expected[d]) << d;
  EXPECT_EQ(EdgeRing(1 << 30), 4);
}

TEST(ErrorRegionsTest, SumsCountEachClassAtTheMapsSize) {
  RegionLabels labels;
  labels.visibility = cv::Mat(4, 4, CV_8UC1, cv::Scalar(static_cast<int>(Visibility::kSeen)));
  labels.edge_ring = cv::Mat(4, 4, CV_8UC1, cv::Scalar(0));
  labels.visibility.colRange(2, 4).setTo(static_cast<int>(Visibility::kOutside));
  labels.edge_ring.rowRange(2, 4).setTo(4);
  // A map at half the GT's size: map pixel (r, c) reads GT pixel (2r, 2c).
  cv::Mat rel_error = (cv::Mat_<float>(2, 2) << 0.005f, 0.03f, kRelErrorMissing, kRelErrorNoGt);
  ErrorRegionSums sums = SumErrorRegions(rel_error, labels);
  EXPECT_EQ(sums.gt_pixels, 3);
  const RegionClassSums& seen = sums.visibility[static_cast<int>(Visibility::kSeen)];
  EXPECT_EQ(seen.gt_pixels, 2);  // (0,0) within 1 %, (1,0) missing
  EXPECT_EQ(seen.within_1, 1);
  EXPECT_EQ(seen.within_5, 1);
  const RegionClassSums& outside = sums.visibility[static_cast<int>(Visibility::kOutside)];
  EXPECT_EQ(outside.gt_pixels, 1);  // (0,1): 3 %
  EXPECT_EQ(outside.within_2, 0);
  EXPECT_EQ(outside.within_5, 1);
  EXPECT_EQ(sums.seen_by_edge_ring[0].gt_pixels, 1);
  EXPECT_EQ(sums.seen_by_edge_ring[4].gt_pixels, 1);
  ErrorRegionSums twice = sums;
  twice += sums;
  EXPECT_EQ(twice.visibility[static_cast<int>(Visibility::kSeen)].within_1, 2);
  EXPECT_EQ(RegionRows(twice).size(), static_cast<size_t>(kNumVisibilities + kNumEdgeRings));
  EXPECT_EQ(RegionRows(twice)[3].first, "seen, 0-1 px from a depth edge");
  EXPECT_EQ(RegionRows(twice).back().first, "seen, 13+ px from a depth edge");

  const cv::Mat odd(4, 1, CV_32FC1, cv::Scalar(0));  // 1 x 4 is no one scale of 4 x 4
  EXPECT_THROW(SumErrorRegions(odd, labels), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::eval
