// COLMAP's binary sparse model: cameras.bin, images.bin, points3D.bin
// (little endian; layout in docs and in COLMAP's Reconstruction::Read*Binary).
// Readers check every count against the bytes left before reserving memory
// and reject malformed records with the record index and id.

#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>

#include "colmap_io/atomic_file.h"
#include "colmap_io/binary_reader.h"
#include "colmap_io/camera_models.h"
#include "colmap_io/error.h"
#include "colmap_io/sparse_model_checks.h"
#include "colmap_io/sparse_model_io.h"

namespace dispmvs::colmap_io {
namespace {

using internal::BinaryReader;

// Smallest possible size of each record, used to bound counts.
constexpr uint64_t kMinCameraBytes = 4 + 4 + 8 + 8 + 3 * 8;  // 3 = fewest params of any model
constexpr uint64_t kMinImageBytes = 4 + 4 * 8 + 3 * 8 + 4 + 1 + 8;  // empty name: just the NUL
constexpr uint64_t kPoint2DBytes = 8 + 8 + 8;
constexpr uint64_t kMinPoint3DBytes = 8 + 3 * 8 + 3 + 8 + 8;
constexpr uint64_t kTrackElementBytes = 4 + 4;

// ---------------------------------------------------------------------------
// Little-endian output

template <typename T>
void WriteInt(std::ostream& out, T value) {
  using U = std::make_unsigned_t<T>;
  const U bits = static_cast<U>(value);
  char bytes[sizeof(T)];
  for (size_t i = 0; i < sizeof(T); ++i) bytes[i] = static_cast<char>((bits >> (8 * i)) & 0xFF);
  out.write(bytes, sizeof(T));
}

void WriteDouble(std::ostream& out, double value) {
  uint64_t bits;
  std::memcpy(&bits, &value, sizeof(bits));
  WriteInt<uint64_t>(out, bits);
}

std::ifstream OpenForReading(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string(), "cannot open for reading");
  return in;
}

}  // namespace

// ---------------------------------------------------------------------------
// Readers

void ReadCamerasBinary(std::istream& in, const std::string& source_name, SparseModel* model) {
  BinaryReader reader(in, source_name);
  model->cameras.clear();
  const uint64_t count = reader.ReadCount("number of cameras", kMinCameraBytes);
  for (uint64_t i = 0; i < count; ++i) {
    reader.SetRecord("camera", i);
    Camera camera;
    camera.camera_id = reader.ReadInt<uint32_t>("camera_id");
    reader.SetRecordId("camera_id", camera.camera_id);
    camera.model_id = reader.ReadInt<int32_t>("model_id");
    const CameraModelInfo* info = FindCameraModelById(camera.model_id);
    if (info == nullptr) {
      reader.Fail("unknown camera model id " + std::to_string(camera.model_id) + " (known: 0..10)");
    }
    camera.width = reader.ReadInt<uint64_t>("width");
    camera.height = reader.ReadInt<uint64_t>("height");
    // The binary form has no parameter count: the model defines it.
    camera.params.resize(info->num_params);
    for (double& param : camera.params) param = reader.ReadDouble("camera parameter");
    if (const std::string problem = internal::CheckCamera(camera); !problem.empty()) {
      reader.Fail(problem);
    }
    if (!model->cameras.emplace(camera.camera_id, std::move(camera)).second) {
      reader.Fail("duplicate camera_id");
    }
  }
  reader.ExpectEnd(count);
}

void ReadImagesBinary(std::istream& in, const std::string& source_name, SparseModel* model) {
  BinaryReader reader(in, source_name);
  model->images.clear();
  model->image_file_order.clear();
  const uint64_t count = reader.ReadCount("number of images", kMinImageBytes);
  for (uint64_t i = 0; i < count; ++i) {
    reader.SetRecord("image", i);
    Image image;
    image.image_id = reader.ReadInt<uint32_t>("image_id");
    reader.SetRecordId("image_id", image.image_id);
    for (int k = 0; k < 4; ++k) image.qvec(k) = reader.ReadDouble("qvec");
    for (int k = 0; k < 3; ++k) image.tvec(k) = reader.ReadDouble("tvec");
    image.camera_id = reader.ReadInt<uint32_t>("camera_id");
    image.name = reader.ReadNulTerminated("name");
    const uint64_t num_points2D = reader.ReadCount("number of points2D", kPoint2DBytes);
    image.points2D.resize(num_points2D);
    for (Point2D& point : image.points2D) {
      point.xy.x() = reader.ReadDouble("point2D x");
      point.xy.y() = reader.ReadDouble("point2D y");
      // Stored as int64 with -1 for "none", which is kInvalidPoint3DId as uint64.
      point.point3D_id = reader.ReadInt<uint64_t>("point2D point3D_id");
    }
    if (const std::string problem = internal::CheckImage(image); !problem.empty()) {
      reader.Fail(problem);
    }
    const image_t image_id = image.image_id;
    if (!model->images.emplace(image_id, std::move(image)).second) {
      reader.Fail("duplicate image_id");
    }
    model->image_file_order.push_back(image_id);
  }
  reader.ExpectEnd(count);
}

void ReadPoints3DBinary(std::istream& in, const std::string& source_name, SparseModel* model) {
  BinaryReader reader(in, source_name);
  model->points3D.clear();
  const uint64_t count = reader.ReadCount("number of points3D", kMinPoint3DBytes);
  for (uint64_t i = 0; i < count; ++i) {
    reader.SetRecord("point3D", i);
    Point3D point;
    point.point3D_id = reader.ReadInt<uint64_t>("point3D_id");
    reader.SetRecordId("point3D_id", point.point3D_id);
    for (int k = 0; k < 3; ++k) point.xyz(k) = reader.ReadDouble("xyz");
    for (uint8_t& channel : point.rgb) channel = reader.ReadInt<uint8_t>("rgb");
    point.error = reader.ReadDouble("error");
    const uint64_t track_length = reader.ReadCount("track length", kTrackElementBytes);
    point.track.resize(track_length);
    for (TrackElement& element : point.track) {
      element.image_id = reader.ReadInt<uint32_t>("track image_id");
      element.point2D_idx = reader.ReadInt<uint32_t>("track point2D_idx");
    }
    if (const std::string problem = internal::CheckPoint3D(point); !problem.empty()) {
      reader.Fail(problem);
    }
    if (!model->points3D.emplace(point.point3D_id, std::move(point)).second) {
      reader.Fail("duplicate point3D_id");
    }
  }
  reader.ExpectEnd(count);
}

SparseModel ReadSparseModelBinary(const std::filesystem::path& dir) {
  SparseModel model;
  {
    const auto path = dir / "cameras.bin";
    std::ifstream in = OpenForReading(path);
    ReadCamerasBinary(in, path.string(), &model);
  }
  {
    const auto path = dir / "images.bin";
    std::ifstream in = OpenForReading(path);
    ReadImagesBinary(in, path.string(), &model);
  }
  {
    const auto path = dir / "points3D.bin";
    std::ifstream in = OpenForReading(path);
    ReadPoints3DBinary(in, path.string(), &model);
  }
  ValidateSparseModel(model, dir.string());
  return model;
}

// ---------------------------------------------------------------------------
// Writers

void WriteCamerasBinary(const SparseModel& model, std::ostream& out,
                        const std::string& target_name) {
  WriteInt<uint64_t>(out, model.cameras.size());
  for (const auto& [id, camera] : model.cameras) {
    const CameraModelInfo* info = FindCameraModelById(camera.model_id);
    if (info == nullptr || camera.params.size() != info->num_params) {
      // The reader derives the parameter count from the model: anything else
      // would shift every later byte.
      throw IoError(target_name,
                    "camera " + std::to_string(id) + ": " + internal::CheckCamera(camera));
    }
    WriteInt<uint32_t>(out, id);
    WriteInt<int32_t>(out, camera.model_id);
    WriteInt<uint64_t>(out, camera.width);
    WriteInt<uint64_t>(out, camera.height);
    for (const double param : camera.params) WriteDouble(out, param);
  }
}

void WriteImagesBinary(const SparseModel& model, std::ostream& out,
                       const std::string& target_name) {
  WriteInt<uint64_t>(out, model.images.size());
  for (const auto& [id, image] : model.images) {
    if (image.name.find('\0') != std::string::npos) {
      throw IoError(target_name, "image " + std::to_string(id) + ": name contains a NUL byte");
    }
    WriteInt<uint32_t>(out, id);
    for (int k = 0; k < 4; ++k) WriteDouble(out, image.qvec(k));
    for (int k = 0; k < 3; ++k) WriteDouble(out, image.tvec(k));
    WriteInt<uint32_t>(out, image.camera_id);
    out.write(image.name.c_str(), static_cast<std::streamsize>(image.name.size() + 1));
    WriteInt<uint64_t>(out, image.points2D.size());
    for (const Point2D& point : image.points2D) {
      WriteDouble(out, point.xy.x());
      WriteDouble(out, point.xy.y());
      WriteInt<uint64_t>(out, point.point3D_id);
    }
  }
}

void WritePoints3DBinary(const SparseModel& model, std::ostream& out,
                         const std::string& /*target_name*/) {
  WriteInt<uint64_t>(out, model.points3D.size());
  for (const auto& [id, point] : model.points3D) {
    WriteInt<uint64_t>(out, id);
    for (int k = 0; k < 3; ++k) WriteDouble(out, point.xyz(k));
    for (const uint8_t channel : point.rgb) WriteInt<uint8_t>(out, channel);
    WriteDouble(out, point.error);
    WriteInt<uint64_t>(out, point.track.size());
    for (const TrackElement& element : point.track) {
      WriteInt<uint32_t>(out, element.image_id);
      WriteInt<uint32_t>(out, element.point2D_idx);
    }
  }
}

void WriteSparseModelBinary(const SparseModel& model, const std::filesystem::path& dir) {
  ValidateSparseModel(model, dir.string());
  const auto cameras = dir / "cameras.bin";
  const auto images = dir / "images.bin";
  const auto points = dir / "points3D.bin";
  WriteFileAtomically(cameras,
                      [&](std::ostream& out) { WriteCamerasBinary(model, out, cameras.string()); });
  WriteFileAtomically(images,
                      [&](std::ostream& out) { WriteImagesBinary(model, out, images.string()); });
  WriteFileAtomically(points,
                      [&](std::ostream& out) { WritePoints3DBinary(model, out, points.string()); });
}

}  // namespace dispmvs::colmap_io
