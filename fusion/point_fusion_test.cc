#include "fusion/point_fusion.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "fusion/test_scene.h"

namespace dispmvs::fusion {
namespace {

using testing::Camera;
using testing::DefaultCameras;
using testing::MakeDepthView;
using testing::Scene;
using testing::Visibility;

// The two-plane scene in 4 views, every view a source of every other, with
// exact depth and normal maps and images of both supported types. The
// vis_index values are deliberately not the view order.
struct SceneViews {
  Scene scene = Scene::TwoPlanes();
  std::vector<Camera> cameras = DefaultCameras(4);
  std::vector<FusionView> views;
  const std::vector<uint32_t> vis_indices = {7, 2, 11, 5};

  SceneViews() {
    for (std::size_t i = 0; i < cameras.size(); ++i) {
      FusionView view;
      view.geometry = MakeDepthView(cameras[i], scene.RenderDepth(cameras[i]));
      view.normals = scene.RenderNormals(cameras[i]);
      view.image = scene.RenderImage(cameras[i], i % 2 == 0 ? CV_8UC3 : CV_32FC3);
      view.vis_index = vis_indices[i];
      for (std::size_t j = 0; j < cameras.size(); ++j) {
        if (j != i) view.source_views.push_back(static_cast<int>(j));
      }
      views.push_back(std::move(view));
    }
  }

  GeometricFilterResult Filter(std::size_t v, const GeometricFilterOptions& options) const {
    std::vector<const DepthView*> sources;
    for (int s : views[v].source_views) sources.push_back(&views[s].geometry);
    return FilterDepthMap(views[v].geometry, sources, options);
  }
};

// Multiplies every `col_step`-th pixel of every `row_step`-th row of a
// one-channel map by `factor`.
void DenseArrayFloatScale(colmap_io::DenseArray* map, int row_step, int col_step, float factor) {
  for (int row = 0; row < map->height(); row += row_step) {
    for (int col = 0; col < map->width(); col += col_step) map->at(row, col) *= factor;
  }
}

// The plane a point lies on, by distance relative to its distance from the
// first camera; -1 if none is within `tolerance`.
int PlaneOf(const Scene& scene, const Eigen::Vector3d& x, double tolerance) {
  for (std::size_t i = 0; i < scene.planes().size(); ++i) {
    const testing::Plane& plane = scene.planes()[i];
    const double slack = tolerance * x.norm();
    if (std::abs(plane.SignedDistance(x)) <= slack && x.x() >= plane.x_min - slack &&
        x.x() <= plane.x_max + slack && x.y() >= plane.y_min - slack && x.y() <= plane.y_max + slack) {
      return static_cast<int>(i);
    }
  }
  return -1;
}

TEST(PointFusionTest, PointsLieOnTheSurfaceWithItsNormalAndColour) {
  const SceneViews s;
  const std::vector<FusedPoint> points = FusePoints(s.views, GeometricFilterOptions());
  ASSERT_GT(points.size(), 3000u);
  for (const FusedPoint& point : points) {
    const Eigen::Vector3d x = point.xyz.cast<double>();
    const int plane = PlaneOf(s.scene, x, 1e-4);
    ASSERT_GE(plane, 0) << "point off the surface: " << x.transpose();
    const testing::Plane& truth = s.scene.planes()[plane];
    // All cameras are on the same side, so every view orients the normal the same way.
    EXPECT_LT((point.normal.cast<double>() - truth.normal).norm(), 1e-5) << x.transpose();
    EXPECT_EQ(point.rgb, truth.rgb) << x.transpose();
  }
}

TEST(PointFusionTest, VisibilityListsTheViewsThatSeeThePoint) {
  const SceneViews s;
  const std::vector<FusedPoint> points = FusePoints(s.views, GeometricFilterOptions());
  int num_checked = 0;
  for (const FusedPoint& point : points) {
    ASSERT_TRUE(std::is_sorted(point.visibility.begin(), point.visibility.end()));
    ASSERT_EQ(std::adjacent_find(point.visibility.begin(), point.visibility.end()),
              point.visibility.end());
    // The reference and at least min_consistent_views = 2 sources.
    EXPECT_GE(point.visibility.size(), 3u);
    const Eigen::Vector3d x = point.xyz.cast<double>();
    const int plane = PlaneOf(s.scene, x, 1e-4);
    ASSERT_GE(plane, 0);
    for (std::size_t v = 0; v < s.cameras.size(); ++v) {
      const bool listed = std::binary_search(point.visibility.begin(), point.visibility.end(),
                                             s.vis_indices[v]);
      switch (s.scene.Classify(s.cameras[v], x, plane)) {
        case Visibility::kVisible:
          EXPECT_TRUE(listed) << "view " << v << " sees " << x.transpose();
          ++num_checked;
          break;
        case Visibility::kHidden:
          EXPECT_FALSE(listed) << "view " << v << " does not see " << x.transpose();
          ++num_checked;
          break;
        case Visibility::kUndecided:
          break;
      }
    }
  }
  EXPECT_GT(num_checked, static_cast<int>(3 * points.size()));
}

TEST(PointFusionTest, ConsumedPixelsAreNotEmittedAgain) {
  const SceneViews s;
  const GeometricFilterOptions options;
  FusionStats stats;
  const std::vector<FusedPoint> points = FusePoints(s.views, options, &stats);
  ASSERT_EQ(stats.points_per_view.size(), 4u);
  std::size_t total = 0;
  for (std::size_t n : stats.points_per_view) total += n;
  EXPECT_EQ(total, points.size());
  // The first reference consumes nothing earlier: one point per pixel that
  // passes the filter.
  EXPECT_EQ(stats.points_per_view[0], s.Filter(0, options).num_kept);
  // The later ones see surface the first reference already fused: they only
  // add the few pixels that no rounded projection hit, and the parts of the
  // surface the first view does not see.
  std::size_t later_kept = 0, later_points = 0, later_consumed = 0;
  for (std::size_t v = 1; v < 4; ++v) {
    later_kept += s.Filter(v, options).num_kept;
    later_points += stats.points_per_view[v];
    later_consumed += stats.consumed_pixels_per_view[v];
  }
  EXPECT_LT(later_points, later_kept / 10) << "consumed pixels emitted again?";
  EXPECT_GT(later_consumed, later_kept / 2);
}

// Views with identical geometry: every pixel maps onto itself, so the first
// view consumes the others entirely and each point is exactly one pixel.
std::vector<FusionView> IdenticalViews(int count) {
  const Scene scene = Scene::TwoPlanes();
  const Camera camera = DefaultCameras(1)[0];
  std::vector<FusionView> views(count);
  const std::vector<uint32_t> vis_indices = {9, 2, 5, 4};
  for (int i = 0; i < count; ++i) {
    views[i].geometry = MakeDepthView(camera, scene.RenderDepth(camera));
    views[i].vis_index = vis_indices[i];
    for (int j = 0; j < count; ++j) {
      if (j != i) views[i].source_views.push_back(j);
    }
  }
  return views;
}

TEST(PointFusionTest, IdenticalViewsGiveOnePointPerPixel) {
  const std::vector<FusionView> views = IdenticalViews(3);
  FusionStats stats;
  const std::vector<FusedPoint> points = FusePoints(views, GeometricFilterOptions(), &stats);
  const std::size_t num_pixels = views[0].geometry.depth.size();
  ASSERT_EQ(points.size(), num_pixels);
  EXPECT_EQ(stats.points_per_view, (std::vector<std::size_t>{num_pixels, 0, 0}));
  EXPECT_EQ(stats.consumed_pixels_per_view, (std::vector<std::size_t>{0, num_pixels, num_pixels}));
  const testing::Camera camera = DefaultCameras(1)[0];
  const Eigen::Matrix3d K_inv = camera.K.inverse();
  const int width = views[0].geometry.depth.width();
  for (std::size_t i = 0; i < points.size(); ++i) {
    // Row-major order, each point exactly its pixel's back-projection.
    const int row = static_cast<int>(i) / width, col = static_cast<int>(i) % width;
    const Eigen::Vector3d x = camera.R.transpose() *
        (views[0].geometry.depth.at(row, col) * (K_inv * Eigen::Vector3d(col, row, 1)) - camera.t);
    EXPECT_LT((points[i].xyz.cast<double>() - x).norm(), 1e-5 * x.norm());
    EXPECT_EQ(points[i].visibility, (std::vector<uint32_t>{2, 5, 9}));
    // No normal maps, no images.
    EXPECT_EQ(points[i].normal, Eigen::Vector3f::Zero());
    EXPECT_EQ(points[i].rgb, (std::array<uint8_t, 3>{0, 0, 0}));
  }
}

// A fronto-parallel plane seen by two cameras 1 apart along x: the disparity
// fx * 1 / depth is exactly 4 pixels, so reference pixel col maps onto source
// pixel col - 4 and back without rounding.
struct IntegerDisparityPair {
  static constexpr int kWidth = 24, kHeight = 10;
  std::vector<FusionView> views = std::vector<FusionView>(2);

  IntegerDisparityPair() {
    Eigen::Matrix3d K;
    K << 40.0, 0, 11.5, 0, 40.0, 4.5, 0, 0, 1;
    for (int i = 0; i < 2; ++i) {
      views[i].geometry.K = K;
      views[i].geometry.depth = colmap_io::DenseArray(kWidth, kHeight, 1, 10.0f);
      views[i].vis_index = static_cast<uint32_t>(3 + i);
      views[i].source_views = {1 - i};
    }
    views[1].geometry.t = Eigen::Vector3d(-1.0, 0, 0);
  }
};

TEST(PointFusionTest, IntegerDisparityConsumesExactlyTheMatchedPixels) {
  IntegerDisparityPair pair;
  pair.views[0].normals = colmap_io::DenseArray(IntegerDisparityPair::kWidth, IntegerDisparityPair::kHeight, 3, 0.0f);
  pair.views[1].normals = pair.views[0].normals;
  for (int row = 0; row < IntegerDisparityPair::kHeight; ++row) {
    for (int col = 0; col < IntegerDisparityPair::kWidth; ++col) {
      pair.views[0].normals.at(row, col, 2) = -1.0f;
      pair.views[1].normals.at(row, col, 0) = 0.6f;
      pair.views[1].normals.at(row, col, 2) = -0.8f;
    }
  }
  pair.views[0].image = cv::Mat(IntegerDisparityPair::kHeight, IntegerDisparityPair::kWidth, CV_8UC3,
                                cv::Scalar(100, 0, 50));
  pair.views[1].image = cv::Mat(IntegerDisparityPair::kHeight, IntegerDisparityPair::kWidth, CV_32FC3,
                                cv::Scalar(200 / 255.0, 254 / 255.0, 52 / 255.0));
  GeometricFilterOptions options;
  options.min_consistent_views = 1;
  FusionStats stats;
  const std::vector<FusedPoint> points = FusePoints(pair.views, options, &stats);
  // Columns 0..3 of view 0 and 20..23 of view 1 have no partner.
  const std::size_t matched = (IntegerDisparityPair::kWidth - 4) * IntegerDisparityPair::kHeight;
  ASSERT_EQ(points.size(), matched);
  EXPECT_EQ(stats.points_per_view, (std::vector<std::size_t>{matched, 0}));
  EXPECT_EQ(stats.consumed_pixels_per_view, (std::vector<std::size_t>{0, matched}));
  const Eigen::Vector3f expected_normal = Eigen::Vector3f(0.6f, 0.0f, -1.8f).normalized();
  for (const FusedPoint& point : points) {
    EXPECT_NEAR(point.xyz.z(), 10.0f, 1e-5f);
    EXPECT_EQ(point.visibility, (std::vector<uint32_t>{3, 4}));
    EXPECT_LT((point.normal - expected_normal).norm(), 1e-6f);
    EXPECT_EQ(point.rgb, (std::array<uint8_t, 3>{150, 127, 51}));
  }
  // Reference pixel (row 0, col 4) is at world x = 10 * (4 - 11.5) / 40.
  EXPECT_NEAR(points[0].xyz.x(), 10.0f * (4 - 11.5f) / 40.0f, 1e-5f);
}

TEST(PointFusionTest, MissingNormalsAndColoursComeFromTheOtherViews) {
  IntegerDisparityPair pair;
  pair.views[1].normals = colmap_io::DenseArray(IntegerDisparityPair::kWidth, IntegerDisparityPair::kHeight, 3, 0.0f);
  for (int row = 0; row < IntegerDisparityPair::kHeight; ++row) {
    for (int col = 0; col < IntegerDisparityPair::kWidth; ++col) pair.views[1].normals.at(row, col, 2) = -1.0f;
  }
  pair.views[1].image = cv::Mat(IntegerDisparityPair::kHeight, IntegerDisparityPair::kWidth, CV_8UC3,
                                cv::Scalar(10, 20, 30));
  GeometricFilterOptions options;
  options.min_consistent_views = 1;
  const std::vector<FusedPoint> points = FusePoints(pair.views, options);
  ASSERT_FALSE(points.empty());
  for (const FusedPoint& point : points) {
    EXPECT_EQ(point.normal, Eigen::Vector3f(0, 0, -1));
    EXPECT_EQ(point.rgb, (std::array<uint8_t, 3>{10, 20, 30}));
  }
}

TEST(PointFusionTest, TooFewAgreeingSourcesGiveNoPoints) {
  const std::vector<FusionView> views = IdenticalViews(2);
  GeometricFilterOptions options;  // 2 needed, each view has 1 source
  EXPECT_TRUE(FusePoints(views, options).empty());
  EXPECT_TRUE(FusePoints({}, options).empty());
}

// A view's own requirement replaces the options' for that reference only:
// the stereo-pair case, where each view has one source and the default asks
// for two.
TEST(PointFusionTest, PerViewMinimumOverridesTheOptions) {
  std::vector<FusionView> views = IdenticalViews(2);
  const std::size_t num_pixels = views[0].geometry.depth.size();
  const GeometricFilterOptions options;  // 2 needed
  views[1].min_consistent_views = 1;
  FusionStats stats;
  EXPECT_EQ(FusePoints(views, options, &stats).size(), num_pixels);
  EXPECT_EQ(stats.points_per_view, (std::vector<std::size_t>{0, num_pixels}));
  views[0].min_consistent_views = 1;
  EXPECT_EQ(FusePoints(views, options, &stats).size(), num_pixels);
  EXPECT_EQ(stats.points_per_view, (std::vector<std::size_t>{num_pixels, 0}));
  // And upwards: 0 views needed by default, 2 (more than it has) for view 0.
  GeometricFilterOptions keep_all;
  keep_all.min_consistent_views = 0;
  views[0].min_consistent_views = 2;
  views[1].min_consistent_views = -1;
  EXPECT_EQ(FusePoints(views, keep_all, &stats).size(), num_pixels);
  EXPECT_EQ(stats.points_per_view, (std::vector<std::size_t>{0, num_pixels}));
}

// With the support rule a point starts only where the geometric filter keeps
// the pixel: the first reference (nothing consumed yet) gives exactly the
// filter's kept pixels, with and without the rule, and the rule drops the
// scattered pixels that agree by accident.
TEST(PointFusionTest, SupportRuleStartsPointsWhereTheFilterKeeps) {
  SceneViews s;
  // Every third pixel of every fifth row of view 0 off by 5 %: they agree
  // with no source, and a 5x5 window holding two of them lacks 95 % support.
  DenseArrayFloatScale(&s.views[0].geometry.depth, 5, 3, 1.05f);
  GeometricFilterOptions rule;
  rule.min_consistent_views = 1;
  for (double support : {0.0, 0.95}) {
    rule.min_support = support;
    FusionStats stats;
    FusePoints(s.views, rule, &stats);
    const GeometricFilterResult kept = s.Filter(0, rule);
    EXPECT_EQ(stats.points_per_view[0], kept.num_kept) << "support " << support;
  }
  GeometricFilterOptions without = rule, with = rule;
  without.min_support = 0.0;
  with.min_support = 0.95;
  EXPECT_LT(s.Filter(0, with).num_kept + 1000, s.Filter(0, without).num_kept);
}

TEST(PointFusionTest, RejectsBadViews) {
  const GeometricFilterOptions options;
  std::vector<FusionView> views = IdenticalViews(3);
  views[0].source_views = {0, 1};
  EXPECT_THROW(FusePoints(views, options), std::invalid_argument);
  views[0].source_views = {1, 3};
  EXPECT_THROW(FusePoints(views, options), std::invalid_argument);
  views[0].source_views = {1, -1};
  EXPECT_THROW(FusePoints(views, options), std::invalid_argument);
  views[0].source_views = {1, 2, 1};
  EXPECT_THROW(FusePoints(views, options), std::invalid_argument);
  views[0].source_views = std::vector<int>(kMaxSourceViews + 1, 1);
  EXPECT_THROW(FusePoints(views, options), std::invalid_argument);

  views = IdenticalViews(3);
  const int width = views[1].geometry.depth.width(), height = views[1].geometry.depth.height();
  views[1].normals = colmap_io::DenseArray(width, height, 1, 0.0f);
  EXPECT_THROW(FusePoints(views, options), std::invalid_argument);
  views[1].normals = colmap_io::DenseArray(width + 1, height, 3, 0.0f);
  EXPECT_THROW(FusePoints(views, options), std::invalid_argument);
  views[1].normals = colmap_io::DenseArray();
  views[1].image = cv::Mat(height, width, CV_8UC1, cv::Scalar(0));
  EXPECT_THROW(FusePoints(views, options), std::invalid_argument);
  views[1].image = cv::Mat(height, width - 1, CV_8UC3, cv::Scalar::all(0));
  EXPECT_THROW(FusePoints(views, options), std::invalid_argument);
  views[1].image = cv::Mat();
  views[1].geometry.K(2, 2) = 0.5;
  EXPECT_THROW(FusePoints(views, options), std::invalid_argument);
  views[1].geometry.K(2, 2) = 1.0;
  GeometricFilterOptions bad_options;
  bad_options.min_consistent_views = -1;
  EXPECT_THROW(FusePoints(views, bad_options), std::invalid_argument);
  for (int bad : {-2, kMaxSourceViews + 1}) {
    views[2].min_consistent_views = bad;
    EXPECT_THROW(FusePoints(views, options), std::invalid_argument);
  }
  views[2].min_consistent_views = -1;
  EXPECT_NO_THROW(FusePoints(views, options));
}

// COLMAP's options beyond the consistency rule (FusionOptions).

TEST(FusionOptionsTest, NormalTestDropsASourceWhoseNormalsDisagree) {
  SceneViews s;
  FusionOptions options;
  options.max_normal_error = 10;
  const std::vector<FusedPoint> exact_normals = FusePoints(s.views, options);
  const std::vector<FusedPoint> no_test = FusePoints(s.views, GeometricFilterOptions());
  // Exact normals agree: only pixels matched across the planes' edge differ.
  EXPECT_NEAR(static_cast<double>(exact_normals.size()), static_cast<double>(no_test.size()),
              0.01 * static_cast<double>(no_test.size()));
  // Turn view 3's normals 30 degrees about its camera's x axis: with a 10
  // degree test it agrees with no other view, so no point lists it; without
  // the test, thousands do.
  const Eigen::Matrix3d turn =
      Eigen::AngleAxisd(30.0 * M_PI / 180.0, Eigen::Vector3d::UnitX()).toRotationMatrix();
  colmap_io::DenseArray& normals = s.views[3].normals;
  const std::size_t plane = static_cast<std::size_t>(normals.width()) * normals.height();
  for (std::size_t i = 0; i < plane; ++i) {
    float* n = normals.data();
    const Eigen::Vector3d turned = turn * Eigen::Vector3d(n[i], n[plane + i], n[2 * plane + i]);
    for (int c = 0; c < 3; ++c) n[c * plane + i] = static_cast<float>(turned[c]);
  }
  auto listing_view_3 = [&](const std::vector<FusedPoint>& points) {
    return std::count_if(points.begin(), points.end(), [&](const FusedPoint& point) {
      return std::binary_search(point.visibility.begin(), point.visibility.end(), s.vis_indices[3]);
    });
  };
  EXPECT_EQ(listing_view_3(FusePoints(s.views, options)), 0);
  EXPECT_GT(listing_view_3(FusePoints(s.views, GeometricFilterOptions())), 1000);
  options.max_normal_error = 35;  // wider than the turn: it agrees again
  EXPECT_GT(listing_view_3(FusePoints(s.views, options)), 1000);
}

TEST(FusionOptionsTest, MaxPixelsTraversalDepthAndSourcesChecked) {
  const SceneViews s;
  const std::vector<FusedPoint> plain = FusePoints(s.views, GeometricFilterOptions());

  // At most 3 pixels per point (reference + 2 sources): fewer pixels are
  // consumed per point, so there are more points.
  FusionOptions options;
  options.max_num_pixels = 3;
  const std::vector<FusedPoint> capped = FusePoints(s.views, options);
  for (const FusedPoint& point : capped) ASSERT_LE(point.visibility.size(), 3u);
  EXPECT_GT(capped.size(), plain.size());

  // Traversal depth 1: every point is its reference pixel alone, exactly on
  // the surface; agreement is still required.
  options = FusionOptions();
  options.max_traversal_depth = 1;
  const std::vector<FusedPoint> single = FusePoints(s.views, options);
  ASSERT_GT(single.size(), plain.size());
  for (const FusedPoint& point : single) {
    ASSERT_EQ(point.visibility.size(), 1u);
    ASSERT_GE(PlaneOf(s.scene, point.xyz.cast<double>(), 1e-5), 0);
  }
  options.consistency.min_consistent_views = 4;  // more than the 3 sources
  options.max_num_pixels = 5;
  EXPECT_TRUE(FusePoints(s.views, options).empty());

  // Each reference checks only its first 2 sources: view 0's points list
  // views 0, 1 and 2 at most.
  options = FusionOptions();
  options.check_num_images = 2;
  FusionStats stats;
  const std::vector<FusedPoint> first_two = FusePoints(s.views, options, &stats);
  ASSERT_GT(stats.points_per_view[0], 1000u);
  for (std::size_t i = 0; i < stats.points_per_view[0]; ++i) {
    for (uint32_t index : first_two[i].visibility) {
      ASSERT_NE(index, s.vis_indices[3]);
    }
  }
}

TEST(FusionOptionsTest, BoundingBoxLeavesOutPixelsOutside) {
  const SceneViews s;
  const std::vector<FusedPoint> plain = FusePoints(s.views, GeometricFilterOptions());
  Eigen::Vector3d low = Eigen::Vector3d::Constant(1e9), high = -low;
  for (const FusedPoint& point : plain) {
    low = low.cwiseMin(point.xyz.cast<double>());
    high = high.cwiseMax(point.xyz.cast<double>());
  }
  FusionOptions options;
  options.bounding_box = BoundingBox{low, Eigen::Vector3d((low.x() + high.x()) / 2, high.y(), high.z())};
  const std::vector<FusedPoint> boxed = FusePoints(s.views, options);
  ASSERT_GT(boxed.size(), plain.size() / 5);
  ASSERT_LT(boxed.size(), plain.size() * 4 / 5);
  for (const FusedPoint& point : boxed) {
    ASSERT_LE(point.xyz.x(), options.bounding_box->max.x() + 1e-5);
    ASSERT_GE(PlaneOf(s.scene, point.xyz.cast<double>(), 1e-4), 0);
  }
}

TEST(FusionOptionsTest, CheckNamesTheBadField) {
  const std::vector<FusionView> views = IdenticalViews(3);
  auto expect_refused = [&](const FusionOptions& options, const std::string& field) {
    try {
      FusePoints(views, options);
      ADD_FAILURE() << field << " accepted";
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find(field), std::string::npos) << error.what();
    }
  };
  FusionOptions options;
  options.max_normal_error = 181;
  expect_refused(options, "max_normal_error");
  options = FusionOptions();
  options.max_num_pixels = 2;  // below min_consistent_views (2) + 1
  expect_refused(options, "max_num_pixels");
  options = FusionOptions();
  options.max_traversal_depth = 0;
  expect_refused(options, "max_traversal_depth");
  options = FusionOptions();
  options.check_num_images = 0;
  expect_refused(options, "check_num_images");
  options = FusionOptions();
  options.bounding_box = BoundingBox{Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1, 1, 0)};
  expect_refused(options, "bounding_box");
}

}  // namespace
}  // namespace dispmvs::fusion
