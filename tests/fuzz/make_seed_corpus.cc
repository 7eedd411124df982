// Writes the seed corpus of every fuzz target, one directory per target
// (tests/fuzz/corpus/<target>/), from small valid files as the project's own
// writers produce them. The committed corpus was made with
//
//   build-fuzz/tests/fuzz/dispmvs_fuzz_seeds tests/fuzz/corpus
//
// (docs/fuzzing.md). Every file is deterministic, so rerunning it on an
// unchanged tree changes nothing.
//
// The sparse-model seeds carry the selector byte the sparse-model targets
// expect (0 cameras, 1 images, 2 points3D); every other target takes a plain
// file.

#include <torch/torch.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "colmap_io/dense_array.h"
#include "colmap_io/ply.h"
#include "colmap_io/sparse_model_io.h"
#include "colmap_io/stereo_config.h"
#include "model/config.h"
#include "model/safetensors.h"

namespace {

namespace fs = std::filesystem;
using namespace dispmvs::colmap_io;

void WriteBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << bytes;
  if (!out) throw std::runtime_error("cannot write " + path.string());
}

fs::path TargetDir(const fs::path& corpus, const std::string& target) {
  const fs::path dir = corpus / target;
  fs::create_directories(dir);
  return dir;
}

// --- sparse models ---------------------------------------------------------

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

template <typename Writer>
std::string WithSelector(char selector, Writer writer, const SparseModel& model) {
  std::ostringstream out;
  out.put(selector);
  writer(model, out, "seed");
  return out.str();
}

void WriteSparseModelSeeds(const fs::path& corpus) {
  const SparseModel model = SeedModel();
  const fs::path binary = TargetDir(corpus, "sparse_model_binary_fuzzer");
  WriteBytes(binary / "cameras.bin", WithSelector(0, WriteCamerasBinary, model));
  WriteBytes(binary / "images.bin", WithSelector(1, WriteImagesBinary, model));
  WriteBytes(binary / "points3D.bin", WithSelector(2, WritePoints3DBinary, model));
  const fs::path text = TargetDir(corpus, "sparse_model_text_fuzzer");
  WriteBytes(text / "cameras.txt", WithSelector(0, WriteCamerasText, model));
  WriteBytes(text / "images.txt", WithSelector(1, WriteImagesText, model));
  WriteBytes(text / "points3D.txt", WithSelector(2, WritePoints3DText, model));
}

// --- dense arrays ----------------------------------------------------------

void WriteDenseArraySeeds(const fs::path& corpus) {
  const fs::path dir = TargetDir(corpus, "dense_array_fuzzer");
  // A depth map with holes (0) and a NaN, a normal map, a one-value map.
  DenseArray depth(5, 4, 1);
  for (int row = 0; row < 4; ++row) {
    for (int col = 0; col < 5; ++col) depth.at(row, col) = (row + 1) * 0.5f + col * 0.125f;
  }
  depth.at(0, 0) = 0.0f;
  depth.at(3, 4) = std::numeric_limits<float>::quiet_NaN();
  WriteDenseArray(depth, dir / "depth.bin");
  DenseArray normal(2, 3, 3);
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 2; ++col) normal.at(row, col, 2) = -1.0f;
  }
  WriteDenseArray(normal, dir / "normal.bin");
  WriteDenseArray(DenseArray(1, 1, 1, 0.75f), dir / "confidence.bin");
}

// --- stereo configs --------------------------------------------------------

void WriteStereoConfigSeeds(const fs::path& corpus) {
  const fs::path dir = TargetDir(corpus, "stereo_config_fuzzer");
  WritePatchMatchConfig({{"a.jpg", SourceSpec::Auto(20)},
                         {"sub/b.png", SourceSpec::All()},
                         {"c d.jpg", SourceSpec::Explicit({"a.jpg", "sub/b.png"})}},
                        dir / "patch-match.cfg");
  WriteFusionConfig({"a.jpg", "sub/b.png", "c d.jpg"}, dir / "fusion.cfg");
  // What the writers never produce but the readers accept (COLMAP's rules):
  // a byte order mark, comments, blank lines, padding and Windows line ends.
  WriteBytes(dir / "patch-match-windows.cfg",
             "\xEF\xBB\xBF# written on Windows\r\n\r\n  a.jpg  \r\n__auto__ , 3\r\n"
             "b.jpg\r\n  c.jpg ,a.jpg\r\n");
  // The input that found the writers' byte order mark bug (docs/fuzzing.md):
  // a name that starts with the mark, which the writers must refuse.
  WriteBytes(dir / "regression-bom-name.cfg", " \xEF\xBB\xBF# a.jpg\nb.jpg\n");
}

// --- PLY -------------------------------------------------------------------

void WritePlySeeds(const fs::path& corpus) {
  const fs::path dir = TargetDir(corpus, "ply_fuzzer");
  PlyPoint p;
  p.xyz = {1.0f, -2.0f, 0.5f};
  p.normal = {0.0f, 0.0f, 1.0f};
  p.rgb = {10, 200, 255};
  PlyPoint q;
  q.xyz = {-0.25f, 3.0f, 1e-3f};
  q.normal = {0.6f, -0.8f, 0.0f};
  q.rgb = {0, 1, 2};
  WritePlyPoints({p, q}, dir / "fused.ply");
  WritePlyPoints({}, dir / "empty.ply");
}

// --- safetensors -----------------------------------------------------------

void WriteSafetensorsSeeds(const fs::path& corpus) {
  namespace model = dispmvs::model;
  const fs::path dir = TargetDir(corpus, "safetensors_fuzzer");
  // Weights as SaveModuleWeights writes them: a model configuration in the
  // metadata (what ReadModelConfig reads), parameters by name.
  const auto options = torch::TensorOptions().dtype(torch::kFloat32);
  model::SaveSafetensors((dir / "weights.safetensors").string(),
                         {{"conv.bias", torch::arange(3, options)},
                          {"conv.weight", torch::linspace(-1, 1, 12, options).view({3, 1, 2, 2})},
                          {"norm.running_mean", torch::zeros({3}, options)}},
                         model::ModelConfig::SmallV2().ToMetadata());
  // Every dtype the loader knows, a scalar and an empty tensor, no metadata.
  model::SaveSafetensors(
      (dir / "dtypes.safetensors").string(),
      {{"f64", torch::tensor({0.5, -2.0}, torch::kFloat64)},
       {"f16", torch::tensor({1.0, 0.25}).to(torch::kFloat16)},
       {"bf16", torch::tensor({3.0}).to(torch::kBFloat16)},
       {"i64", torch::tensor({int64_t{1} << 40}, torch::kInt64)},
       {"i32", torch::tensor({-7}, torch::kInt32)},
       {"i16", torch::tensor({300}, torch::kInt16)},
       {"i8", torch::tensor({-1, 2}, torch::kInt8)},
       {"u8", torch::tensor({255}, torch::kUInt8)},
       {"bool", torch::tensor({true, false, true})},
       {"scalar", torch::tensor(2.5f)},
       {"empty", torch::zeros({0, 4})}},
      {});
}

// --- images ----------------------------------------------------------------

void WriteImageSeeds(const fs::path& corpus) {
  const fs::path dir = TargetDir(corpus, "image_fuzzer");
  // A small gradient, in the types ReadImageRgb accepts (OpenCV order: BGR).
  cv::Mat bgr(6, 8, CV_8UC3);
  for (int row = 0; row < bgr.rows; ++row) {
    for (int col = 0; col < bgr.cols; ++col) {
      bgr.at<cv::Vec3b>(row, col) = cv::Vec3b(static_cast<uint8_t>(30 * col),
                                              static_cast<uint8_t>(40 * row), 128);
    }
  }
  cv::Mat bgra;
  cv::cvtColor(bgr, bgra, cv::COLOR_BGR2BGRA);
  cv::Mat grey16(5, 3, CV_16UC1);
  for (int i = 0; i < 15; ++i) grey16.at<uint16_t>(i / 3, i % 3) = static_cast<uint16_t>(i * 4369);
  cv::Mat grey8;
  grey16.convertTo(grey8, CV_8U, 1.0 / 257.0);

  // How the project writes images (synth/, examples/): cv::imencode.
  const auto encode = [&](const std::string& name, const cv::Mat& image) {
    const std::string extension = fs::path(name).extension().string();
    std::vector<uchar> bytes;
    if (!cv::imencode(extension, image, bytes)) throw std::runtime_error("cannot encode " + name);
    WriteBytes(dir / name, std::string(bytes.begin(), bytes.end()));
  };
  encode("colour.png", bgr);
  encode("alpha.png", bgra);
  encode("grey16.png", grey16);
  encode("colour.jpg", bgr);
  encode("grey.bmp", grey8);
  encode("grey16.pgm", grey16);
  encode("colour.ppm", bgr);
  encode("colour.tif", bgr);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: " << argv[0] << " CORPUS_DIR   (writes CORPUS_DIR/<target>/...)\n";
    return 2;
  }
  const fs::path corpus = argv[1];
  try {
    WriteSparseModelSeeds(corpus);
    WriteDenseArraySeeds(corpus);
    WriteStereoConfigSeeds(corpus);
    WritePlySeeds(corpus);
    WriteSafetensorsSeeds(corpus);
    WriteImageSeeds(corpus);
  } catch (const std::exception& e) {
    std::cerr << "dispmvs_fuzz_seeds: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
