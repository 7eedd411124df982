#pragma once
// Builds COLMAP sparse models in memory with known geometry, for tests.
//
//   ModelBuilder builder;
//   const auto cam = builder.AddPinholeCamera(320, 240, 300, 300, 160, 120);
//   const auto a = builder.AddImageLookingAt(cam, "a.png", {0, 0, -5}, {0, 0, 0});
//   const auto b = builder.AddImageLookingAt(cam, "b.png", {1, 0, -5}, {0, 0, 0});
//   builder.AddPoint({0, 0, 1}, {a, b});   // projected into a and b
//   const SparseModel& model = builder.model();
//
// Ids count up from 1 in insertion order. Points2D and tracks are always
// consistent: AddPoint appends one observation to each observing image and
// the matching element to the point's track.

#include <string>
#include <vector>

#include <Eigen/Core>

#include "colmap_io/sparse_model.h"

namespace dispmvs::testing {

// World-to-camera rotation (COLMAP's convention: camera x right, y down,
// z forward) of a camera at `centre` looking at `target`, with `up` (world
// frame) appearing upwards in the image. Throws std::invalid_argument if the
// viewing direction is zero or parallel to `up`.
Eigen::Matrix3d LookAtRotation(const Eigen::Vector3d& centre, const Eigen::Vector3d& target,
                               const Eigen::Vector3d& up);

class ModelBuilder {
 public:
  // A PINHOLE camera (model id 1) with params fx, fy, cx, cy.
  colmap_io::camera_t AddPinholeCamera(int width, int height, double fx, double fy, double cx,
                                       double cy);

  // An image at `centre` looking at `target` (see LookAtRotation); `up`
  // defaults to world -y so that world +y points down the image, as in the
  // camera frame of an identity pose.
  colmap_io::image_t AddImageLookingAt(colmap_io::camera_t camera_id, const std::string& name,
                                       const Eigen::Vector3d& centre,
                                       const Eigen::Vector3d& target,
                                       const Eigen::Vector3d& up = Eigen::Vector3d(0, -1, 0));

  // An image with an explicit world-to-camera pose.
  colmap_io::image_t AddImageWithPose(colmap_io::camera_t camera_id, const std::string& name,
                                      const Eigen::Matrix3d& R_world_to_camera,
                                      const Eigen::Vector3d& t_world_to_camera);

  // A 3-D point observed by `observers` (each at most once is the usual case;
  // repeating an id adds a second observation). Each observation's xy is the
  // projection K (R X + t) of the point in COLMAP's pixel convention; for a
  // point on the camera plane (z == 0) it is (0, 0). Points behind a camera
  // are still recorded (tests use them as bad input). Unknown image ids throw
  // std::out_of_range. Project() assumes the PINHOLE cameras added above.
  colmap_io::point3D_t AddPoint(const Eigen::Vector3d& xyz,
                                const std::vector<colmap_io::image_t>& observers);

  // An observation that refers to no 3-D point (point3D_id = -1).
  void AddUnmatchedObservation(colmap_io::image_t image_id, const Eigen::Vector2d& xy);

  const colmap_io::SparseModel& model() const { return model_; }
  colmap_io::SparseModel& mutable_model() { return model_; }

  // Projection of `xyz` into `image_id` (COLMAP pixel convention) and its
  // camera-frame depth.
  Eigen::Vector2d Project(colmap_io::image_t image_id, const Eigen::Vector3d& xyz) const;
  double Depth(colmap_io::image_t image_id, const Eigen::Vector3d& xyz) const;

 private:
  colmap_io::SparseModel model_;
  colmap_io::point3D_t next_point3D_id_ = 1;
};

}  // namespace dispmvs::testing
