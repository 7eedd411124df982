// Writes a seed corpus for the sparse-model fuzzers: one file per reader,
// holding a small valid model file as our writers produce it, prefixed with
// the selector byte the fuzz targets expect (0 cameras, 1 images,
// 2 points3D). Usage: sparse_model_fuzz_seeds BINARY_DIR TEXT_DIR

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

#include "colmap_io/sparse_model_io.h"

namespace {

using namespace dispmvs::colmap_io;

SparseModel SeedModel() {
  SparseModel m;
  Camera simple;
  simple.camera_id = 1;
  simple.model_id = 0;  // SIMPLE_PINHOLE
  simple.width = 640;
  simple.height = 480;
  simple.params = {500, 320, 240};
  Camera opencv;
  opencv.camera_id = 2;
  opencv.model_id = 4;  // OPENCV
  opencv.width = 1024;
  opencv.height = 768;
  opencv.params = {800, 801, 512, 384, 0.1, -0.05, 0.001, -0.002};
  m.cameras[1] = simple;
  m.cameras[2] = opencv;

  Image a;
  a.image_id = 1;
  a.camera_id = 1;
  a.name = "a.jpg";
  a.tvec = Eigen::Vector3d(0.1, 0.2, 0.3);
  Image b;
  b.image_id = 2;
  b.camera_id = 2;
  b.name = "sub/b.png";
  b.qvec = Eigen::Vector4d(0.5, 0.5, -0.5, 0.5);
  Point2D seen;
  seen.xy = Eigen::Vector2d(10.5, 20.25);
  seen.point3D_id = 7;
  Point2D unseen;
  unseen.xy = Eigen::Vector2d(1.0 / 3.0, 2);
  a.points2D = {seen, unseen};
  b.points2D = {unseen, seen};
  m.images[1] = a;
  m.images[2] = b;

  Point3D p;
  p.point3D_id = 7;
  p.xyz = Eigen::Vector3d(1, -2, 3.5);
  p.rgb = {255, 128, 0};
  p.error = 0.75;
  p.track = {{1, 0}, {2, 1}};
  m.points3D[7] = p;
  return m;
}

void WriteSeed(const std::filesystem::path& path, char selector, const std::string& content) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.put(selector);
  out << content;
  if (!out) throw std::runtime_error("cannot write " + path.string());
}

template <typename Writer>
std::string WriteToString(Writer writer, const SparseModel& model) {
  std::ostringstream out;
  writer(model, out, "seed");
  return out.str();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::cerr << "usage: " << argv[0] << " BINARY_CORPUS_DIR TEXT_CORPUS_DIR\n";
    return 2;
  }
  const std::filesystem::path binary_dir = argv[1];
  const std::filesystem::path text_dir = argv[2];
  std::filesystem::create_directories(binary_dir);
  std::filesystem::create_directories(text_dir);
  const SparseModel model = SeedModel();
  WriteSeed(binary_dir / "cameras.bin", 0, WriteToString(WriteCamerasBinary, model));
  WriteSeed(binary_dir / "images.bin", 1, WriteToString(WriteImagesBinary, model));
  WriteSeed(binary_dir / "points3D.bin", 2, WriteToString(WritePoints3DBinary, model));
  WriteSeed(text_dir / "cameras.txt", 0, WriteToString(WriteCamerasText, model));
  WriteSeed(text_dir / "images.txt", 1, WriteToString(WriteImagesText, model));
  WriteSeed(text_dir / "points3D.txt", 2, WriteToString(WritePoints3DText, model));
  return 0;
}
