#include "eval/rectified_pair.h"

#include <gtest/gtest.h>

#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "colmap_io/camera_models.h"
#include "tests/support/model_builder.h"

namespace dispmvs::eval {
namespace {

using colmap_io::camera_t;
using colmap_io::image_t;
using dispmvs::testing::ModelBuilder;

// A rig that is not axis-aligned, so that the test exercises the camera
// frame rather than the world frame.
const Eigen::Matrix3d& RigRotation() {
  static const Eigen::Matrix3d R =
      dispmvs::testing::LookAtRotation({1, 2, -5}, {0.3, -0.2, 1}, {0, -1, 0.2});
  return R;
}
const Eigen::Vector3d kLeftCentre(1, 2, -5);

// The camera axes in world coordinates: the rows of the world-to-camera rotation.
Eigen::Vector3d CameraAxis(int axis) { return RigRotation().row(axis).transpose(); }

image_t AddImageAt(ModelBuilder* builder, camera_t camera, const std::string& name,
                   const Eigen::Vector3d& centre, const Eigen::Matrix3d& R = RigRotation()) {
  return builder->AddImageWithPose(camera, name, R, -R * centre);
}

const colmap_io::Image& ImageOf(const ModelBuilder& builder, image_t id) {
  return builder.model().images.at(id);
}
const colmap_io::Camera& CameraOf(const ModelBuilder& builder, image_t id) {
  return builder.model().cameras.at(ImageOf(builder, id).camera_id);
}

std::optional<double> Baseline(const ModelBuilder& builder, image_t a, image_t b) {
  return RectifiedBaseline(CameraOf(builder, a), ImageOf(builder, a), CameraOf(builder, b),
                           ImageOf(builder, b));
}

TEST(EvalRectifiedPairTest, AcceptsARealRectifiedPair) {
  ModelBuilder builder;
  // Middlebury-like: the right camera's principal point is shifted by doffs.
  const camera_t left_camera = builder.AddPinholeCamera(741, 500, 995, 995, 311.2, 254.9);
  const camera_t right_camera = builder.AddPinholeCamera(741, 500, 995, 995, 342.3, 254.9);
  const double baseline = 0.193;
  const image_t left = AddImageAt(&builder, left_camera, "left.png", kLeftCentre);
  const image_t right =
      AddImageAt(&builder, right_camera, "right.png", kLeftCentre + baseline * CameraAxis(0));
  const std::optional<double> found = Baseline(builder, left, right);
  ASSERT_TRUE(found.has_value());
  EXPECT_NEAR(*found, baseline, 1e-12);
  const std::optional<double> reverse = Baseline(builder, right, left);
  ASSERT_TRUE(reverse.has_value());
  EXPECT_NEAR(*reverse, baseline, 1e-12);

  // What "rectified" promises, checked by projecting points: the same image
  // row in both views, and x_left - x_right = f B / z + (cx_left - cx_right).
  for (const Eigen::Vector3d& offset : {Eigen::Vector3d(0.1, -0.2, 2.0), Eigen::Vector3d(-0.4, 0.3, 3.5),
                                       Eigen::Vector3d(0.7, 0.5, 1.2)}) {
    const Eigen::Vector3d point = kLeftCentre + RigRotation().transpose() * offset;
    const Eigen::Vector2d x_left = builder.Project(left, point);
    const Eigen::Vector2d x_right = builder.Project(right, point);
    EXPECT_NEAR(x_left.y(), x_right.y(), 1e-9);
    EXPECT_NEAR(x_left.x() - x_right.x(), 995 * baseline / offset.z() + (311.2 - 342.3), 1e-9);
  }
}

TEST(EvalRectifiedPairTest, SimplePinholeMatchesAnEqualPinhole) {
  ModelBuilder builder;
  const camera_t pinhole = builder.AddPinholeCamera(64, 48, 50, 50, 32, 24);
  colmap_io::Camera simple;
  simple.camera_id = 2;
  simple.model_id = colmap_io::kSimplePinholeModelId;
  simple.width = 64;
  simple.height = 48;
  simple.params = {50, 30, 24};  // f, cx, cy
  builder.mutable_model().cameras[2] = simple;
  const image_t a = AddImageAt(&builder, pinhole, "a", kLeftCentre);
  const image_t b = AddImageAt(&builder, 2, "b", kLeftCentre - 0.5 * CameraAxis(0));
  const std::optional<double> found = Baseline(builder, a, b);
  ASSERT_TRUE(found.has_value());
  EXPECT_NEAR(*found, 0.5, 1e-12);
}

TEST(EvalRectifiedPairTest, RejectsWhatIsNotARectifiedPair) {
  ModelBuilder builder;
  const camera_t camera = builder.AddPinholeCamera(64, 48, 50, 50, 32, 24);
  const camera_t other_fy = builder.AddPinholeCamera(64, 48, 50, 50.001, 32, 24);
  const camera_t other_fx = builder.AddPinholeCamera(64, 48, 50.001, 50, 32, 24);
  const camera_t other_cy = builder.AddPinholeCamera(64, 48, 50, 50, 32, 24.5);
  const Eigen::Vector3d right = kLeftCentre + 1.0 * CameraAxis(0);
  const image_t a = AddImageAt(&builder, camera, "a", kLeftCentre);

  // Within tolerance: a rotation 1e-12 rad off and a baseline 1e-12 off-axis.
  const Eigen::Matrix3d nearly =
      RigRotation() * Eigen::AngleAxisd(1e-12, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const image_t ok_rotation = AddImageAt(&builder, camera, "ok_rotation", right, nearly);
  const image_t ok_offset =
      AddImageAt(&builder, camera, "ok_offset", right + 1e-12 * CameraAxis(1));
  EXPECT_TRUE(Baseline(builder, a, ok_rotation).has_value());
  EXPECT_TRUE(Baseline(builder, a, ok_offset).has_value());

  // A rotation 1e-6 rad off (entries change by ~1e-6).
  const Eigen::Matrix3d rotated =
      RigRotation() * Eigen::AngleAxisd(1e-6, Eigen::Vector3d::UnitY()).toRotationMatrix();
  EXPECT_FALSE(Baseline(builder, a, AddImageAt(&builder, camera, "rotated", right, rotated)));
  // A baseline with a y or a z component of 1e-6 of its length.
  EXPECT_FALSE(
      Baseline(builder, a, AddImageAt(&builder, camera, "y", right + 1e-6 * CameraAxis(1))));
  EXPECT_FALSE(
      Baseline(builder, a, AddImageAt(&builder, camera, "z", right + 1e-6 * CameraAxis(2))));
  // Forward motion only, and no motion at all.
  EXPECT_FALSE(Baseline(builder, a,
                        AddImageAt(&builder, camera, "forward", kLeftCentre + CameraAxis(2))));
  EXPECT_FALSE(Baseline(builder, a, AddImageAt(&builder, camera, "same", kLeftCentre)));
  // Other intrinsics.
  EXPECT_FALSE(Baseline(builder, a, AddImageAt(&builder, other_fy, "fy", right)));
  EXPECT_FALSE(Baseline(builder, a, AddImageAt(&builder, other_fx, "fx", right)));
  EXPECT_FALSE(Baseline(builder, a, AddImageAt(&builder, other_cy, "cy", right)));
  // A camera that is not a pinhole one (SIMPLE_RADIAL with k = 0 would
  // project the same, but dense MVS does not take it).
  colmap_io::Camera radial;
  radial.camera_id = 10;
  radial.model_id = 2;  // SIMPLE_RADIAL: f, cx, cy, k
  radial.width = 64;
  radial.height = 48;
  radial.params = {50, 32, 24, 0};
  builder.mutable_model().cameras[10] = radial;
  EXPECT_FALSE(Baseline(builder, a, AddImageAt(&builder, 10, "radial", right)));
}

TEST(EvalRectifiedPairTest, FindsTheNearestPartner) {
  ModelBuilder builder;
  const camera_t camera = builder.AddPinholeCamera(64, 48, 50, 50, 32, 24);
  const image_t a = AddImageAt(&builder, camera, "a", kLeftCentre);
  AddImageAt(&builder, camera, "far", kLeftCentre + 2.0 * CameraAxis(0));
  const image_t near = AddImageAt(&builder, camera, "near", kLeftCentre - 0.75 * CameraAxis(0));
  const image_t lonely = AddImageAt(&builder, camera, "lonely", kLeftCentre + CameraAxis(1));
  const std::optional<RectifiedPartner> partner = FindRectifiedPartner(builder.model(), a);
  ASSERT_TRUE(partner.has_value());
  EXPECT_EQ(partner->image_id, near);
  EXPECT_EQ(partner->name, "near");
  EXPECT_NEAR(partner->baseline, 0.75, 1e-12);
  EXPECT_FALSE(FindRectifiedPartner(builder.model(), lonely).has_value());
  // Equal baselines on both sides: the smaller name.
  const image_t b = AddImageAt(&builder, camera, "b", kLeftCentre - 0.75 * CameraAxis(0) -
                                                          0.75 * CameraAxis(0));
  const std::optional<RectifiedPartner> of_near = FindRectifiedPartner(builder.model(), near);
  ASSERT_TRUE(of_near.has_value());
  EXPECT_EQ(of_near->name, "a");  // a and b are both 0.75 from "near"
  EXPECT_NE(of_near->image_id, b);
  EXPECT_THROW(FindRectifiedPartner(builder.model(), 99), std::out_of_range);
}

}  // namespace
}  // namespace dispmvs::eval
