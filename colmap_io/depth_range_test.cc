#include "colmap_io/depth_range.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <gtest/gtest.h>

#include "tests/support/model_builder.h"

namespace dispmvs::colmap_io {
namespace {

using testing::ModelBuilder;

// A camera at the origin looking down +z with an identity pose, so a point's
// depth is simply its z coordinate.
struct IdentityScene {
  ModelBuilder builder;
  camera_t camera = builder.AddPinholeCamera(100, 100, 50, 50, 50, 50);
  image_t image = builder.AddImageLookingAt(camera, "ref.png", {0, 0, 0}, {0, 0, 1});
};

TEST(DepthRangeTest, HundredDepthsGiveColmapPercentilesAndMargins) {
  IdentityScene scene;
  // Depths 1..100, added out of order so the code has to sort.
  for (int i = 0; i < 100; ++i) {
    const double depth = 1 + (i * 37) % 100;  // 37 is coprime with 100: a permutation
    scene.builder.AddPoint({0.01 * depth, -0.02 * depth, depth}, {scene.image});
  }
  const DepthRange range = ComputeDepthRange(scene.builder.model(), scene.image);
  ASSERT_TRUE(range.valid);
  EXPECT_EQ(range.num_points, 100u);
  // sorted[floor(100 * 0.01)] = sorted[1] = 2; sorted[floor(100 * 0.99)] = 100.
  EXPECT_DOUBLE_EQ(range.d_min, 0.75 * 2.0);
  EXPECT_DOUBLE_EQ(range.d_max, 1.25 * 100.0);
}

TEST(DepthRangeTest, DepthIsMeasuredAlongARotatedViewingDirection) {
  ModelBuilder builder;
  const camera_t camera = builder.AddPinholeCamera(100, 100, 50, 50, 50, 50);
  // Camera at x = 10 looking towards -x: a point at (10 - k, y, z) has depth k.
  const image_t image = builder.AddImageLookingAt(camera, "side.png", {10, 0, 0}, {0, 0, 0});
  for (int k = 1; k <= 10; ++k) builder.AddPoint({10.0 - k, 0.3 * k, -0.2 * k}, {image});
  const DepthRange range = ComputeDepthRange(builder.model(), image);
  ASSERT_TRUE(range.valid);
  // n = 10: sorted[floor(0.1)] = sorted[0] = 1 and sorted[floor(9.9)] = sorted[9] = 10.
  EXPECT_NEAR(range.d_min, 0.75, 1e-12);
  EXPECT_NEAR(range.d_max, 12.5, 1e-12);
}

TEST(DepthRangeTest, PointsBehindOnOrNonFiniteAreIgnored) {
  IdentityScene scene;
  for (double depth = 1; depth <= 10; ++depth) scene.builder.AddPoint({0, 0, depth}, {scene.image});
  // With n = 10 the low percentile is the smallest depth, so any of these
  // leaking in would change d_min.
  scene.builder.AddPoint({0, 0, -3}, {scene.image});
  scene.builder.AddPoint({1, 1, 0}, {scene.image});
  scene.builder.AddPoint({0, 0, std::numeric_limits<double>::quiet_NaN()}, {scene.image});
  scene.builder.AddPoint({0, 0, std::numeric_limits<double>::infinity()}, {scene.image});
  const DepthRange range = ComputeDepthRange(scene.builder.model(), scene.image);
  ASSERT_TRUE(range.valid);
  EXPECT_EQ(range.num_points, 10u);
  EXPECT_DOUBLE_EQ(range.d_min, 0.75);
  EXPECT_DOUBLE_EQ(range.d_max, 12.5);
}

TEST(DepthRangeTest, DanglingAndUnmatchedObservationsAreIgnored) {
  IdentityScene scene;
  scene.builder.AddPoint({0, 0, 4}, {scene.image});
  scene.builder.AddUnmatchedObservation(scene.image, {10, 10});
  Point2D dangling;
  dangling.point3D_id = 999;  // no such point
  scene.builder.mutable_model().images.at(scene.image).points2D.push_back(dangling);
  const DepthRange range = ComputeDepthRange(scene.builder.model(), scene.image);
  ASSERT_TRUE(range.valid);
  EXPECT_EQ(range.num_points, 1u);
  EXPECT_DOUBLE_EQ(range.d_min, 3.0);  // single point: both percentiles pick 4
  EXPECT_DOUBLE_EQ(range.d_max, 5.0);
}

TEST(DepthRangeTest, ImageSeeingNoPointsIsInvalid) {
  IdentityScene scene;
  scene.builder.AddUnmatchedObservation(scene.image, {1, 1});
  const DepthRange range = ComputeDepthRange(scene.builder.model(), scene.image);
  EXPECT_FALSE(range.valid);
  EXPECT_EQ(range.num_points, 0u);
  EXPECT_EQ(range.d_min, 0.0);
  EXPECT_EQ(range.d_max, 0.0);
}

TEST(DepthRangeTest, TooFewPointsIsInvalidButCounted) {
  IdentityScene scene;
  for (double depth = 1; depth <= 3; ++depth) scene.builder.AddPoint({0, 0, depth}, {scene.image});
  DepthRangeOptions options;
  options.min_num_points = 4;
  const DepthRange range = ComputeDepthRange(scene.builder.model(), scene.image, options);
  EXPECT_FALSE(range.valid);
  EXPECT_EQ(range.num_points, 3u);
  options.min_num_points = 3;
  EXPECT_TRUE(ComputeDepthRange(scene.builder.model(), scene.image, options).valid);
}

TEST(DepthRangeTest, CustomPercentilesAndStretch) {
  IdentityScene scene;
  for (double depth = 1; depth <= 100; ++depth) {
    scene.builder.AddPoint({0, 0, depth}, {scene.image});
  }
  DepthRangeOptions options;
  options.min_percentile = 0.1;
  options.max_percentile = 0.9;
  options.stretch_ratio = 0.0;
  const DepthRange range = ComputeDepthRange(scene.builder.model(), scene.image, options);
  ASSERT_TRUE(range.valid);
  EXPECT_DOUBLE_EQ(range.d_min, 11.0);  // sorted[10]
  EXPECT_DOUBLE_EQ(range.d_max, 91.0);  // sorted[90]
  options.max_percentile = 1.0;  // clamps to the last element
  EXPECT_DOUBLE_EQ(ComputeDepthRange(scene.builder.model(), scene.image, options).d_max, 100.0);
}

TEST(DepthRangeTest, OptionsCheckRejectsNonsense) {
  const auto expect_rejected = [](const DepthRangeOptions& options) {
    EXPECT_THROW(options.Check(), std::invalid_argument);
  };
  DepthRangeOptions options;
  EXPECT_NO_THROW(options.Check());
  options.min_percentile = -0.1;
  expect_rejected(options);
  options = {};
  options.max_percentile = 1.5;
  expect_rejected(options);
  options = {};
  options.min_percentile = 0.8;
  options.max_percentile = 0.2;
  expect_rejected(options);
  options = {};
  options.stretch_ratio = 1.0;
  expect_rejected(options);
  options = {};
  options.stretch_ratio = std::numeric_limits<double>::quiet_NaN();
  expect_rejected(options);
  options = {};
  options.min_num_points = 0;
  expect_rejected(options);

  IdentityScene scene;
  options = {};
  options.stretch_ratio = -1.0;
  EXPECT_THROW(ComputeDepthRange(scene.builder.model(), scene.image, options),
               std::invalid_argument);
}

TEST(DepthRangeTest, UnknownImageThrows) {
  IdentityScene scene;
  EXPECT_THROW(ComputeDepthRange(scene.builder.model(), scene.image + 7), std::invalid_argument);
}

TEST(DepthRangeTest, AllImagesAndFallbackFromTheUnionOfValidRanges) {
  ModelBuilder builder;
  const camera_t camera = builder.AddPinholeCamera(100, 100, 50, 50, 50, 50);
  const image_t near = builder.AddImageLookingAt(camera, "near.png", {0, 0, 0}, {0, 0, 1});
  const image_t far = builder.AddImageLookingAt(camera, "far.png", {0, 0, -10}, {0, 0, 1});
  const image_t empty = builder.AddImageLookingAt(camera, "empty.png", {5, 0, 0}, {5, 0, 1});
  // Seen by `near` at depth z and by `far` at depth z + 10.
  for (double z = 2; z <= 4; ++z) builder.AddPoint({0, 0, z}, {near, far});

  const auto ranges = ComputeDepthRanges(builder.model());
  ASSERT_EQ(ranges.size(), 3u);
  EXPECT_DOUBLE_EQ(ranges.at(near).d_min, 1.5);   // 0.75 * 2
  EXPECT_DOUBLE_EQ(ranges.at(near).d_max, 5.0);   // 1.25 * 4
  EXPECT_DOUBLE_EQ(ranges.at(far).d_min, 9.0);    // 0.75 * 12
  EXPECT_DOUBLE_EQ(ranges.at(far).d_max, 17.5);   // 1.25 * 14
  EXPECT_FALSE(ranges.at(empty).valid);

  const DepthRange fallback = FallbackDepthRange(ranges);
  ASSERT_TRUE(fallback.valid);
  EXPECT_DOUBLE_EQ(fallback.d_min, 1.5);
  EXPECT_DOUBLE_EQ(fallback.d_max, 17.5);
  EXPECT_EQ(fallback.num_points, 6u);

  EXPECT_FALSE(FallbackDepthRange({{empty, ranges.at(empty)}}).valid);
  EXPECT_FALSE(FallbackDepthRange({}).valid);
}

}  // namespace
}  // namespace dispmvs::colmap_io
