// Interoperability with the real COLMAP binary (Debian's colmap 3.8): models
// written by our writers are converted by `colmap model_converter` and read
// back by our readers, in every direction, and must come back unchanged.
//
// What COLMAP 3.8's model_converter does to a model (found by running it;
// see Reconstruction::Read*/Write* in COLMAP's src/base/reconstruction.cc):
//  * Values are copied exactly: the binary form stores the doubles, and the
//    text form prints them with 17 significant digits, enough to restore
//    every double bit for bit. So all comparisons below are exact.
//  * Quaternions are normalised on reading and again on writing. Unit
//    quaternions with power-of-two components (used in the main model) are
//    unchanged; other ones may move by an ulp, and non-unit ones come back
//    scaled to unit length (QuaternionsComeBackNormalised).
//  * Nothing is dropped or reordered within a record: every image read from
//    a model file counts as registered and is written, points without a
//    track and images without points2D survive, track order is kept.
//  * Records are written in hash-map order, not id order, so the files are
//    not byte-identical to ours; the models they hold are.
//  * It requires what our validation requires (an image's camera must
//    exist, parameter counts must match the model); it aborts otherwise.
//  * Its text headers are the ones our text writer produces.

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "colmap_io/sparse_model.h"
#include "colmap_io/sparse_model_io.h"
#include "tests/support/sparse_model_fixtures.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::colmap_io {
namespace {

namespace fs = std::filesystem;
using testing::ExpectIdenticalModels;
using testing::MakeCamera;
using testing::MakeImage;
using testing::ReadFileBytes;
using testing::TempDir;

std::optional<fs::path> FindColmapOnPath() {
  const char* path_env = std::getenv("PATH");
  if (path_env == nullptr) return std::nullopt;
  std::stringstream dirs(path_env);
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    if (dir.empty()) continue;
    const fs::path candidate = fs::path(dir) / "colmap";
    std::error_code ec;
    const auto perms = fs::status(candidate, ec).permissions();
    if (!ec && fs::is_regular_file(candidate, ec) &&
        (perms & fs::perms::owner_exec) != fs::perms::none) {
      return candidate;
    }
  }
  return std::nullopt;
}

// Runs `colmap model_converter`, failing the test (with COLMAP's output)
// when colmap is missing or does not exit 0. Callers wrap it in
// ASSERT_NO_FATAL_FAILURE.
void RunModelConverter(const fs::path& input, const fs::path& output, const char* type,
                       const fs::path& log_dir) {
  const std::optional<fs::path> colmap = FindColmapOnPath();
  ASSERT_TRUE(colmap.has_value())
      << "the `colmap` binary is not on PATH: install COLMAP 3.8 (Debian package `colmap`); "
         "CI installs it, and these interop tests cannot run without it";
  fs::create_directories(output);
  const fs::path log = log_dir / "colmap.log";
  // Temp paths contain no quotes, so single quotes suffice. Headless: COLMAP
  // links Qt, which must not look for a display.
  const std::string command = "QT_QPA_PLATFORM=offscreen '" + colmap->string() +
                              "' model_converter --input_path '" + input.string() +
                              "' --output_path '" + output.string() + "' --output_type " + type +
                              " > '" + log.string() + "' 2>&1";
  const int status = std::system(command.c_str());
  ASSERT_EQ(status, 0) << command << "\n" << ReadFileBytes(log);
}

// Adds a 3-D point observed as a new point2D in each of `observers`.
void AddPoint(SparseModel* m, point3D_t id, const Eigen::Vector3d& xyz, std::array<uint8_t, 3> rgb,
              double error, const std::vector<image_t>& observers) {
  Point3D point;
  point.point3D_id = id;
  point.xyz = xyz;
  point.rgb = rgb;
  point.error = error;
  for (const image_t image_id : observers) {
    Image& image = m->images.at(image_id);
    Point2D obs;
    // Distinct, awkward coordinates derived from the ids.
    obs.xy = Eigen::Vector2d(static_cast<double>(id) / 3.0 + image_id, 0.1 * image_id + 7.0 / 11.0);
    obs.point3D_id = id;
    point.track.push_back({image_id, static_cast<uint32_t>(image.points2D.size())});
    image.points2D.push_back(obs);
  }
  m->points3D[id] = point;
}

// Five camera models, sub-folder names, observations with and without 3-D
// points, an image without any, a point without a track, ids above 2^32,
// and doubles that only 17 digits restore (1/3, 0.1, -0.0, subnormals).
SparseModel MakeInteropModel() {
  SparseModel m;
  m.cameras[1] = MakeCamera(1, 0, 640, 480, {500.25, 320, 240});                  // SIMPLE_PINHOLE
  m.cameras[2] = MakeCamera(2, 1, 800, 600, {700.1, 701.0 / 3.0, 400.5, 299.5});  // PINHOLE
  m.cameras[3] = MakeCamera(3, 2, 1024, 768, {900, 512, 384, -0.0123456789});     // SIMPLE_RADIAL
  m.cameras[5] = MakeCamera(5, 4, 1920, 1080,                                     // OPENCV
                            {1500.5, 1501.5, 960, 540, 0.1, -0.2, 1e-5, -3e-6});
  m.cameras[8] = MakeCamera(
      8, 6, 4000, 3000,  // FULL_OPENCV
      {3000, 3000, 2000, 1500, 0.01, -0.02, 0.003, -0.004, 5e-4, -0.0, 5e-324, 1.0 / 7.0});

  // Unit quaternions whose components are powers of two (or zero): COLMAP's
  // renormalisation leaves them unchanged.
  m.images[1] = MakeImage(1, 1, "a.jpg", {1, 0, 0, 0}, {0.1, -0.2, 0.3});
  m.images[2] = MakeImage(2, 2, "set1/b.png", {0.5, 0.5, -0.5, 0.5}, {1.0 / 3.0, 2, -1e-12});
  m.images[3] = MakeImage(3, 3, "set1/deep/c.JPG", {0, 0, 0, 1}, {-0.0, 5, 6});
  m.images[7] = MakeImage(7, 5, "set2/d.tif", {0, 1, 0, 0}, {1e10, -2.5, 3.75});
  m.images[9] = MakeImage(9, 8, "e.jpg", {0.5, -0.5, -0.5, -0.5}, {0, 0, 0});  // sees nothing
  m.images[1].points2D.push_back({Eigen::Vector2d(0.5, 0.5), kInvalidPoint3DId});

  AddPoint(&m, 1, {1, 2, 3}, {255, 128, 0}, 0.5, {1, 2});
  AddPoint(&m, 2, {1.0 / 3.0, -0.1, 1e-300}, {1, 2, 3}, 0.123456789012345678, {2, 3, 7});
  AddPoint(&m, (uint64_t{1} << 33) + 5, {-7, 8, 9}, {9, 8, 7}, -1, {7, 1});
  AddPoint(&m, 40, {0, 0, 0}, {0, 0, 0}, 2.5, {});  // no track
  m.images[7].points2D.push_back({Eigen::Vector2d(1919.75, 1079.25), kInvalidPoint3DId});
  return m;
}

// The '#' lines of a text model file.
std::vector<std::string> CommentLines(const fs::path& path) {
  std::stringstream in(ReadFileBytes(path));
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty() && line[0] == '#') lines.push_back(line);
  }
  return lines;
}

TEST(ColmapInteropTest, OurBinaryToColmapText) {
  TempDir tmp;
  const SparseModel model = MakeInteropModel();
  WriteSparseModelBinary(model, tmp.path() / "ours");
  ASSERT_NO_FATAL_FAILURE(
      RunModelConverter(tmp.path() / "ours", tmp.path() / "colmap", "TXT", tmp.path()));
  ExpectIdenticalModels(model, ReadSparseModelText(tmp.path() / "colmap"));

  // Our text writer produces COLMAP's header comments, statistics included.
  WriteSparseModelText(model, tmp.path() / "ours_txt");
  for (const char* file : {"cameras.txt", "images.txt", "points3D.txt"}) {
    EXPECT_EQ(CommentLines(tmp.path() / "ours_txt" / file),
              CommentLines(tmp.path() / "colmap" / file))
        << file;
  }
}

TEST(ColmapInteropTest, OurTextToColmapBinary) {
  TempDir tmp;
  const SparseModel model = MakeInteropModel();
  WriteSparseModelText(model, tmp.path() / "ours");
  ASSERT_NO_FATAL_FAILURE(
      RunModelConverter(tmp.path() / "ours", tmp.path() / "colmap", "BIN", tmp.path()));
  ExpectIdenticalModels(model, ReadSparseModelBinary(tmp.path() / "colmap"));
}

TEST(ColmapInteropTest, OurBinaryToColmapBinary) {
  TempDir tmp;
  const SparseModel model = MakeInteropModel();
  WriteSparseModelBinary(model, tmp.path() / "ours");
  ASSERT_NO_FATAL_FAILURE(
      RunModelConverter(tmp.path() / "ours", tmp.path() / "colmap", "BIN", tmp.path()));
  ExpectIdenticalModels(model, ReadSparseModelBinary(tmp.path() / "colmap"));
  // Same sizes: COLMAP wrote the same records, merely in another order.
  for (const char* file : {"cameras.bin", "images.bin", "points3D.bin"}) {
    EXPECT_EQ(fs::file_size(tmp.path() / "ours" / file),
              fs::file_size(tmp.path() / "colmap" / file))
        << file;
  }
}

TEST(ColmapInteropTest, QuaternionsComeBackNormalised) {
  TempDir tmp;
  SparseModel model = MakeInteropModel();
  model.images.at(1).qvec = Eigen::Vector4d(2, 0, 0, 0);  // norm 2
  model.images.at(2).qvec = Eigen::Vector4d(0, 0, 3, 4);  // norm 5
  const Eigen::Vector4d generic = Eigen::Vector4d(0.1, -0.7, 0.5, 0.3).normalized();
  model.images.at(3).qvec = generic;
  WriteSparseModelBinary(model, tmp.path() / "ours");
  ASSERT_NO_FATAL_FAILURE(
      RunModelConverter(tmp.path() / "ours", tmp.path() / "colmap", "BIN", tmp.path()));
  const SparseModel back = ReadSparseModelBinary(tmp.path() / "colmap");
  EXPECT_EQ(back.images.at(1).qvec, Eigen::Vector4d(1, 0, 0, 0));
  EXPECT_TRUE(back.images.at(2).qvec.isApprox(Eigen::Vector4d(0, 0, 0.6, 0.8), 1e-15))
      << back.images.at(2).qvec.transpose();
  // Already unit: at most rounding in the last bits from renormalising.
  EXPECT_TRUE(back.images.at(3).qvec.isApprox(generic, 1e-15))
      << back.images.at(3).qvec.transpose();
  // The rotation they describe is the same.
  for (const image_t id : {1u, 2u, 3u}) {
    EXPECT_TRUE(
        back.images.at(id).RotationMatrix().isApprox(model.images.at(id).RotationMatrix(), 1e-14))
        << "image " << id;
  }
}

}  // namespace
}  // namespace dispmvs::colmap_io
