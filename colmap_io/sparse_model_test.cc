// Tests of the COLMAP sparse-model types, readers and writers: exact round
// trips, byte layouts and text lines built by hand, geometry worked out by
// hand, and one test per kind of malformed input.

#include "colmap_io/sparse_model.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <new>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "colmap_io/camera_models.h"
#include "colmap_io/error.h"
#include "colmap_io/sparse_model_io.h"
#include "tests/support/sparse_model_fixtures.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::colmap_io {
namespace {

using testing::ExpectIdenticalModels;
using testing::MakeCamera;
using testing::MakeImage;
using testing::ReadFileBytes;
using testing::TempDir;
using testing::WriteFileBytes;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// ---------------------------------------------------------------------------
// Helpers

// Little-endian byte strings written by hand, independent of the writer.
class Bytes {
 public:
  Bytes& U8(uint8_t v) { return Raw(&v, 1); }
  Bytes& U32(uint32_t v) { return Int(v, 4); }
  Bytes& I32(int32_t v) { return Int(static_cast<uint32_t>(v), 4); }
  Bytes& U64(uint64_t v) { return Int(v, 8); }
  Bytes& I64(int64_t v) { return Int(static_cast<uint64_t>(v), 8); }
  Bytes& F64(double v) {
    uint64_t bits;
    std::memcpy(&bits, &v, 8);
    return Int(bits, 8);
  }
  Bytes& Str(const std::string& s) {  // NUL-terminated
    data_ += s;
    data_.push_back('\0');
    return *this;
  }
  const std::string& str() const { return data_; }

 private:
  Bytes& Int(uint64_t v, int n) {
    for (int i = 0; i < n; ++i) data_.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
    return *this;
  }
  Bytes& Raw(const void* p, size_t n) {
    data_.append(static_cast<const char*>(p), n);
    return *this;
  }
  std::string data_;
};

Point2D Obs(double x, double y, point3D_t id = kInvalidPoint3DId) {
  Point2D p;
  p.xy = Eigen::Vector2d(x, y);
  p.point3D_id = id;
  return p;
}

// Several camera models, names in sub-folders, awkward doubles (1/3, 0.1,
// -0.0, the smallest subnormal, huge values), point ids above 2^32, an image
// without points2D and a point without a track.
SparseModel MakeRichModel() {
  SparseModel m;
  m.cameras[1] = MakeCamera(1, 0, 640, 480, {500, 320, 240});                    // SIMPLE_PINHOLE
  m.cameras[2] = MakeCamera(2, 1, 800, 600, {700.5, 701.25, 400.1, 1.0 / 3.0});  // PINHOLE
  m.cameras[7] = MakeCamera(7, 4, 1024, 768,                                     // OPENCV
                            {0.1, 1e300, 511.5, 383.5, -0.0, 5e-324, 1e-17, -2.5});
  m.cameras[9] = MakeCamera(9, 6, 4000, 3000,  // FULL_OPENCV
                            {3000.125, 3001.0625, 2000, 1500, 0.01, -0.02, 0.003, -0.004, 0.0005,
                             1.0 / 7.0, -1.0 / 9.0, 2.0 / 3.0});
  m.cameras[10] = MakeCamera(10, 10, 100, 50,  // THIN_PRISM_FISHEYE
                             {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12});

  const point3D_t big_id = (uint64_t{1} << 40) + 3;
  Image a = MakeImage(1, 1, "a.jpg", {1, 0, 0, 0}, {0.1, -0.2, 0.3});
  a.points2D = {Obs(10.5, 20.25, 5), Obs(1.0 / 3.0, 2.0 / 3.0), Obs(300, 200, big_id)};
  Image b = MakeImage(4, 2, "sub/dir/b.png", Eigen::Vector4d(0.1, -0.7, 0.5, 0.3).normalized(),
                      {-1e-9, 12345.678, -0.0});
  b.points2D = {Obs(-0.0, 599.999, big_id), Obs(1, 2, 5)};
  // No points2D at all.
  const Image c = MakeImage(70000, 9, "sub/c.JPG", {0.5, 0.5, -0.5, 0.5}, {1, 2, 3});
  Image d = MakeImage(5, 7, "d.tif", {1, 0, 0, 0}, {0, 0, 0});
  d.points2D = {Obs(5, 6)};
  m.images[a.image_id] = a;
  m.images[b.image_id] = b;
  m.images[c.image_id] = c;
  m.images[d.image_id] = d;

  Point3D p5;
  p5.point3D_id = 5;
  p5.xyz = Eigen::Vector3d(1.0 / 3.0, -2.5, 1e-310);
  p5.rgb = {255, 0, 128};
  p5.error = 0.123456789012345678;
  p5.track = {{4, 1}, {1, 0}};
  Point3D pbig;
  pbig.point3D_id = big_id;
  pbig.xyz = Eigen::Vector3d(-7, 8.5, 1e20);
  pbig.rgb = {1, 2, 3};
  pbig.error = -1;
  pbig.track = {{1, 2}, {4, 0}};
  Point3D lonely;  // no track: legal in the format
  lonely.point3D_id = 6;
  lonely.xyz = Eigen::Vector3d(0, 0, 1);
  m.points3D[p5.point3D_id] = p5;
  m.points3D[pbig.point3D_id] = pbig;
  m.points3D[lonely.point3D_id] = lonely;
  return m;
}

// Runs `action`, expecting an IoError whose message contains every fragment.
void ExpectIoError(const std::function<void()>& action, const std::vector<std::string>& fragments) {
  try {
    action();
  } catch (const IoError& e) {
    const std::string message = e.what();
    for (const std::string& fragment : fragments) {
      EXPECT_NE(message.find(fragment), std::string::npos)
          << "message '" << message << "' lacks '" << fragment << "'";
    }
    return;
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected IoError, got another exception: " << e.what();
    return;
  }
  ADD_FAILURE() << "expected IoError, nothing was thrown";
}

// A directory holding a valid binary (or text) model, whose single files the
// bad-input tests then replace.
class BadInputTest : public ::testing::Test {
 protected:
  void SetUp() override {
    WriteSparseModelBinary(MakeRichModel(), dir_.path());
    WriteSparseModelText(MakeRichModel(), dir_.path());
  }
  void ExpectBinaryError(const std::string& file, const std::string& bytes,
                         std::vector<std::string> fragments) {
    WriteFileBytes(dir_.path() / file, bytes);
    fragments.push_back(file);
    ExpectIoError([&] { ReadSparseModelBinary(dir_.path()); }, fragments);
  }
  void ExpectTextError(const std::string& file, const std::string& text,
                       std::vector<std::string> fragments) {
    WriteFileBytes(dir_.path() / file, text);
    fragments.push_back(file);
    ExpectIoError([&] { ReadSparseModelText(dir_.path()); }, fragments);
  }
  TempDir dir_;
};

// One SIMPLE_PINHOLE camera record.
Bytes& AppendCamera(Bytes& b, uint32_t id, int32_t model_id = 0) {
  b.U32(id).I32(model_id).U64(640).U64(480);
  const size_t n = CameraModelById(model_id).num_params;
  for (size_t i = 0; i < n; ++i) b.F64(100.0 + static_cast<double>(i));
  return b;
}

// The head of one image record up to and including the name.
Bytes& AppendImageHead(Bytes& b, uint32_t id, const std::string& name, double qw = 1, double tx = 0,
                       uint32_t camera_id = 1) {
  return b.U32(id).F64(qw).F64(0).F64(0).F64(0).F64(tx).F64(0).F64(0).U32(camera_id).Str(name);
}

// ---------------------------------------------------------------------------
// Camera models

TEST(CameraModelsTest, TableMatchesColmap) {
  // Ids, names and parameter counts as in COLMAP 3.8's camera_models.h.
  const std::vector<std::pair<std::string, size_t>> expected = {{"SIMPLE_PINHOLE", 3},
                                                                {"PINHOLE", 4},
                                                                {"SIMPLE_RADIAL", 4},
                                                                {"RADIAL", 5},
                                                                {"OPENCV", 8},
                                                                {"OPENCV_FISHEYE", 8},
                                                                {"FULL_OPENCV", 12},
                                                                {"FOV", 5},
                                                                {"SIMPLE_RADIAL_FISHEYE", 4},
                                                                {"RADIAL_FISHEYE", 5},
                                                                {"THIN_PRISM_FISHEYE", 12}};
  ASSERT_EQ(AllCameraModels().size(), expected.size());
  for (size_t id = 0; id < expected.size(); ++id) {
    const CameraModelInfo& by_id = CameraModelById(static_cast<int>(id));
    EXPECT_EQ(by_id.id, static_cast<int>(id));
    EXPECT_EQ(by_id.name, expected[id].first);
    EXPECT_EQ(by_id.num_params, expected[id].second) << expected[id].first;
    EXPECT_EQ(&CameraModelByName(expected[id].first), &by_id);
  }
}

TEST(CameraModelsTest, UnknownIdOrNameIsAClearError) {
  EXPECT_EQ(FindCameraModelById(11), nullptr);
  EXPECT_EQ(FindCameraModelById(-1), nullptr);
  EXPECT_EQ(FindCameraModelByName("pinhole"), nullptr);  // names are case sensitive
  try {
    CameraModelById(42);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("42"), std::string::npos) << e.what();
  }
  EXPECT_THROW(CameraModelByName("FISHEYE_DELUXE"), std::invalid_argument);
}

// ---------------------------------------------------------------------------
// Geometry

TEST(SparseModelGeometryTest, CalibrationMatrixOfPinholeModels) {
  const Camera simple = MakeCamera(3, 0, 640, 480, {500, 320, 240});
  Eigen::Matrix3d expected;
  expected << 500, 0, 320, 0, 500, 240, 0, 0, 1;
  EXPECT_TRUE(simple.IsPinhole());
  EXPECT_EQ(simple.CalibrationMatrix(), expected);

  const Camera pinhole = MakeCamera(4, 1, 640, 480, {510, 520, 330, 250});
  expected << 510, 0, 330, 0, 520, 250, 0, 0, 1;
  EXPECT_TRUE(pinhole.IsPinhole());
  EXPECT_EQ(pinhole.CalibrationMatrix(), expected);
}

TEST(SparseModelGeometryTest, CalibrationMatrixRejectsDistortedModels) {
  const Camera opencv = MakeCamera(8, 4, 640, 480, {500, 500, 320, 240, 0.1, 0, 0, 0});
  EXPECT_FALSE(opencv.IsPinhole());
  try {
    opencv.CalibrationMatrix();
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("OPENCV"), std::string::npos) << e.what();
  }
  const Camera short_params = MakeCamera(8, 1, 640, 480, {500, 500, 320});
  EXPECT_THROW(short_params.CalibrationMatrix(), std::invalid_argument);
}

TEST(SparseModelGeometryTest, NinetyDegreesAboutZ) {
  // q = (cos 45°, 0, 0, sin 45°) rotates x to y: R = [0 -1 0; 1 0 0; 0 0 1].
  Image image;
  image.qvec = Eigen::Vector4d(std::sqrt(0.5), 0, 0, std::sqrt(0.5));
  image.tvec = Eigen::Vector3d(1, 2, 3);
  Eigen::Matrix3d R;
  R << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  EXPECT_TRUE(image.RotationMatrix().isApprox(R, 1e-12)) << image.RotationMatrix();
  // C = -R^T t = -(2, -1, 3).
  EXPECT_TRUE(image.ProjectionCenter().isApprox(Eigen::Vector3d(-2, 1, -3), 1e-12))
      << image.ProjectionCenter().transpose();
  EXPECT_TRUE(image.ViewingDirection().isApprox(Eigen::Vector3d(0, 0, 1), 1e-12));
}

TEST(SparseModelTest, AddObservedPointKeepsTracksAndImagesInAgreement) {
  SparseModel model;
  model.cameras[1] = MakeCamera(1, 1, 640, 480, {500, 500, 320, 240});
  for (image_t id : {1u, 2u}) {
    Image image;
    image.image_id = id;
    image.camera_id = 1;
    image.name = "im" + std::to_string(id) + ".png";
    image.points2D.push_back(Point2D{});  // an unmatched keypoint before ours
    model.images[id] = image;
  }
  Point3D point;
  point.point3D_id = 7;
  point.xyz = Eigen::Vector3d(1, 2, 3);
  point.track.push_back({99, 99});  // stale: must be replaced
  model.AddObservedPoint(point, {{2, Eigen::Vector2d(10, 20)}, {1, Eigen::Vector2d(30, 40)}});

  const Point3D& added = model.points3D.at(7);
  ASSERT_EQ(added.track.size(), 2u);
  EXPECT_EQ(added.track[0].image_id, 2u);
  EXPECT_EQ(added.track[0].point2D_idx, 1u);
  EXPECT_EQ(added.track[1].image_id, 1u);
  EXPECT_EQ(added.track[1].point2D_idx, 1u);
  EXPECT_EQ(model.images.at(2).points2D.at(1).xy, Eigen::Vector2d(10, 20));
  EXPECT_EQ(model.images.at(1).points2D.at(1).point3D_id, 7u);
  EXPECT_NO_THROW(ValidateSparseModel(model, "in-memory model"));
  EXPECT_THROW(model.AddObservedPoint(point, {{5, Eigen::Vector2d(0, 0)}}), std::out_of_range);
}

TEST(SparseModelGeometryTest, SetPoseGivesTheHandComputedQuaternion) {
  // R = [0 -1 0; 1 0 0; 0 0 1] (90 degrees about z) is q = (cos 45°, 0, 0, sin 45°).
  Eigen::Matrix3d R;
  R << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  Image image;
  image.SetPose(R, Eigen::Vector3d(1, 2, 3));
  EXPECT_TRUE(image.qvec.isApprox(Eigen::Vector4d(std::sqrt(0.5), 0, 0, std::sqrt(0.5)), 1e-12))
      << image.qvec.transpose();
  EXPECT_EQ(image.tvec, Eigen::Vector3d(1, 2, 3));
}

TEST(SparseModelGeometryTest, NinetyDegreesAboutXWithUnnormalisedQuaternion) {
  // (2, 2, 0, 0) is 90° about x once normalised: R = [1 0 0; 0 0 -1; 0 1 0].
  Image image;
  image.qvec = Eigen::Vector4d(2, 2, 0, 0);
  image.tvec = Eigen::Vector3d(0, 0, 5);
  Eigen::Matrix3d R;
  R << 1, 0, 0, 0, 0, -1, 0, 1, 0;
  EXPECT_TRUE(image.RotationMatrix().isApprox(R, 1e-12)) << image.RotationMatrix();
  // The camera's +z axis is row 2 of R: world +y. C = -R^T (0,0,5) = (0,-5,0).
  EXPECT_TRUE(image.ViewingDirection().isApprox(Eigen::Vector3d(0, 1, 0), 1e-12));
  EXPECT_TRUE(image.ProjectionCenter().isApprox(Eigen::Vector3d(0, -5, 0), 1e-12));
}

TEST(SparseModelTest, FindImageByName) {
  const SparseModel model = MakeRichModel();
  const Image* b = model.FindImageByName("sub/dir/b.png");
  ASSERT_NE(b, nullptr);
  EXPECT_EQ(b->image_id, 4u);
  EXPECT_EQ(model.FindImageByName("b.png"), nullptr);
  EXPECT_EQ(model.FindImageByName(""), nullptr);
}

// ---------------------------------------------------------------------------
// Round trips and layouts

TEST(SparseModelIoTest, BinaryRoundTripIsBitExact) {
  TempDir dir;
  const SparseModel model = MakeRichModel();
  WriteSparseModelBinary(model, dir.path());
  const SparseModel back = ReadSparseModelBinary(dir.path());
  ExpectIdenticalModels(model, back);
  // Writing what was read gives the same bytes again.
  TempDir again;
  WriteSparseModelBinary(back, again.path());
  for (const char* file : {"cameras.bin", "images.bin", "points3D.bin"}) {
    EXPECT_EQ(ReadFileBytes(dir.path() / file), ReadFileBytes(again.path() / file)) << file;
  }
}

TEST(SparseModelIoTest, TextRoundTripIsExact) {
  TempDir dir;
  const SparseModel model = MakeRichModel();
  WriteSparseModelText(model, dir.path());
  ExpectIdenticalModels(model, ReadSparseModelText(dir.path()));
}

TEST(SparseModelIoTest, BinaryLayoutMatchesHandBuiltBytes) {
  SparseModel m;
  m.cameras[3] = MakeCamera(3, 1, 64, 48, {50, 51, 32, 24});
  Image image;
  image.image_id = 2;
  image.camera_id = 3;
  image.name = "x/y.png";
  image.qvec = Eigen::Vector4d(0, 1, 0, 0);
  image.tvec = Eigen::Vector3d(4, 5, 6);
  image.points2D = {Obs(1.5, 2.5, 9), Obs(3, 4)};
  m.images[2] = image;
  Point3D point;
  point.point3D_id = 9;
  point.xyz = Eigen::Vector3d(7, 8, 9);
  point.rgb = {10, 20, 30};
  point.error = 0.5;
  point.track = {{2, 0}};
  m.points3D[9] = point;

  TempDir dir;
  WriteSparseModelBinary(m, dir.path());
  Bytes cameras;
  cameras.U64(1).U32(3).I32(1).U64(64).U64(48).F64(50).F64(51).F64(32).F64(24);
  Bytes images;
  images.U64(1).U32(2).F64(0).F64(1).F64(0).F64(0).F64(4).F64(5).F64(6).U32(3).Str("x/y.png");
  images.U64(2).F64(1.5).F64(2.5).I64(9).F64(3).F64(4).I64(-1);
  Bytes points;
  points.U64(1).U64(9).F64(7).F64(8).F64(9).U8(10).U8(20).U8(30).F64(0.5).U64(1).U32(2).U32(0);
  EXPECT_EQ(ReadFileBytes(dir.path() / "cameras.bin"), cameras.str());
  EXPECT_EQ(ReadFileBytes(dir.path() / "images.bin"), images.str());
  EXPECT_EQ(ReadFileBytes(dir.path() / "points3D.bin"), points.str());
}

// COLMAP numbers the images of a dense workspace in images.bin's file order
// (fused.ply.vis stores those numbers), which need not be id order.
TEST(SparseModelIoTest, ReadersRecordTheFileOrderOfImages) {
  SparseModel m;
  m.cameras[1] = MakeCamera(1, 1, 64, 48, {50, 51, 32, 24});
  TempDir dir;
  WriteSparseModelBinary(m, dir.path());  // cameras.bin and an empty points3D.bin
  Bytes images;
  images.U64(3);
  for (const uint32_t id : {7u, 2u, 5u}) {
    images.U32(id).F64(1).F64(0).F64(0).F64(0).F64(0).F64(0).F64(0).U32(1);
    images.Str("im" + std::to_string(id) + ".png").U64(0);
  }
  {
    std::ofstream out(dir.path() / "images.bin", std::ios::binary);
    out << images.str();
  }
  const SparseModel binary = ReadSparseModelBinary(dir.path());
  EXPECT_EQ(binary.image_file_order, (std::vector<image_t>{7, 2, 5}));
  EXPECT_EQ(binary.DenseImageOrder(), (std::vector<image_t>{7, 2, 5}));

  // The text reader too (our text writer writes ascending ids).
  TempDir text;
  WriteSparseModelText(binary, text.path());
  EXPECT_EQ(ReadSparseModelText(text.path()).image_file_order, (std::vector<image_t>{2, 5, 7}));

  // A model built in code, or one whose recorded order went stale, uses ids.
  SparseModel edited = binary;
  edited.images.erase(2);
  EXPECT_EQ(edited.DenseImageOrder(), (std::vector<image_t>{5, 7}));
  edited.image_file_order.clear();
  EXPECT_EQ(edited.DenseImageOrder(), (std::vector<image_t>{5, 7}));
}

TEST(SparseModelIoTest, TextLinesMatchColmapsLayout) {
  SparseModel m;
  m.cameras[1] = MakeCamera(1, 0, 640, 480, {500, 320, 240});
  Image image;
  image.image_id = 3;
  image.camera_id = 1;
  image.name = "sub/im.jpg";
  image.qvec = Eigen::Vector4d(1, 0, 0, 0);
  image.tvec = Eigen::Vector3d(0.5, -1, 2);
  image.points2D = {Obs(1.5, 2.25, 4), Obs(0.1, 3)};
  m.images[3] = image;
  Image empty = image;
  empty.image_id = 8;
  empty.name = "empty.jpg";
  empty.points2D.clear();
  m.images[8] = empty;
  Point3D point;
  point.point3D_id = 4;
  point.xyz = Eigen::Vector3d(1, 2, 3);
  point.rgb = {10, 0, 255};
  point.error = 0.25;
  point.track = {{3, 0}};
  m.points3D[4] = point;

  TempDir dir;
  WriteSparseModelText(m, dir.path());
  EXPECT_EQ(ReadFileBytes(dir.path() / "cameras.txt"),
            "# Camera list with one line of data per camera:\n"
            "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
            "# Number of cameras: 1\n"
            "1 SIMPLE_PINHOLE 640 480 500 320 240\n");
  // One observation over two images: 0.5 per image. 0.1 needs 17 digits.
  EXPECT_EQ(ReadFileBytes(dir.path() / "images.txt"),
            "# Image list with two lines of data per image:\n"
            "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
            "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
            "# Number of images: 2, mean observations per image: 0.5\n"
            "3 1 0 0 0 0.5 -1 2 1 sub/im.jpg\n"
            "1.5 2.25 4 0.10000000000000001 3 -1\n"
            "8 1 0 0 0 0.5 -1 2 1 empty.jpg\n"
            "\n");
  EXPECT_EQ(ReadFileBytes(dir.path() / "points3D.txt"),
            "# 3D point list with one line of data per point:\n"
            "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
            "# Number of points: 1, mean track length: 1\n"
            "4 1 2 3 10 0 255 0.25 3 0\n");
}

TEST(SparseModelIoTest, TextDoublesArePrintedLikePrintf17g) {
  // COLMAP prints doubles through a stream with precision 17, i.e. %.17g.
  // Random bit patterns cover subnormals, huge and tiny exponents, signs.
  std::mt19937_64 rng(12345);
  SparseModel m;
  std::string expected;
  for (camera_t id = 1; id <= 300; ++id) {
    Camera c = MakeCamera(id, 6, 10, 10, {});  // FULL_OPENCV: 12 parameters
    std::string line = std::to_string(id) + " FULL_OPENCV 10 10";
    while (c.params.size() < 12) {
      const uint64_t bits = rng();
      double value;
      std::memcpy(&value, &bits, sizeof(value));
      if (!std::isfinite(value)) continue;
      if (c.params.size() == 0) value = std::ldexp(static_cast<double>(bits % 1000), -3);  // short
      c.params.push_back(value);
      char buffer[64];
      std::snprintf(buffer, sizeof(buffer), "%.17g", value);
      line += std::string(" ") + buffer;
    }
    m.cameras[id] = c;
    expected += line + "\n";
  }
  std::ostringstream out;
  WriteCamerasText(m, out, "cameras.txt");
  const std::string text = out.str();
  const size_t body = text.find("\n1 ");
  ASSERT_NE(body, std::string::npos);
  EXPECT_EQ(text.substr(body + 1), expected);
}

TEST(SparseModelIoTest, TextReaderAcceptsColmapQuirks) {
  // Tabs, trailing spaces (COLMAP leaves one after an empty track), CRLF
  // line ends, blank lines and comments between records.
  TempDir dir;
  WriteFileBytes(dir.path() / "cameras.txt", "# c\n\n1\tPINHOLE 64 48 50 51 32 24 \r\n");
  WriteFileBytes(dir.path() / "images.txt",
                 "# i\n2 1 0 0 0 0 0 0 1 a.png\r\n10 20 -1 \r\n# between\n"
                 "3 1 0 0 0 0 0 0 1 b.png\n\n");
  WriteFileBytes(dir.path() / "points3D.txt", "# p\n7 1 2 3 4 5 6 0.5 \n");
  const SparseModel m = ReadSparseModelText(dir.path());
  ASSERT_EQ(m.cameras.size(), 1u);
  EXPECT_EQ(m.cameras.at(1).params, (std::vector<double>{50, 51, 32, 24}));
  ASSERT_EQ(m.images.size(), 2u);
  ASSERT_EQ(m.images.at(2).points2D.size(), 1u);
  EXPECT_EQ(m.images.at(2).points2D[0].xy, Eigen::Vector2d(10, 20));
  EXPECT_FALSE(m.images.at(2).points2D[0].HasPoint3D());
  EXPECT_TRUE(m.images.at(3).points2D.empty());
  ASSERT_EQ(m.points3D.size(), 1u);
  EXPECT_TRUE(m.points3D.at(7).track.empty());
  EXPECT_EQ(m.points3D.at(7).rgb, (std::array<uint8_t, 3>{4, 5, 6}));
}

// ---------------------------------------------------------------------------
// Directory level

TEST(SparseModelIoTest, DetectsFormatAndPrefersBinary) {
  TempDir dir;
  SparseModel binary_model = MakeRichModel();
  SparseModel text_model = MakeRichModel();
  text_model.cameras.at(1).params[0] = 123;  // tells the two apart
  WriteSparseModelText(text_model, dir.path());
  EXPECT_EQ(DetectSparseModelFormat(dir.path()), SparseModelFormat::kText);
  ExpectIdenticalModels(text_model, ReadSparseModel(dir.path()));

  WriteSparseModelBinary(binary_model, dir.path());
  EXPECT_EQ(DetectSparseModelFormat(dir.path()), SparseModelFormat::kBinary);
  ExpectIdenticalModels(binary_model, ReadSparseModel(dir.path()));

  // An incomplete binary trio falls back to the complete text one.
  std::filesystem::remove(dir.path() / "points3D.bin");
  EXPECT_EQ(DetectSparseModelFormat(dir.path()), SparseModelFormat::kText);
}

TEST(SparseModelIoTest, IgnoresFilesOfNewerColmapReleases) {
  TempDir dir;
  WriteSparseModelBinary(MakeRichModel(), dir.path());
  WriteFileBytes(dir.path() / "rigs.bin", "\x01\x02garbage");
  WriteFileBytes(dir.path() / "frames.bin", "garbage");
  WriteFileBytes(dir.path() / "project.ini", "[General]\n");
  ExpectIdenticalModels(MakeRichModel(), ReadSparseModel(dir.path()));
}

TEST(SparseModelIoTest, NoModelIsAnErrorNamingTheDirectory) {
  TempDir dir;
  WriteFileBytes(dir.path() / "cameras.bin", "");
  ExpectIoError([&] { DetectSparseModelFormat(dir.path()); }, {dir.path().string()});
  ExpectIoError([&] { ReadSparseModel(dir.path()); }, {dir.path().string()});
  ExpectIoError([&] { ReadSparseModelText(dir.path()); }, {"cameras.txt", "cannot open"});
}

TEST(SparseModelIoTest, WritersRefuseModelsTheReadersWouldReject) {
  TempDir dir;
  SparseModel spaced = MakeRichModel();
  spaced.images.at(1).name = "with space.jpg";
  WriteSparseModelBinary(spaced, dir.path() / "bin");  // binary holds any name
  EXPECT_EQ(ReadSparseModelBinary(dir.path() / "bin").images.at(1).name, "with space.jpg");
  ExpectIoError([&] { WriteSparseModelText(spaced, dir.path() / "txt"); },
                {"images.txt", "whitespace"});

  SparseModel orphan = MakeRichModel();
  orphan.images.at(5).camera_id = 99;
  ExpectIoError([&] { WriteSparseModelBinary(orphan, dir.path() / "o"); }, {"camera 99"});

  SparseModel wrong_count = MakeRichModel();
  wrong_count.cameras.at(2).params.pop_back();
  ExpectIoError([&] { WriteSparseModelBinary(wrong_count, dir.path() / "w"); },
                {"PINHOLE takes 4 parameters"});
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "w" / "cameras.bin"));
}

// ---------------------------------------------------------------------------
// Bad binary input

TEST_F(BadInputTest, TruncatedFiles) {
  for (const char* file : {"cameras.bin", "images.bin", "points3D.bin"}) {
    const std::string good = ReadFileBytes(dir_.path() / file);
    ExpectBinaryError(file, good.substr(0, good.size() - 1), {"truncated"});
    ExpectBinaryError(file, "", {"truncated"});
    WriteFileBytes(dir_.path() / file, good);
  }
  // Cut inside the name: no NUL before the end.
  Bytes images;
  images.U64(1);
  AppendImageHead(images, 1, "");
  std::string cut = images.str();
  cut.pop_back();  // drop the NUL
  cut += "name-without-end";
  ExpectBinaryError("images.bin", cut, {"image #0", "image_id 1", "NUL"});
}

TEST_F(BadInputTest, CountsThatDoNotMatchTheData) {
  Bytes one_camera;
  one_camera.U64(2);  // declares two, holds one
  AppendCamera(one_camera, 1);
  ExpectBinaryError("cameras.bin", one_camera.str(), {"number of cameras", "wrong count"});
  Bytes extra;
  extra.U64(1);  // declares one, holds two
  AppendCamera(AppendCamera(extra, 1), 2);
  ExpectBinaryError("cameras.bin", extra.str(), {"unexpected bytes", "wrong count"});
}

TEST_F(BadInputTest, HugeCountsFailFastWithoutAllocating) {
  const uint64_t huge = uint64_t{1} << 60;
  Bytes cameras;
  cameras.U64(huge);
  AppendCamera(cameras, 1);
  Bytes images;
  images.U64(1);
  AppendImageHead(images, 1, "a.jpg").U64(huge).F64(1).F64(2).I64(-1);
  Bytes points;
  points.U64(1).U64(5).F64(1).F64(2).F64(3).U8(0).U8(0).U8(0).F64(0).U64(huge).U32(1).U32(0);
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"cameras.bin", cameras.str()}, {"images.bin", images.str()}, {"points3D.bin", points.str()}};
  for (const auto& [file, bytes] : cases) {
    WriteFileBytes(dir_.path() / file, bytes);
    const auto start = std::chrono::steady_clock::now();
    try {
      ReadSparseModelBinary(dir_.path());
      ADD_FAILURE() << file << ": no exception";
    } catch (const IoError& e) {
      EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(std::to_string(huge)), std::string::npos) << e.what();
    } catch (const std::bad_alloc&) {
      ADD_FAILURE() << file << ": tried to allocate for the bogus count";
    } catch (const std::length_error&) {
      ADD_FAILURE() << file << ": tried to allocate for the bogus count";
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_LT(seconds, 2.0) << file;  // generous: the machine is shared
    SetUp();                          // restore the good trio
  }
}

TEST_F(BadInputTest, UnknownCameraModelId) {
  Bytes b;
  b.U64(1).U32(3).I32(11).U64(64).U64(48);
  for (int i = 0; i < 12; ++i) b.F64(1);
  ExpectBinaryError("cameras.bin", b.str(), {"camera #0", "camera_id 3", "model id 11"});
}

TEST_F(BadInputTest, ParameterCountOfAnotherModel) {
  // Declares PINHOLE (4 parameters) but holds SIMPLE_PINHOLE's 3: the file
  // then ends one double early.
  Bytes b;
  b.U64(1).U32(1).I32(1).U64(64).U64(48).F64(50).F64(32).F64(24);
  ExpectBinaryError("cameras.bin", b.str(), {"camera #0", "truncated"});
}

TEST_F(BadInputTest, NonFiniteOrDegenerateCameras) {
  Bytes nan_param;
  nan_param.U64(1).U32(1).I32(0).U64(64).U64(48).F64(50).F64(kNaN).F64(24);
  ExpectBinaryError("cameras.bin", nan_param.str(), {"camera_id 1", "non-finite"});
  Bytes zero_size;
  zero_size.U64(1).U32(1).I32(0).U64(0).U64(48).F64(50).F64(32).F64(24);
  ExpectBinaryError("cameras.bin", zero_size.str(), {"camera_id 1", "zero"});
}

TEST_F(BadInputTest, DuplicateIds) {
  Bytes cameras;
  cameras.U64(2);
  AppendCamera(AppendCamera(cameras, 4), 4);
  ExpectBinaryError("cameras.bin", cameras.str(), {"camera #1", "duplicate camera_id"});
  SetUp();
  Bytes images;
  images.U64(2);
  AppendImageHead(images, 9, "a.jpg").U64(0);
  AppendImageHead(images, 9, "b.jpg").U64(0);
  ExpectBinaryError("images.bin", images.str(), {"image #1", "image_id 9", "duplicate"});
  SetUp();
  Bytes points;
  points.U64(2);
  for (int i = 0; i < 2; ++i) points.U64(77).F64(1).F64(2).F64(3).U8(1).U8(2).U8(3).F64(0).U64(0);
  ExpectBinaryError("points3D.bin", points.str(), {"point3D #1", "point3D_id 77", "duplicate"});
}

TEST_F(BadInputTest, NonFinitePosesAndCoordinates) {
  Bytes nan_q;
  nan_q.U64(1);
  AppendImageHead(nan_q, 1, "a.jpg", kNaN).U64(0);
  ExpectBinaryError("images.bin", nan_q.str(), {"image_id 1", "quaternion"});
  Bytes inf_t;
  inf_t.U64(1);
  AppendImageHead(inf_t, 2, "a.jpg", 1, kInf).U64(0);
  ExpectBinaryError("images.bin", inf_t.str(), {"image_id 2", "translation"});
  Bytes nan_xy;
  nan_xy.U64(1);
  AppendImageHead(nan_xy, 3, "a.jpg").U64(1).F64(1).F64(kNaN).I64(-1);
  ExpectBinaryError("images.bin", nan_xy.str(), {"image_id 3", "point2D #0"});
  SetUp();  // restore a good images.bin
  Bytes inf_xyz;
  inf_xyz.U64(1).U64(5).F64(1).F64(-kInf).F64(3).U8(0).U8(0).U8(0).F64(0).U64(0);
  ExpectBinaryError("points3D.bin", inf_xyz.str(), {"point3D_id 5", "non-finite position"});
  Bytes nan_error;
  nan_error.U64(1).U64(5).F64(1).F64(2).F64(3).U8(0).U8(0).U8(0).F64(kNaN).U64(0);
  ExpectBinaryError("points3D.bin", nan_error.str(), {"point3D_id 5", "error"});
}

TEST_F(BadInputTest, QuaternionThatCannotBeNormalised) {
  Bytes zero_q;
  zero_q.U64(1);
  AppendImageHead(zero_q, 6, "a.jpg", 0).U64(0);  // (0, 0, 0, 0)
  ExpectBinaryError("images.bin", zero_q.str(), {"image_id 6", "cannot be normalised"});
}

TEST_F(BadInputTest, InconsistentFilesNameTheDirectory) {
  const std::string dir = dir_.path().string();
  // images.bin of the rich model, but without camera 7 in cameras.bin.
  Bytes cameras;
  cameras.U64(4);
  for (const auto& [id, cam] : MakeRichModel().cameras) {
    if (id == 7) continue;
    cameras.U32(id).I32(cam.model_id).U64(cam.width).U64(cam.height);
    for (const double p : cam.params) cameras.F64(p);
  }
  WriteFileBytes(dir_.path() / "cameras.bin", cameras.str());
  ExpectIoError([&] { ReadSparseModelBinary(dir_.path()); }, {dir, "image 5", "camera 7"});
  SetUp();

  auto expect_points_error = [&](const Bytes& points, std::vector<std::string> fragments) {
    WriteFileBytes(dir_.path() / "points3D.bin", points.str());
    fragments.push_back(dir);
    ExpectIoError([&] { ReadSparseModelBinary(dir_.path()); }, fragments);
    SetUp();
  };
  // The rich model's points, with one thing changed each time.
  auto points_with = [](uint32_t image_of_5, uint32_t idx_of_5, bool drop_big) {
    Bytes b;
    b.U64(drop_big ? 2 : 3);
    b.U64(5).F64(1).F64(2).F64(3).U8(0).U8(0).U8(0).F64(0).U64(2);
    b.U32(4).U32(1).U32(image_of_5).U32(idx_of_5);
    b.U64(6).F64(0).F64(0).F64(1).U8(0).U8(0).U8(0).F64(0).U64(0);
    if (!drop_big) {
      b.U64((uint64_t{1} << 40) + 3).F64(1).F64(2).F64(3).U8(0).U8(0).U8(0).F64(0).U64(2);
      b.U32(1).U32(2).U32(4).U32(0);
    }
    return b;
  };
  // Unchanged, the hand-built points3D.bin is consistent with the other files.
  WriteFileBytes(dir_.path() / "points3D.bin", points_with(1, 0, false).str());
  EXPECT_NO_THROW(ReadSparseModelBinary(dir_.path()));
  expect_points_error(points_with(99, 0, false), {"point3D 5", "image 99", "no such image"});
  expect_points_error(points_with(1, 3, false), {"point3D 5", "only 3 points2D"});
  expect_points_error(points_with(1, 1, false), {"point3D 5", "does not refer back"});
  expect_points_error(points_with(1, 0, true), {"point3D 1099511627779", "points3D does not"});
  expect_points_error(points_with(4, 1, false), {"point3D 5", "listed twice"});
}

TEST_F(BadInputTest, DuplicateImageNames) {
  Bytes images;
  images.U64(2);
  AppendImageHead(images, 1, "same.jpg").U64(0);
  AppendImageHead(images, 2, "same.jpg").U64(0);
  Bytes points;
  points.U64(0);
  WriteFileBytes(dir_.path() / "points3D.bin", points.str());
  WriteFileBytes(dir_.path() / "images.bin", images.str());
  ExpectIoError([&] { ReadSparseModelBinary(dir_.path()); },
                {dir_.path().string(), "same name 'same.jpg'"});
}

// ---------------------------------------------------------------------------
// Bad text input (line numbers count from 1, comments included)

TEST_F(BadInputTest, TextCameras) {
  const std::string head = "# comment\n# comment\n";
  ExpectTextError("cameras.txt", head + "1 PINHOLE abc 48 1 2 3 4\n", {"line 3", "WIDTH", "abc"});
  ExpectTextError("cameras.txt", head + "\n1 PINHOLE 64\n", {"line 4", "found 3 fields"});
  ExpectTextError("cameras.txt", head + "1 PINHOLEX 64 48 1 2 3 4\n",
                  {"line 3", "unknown camera model 'PINHOLEX'"});
  ExpectTextError("cameras.txt", head + "1 PINHOLE 64 48 1 2 3\n",
                  {"line 3", "PINHOLE takes 4 parameters", "3 were given"});
  ExpectTextError("cameras.txt", head + "1 SIMPLE_PINHOLE 64 48 1 2 3\n1 PINHOLE 64 48 1 2 3 4\n",
                  {"line 4", "duplicate camera id 1"});
  ExpectTextError("cameras.txt", head + "-1 PINHOLE 64 48 1 2 3 4\n", {"line 3", "CAMERA_ID"});
  ExpectTextError("cameras.txt", head + "1 PINHOLE 64 48 1 2 3 nan\n", {"line 3", "non-finite"});
  ExpectTextError("cameras.txt", head + "1 PINHOLE 64 48 1 2 3 4x\n", {"line 3", "'4x'"});
}

TEST_F(BadInputTest, TextImages) {
  const std::string head = "# comment\n";
  ExpectTextError("images.txt", head + "1 one 0 0 0 0 0 0 1 a.jpg\n\n", {"line 2", "'one'"});
  ExpectTextError("images.txt", head + "1 1 0 0 0 0 0 0 1\n\n", {"line 2", "found 9 fields"});
  ExpectTextError("images.txt", head + "1 1 0 0 0 0 0 0 1 my photo.jpg\n\n",
                  {"line 2", "cannot contain spaces"});
  ExpectTextError("images.txt", head + "1 1 0 0 0 0 0 0 1 a.jpg\n",
                  {"image 1", "missing the POINTS2D line"});
  ExpectTextError("images.txt", head + "1 1 0 0 0 0 0 0 1 a.jpg\n1 2 -1 3\n",
                  {"line 3", "found 4 fields"});
  ExpectTextError("images.txt", head + "1 1 0 0 0 0 0 0 1 a.jpg\n1 2 x\n",
                  {"line 3", "POINT3D_ID", "'x'"});
  ExpectTextError("images.txt", head + "1 1 0 0 0 0 0 0 1 a.jpg\n1 2 -2\n",
                  {"line 3", "POINT3D_ID", "'-2'"});
  ExpectTextError("images.txt", head + "1 nan 0 0 0 0 0 0 1 a.jpg\n\n",
                  {"line 2", "image 1", "quaternion"});
  ExpectTextError("images.txt", head + "1 0 0 0 0 0 0 0 1 a.jpg\n\n",
                  {"line 2", "cannot be normalised"});
  ExpectTextError("images.txt", head + "1 1 0 0 0 inf 0 0 1 a.jpg\n\n", {"line 2", "translation"});
  ExpectTextError("images.txt",
                  head +
                      "1 1 0 0 0 0 0 0 1 a.jpg\n\n2 1 0 0 0 0 0 0 1 b.jpg\n\n"
                      "1 1 0 0 0 0 0 0 1 c.jpg\n\n",
                  {"line 6", "duplicate image id 1"});
}

TEST_F(BadInputTest, TextPoints3D) {
  const std::string head = "# comment\n";
  ExpectTextError("points3D.txt", head + "5 1 2 3 256 0 0 0.5\n", {"line 2", "colour", "'256'"});
  ExpectTextError("points3D.txt", head + "5 1 2 3 1 0 0 0.5 1\n", {"line 2", "found 9 fields"});
  ExpectTextError("points3D.txt", head + "5 1 2 3 1 0 0\n", {"line 2", "found 7 fields"});
  ExpectTextError("points3D.txt", head + "5 1 2 3 1 0 0 err\n", {"line 2", "ERROR", "'err'"});
  ExpectTextError("points3D.txt", head + "5 1 2 -inf 1 0 0 0.5\n", {"line 2", "non-finite"});
  ExpectTextError("points3D.txt", head + "5 1 2 3 1 0 0 0.5\n5 1 2 3 1 0 0 0.5\n",
                  {"line 3", "duplicate point3D id 5"});
  ExpectTextError("points3D.txt", head + "5 1 2 3 1 0 0 0.5 1 -4\n", {"line 2", "POINT2D_IDX"});
}

}  // namespace
}  // namespace dispmvs::colmap_io
