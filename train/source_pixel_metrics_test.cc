#include "train/source_pixel_metrics.h"

#include <cmath>

#include <gtest/gtest.h>

namespace dispmvs::train {
namespace {

// A fronto-parallel plane at depth kDepth seen by a reference camera at the
// origin and sources translated along +x by the given baselines, all with
// the same pinhole (f = kFocal): the true match of reference pixel (u, v) in
// a source of baseline t is (u - kFocal t / kDepth, v), on the plane at the
// same depth. Everything below is computed from that by hand.
constexpr int64_t kWidth = 64, kHeight = 16;
constexpr double kFocal = 50.0, kDepth = 1.4;

struct PlaneRig {
  torch::Tensor gt_depths, intrinsics, extrinsics;
};

PlaneRig MakePlaneRig(const std::vector<double>& baselines) {
  const int64_t views = 1 + static_cast<int64_t>(baselines.size());
  PlaneRig rig;
  rig.gt_depths = torch::full({1, views, 1, kHeight, kWidth}, kDepth, torch::kFloat32);
  torch::Tensor K = torch::eye(3, torch::kFloat32);
  K[0][0] = kFocal;
  K[1][1] = kFocal;
  K[0][2] = (kWidth - 1) / 2.0;
  K[1][2] = (kHeight - 1) / 2.0;
  rig.intrinsics = K.expand({1, views, 3, 3}).clone();
  rig.extrinsics = torch::eye(4, torch::kFloat32).expand({1, views, 4, 4}).clone();
  for (int64_t i = 1; i < views; ++i) {
    // World to camera of a centre at (t, 0, 0): x_cam = x_world - (t, 0, 0).
    rig.extrinsics[0][i][0][3] = -baselines[static_cast<size_t>(i - 1)];
  }
  return rig;
}

torch::Tensor PlaneDepth(double depth) {
  return torch::full({1, 1, kHeight, kWidth}, depth, torch::kFloat32);
}

torch::Tensor AllValid() { return torch::ones({1, 1, kHeight, kWidth}, torch::kBool); }

// Reference columns whose match lies inside a source of baseline t: u - d >= 0.
int64_t SeenColumns(double baseline) {
  const double disparity = kFocal * baseline / kDepth;
  return kWidth - static_cast<int64_t>(std::ceil(disparity));
}

TEST(SourcePixelMetricsTest, ExactDepthsMatchToTheSubPixelOnThePlane) {
  const PlaneRig rig = MakePlaneRig({1.0});
  torch::Tensor seen;
  const SourcePixelCounts c = CountSourcePixels(rig.gt_depths, rig.intrinsics, rig.extrinsics,
                                                PlaneDepth(kDepth), AllValid(), &seen);
  const int64_t expected = SeenColumns(1.0) * kHeight;  // 28 columns of 16 rows
  EXPECT_EQ(c.seeing_pairs, expected);
  EXPECT_EQ(c.seen_pixels, expected);
  EXPECT_EQ(seen.sum().item<int64_t>(), expected);
  EXPECT_EQ(c.pairs_within_1px, expected);
  EXPECT_EQ(c.pairs_within_2px, expected);
  // 2 % farther moves the match by (f t / d) (1 - 1 / 1.02) = 0.700 px, the
  // smaller of the two moves: at least half a pixel, not one.
  ASSERT_NEAR(kFocal / kDepth * (1 - 1 / 1.02), 0.700, 1e-3);
  EXPECT_EQ(c.moves_half_px, expected);
  EXPECT_EQ(c.moves_1px, 0);
  // The leftmost seen column sees, the one before does not.
  const int64_t first = kWidth - SeenColumns(1.0);
  EXPECT_TRUE(seen[0][0][3][first].item<bool>());
  EXPECT_FALSE(seen[0][0][3][first - 1].item<bool>());
}

TEST(SourcePixelMetricsTest, ADepthErrorIsMeasuredInSourcePixels) {
  const PlaneRig rig = MakePlaneRig({1.0});
  const int64_t expected = SeenColumns(1.0) * kHeight;
  // 3 % farther: the match moves by (f t / d)(1 - 1 / 1.03) = 1.040 px.
  ASSERT_NEAR(kFocal / kDepth * (1 - 1 / 1.03), 1.040, 1e-3);
  const SourcePixelCounts far = CountSourcePixels(rig.gt_depths, rig.intrinsics, rig.extrinsics,
                                                  PlaneDepth(kDepth * 1.03), AllValid());
  EXPECT_EQ(far.pairs_within_1px, 0);
  EXPECT_EQ(far.pairs_within_2px, expected);
  // 1 % nearer: (f t / d)(1 / 0.99 - 1) = 0.361 px.
  const SourcePixelCounts near = CountSourcePixels(rig.gt_depths, rig.intrinsics, rig.extrinsics,
                                                   PlaneDepth(kDepth * 0.99), AllValid());
  EXPECT_EQ(near.pairs_within_1px, expected);
  // A pixel without a prediction is within nothing; the truth does not change.
  torch::Tensor half = AllValid().clone();
  half.narrow(2, 0, kHeight / 2).fill_(false);
  const SourcePixelCounts partial = CountSourcePixels(rig.gt_depths, rig.intrinsics,
                                                      rig.extrinsics, PlaneDepth(kDepth), half);
  EXPECT_EQ(partial.seeing_pairs, expected);
  EXPECT_EQ(partial.pairs_within_1px, expected / 2);
  const SourcePixelCounts nan = CountSourcePixels(rig.gt_depths, rig.intrinsics, rig.extrinsics,
                                                  PlaneDepth(std::nan("")), AllValid());
  EXPECT_EQ(nan.pairs_within_2px, 0);
}

TEST(SourcePixelMetricsTest, OnlySeeingSourcesCount) {
  // The second source (t = 2: disparity 71 px > the width) sees nothing;
  // there 2 % would move the match 1.4 px, which must not count.
  const PlaneRig rig = MakePlaneRig({1.0, 2.0});
  ASSERT_LE(SeenColumns(2.0), 0);
  const SourcePixelCounts c = CountSourcePixels(rig.gt_depths, rig.intrinsics, rig.extrinsics,
                                                PlaneDepth(kDepth), AllValid());
  const int64_t expected = SeenColumns(1.0) * kHeight;
  EXPECT_EQ(c.seeing_pairs, expected);
  EXPECT_EQ(c.seen_pixels, expected);
  EXPECT_EQ(c.moves_1px, 0);
  // With a wider third source that sees the plane's right part
  // (t = 1.5: disparity 53.6 px), those pixels' best move is 1.05 px.
  const PlaneRig wider = MakePlaneRig({1.0, 2.0, 1.5});
  const SourcePixelCounts w = CountSourcePixels(wider.gt_depths, wider.intrinsics,
                                                wider.extrinsics, PlaneDepth(kDepth), AllValid());
  EXPECT_EQ(w.seen_pixels, expected);
  EXPECT_EQ(w.seeing_pairs, expected + SeenColumns(1.5) * kHeight);
  EXPECT_EQ(w.moves_1px, SeenColumns(1.5) * kHeight);
  const SourcePixelShares shares = SharesOf(w);
  EXPECT_DOUBLE_EQ(shares.moves_half_px, 1.0);
  EXPECT_DOUBLE_EQ(shares.within_1px, 1.0);
}

TEST(SourcePixelMetricsTest, RefusesMismatchedShapes) {
  const PlaneRig rig = MakePlaneRig({1.0});
  EXPECT_THROW(CountSourcePixels(rig.gt_depths, rig.intrinsics, rig.extrinsics,
                                 PlaneDepth(kDepth).squeeze(1), AllValid()),
               std::invalid_argument);
  EXPECT_THROW(CountSourcePixels(rig.gt_depths.select(1, 0), rig.intrinsics, rig.extrinsics,
                                 PlaneDepth(kDepth), AllValid()),
               std::invalid_argument);
  EXPECT_EQ(SharesOf(SourcePixelCounts()).within_1px, 0.0);
}

}  // namespace
}  // namespace dispmvs::train
