#pragma once
// In-memory COLMAP sparse model: cameras, images (poses + 2-D observations)
// and 3-D points with tracks. Field meanings and id types follow COLMAP's own
// (see docs/colmap-layout.md); poses are world-to-camera.

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace dispmvs::colmap_io {

using camera_t = uint32_t;
using image_t = uint32_t;
using point3D_t = uint64_t;
// images.bin stores point3D ids as int64 with -1 meaning "no 3-D point".
constexpr point3D_t kInvalidPoint3DId = static_cast<point3D_t>(-1);

struct Camera {
  camera_t camera_id = 0;
  int model_id = -1;  // see camera_models.h
  uint64_t width = 0;
  uint64_t height = 0;
  std::vector<double> params;

  // True for SIMPLE_PINHOLE and PINHOLE, the models dense MVS accepts.
  bool IsPinhole() const;
  // fx, fy, cx, cy in COLMAP's convention (top-left pixel centre at 0.5,0.5).
  // Throws std::invalid_argument naming the model if it is not a pinhole one.
  Eigen::Matrix3d CalibrationMatrix() const;
};

struct Point2D {
  Eigen::Vector2d xy = Eigen::Vector2d::Zero();
  point3D_t point3D_id = kInvalidPoint3DId;
  bool HasPoint3D() const { return point3D_id != kInvalidPoint3DId; }
};

struct Image {
  image_t image_id = 0;
  // Rotation world->camera as a unit quaternion (w, x, y, z), as COLMAP stores it.
  Eigen::Vector4d qvec = Eigen::Vector4d(1, 0, 0, 0);
  Eigen::Vector3d tvec = Eigen::Vector3d::Zero();
  camera_t camera_id = 0;
  std::string name;  // relative to the images folder; may contain '/'
  std::vector<Point2D> points2D;

  // Sets qvec from a world->camera rotation matrix and tvec = t.
  void SetPose(const Eigen::Matrix3d& R_world_to_camera, const Eigen::Vector3d& t);

  Eigen::Matrix3d RotationMatrix() const;       // world -> camera
  Eigen::Vector3d ProjectionCenter() const;     // camera centre in world frame
  Eigen::Vector3d ViewingDirection() const;     // camera +z axis in world frame
};

struct TrackElement {
  image_t image_id = 0;
  uint32_t point2D_idx = 0;
};

struct Point3D {
  point3D_t point3D_id = 0;
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  std::array<uint8_t, 3> rgb = {0, 0, 0};
  double error = -1.0;
  std::vector<TrackElement> track;
};

struct SparseModel {
  std::map<camera_t, Camera> cameras;
  std::map<image_t, Image> images;
  std::map<point3D_t, Point3D> points3D;

  // Image ids in the order the readers met them in images.bin / images.txt.
  // COLMAP's dense stage numbers images in this order (mvs::Model takes them
  // in registration order, which is file order), and fused.ply.vis stores
  // those numbers. Empty for models built in code: see DenseImageOrder().
  std::vector<image_t> image_file_order;

  // The image ids in COLMAP's dense numbering: image_file_order when it lists
  // exactly the model's images, else all ids in ascending order (what our
  // writers produce, so a model written by us and read by COLMAP agrees).
  std::vector<image_t> DenseImageOrder() const;

  // Returns nullptr if absent.
  const Image* FindImageByName(const std::string& name) const;

  // Inserts `point` (its track is replaced) as observed in each listed image
  // at the given pixel, appending the matching points2D to those images so
  // that tracks and images agree. Throws std::out_of_range for an unknown image.
  void AddObservedPoint(Point3D point,
                        const std::vector<std::pair<image_t, Eigen::Vector2d>>& observations);
};

}  // namespace dispmvs::colmap_io
