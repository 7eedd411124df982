#include "colmap_io/view_selection.h"

#include <cmath>
#include <map>
#include <stdexcept>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "tests/support/model_builder.h"

namespace dispmvs::colmap_io {
namespace {

using testing::ModelBuilder;

constexpr double kPi = 3.14159265358979323846;
double Radians(double degrees) { return degrees * kPi / 180.0; }

// Reference at (0, 0, -10) looking at the origin; views on a circle of radius
// 10 around the origin in the x-z plane, so a point AT the origin is seen
// from the reference and from a view at angle theta under exactly theta.
struct CircleScene {
  ModelBuilder builder;
  camera_t camera = builder.AddPinholeCamera(320, 240, 300, 300, 160, 120);
  image_t reference = builder.AddImageLookingAt(camera, "ref.png", {0, 0, -10}, {0, 0, 0});

  image_t AddViewAt(double theta_deg, const std::string& name) {
    const double t = Radians(theta_deg);
    return builder.AddImageLookingAt(camera, name, {10 * std::sin(t), 0, -10 * std::cos(t)},
                                     {0, 0, 0});
  }
  // `count` points near the origin seen by the reference and `others`.
  void AddSharedPoints(int count, const std::vector<image_t>& others) {
    std::vector<image_t> observers = {reference};
    observers.insert(observers.end(), others.begin(), others.end());
    for (int i = 0; i < count; ++i) {
      builder.AddPoint({0.05 * (i % 7) - 0.15, 0.04 * (i % 5) - 0.1, 0.03 * (i % 3)}, observers);
    }
  }
};

TEST(ViewSelectionTest, OrdersBySharedPointsNotById) {
  CircleScene scene;
  const image_t ten = scene.AddViewAt(10, "ten.png");       // id 2
  const image_t thirty = scene.AddViewAt(-15, "thirty.png");  // id 3
  const image_t twenty = scene.AddViewAt(20, "twenty.png");   // id 4
  scene.AddSharedPoints(10, {ten, thirty, twenty});
  scene.AddSharedPoints(10, {thirty, twenty});
  scene.AddSharedPoints(10, {thirty});

  const auto ranked = RankSourceViews(scene.builder.model(), scene.reference);
  ASSERT_EQ(ranked.size(), 3u);
  EXPECT_EQ(ranked[0].image_id, thirty);
  EXPECT_EQ(ranked[0].num_shared_points, 30u);
  EXPECT_EQ(ranked[1].image_id, twenty);
  EXPECT_EQ(ranked[1].num_shared_points, 20u);
  EXPECT_EQ(ranked[2].image_id, ten);
  EXPECT_EQ(ranked[2].num_shared_points, 10u);

  EXPECT_EQ(SelectSourceViews(scene.builder.model(), scene.reference, 2),
            (std::vector<image_t>{thirty, twenty}));
  // Asking for more than exist returns all of them; asking for none, none.
  EXPECT_EQ(SelectSourceViews(scene.builder.model(), scene.reference, 10),
            (std::vector<image_t>{thirty, twenty, ten}));
  EXPECT_TRUE(SelectSourceViews(scene.builder.model(), scene.reference, 0).empty());
}

TEST(ViewSelectionTest, TiesAreBrokenByAscendingImageId) {
  CircleScene scene;
  const image_t a = scene.AddViewAt(10, "a.png");
  const image_t b = scene.AddViewAt(-10, "b.png");
  const image_t c = scene.AddViewAt(20, "c.png");
  scene.AddSharedPoints(5, {c, b});
  scene.AddSharedPoints(5, {a});
  scene.AddSharedPoints(3, {c, b});
  scene.AddSharedPoints(3, {a});
  EXPECT_EQ(SelectSourceViews(scene.builder.model(), scene.reference, 3),
            (std::vector<image_t>{a, b, c}));
}

TEST(ViewSelectionTest, ZeroBaselineViewIsExcludedHoweverManyPointsItShares) {
  CircleScene scene;
  const image_t good = scene.AddViewAt(15, "good.png");
  // Same centre as the reference, looking slightly elsewhere: every
  // triangulation angle is 0.
  const image_t rotated_only =
      scene.builder.AddImageLookingAt(scene.camera, "rotated.png", {0, 0, -10}, {0.5, 0.2, 0});
  scene.AddSharedPoints(40, {rotated_only});
  scene.AddSharedPoints(5, {good});
  const auto ranked = RankSourceViews(scene.builder.model(), scene.reference);
  ASSERT_EQ(ranked.size(), 1u);
  EXPECT_EQ(ranked[0].image_id, good);

  ViewSelectionOptions no_minimum;
  no_minimum.min_triangulation_angle_deg = 0.0;  // angle 0 >= 0 passes
  const auto all = RankSourceViews(scene.builder.model(), scene.reference, no_minimum);
  ASSERT_EQ(all.size(), 2u);
  EXPECT_EQ(all[0].image_id, rotated_only);
  EXPECT_NEAR(all[0].triangulation_angle_deg, 0.0, 1e-9);  // centres equal up to rounding
}

TEST(ViewSelectionTest, AngleOfPointsAtTheCircleCentreIsTheViewAngle) {
  CircleScene scene;
  const image_t view = scene.AddViewAt(30, "v.png");
  for (int i = 0; i < 4; ++i) scene.builder.AddPoint({0, 0, 0}, {scene.reference, view});
  const auto ranked = RankSourceViews(scene.builder.model(), scene.reference);
  ASSERT_EQ(ranked.size(), 1u);
  EXPECT_NEAR(ranked[0].triangulation_angle_deg, 30.0, 1e-9);

  ViewSelectionOptions options;
  options.min_triangulation_angle_deg = 30.5;
  EXPECT_TRUE(RankSourceViews(scene.builder.model(), scene.reference, options).empty());
  options.min_triangulation_angle_deg = 29.5;
  EXPECT_EQ(RankSourceViews(scene.builder.model(), scene.reference, options).size(), 1u);
}

TEST(ViewSelectionTest, ObtuseAnglesAreFoldedToTheAcuteSide) {
  CircleScene scene;
  // A view at 150 degrees sees the origin under 150 degrees; COLMAP folds it
  // to 180 - 150 = 30.
  const image_t view = scene.AddViewAt(150, "behind.png");
  scene.builder.AddPoint({0, 0, 0}, {scene.reference, view});
  const auto ranked = RankSourceViews(scene.builder.model(), scene.reference);
  ASSERT_EQ(ranked.size(), 1u);
  EXPECT_NEAR(ranked[0].triangulation_angle_deg, 30.0, 1e-9);
}

TEST(ViewSelectionTest, PairAngleIsTheRequestedPercentileOfPointAngles) {
  ModelBuilder builder;
  const camera_t camera = builder.AddPinholeCamera(320, 240, 300, 300, 160, 120);
  const image_t reference = builder.AddImageLookingAt(camera, "ref.png", {0, 0, -10}, {0, 0, 0});
  const image_t view = builder.AddImageLookingAt(camera, "v.png", {1, 0, -10}, {1, 0, 0});
  // A point on the reference's axis at distance s is seen under atan(1 / s):
  // place points under 8, 2, 6, 4 degrees (unsorted on purpose).
  for (const double degrees : {8.0, 2.0, 6.0, 4.0}) {
    builder.AddPoint({0, 0, -10 + 1.0 / std::tan(Radians(degrees))}, {reference, view});
  }
  const auto angle_at = [&](double percentile) {
    ViewSelectionOptions options;
    options.min_triangulation_angle_deg = 0.0;
    options.triangulation_angle_percentile = percentile;
    const auto ranked = RankSourceViews(builder.model(), reference, options);
    EXPECT_EQ(ranked.size(), 1u);
    return ranked.empty() ? -1.0 : ranked[0].triangulation_angle_deg;
  };
  // Index round(p / 100 * 3) into {2, 4, 6, 8}.
  EXPECT_NEAR(angle_at(75.0), 6.0, 1e-9);  // round(2.25) = 2
  EXPECT_NEAR(angle_at(0.0), 2.0, 1e-9);
  EXPECT_NEAR(angle_at(40.0), 4.0, 1e-9);  // round(1.2) = 1
  EXPECT_NEAR(angle_at(100.0), 8.0, 1e-9);

  ViewSelectionOptions options;  // default: 75th percentile = 6 degrees
  options.min_triangulation_angle_deg = 7.0;
  EXPECT_TRUE(SelectSourceViews(builder.model(), reference, 4, options).empty());
  options.min_triangulation_angle_deg = 5.0;
  EXPECT_EQ(SelectSourceViews(builder.model(), reference, 4, options),
            (std::vector<image_t>{view}));
}

TEST(ViewSelectionTest, RepeatedObservationCountsOnce) {
  CircleScene scene;
  const image_t view = scene.AddViewAt(20, "v.png");
  scene.builder.AddPoint({0, 0, 0}, {scene.reference, scene.reference, view, view});
  const auto ranked = RankSourceViews(scene.builder.model(), scene.reference);
  ASSERT_EQ(ranked.size(), 1u);
  EXPECT_EQ(ranked[0].num_shared_points, 1u);
}

TEST(ViewSelectionTest, ImageWithoutPointsGetsNoSources) {
  CircleScene scene;
  const image_t view = scene.AddViewAt(20, "v.png");
  const image_t lonely = scene.AddViewAt(-20, "lonely.png");
  scene.AddSharedPoints(10, {view});
  scene.builder.AddUnmatchedObservation(lonely, {3, 4});
  EXPECT_TRUE(SelectSourceViews(scene.builder.model(), lonely, 4).empty());
}

TEST(ViewSelectionTest, BadArgumentsThrow) {
  CircleScene scene;
  EXPECT_THROW(RankSourceViews(scene.builder.model(), 42), std::invalid_argument);
  ViewSelectionOptions options;
  options.min_triangulation_angle_deg = -1.0;
  EXPECT_THROW(options.Check(), std::invalid_argument);
  EXPECT_THROW(SelectSourceViews(scene.builder.model(), scene.reference, 1, options),
               std::invalid_argument);
  options = {};
  options.triangulation_angle_percentile = 101.0;
  EXPECT_THROW(options.Check(), std::invalid_argument);
  options.triangulation_angle_percentile = std::nan("");
  EXPECT_THROW(options.Check(), std::invalid_argument);
}

// ---- From the poses alone ----

// A camera at (x, 0, 0) with an identity rotation: looking along +z, image
// 100 x 100 with f = 100 and the principal point in the middle, so a point
// (X, Y, Z) is inside its image iff |X - x| <= Z / 2 and |Y| <= Z / 2.
struct RowScene {
  ModelBuilder builder;
  camera_t camera = builder.AddPinholeCamera(100, 100, 100, 100, 50, 50);
  image_t AddForward(double x, const std::string& name) {
    return builder.AddImageWithPose(camera, name, Eigen::Matrix3d::Identity(),
                                    Eigen::Vector3d(-x, 0, 0));
  }
  // Looking along +z turned by `degrees` about the y axis, centre at (x, 0, 0).
  image_t AddTurned(double x, double degrees, const std::string& name) {
    const Eigen::Matrix3d R =
        Eigen::AngleAxisd(Radians(degrees), Eigen::Vector3d::UnitY()).toRotationMatrix();
    return builder.AddImageWithPose(camera, name, R, -R * Eigen::Vector3d(x, 0, 0));
  }
};

TEST(PoseViewSelectionTest, RowOfForwardCamerasRanksNearestFirstAndDropsUselessViews) {
  RowScene scene;
  const image_t reference = scene.AddForward(0, "ref.png");
  const image_t far = scene.AddForward(7, "far.png");
  const image_t near = scene.AddForward(1, "near.png");
  const image_t second = scene.AddForward(-2, "second.png");
  const image_t third = scene.AddForward(4, "third.png");
  // Same centre, turned 5 degrees: sees most samples, but every
  // triangulation angle is 0.
  const image_t same_centre = scene.AddTurned(0, 5, "same_centre.png");
  // Beside the reference but looking back along -z: every sample (z >= 2)
  // is behind it.
  const image_t away = scene.AddTurned(0.5, 180, "away.png");

  // Reference samples: X = u Z with u in {+-1/16, +-3/16, +-5/16, +-7/16}
  // (the 8 columns), Z in [2, 100]. A view at x sees the ones with
  // |u - x / Z| <= 1/2: for every depth, a window of width 1 over the u grid
  // shifted by x / Z, which holds fewer grid values the larger |x| is (at
  // Z = 2: 8 for x = 0, 4 for |x| = 1, none for |x| >= 2). So the counts
  // fall strictly with the distance. The smallest angle of interest, x = 1
  // at Z = 100, is still 0.57 degrees, and the 75th percentile is far above
  // the 1 degree minimum.
  const auto ranked = RankSourceViewsByPose(scene.builder.model(), reference, 2, 100);
  ASSERT_EQ(ranked.size(), 4u);
  EXPECT_EQ(ranked[0].image_id, near);
  EXPECT_EQ(ranked[1].image_id, second);
  EXPECT_EQ(ranked[2].image_id, third);
  EXPECT_EQ(ranked[3].image_id, far);
  EXPECT_GT(ranked[0].num_shared_samples, ranked[1].num_shared_samples);
  EXPECT_GT(ranked[1].num_shared_samples, ranked[2].num_shared_samples);
  EXPECT_GT(ranked[2].num_shared_samples, ranked[3].num_shared_samples);
  for (const auto& candidate : ranked) {
    EXPECT_GE(candidate.triangulation_angle_deg, 1.0);
    EXPECT_NEAR(candidate.viewing_angle_deg, 0.0, 1e-9);
  }
  EXPECT_EQ(SelectSourceViewsByPose(scene.builder.model(), reference, 2, 2, 100),
            (std::vector<image_t>{near, second}));

  // Without the angle minimum the same-centre view is in (angle ~0), which
  // shows the minimum is what kept it out; the view looking away is never in.
  ViewSelectionOptions options;
  options.min_triangulation_angle_deg = 0;
  options.max_viewing_angle_deg = 180;
  const auto all = RankSourceViewsByPose(scene.builder.model(), reference, 2, 100, options);
  ASSERT_EQ(all.size(), 5u);
  for (const auto& candidate : all) {
    EXPECT_NE(candidate.image_id, away);
    if (candidate.image_id == same_centre) {
      EXPECT_NEAR(candidate.triangulation_angle_deg, 0.0, 1e-6);
    }
  }
}

TEST(PoseViewSelectionTest, ViewingAngleLimitExcludesTurnedViews) {
  RowScene scene;
  const image_t reference = scene.AddForward(0, "ref.png");
  // At x = 2, turned 30 degrees towards the reference's axis (the world-to-
  // camera rotation Ry(30) makes the optical axis, its third row,
  // (-sin 30, 0, cos 30)): it sees the frustum well.
  const image_t turned = scene.AddTurned(2, 30, "turned.png");
  const auto ranked = RankSourceViewsByPose(scene.builder.model(), reference, 2, 100);
  ASSERT_EQ(ranked.size(), 1u);
  EXPECT_EQ(ranked[0].image_id, turned);
  EXPECT_NEAR(ranked[0].viewing_angle_deg, 30.0, 1e-9);
  ViewSelectionOptions options;
  options.max_viewing_angle_deg = 29;
  EXPECT_TRUE(RankSourceViewsByPose(scene.builder.model(), reference, 2, 100, options).empty());
}

TEST(PoseViewSelectionTest, SampleDepthsDecideWhatTheFrustaShare) {
  RowScene scene;
  const image_t reference = scene.AddForward(0, "ref.png");
  const image_t side = scene.AddForward(3, "side.png");
  // All samples at Z = 2: the view at x = 3 needs |u - 1.5| <= 0.5, no u of
  // the grid reaches 1, so it shares nothing.
  EXPECT_TRUE(RankSourceViewsByPose(scene.builder.model(), reference, 2, 2).empty());
  // At Z = 20 it sees u >= 0.15 - 0.5, i.e. all but the column at -7/16.
  const auto ranked = RankSourceViewsByPose(scene.builder.model(), reference, 20, 20);
  ASSERT_EQ(ranked.size(), 1u);
  EXPECT_EQ(ranked[0].image_id, side);
  EXPECT_EQ(ranked[0].num_shared_samples,
            static_cast<std::size_t>(kPoseSampleGrid * (kPoseSampleGrid - 1) * kPoseSampleDepths));
}

TEST(PoseViewSelectionTest, SharesSparsePointsNeedsAnotherObserver) {
  CircleScene scene;
  const image_t view = scene.AddViewAt(20, "v.png");
  const image_t lonely = scene.AddViewAt(-20, "lonely.png");
  scene.AddSharedPoints(3, {view});
  scene.builder.AddPoint({0, 0, 0}, {lonely});  // seen by nobody else
  EXPECT_TRUE(SharesSparsePoints(scene.builder.model(), scene.reference));
  EXPECT_TRUE(SharesSparsePoints(scene.builder.model(), view));
  EXPECT_FALSE(SharesSparsePoints(scene.builder.model(), lonely));
  EXPECT_THROW(SharesSparsePoints(scene.builder.model(), 42), std::invalid_argument);
}

TEST(PoseViewSelectionTest, GuessedDepthsFollowTheTypicalBaseline) {
  RowScene scene;
  EXPECT_FALSE(GuessSampleDepthsFromPoses(scene.builder.model()).has_value());
  scene.AddForward(0, "a.png");
  EXPECT_FALSE(GuessSampleDepthsFromPoses(scene.builder.model()).has_value());
  scene.AddTurned(0, 10, "a_turned.png");
  EXPECT_FALSE(GuessSampleDepthsFromPoses(scene.builder.model()).has_value());  // baseline 0

  RowScene row;
  for (const double x : {0.0, 1.0, 3.0, 7.0}) row.AddForward(x, std::to_string(x) + ".png");
  // Nearest-centre distances 1, 1, 2, 4; the median pick (index
  // round(0.5 * 3) = 2 of the sorted list) is 2.
  const auto depths = GuessSampleDepthsFromPoses(row.builder.model());
  ASSERT_TRUE(depths.has_value());
  EXPECT_NEAR(depths->first, 4.0, 1e-12);
  EXPECT_NEAR(depths->second, 200.0, 1e-12);
}

// Own range first, then the union of the others', then the guess from the
// baselines (computed once).
TEST(PoseViewSelectionTest, SampleDepthsPreferTheImagesOwnRange) {
  RowScene row;
  const image_t a = row.AddForward(0, "a.png");
  const image_t b = row.AddForward(1, "b.png");
  const image_t c = row.AddForward(3, "c.png");
  std::map<image_t, DepthRange> ranges;
  ranges[a] = {2.0, 5.0, 10, true};
  ranges[b] = {0.0, 0.0, 0, false};
  ranges[c] = {3.0, 9.0, 4, true};
  PoseSampleDepths with_ranges(row.builder.model(), ranges);
  EXPECT_EQ(with_ranges.For(a), std::make_pair(2.0, 5.0));
  EXPECT_EQ(with_ranges.For(b), std::make_pair(2.0, 9.0));  // the union
  EXPECT_FALSE(with_ranges.guessed().has_value());

  const std::map<image_t, DepthRange> none{{a, {}}, {b, {}}, {c, {}}};
  PoseSampleDepths without(row.builder.model(), none);
  // Nearest-centre distances 1, 1, 2: the median is 1.
  EXPECT_EQ(without.For(b), std::make_pair(2.0, 100.0));
  ASSERT_TRUE(without.guessed().has_value());
  EXPECT_EQ(*without.guessed(), std::make_pair(2.0, 100.0));
}

TEST(PoseViewSelectionTest, BadArgumentsThrow) {
  RowScene scene;
  const image_t reference = scene.AddForward(0, "ref.png");
  scene.AddForward(1, "b.png");
  const auto& model = scene.builder.model();
  EXPECT_THROW(RankSourceViewsByPose(model, 42, 1, 2), std::invalid_argument);
  EXPECT_THROW(RankSourceViewsByPose(model, reference, 0, 2), std::invalid_argument);
  EXPECT_THROW(RankSourceViewsByPose(model, reference, 3, 2), std::invalid_argument);
  EXPECT_THROW(RankSourceViewsByPose(model, reference, 1, std::nan("")), std::invalid_argument);
  ViewSelectionOptions options;
  options.max_viewing_angle_deg = 0;
  EXPECT_THROW(options.Check(), std::invalid_argument);
  EXPECT_THROW(RankSourceViewsByPose(model, reference, 1, 2, options), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::colmap_io
