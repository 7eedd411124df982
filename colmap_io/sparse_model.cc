// Geometry helpers of the sparse-model types, the per-record checks shared by
// the readers, cross-file validation and the format-detecting directory reader.

#include "colmap_io/sparse_model.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include "colmap_io/camera_models.h"
#include "colmap_io/error.h"
#include "colmap_io/sparse_model_checks.h"
#include "colmap_io/sparse_model_io.h"

namespace dispmvs::colmap_io {

// ---------------------------------------------------------------------------
// Camera / Image geometry

bool Camera::IsPinhole() const {
  return model_id == kSimplePinholeModelId || model_id == kPinholeModelId;
}

Eigen::Matrix3d Camera::CalibrationMatrix() const {
  const CameraModelInfo* model = FindCameraModelById(model_id);
  if (!IsPinhole()) {
    throw std::invalid_argument(
        "camera " + std::to_string(camera_id) + " uses model " +
        (model ? std::string(model->name) : "id " + std::to_string(model_id)) +
        ", not SIMPLE_PINHOLE or PINHOLE: undistort the images first (colmap image_undistorter)");
  }
  if (params.size() != model->num_params) {
    throw std::invalid_argument("camera " + std::to_string(camera_id) + " (" + model->name +
                                ") has " + std::to_string(params.size()) +
                                " parameters, expected " + std::to_string(model->num_params));
  }
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  if (model_id == kSimplePinholeModelId) {  // f, cx, cy
    K(0, 0) = params[0];
    K(1, 1) = params[0];
    K(0, 2) = params[1];
    K(1, 2) = params[2];
  } else {  // fx, fy, cx, cy
    K(0, 0) = params[0];
    K(1, 1) = params[1];
    K(0, 2) = params[2];
    K(1, 2) = params[3];
  }
  return K;
}

void Image::SetPose(const Eigen::Matrix3d& R_world_to_camera, const Eigen::Vector3d& t) {
  const Eigen::Quaterniond q(R_world_to_camera);
  qvec = Eigen::Vector4d(q.w(), q.x(), q.y(), q.z());
  tvec = t;
}

Eigen::Matrix3d Image::RotationMatrix() const {
  // Normalised here rather than on reading, so that reading and writing a
  // model keeps the stored values bit for bit (COLMAP's files hold unit
  // quaternions anyway; the readers reject ones that cannot be normalised).
  const Eigen::Quaterniond q(qvec(0), qvec(1), qvec(2), qvec(3));
  return q.normalized().toRotationMatrix();
}

Eigen::Vector3d Image::ProjectionCenter() const {
  // x_cam = R x_world + t  =>  the centre (x_cam = 0) is -R^T t.
  return -RotationMatrix().transpose() * tvec;
}

Eigen::Vector3d Image::ViewingDirection() const {
  // The camera's +z axis expressed in the world frame is the third row of R.
  return RotationMatrix().row(2).transpose();
}

std::vector<image_t> SparseModel::DenseImageOrder() const {
  std::vector<image_t> order;
  if (image_file_order.size() == images.size()) {
    order = image_file_order;
    std::vector<image_t> sorted = order;
    std::sort(sorted.begin(), sorted.end());
    const bool same_set = std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end() &&
                          std::all_of(sorted.begin(), sorted.end(),
                                      [&](image_t id) { return images.count(id) > 0; });
    if (same_set) return order;
    order.clear();
  }
  for (const auto& [id, image] : images) order.push_back(id);
  return order;
}

const Image* SparseModel::FindImageByName(const std::string& name) const {
  for (const auto& [id, image] : images) {
    if (image.name == name) return &image;
  }
  return nullptr;
}

void SparseModel::AddObservedPoint(
    Point3D point, const std::vector<std::pair<image_t, Eigen::Vector2d>>& observations) {
  point.track.clear();
  for (const auto& [image_id, xy] : observations) {
    Image& image = images.at(image_id);
    Point2D point2D;
    point2D.xy = xy;
    point2D.point3D_id = point.point3D_id;
    point.track.push_back({image_id, static_cast<uint32_t>(image.points2D.size())});
    image.points2D.push_back(point2D);
  }
  points3D[point.point3D_id] = std::move(point);
}

// ---------------------------------------------------------------------------
// Per-record checks shared by the binary and text readers

namespace internal {
namespace {

bool AllFinite(const double* values, size_t count) {
  for (size_t i = 0; i < count; ++i) {
    if (!std::isfinite(values[i])) return false;
  }
  return true;
}

}  // namespace

std::string CheckCamera(const Camera& camera) {
  const CameraModelInfo* model = FindCameraModelById(camera.model_id);
  if (model == nullptr) {
    return "unknown camera model id " + std::to_string(camera.model_id) + " (known: 0..10)";
  }
  if (camera.params.size() != model->num_params) {
    return std::string("model ") + model->name + " takes " + std::to_string(model->num_params) +
           " parameters (" + model->params_info + ") but " + std::to_string(camera.params.size()) +
           " were given";
  }
  if (!AllFinite(camera.params.data(), camera.params.size())) {
    return "non-finite camera parameter (NaN or inf)";
  }
  if (camera.width == 0 || camera.height == 0) {
    return "zero image width or height";
  }
  return {};
}

std::string CheckImage(const Image& image) {
  if (!AllFinite(image.qvec.data(), 4)) return "non-finite rotation quaternion (NaN or inf)";
  if (!AllFinite(image.tvec.data(), 3)) return "non-finite translation (NaN or inf)";
  // A quaternion far from unit length is still a rotation once normalised;
  // one whose norm is ~0 (or overflows) does not describe any rotation.
  const double norm = image.qvec.norm();
  if (!(norm > 1e-12) || !std::isfinite(norm)) {
    return "rotation quaternion cannot be normalised (norm " + std::to_string(norm) + ")";
  }
  for (size_t i = 0; i < image.points2D.size(); ++i) {
    if (!AllFinite(image.points2D[i].xy.data(), 2)) {
      return "non-finite coordinates in point2D #" + std::to_string(i);
    }
  }
  return {};
}

std::string CheckPoint3D(const Point3D& point) {
  if (!AllFinite(point.xyz.data(), 3)) return "non-finite position (NaN or inf)";
  if (!std::isfinite(point.error)) return "non-finite reprojection error (NaN or inf)";
  return {};
}

}  // namespace internal

// ---------------------------------------------------------------------------
// Cross-file validation

namespace {

[[noreturn]] void Fail(const std::string& source_name, const std::string& what) {
  throw IoError(source_name, what);
}

// For each image: the image, and which of its points2D some track lists.
struct Observations {
  const Image* image;
  std::vector<bool> listed;
};

// Map keys and the ids inside the records must agree; a writer would
// otherwise silently store a different id than the caller looked up.
void ValidateCameras(const SparseModel& model, const std::string& source_name) {
  for (const auto& [id, camera] : model.cameras) {
    if (camera.camera_id != id) {
      Fail(source_name, "camera stored under id " + std::to_string(id) + " has camera_id " +
                            std::to_string(camera.camera_id));
    }
    if (const std::string problem = internal::CheckCamera(camera); !problem.empty()) {
      Fail(source_name, "camera " + std::to_string(id) + ": " + problem);
    }
  }
}

// Images: ids, values, cameras that exist, unique names. Returns the
// observation marks, none listed yet.
std::unordered_map<image_t, Observations> ValidateImages(const SparseModel& model,
                                                          const std::string& source_name) {
  std::unordered_map<std::string, image_t> image_ids_by_name;
  std::unordered_map<image_t, Observations> observations;
  for (const auto& [id, image] : model.images) {
    if (image.image_id != id) {
      Fail(source_name, "image stored under id " + std::to_string(id) + " has image_id " +
                            std::to_string(image.image_id));
    }
    if (const std::string problem = internal::CheckImage(image); !problem.empty()) {
      Fail(source_name, "image " + std::to_string(id) + ": " + problem);
    }
    if (model.cameras.count(image.camera_id) == 0) {
      Fail(source_name, "image " + std::to_string(id) + " ('" + image.name + "') uses camera " +
                            std::to_string(image.camera_id) + ", which cameras does not contain");
    }
    const auto [it, inserted] = image_ids_by_name.emplace(image.name, id);
    if (!inserted) {
      Fail(source_name, "images " + std::to_string(it->second) + " and " + std::to_string(id) +
                            " have the same name '" + image.name + "'");
    }
    observations[id] = Observations{&image, std::vector<bool>(image.points2D.size(), false)};
  }
  return observations;
}

// Points3D: ids and values, and every track element names an existing
// point2D that refers back to the point, once; marks it in `observations`.
void ValidateTracks(const SparseModel& model, const std::string& source_name,
                    std::unordered_map<image_t, Observations>* observations) {
  for (const auto& [id, point] : model.points3D) {
    if (point.point3D_id != id) {
      Fail(source_name, "point3D stored under id " + std::to_string(id) + " has point3D_id " +
                            std::to_string(point.point3D_id));
    }
    if (const std::string problem = internal::CheckPoint3D(point); !problem.empty()) {
      Fail(source_name, "point3D " + std::to_string(id) + ": " + problem);
    }
    for (size_t e = 0; e < point.track.size(); ++e) {
      const TrackElement& el = point.track[e];
      // Built only on failure: models hold millions of track elements.
      // (C++17 lambdas cannot capture structured bindings, hence point_id.)
      const auto where = [&, point_id = id] {
        return "point3D " + std::to_string(point_id) + " track element #" + std::to_string(e) +
               " (image " + std::to_string(el.image_id) + ", point2D " +
               std::to_string(el.point2D_idx) + ")";
      };
      const auto found = observations->find(el.image_id);
      if (found == observations->end()) Fail(source_name, where() + ": no such image");
      const Image& image = *found->second.image;
      if (el.point2D_idx >= image.points2D.size()) {
        Fail(source_name, where() + ": the image has only " +
                              std::to_string(image.points2D.size()) + " points2D");
      }
      if (image.points2D[el.point2D_idx].point3D_id != id) {
        Fail(source_name, where() + ": that point2D does not refer back to this point3D");
      }
      std::vector<bool>& listed = found->second.listed;
      if (listed[el.point2D_idx]) Fail(source_name, where() + ": listed twice");
      listed[el.point2D_idx] = true;
    }
  }
}

// Every observation must appear in its point's track (the reverse of
// ValidateTracks), otherwise tracks and images disagree about what was seen.
// The marks replace a points3D lookup per observation, which dominated the
// run time on large models; the lookup is only made to word the error.
void ValidateObservationsListed(const SparseModel& model, const std::string& source_name,
                                const std::unordered_map<image_t, Observations>& observations) {
  for (const auto& [id, image] : model.images) {
    const std::vector<bool>& listed = observations.at(id).listed;
    for (size_t k = 0; k < image.points2D.size(); ++k) {
      const point3D_t point3D_id = image.points2D[k].point3D_id;
      if (image.points2D[k].HasPoint3D() && !listed[k]) {
        Fail(source_name,
             "image " + std::to_string(id) + " point2D #" + std::to_string(k) +
                 " refers to point3D " + std::to_string(point3D_id) +
                 (model.points3D.count(point3D_id) == 0
                      ? ", which points3D does not contain"
                      : " but that point's track does not list it"));
      }
    }
  }
}

}  // namespace

void ValidateSparseModel(const SparseModel& model, const std::string& source_name) {
  ValidateCameras(model, source_name);
  std::unordered_map<image_t, Observations> observations = ValidateImages(model, source_name);
  ValidateTracks(model, source_name, &observations);
  ValidateObservationsListed(model, source_name, observations);
}

// ---------------------------------------------------------------------------
// Directory level

namespace {

bool HasTrio(const std::filesystem::path& dir, const char* extension) {
  std::error_code ec;
  for (const char* stem : {"cameras", "images", "points3D"}) {
    if (!std::filesystem::is_regular_file(dir / (std::string(stem) + extension), ec)) {
      return false;
    }
  }
  return true;
}

}  // namespace

SparseModelFormat DetectSparseModelFormat(const std::filesystem::path& dir) {
  if (HasTrio(dir, ".bin")) return SparseModelFormat::kBinary;
  if (HasTrio(dir, ".txt")) return SparseModelFormat::kText;
  throw IoError(dir.string(),
                "no COLMAP sparse model here: expected cameras, images and points3D as "
                ".bin (all three) or .txt (all three)");
}

SparseModel ReadSparseModel(const std::filesystem::path& dir) {
  switch (DetectSparseModelFormat(dir)) {
    case SparseModelFormat::kBinary:
      return ReadSparseModelBinary(dir);
    case SparseModelFormat::kText:
      return ReadSparseModelText(dir);
  }
  throw IoError(dir.string(), "unhandled sparse model format");  // unreachable
}

}  // namespace dispmvs::colmap_io
