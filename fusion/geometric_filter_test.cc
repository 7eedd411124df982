#include "fusion/geometric_filter.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "fusion/test_scene.h"

namespace dispmvs::fusion {
namespace {

using testing::Camera;
using testing::DefaultCameras;
using testing::MakeDepthView;
using testing::Scene;
using testing::Visibility;

// The two-plane scene rendered exactly into the reference (camera 0, in the
// middle) and two sources (left and right), so that the background beside
// the foreground rectangle is occluded in one source or the other.
struct SceneViews {
  Scene scene = Scene::TwoPlanes();
  std::vector<Camera> cameras = DefaultCameras(3);
  std::vector<DepthView> views;

  SceneViews() {
    for (const Camera& camera : cameras) views.push_back(MakeDepthView(camera, scene.RenderDepth(camera)));
  }
  std::vector<const DepthView*> Sources() const { return {&views[1], &views[2]}; }
};

// The verdict on one reference pixel, from the analytic scene alone.
struct Expectation {
  bool decided = false;  // every source either kVisible or kHidden
  uint32_t visible_mask = 0;
};

Expectation Expect(const SceneViews& s, int row, int col) {
  const testing::Hit hit = s.scene.RayCast(s.cameras[0], col, row);
  Expectation e;
  e.decided = true;
  for (int i = 1; i < static_cast<int>(s.cameras.size()); ++i) {
    const Visibility v = s.scene.Classify(s.cameras[i], hit.world, hit.plane);
    if (v == Visibility::kUndecided) e.decided = false;
    if (v == Visibility::kVisible) e.visible_mask |= 1u << (i - 1);
  }
  return e;
}

TEST(GeometricFilterTest, ExactMapsPassWhereVisibleAndFailWhereOccluded) {
  const SceneViews s;
  GeometricFilterOptions options;  // min_consistent_views = 2: both sources
  const GeometricFilterResult result = FilterDepthMap(s.views[0], s.Sources(), options);
  const int width = s.cameras[0].width;
  int num_decided = 0, num_visible = 0, num_occluded = 0;
  for (int row = 0; row < s.cameras[0].height; ++row) {
    for (int col = 0; col < width; ++col) {
      const Expectation e = Expect(s, row, col);
      if (!e.decided) continue;
      ++num_decided;
      const std::size_t index = static_cast<std::size_t>(row) * width + col;
      EXPECT_EQ(result.consistent_mask[index], e.visible_mask) << row << "," << col;
      if (e.visible_mask == 3u) {
        ++num_visible;
        EXPECT_EQ(result.depth.at(row, col), s.views[0].depth.at(row, col)) << row << "," << col;
      } else {
        ++num_occluded;
        EXPECT_EQ(result.depth.at(row, col), 0.0f) << row << "," << col;
      }
    }
  }
  // The scene must decide most pixels and contain both cases in numbers.
  EXPECT_GT(num_decided, 0.8 * width * s.cameras[0].height);
  EXPECT_GT(num_visible, 1000);
  EXPECT_GT(num_occluded, 200);
}

TEST(GeometricFilterTest, CountAndKeptPixelsAgreeWithMask) {
  const SceneViews s;
  GeometricFilterOptions options;
  options.min_consistent_views = 1;
  const GeometricFilterResult result = FilterDepthMap(s.views[0], s.Sources(), options);
  std::size_t kept = 0;
  for (std::size_t i = 0; i < result.consistent_mask.size(); ++i) {
    const uint32_t mask = result.consistent_mask[i];
    EXPECT_EQ(result.num_consistent[i], ((mask & 1u) ? 1 : 0) + ((mask & 2u) ? 1 : 0));
    EXPECT_EQ(result.depth.data()[i] > 0.0f, result.num_consistent[i] >= 1);
    if (result.depth.data()[i] > 0.0f) ++kept;
  }
  EXPECT_EQ(result.num_kept, kept);
  // With one source enough, pixels occluded in only one source survive.
  const GeometricFilterResult strict = FilterDepthMap(s.views[0], s.Sources(), GeometricFilterOptions());
  EXPECT_GT(result.num_kept, strict.num_kept + 100);
}

TEST(GeometricFilterTest, PerturbedRegionFails) {
  SceneViews s;
  const GeometricFilterResult exact = FilterDepthMap(s.views[0], s.Sources(), GeometricFilterOptions());
  // +3 % in one block of the reference (three times the default tolerance).
  DepthView perturbed = s.views[0];
  auto in_block = [](int row, int col) { return row >= 10 && row < 40 && col >= 15 && col < 45; };
  for (int row = 0; row < perturbed.depth.height(); ++row) {
    for (int col = 0; col < perturbed.depth.width(); ++col) {
      if (in_block(row, col)) perturbed.depth.at(row, col) *= 1.03f;
    }
  }
  const GeometricFilterResult result = FilterDepthMap(perturbed, s.Sources(), GeometricFilterOptions());
  int num_block_pixels_kept_before = 0;
  for (int row = 0; row < perturbed.depth.height(); ++row) {
    for (int col = 0; col < perturbed.depth.width(); ++col) {
      if (in_block(row, col)) {
        EXPECT_EQ(result.depth.at(row, col), 0.0f) << row << "," << col;
        EXPECT_EQ(result.consistent_mask[row * perturbed.depth.width() + col], 0u);
        if (exact.depth.at(row, col) > 0.0f) ++num_block_pixels_kept_before;
      } else {
        EXPECT_EQ(result.depth.at(row, col), exact.depth.at(row, col)) << row << "," << col;
      }
    }
  }
  EXPECT_GT(num_block_pixels_kept_before, 500);
}

// Two views with the same K and R, the source shifted by `baseline` along x:
// reference pixel (col, row) at depth d lands on source column
// col - fx * baseline / d.
struct StereoPair {
  static constexpr int kWidth = 30, kHeight = 20;
  static constexpr double kFx = 100.0, kBaseline = 1.0, kDepth = 10.0;  // disparity 10
  DepthView reference, source;

  explicit StereoPair(float source_depth) {
    Eigen::Matrix3d K;
    K << kFx, 0, 14.2, 0, 90.0, 9.7, 0, 0, 1;
    reference.K = source.K = K;
    source.t = Eigen::Vector3d(-kBaseline, 0, 0);
    reference.depth = colmap_io::DenseArray(kWidth, kHeight, 1, static_cast<float>(kDepth));
    source.depth = colmap_io::DenseArray(kWidth, kHeight, 1, source_depth);
  }
};

// The source depth whose point reprojects `error` pixels (along the row) from
// the reference pixel: back in the reference it lands on column
// col - 10 + fx * b / d_src, i.e. off by fx * b / d_src - 10 = error.
float DepthForReprojectionError(double error) {
  return static_cast<float>(StereoPair::kFx * StereoPair::kBaseline / (10.0 + error));
}

TEST(GeometricFilterTest, ReprojectionThresholdIsRespectedAtTheBoundary) {
  GeometricFilterOptions options;
  options.min_consistent_views = 1;
  options.max_relative_depth_error = 0.5;  // isolate the reprojection test
  for (const auto& [error, expect_pass] :
       std::vector<std::pair<double, bool>>{{0.98, true}, {1.02, false}, {-0.98, true}, {-1.02, false}}) {
    const StereoPair pair(DepthForReprojectionError(error));
    const GeometricFilterResult result = FilterDepthMap(pair.reference, {&pair.source}, options);
    for (int col = 0; col < StereoPair::kWidth; ++col) {
      // Columns < 10 project outside the source.
      const bool pass = expect_pass && col >= 10;
      EXPECT_EQ(result.depth.at(7, col) > 0.0f, pass) << "error " << error << " col " << col;
    }
  }
  // The same error passes a looser threshold.
  options.max_reprojection_error = 1.05;
  const StereoPair pair(DepthForReprojectionError(1.02));
  EXPECT_EQ(FilterDepthMap(pair.reference, {&pair.source}, options).num_kept,
            static_cast<std::size_t>((StereoPair::kWidth - 10) * StereoPair::kHeight));
}

TEST(GeometricFilterTest, RelativeDepthThresholdIsRespectedAtTheBoundary) {
  // Same pose: every pixel maps onto itself and reprojects with zero error,
  // only the depth differs.
  GeometricFilterOptions options;
  options.min_consistent_views = 1;
  for (const auto& [factor, expect_pass] : std::vector<std::pair<double, bool>>{
           {1.0098, true}, {1.0102, false}, {0.9902, true}, {0.9898, false}}) {
    StereoPair pair(static_cast<float>(StereoPair::kDepth * factor));
    pair.source.t.setZero();
    const GeometricFilterResult result = FilterDepthMap(pair.reference, {&pair.source}, options);
    EXPECT_EQ(result.num_kept, expect_pass ? result.depth.size() : 0u) << "factor " << factor;
  }
}

TEST(GeometricFilterTest, MinConsistentViewsCountsAgreeingSources) {
  const SceneViews s;
  GeometricFilterOptions options;
  options.min_consistent_views = 0;  // keeps every valid depth
  EXPECT_EQ(FilterDepthMap(s.views[0], s.Sources(), options).num_kept, s.views[0].depth.size());
  options.min_consistent_views = 3;  // more than there are sources
  EXPECT_EQ(FilterDepthMap(s.views[0], s.Sources(), options).num_kept, 0u);
}

// The support rule against a direct count of each window: with the source
// at the reference's pose every pixel maps onto itself, so a pixel passes
// exactly where the source holds the reference's depth.
TEST(GeometricFilterTest, SupportKeepsPassingPixelsWhoseWindowPassesToo) {
  StereoPair pair(10.0f);
  pair.source.t.setZero();
  const int width = StereoPair::kWidth, height = StereoPair::kHeight;
  std::vector<bool> agrees(static_cast<std::size_t>(width) * height);
  uint32_t state = 12345u;  // a fixed pattern, about 70 % agreeing
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      state = state * 1664525u + 1013904223u;
      const bool agree = (state >> 8) % 10 < 7;
      agrees[row * width + col] = agree;
      if (!agree) pair.source.depth.at(row, col) = 10.5f;  // 5 %: fails
    }
  }
  GeometricFilterOptions options;
  options.min_consistent_views = 1;
  const GeometricFilterResult plain = FilterDepthMap(pair.reference, {&pair.source}, options);
  for (int i = 0; i < width * height; ++i) ASSERT_EQ(plain.depth.data()[i] > 0.0f, agrees[i]) << i;

  for (const auto& [radius, support] :
       std::vector<std::pair<int, double>>{{1, 0.6}, {2, 0.6}, {2, 0.75}, {3, 1.0}, {2, 0.0}}) {
    options.support_radius = radius;
    options.min_support = support;
    const GeometricFilterResult result = FilterDepthMap(pair.reference, {&pair.source}, options);
    std::size_t expected_kept = 0;
    for (int row = 0; row < height; ++row) {
      for (int col = 0; col < width; ++col) {
        int inside = 0, passing = 0;
        for (int r = row - radius; r <= row + radius; ++r) {
          for (int c = col - radius; c <= col + radius; ++c) {
            if (r < 0 || r >= height || c < 0 || c >= width) continue;
            ++inside;
            passing += agrees[r * width + c] ? 1 : 0;
          }
        }
        const bool keep = agrees[row * width + col] && passing >= support * inside;
        expected_kept += keep ? 1 : 0;
        EXPECT_EQ(result.depth.at(row, col), keep ? 10.0f : 0.0f)
            << "radius " << radius << " support " << support << " at " << row << "," << col;
        // Agreement itself is reported as without the support rule.
        EXPECT_EQ(result.consistent_mask[row * width + col], plain.consistent_mask[row * width + col]);
      }
    }
    EXPECT_EQ(result.num_kept, expected_kept) << "radius " << radius << " support " << support;
    if (support > 0.0) {
      EXPECT_LT(result.num_kept, plain.num_kept);
    }
  }
}

TEST(GeometricFilterTest, SupportDropsAnAgreementNoNeighbourShares) {
  StereoPair pair(10.5f);  // every pixel fails ...
  pair.source.t.setZero();
  pair.source.depth.at(9, 14) = 10.0f;  // ... but one
  pair.source.depth.at(9, 15) = 10.0f;  // and its neighbour
  GeometricFilterOptions options;
  options.min_consistent_views = 1;
  EXPECT_EQ(FilterDepthMap(pair.reference, {&pair.source}, options).num_kept, 2u);
  options.min_support = 2.0 / 25.0;  // two of a 5x5 window: both stay
  EXPECT_EQ(FilterDepthMap(pair.reference, {&pair.source}, options).num_kept, 2u);
  options.min_support = 3.0 / 25.0;
  EXPECT_EQ(FilterDepthMap(pair.reference, {&pair.source}, options).num_kept, 0u);
}

TEST(GeometricFilterTest, NonFiniteAndNonPositiveDepthsAreNoDepth) {
  StereoPair pair(10.0f);
  pair.source.t.setZero();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  pair.reference.depth.at(1, 1) = nan;
  pair.reference.depth.at(1, 2) = inf;
  pair.reference.depth.at(1, 3) = -10.0f;
  pair.reference.depth.at(1, 4) = 0.0f;
  pair.source.depth.at(2, 1) = nan;
  pair.source.depth.at(2, 2) = -inf;
  pair.source.depth.at(2, 3) = -10.0f;
  pair.source.depth.at(2, 4) = 0.0f;
  GeometricFilterOptions options;
  options.min_consistent_views = 1;
  const GeometricFilterResult result = FilterDepthMap(pair.reference, {&pair.source}, options);
  for (float v : result.depth.values()) EXPECT_TRUE(std::isfinite(v) && v >= 0.0f);
  for (int col = 1; col <= 4; ++col) {
    EXPECT_EQ(result.depth.at(1, col), 0.0f);
    EXPECT_EQ(result.depth.at(2, col), 0.0f);
    EXPECT_EQ(result.consistent_mask[1 * StereoPair::kWidth + col], 0u);
    EXPECT_EQ(result.consistent_mask[2 * StereoPair::kWidth + col], 0u);
  }
  EXPECT_EQ(result.num_kept, result.depth.size() - 8);
}

TEST(GeometricFilterTest, ConfidenceBelowThresholdIsNoDepthInReferenceAndSource) {
  StereoPair pair(10.0f);
  pair.source.t.setZero();
  pair.reference.confidence = colmap_io::DenseArray(StereoPair::kWidth, StereoPair::kHeight, 1, 0.9f);
  pair.source.confidence = colmap_io::DenseArray(StereoPair::kWidth, StereoPair::kHeight, 1, 0.9f);
  pair.reference.confidence.at(3, 3) = 0.4f;
  pair.reference.confidence.at(3, 4) = std::numeric_limits<float>::quiet_NaN();
  pair.source.confidence.at(5, 5) = 0.4f;
  pair.reference.confidence.at(6, 6) = 0.5f;  // exactly the threshold: kept
  GeometricFilterOptions options;
  options.min_consistent_views = 1;
  options.min_confidence = 0.5;
  const GeometricFilterResult result = FilterDepthMap(pair.reference, {&pair.source}, options);
  EXPECT_EQ(result.depth.at(3, 3), 0.0f);
  EXPECT_EQ(result.depth.at(3, 4), 0.0f);
  EXPECT_EQ(result.depth.at(5, 5), 0.0f);
  EXPECT_GT(result.depth.at(6, 6), 0.0f);
  EXPECT_EQ(result.num_kept, result.depth.size() - 3);
  options.min_confidence = 0.0;
  EXPECT_EQ(FilterDepthMap(pair.reference, {&pair.source}, options).num_kept,
            result.depth.size() - 1);  // only the NaN confidence
}

TEST(GeometricFilterTest, OptionsCheckNamesTheField) {
  auto expect_field = [](GeometricFilterOptions options, const std::string& field) {
    try {
      options.Check();
      ADD_FAILURE() << "no exception for " << field;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  GeometricFilterOptions o;
  EXPECT_NO_THROW(o.Check());
  o = {};
  o.max_reprojection_error = -1;
  expect_field(o, "max_reprojection_error");
  o = {};
  o.max_reprojection_error = std::numeric_limits<double>::quiet_NaN();
  expect_field(o, "max_reprojection_error");
  o = {};
  o.max_relative_depth_error = std::numeric_limits<double>::infinity();
  expect_field(o, "max_relative_depth_error");
  o = {};
  o.min_consistent_views = -1;
  expect_field(o, "min_consistent_views");
  o = {};
  o.min_consistent_views = kMaxSourceViews + 1;
  expect_field(o, "min_consistent_views");
  o = {};
  o.min_confidence = std::numeric_limits<double>::quiet_NaN();
  expect_field(o, "min_confidence");
  for (double support : {-0.1, 1.1, std::numeric_limits<double>::quiet_NaN()}) {
    o = {};
    o.min_support = support;
    expect_field(o, "min_support");
  }
  for (int radius : {0, kMaxSupportRadius + 1}) {
    o = {};
    o.support_radius = radius;
    expect_field(o, "support_radius");
  }
}

TEST(GeometricFilterTest, RejectsBadInputs) {
  const StereoPair pair(10.0f);
  const GeometricFilterOptions options;
  std::vector<const DepthView*> too_many(kMaxSourceViews + 1, &pair.source);
  EXPECT_THROW(FilterDepthMap(pair.reference, too_many, options), std::invalid_argument);
  std::vector<const DepthView*> all(kMaxSourceViews, &pair.source);
  EXPECT_NO_THROW(FilterDepthMap(pair.reference, all, options));
  EXPECT_THROW(FilterDepthMap(pair.reference, {nullptr}, options), std::invalid_argument);

  DepthView bad = pair.reference;
  bad.confidence = colmap_io::DenseArray(3, 3, 1, 1.0f);
  EXPECT_THROW(FilterDepthMap(bad, {&pair.source}, options), std::invalid_argument);
  bad = pair.reference;
  bad.depth = colmap_io::DenseArray();
  EXPECT_THROW(FilterDepthMap(bad, {&pair.source}, options), std::invalid_argument);
  bad = pair.reference;
  bad.K(2, 0) = 0.1;
  EXPECT_THROW(FilterDepthMap(pair.reference, {&bad}, options), std::invalid_argument);
  bad = pair.reference;
  bad.R(0, 0) = 2.0;
  EXPECT_THROW(FilterDepthMap(pair.reference, {&bad}, options), std::invalid_argument);
  bad = pair.reference;
  bad.t.x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(FilterDepthMap(bad, {&pair.source}, options), std::invalid_argument);
  GeometricFilterOptions bad_options;
  bad_options.max_relative_depth_error = -0.1;
  EXPECT_THROW(FilterDepthMap(pair.reference, {&pair.source}, bad_options), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::fusion
