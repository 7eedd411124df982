#include "colmap_io/camera_models.h"

#include <stdexcept>

namespace dispmvs::colmap_io {

const std::vector<CameraModelInfo>& AllCameraModels() {
  // Index == id; FindCameraModelById relies on it.
  static const std::vector<CameraModelInfo> kModels = {
      {0, "SIMPLE_PINHOLE", 3, "f, cx, cy"},
      {1, "PINHOLE", 4, "fx, fy, cx, cy"},
      {2, "SIMPLE_RADIAL", 4, "f, cx, cy, k"},
      {3, "RADIAL", 5, "f, cx, cy, k1, k2"},
      {4, "OPENCV", 8, "fx, fy, cx, cy, k1, k2, p1, p2"},
      {5, "OPENCV_FISHEYE", 8, "fx, fy, cx, cy, k1, k2, k3, k4"},
      {6, "FULL_OPENCV", 12, "fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6"},
      {7, "FOV", 5, "fx, fy, cx, cy, omega"},
      {8, "SIMPLE_RADIAL_FISHEYE", 4, "f, cx, cy, k"},
      {9, "RADIAL_FISHEYE", 5, "f, cx, cy, k1, k2"},
      {10, "THIN_PRISM_FISHEYE", 12, "fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1"},
  };
  return kModels;
}

const CameraModelInfo* FindCameraModelById(int model_id) {
  const auto& models = AllCameraModels();
  if (model_id < 0 || static_cast<size_t>(model_id) >= models.size()) return nullptr;
  return &models[static_cast<size_t>(model_id)];
}

const CameraModelInfo* FindCameraModelByName(const std::string& name) {
  for (const CameraModelInfo& model : AllCameraModels()) {
    if (name == model.name) return &model;
  }
  return nullptr;
}

const CameraModelInfo& CameraModelById(int model_id) {
  const CameraModelInfo* model = FindCameraModelById(model_id);
  if (model == nullptr) {
    throw std::invalid_argument("unknown COLMAP camera model id " + std::to_string(model_id) +
                                " (known: 0..10)");
  }
  return *model;
}

const CameraModelInfo& CameraModelByName(const std::string& name) {
  const CameraModelInfo* model = FindCameraModelByName(name);
  if (model == nullptr) {
    throw std::invalid_argument("unknown COLMAP camera model name '" + name + "'");
  }
  return *model;
}

}  // namespace dispmvs::colmap_io
