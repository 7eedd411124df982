#pragma once
// COLMAP's camera models: numeric id (stored in cameras.bin), name (stored in
// cameras.txt) and parameter layout. The table matches COLMAP 3.8
// (src/base/camera_models.h, later src/colmap/sensor/models.h). Newer COLMAP
// releases append models with ids above 10; files using them are rejected
// with a clear error rather than misread.

#include <cstddef>
#include <string>
#include <vector>

namespace dispmvs::colmap_io {

struct CameraModelInfo {
  int id;
  const char* name;  // as written in cameras.txt, e.g. "PINHOLE"
  size_t num_params;
  const char* params_info;  // parameter names in storage order, e.g. "fx, fy, cx, cy"
};

// Every known model, ordered by id (ids are 0..10 without gaps).
const std::vector<CameraModelInfo>& AllCameraModels();

// nullptr when unknown; use these where the caller reports its own error.
const CameraModelInfo* FindCameraModelById(int model_id);
const CameraModelInfo* FindCameraModelByName(const std::string& name);

// As the Find* variants, but throw std::invalid_argument naming the unknown
// id or name.
const CameraModelInfo& CameraModelById(int model_id);
const CameraModelInfo& CameraModelByName(const std::string& name);

// Ids of the models used below by name.
constexpr int kSimplePinholeModelId = 0;
constexpr int kPinholeModelId = 1;

}  // namespace dispmvs::colmap_io
