// Precision and robustness tests of model/geometry.
//
// The reference is an independent computation in double with Eigen: explicit
// 3-D points X = d K_ref^-1 p~ (the reference camera sits at the origin),
// moved into the source camera (R X + T) and projected with K_src. It never
// uses the a / b coefficients of geometry.h.
//
// Conditioning (which random configurations are meaningful tests). The
// library's rounding errors are a few eps times the pixel coordinates involved
// (magnitude C = the largest image dimension, which also bounds f and c).
// Inverse depth from a match is as accurate as the match position relative to
// how far the match moves when the depth changes: with
//   S = |dp_src / d ln w|  (pixels the match moves per unit RELATIVE change of depth),
// a pixel error delta gives a relative depth error delta / S. So a sample is
// only a fair test of a relative tolerance `tol` when
//   S >= 10 * eps * C / tol,
// i.e. when even ten roundings of the largest coordinate stay below the
// tolerance. A small ray/baseline angle (tiny baseline, far point, pixel
// near the epipole) shows up as a small S and is skipped. Samples must also be
// in front of both cameras and project inside the source image (the network
// only ever matches inside it). For float32 the cameras are rounded from the
// double scene; that input rounding is part of the same eps * C budget.
// Tolerances are derived the same way (a few dozen eps times the magnitudes
// involved), never fitted to the outputs; the tests print the worst errors.

#include "model/geometry.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace dispmvs::model {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector2d;
using Eigen::Vector3d;
using RowMatrix3d = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

constexpr double kPi = 3.14159265358979323846;

double Epsilon(torch::ScalarType dtype) {
  return dtype == torch::kFloat32 ? std::numeric_limits<float>::epsilon()
                                  : std::numeric_limits<double>::epsilon();
}
// Relative depth tolerance required by the brief.
double DepthTolerance(torch::ScalarType dtype) { return dtype == torch::kFloat32 ? 1e-4 : 1e-9; }

torch::Tensor MatrixTensor(const Matrix3d& m, torch::ScalarType dtype) {
  RowMatrix3d row_major = m;
  return torch::from_blob(row_major.data(), {1, 3, 3}, torch::kFloat64).clone().to(dtype);
}
torch::Tensor VectorTensor(const Vector3d& v, torch::ScalarType dtype) {
  Vector3d copy = v;
  return torch::from_blob(copy.data(), {1, 3}, torch::kFloat64).clone().to(dtype);
}
torch::Tensor AsDouble(const torch::Tensor& t) {
  return t.detach().to(torch::kCPU, torch::kFloat64).contiguous();
}

// Reference camera at the origin; (R, T) maps reference to source coordinates.
struct Scene {
  Matrix3d K_ref, K_src, R;
  Vector3d T;
  int ref_width = 0, ref_height = 0, src_width = 0, src_height = 0;

  Vector3d BackProject(const Vector2d& pixel, double depth) const {
    return depth * (K_ref.inverse() * Vector3d(pixel.x(), pixel.y(), 1.0));
  }
  Vector3d ToSource(const Vector3d& X) const { return R * X + T; }
  // Projection into the source image; z of the source-camera point in *z_src.
  Vector2d Project(const Vector3d& X, double* z_src = nullptr) const {
    const Vector3d Xs = ToSource(X);
    if (z_src != nullptr) *z_src = Xs.z();
    const Vector3d h = K_src * Xs;
    return h.head<2>() / h.z();
  }
  Vector2d ProjectDepth(const Vector2d& pixel, double depth) const {
    return Project(BackProject(pixel, depth));
  }
  bool InSource(const Vector2d& p) const {
    return p.x() >= -0.5 && p.x() <= src_width - 0.5 && p.y() >= -0.5 && p.y() <= src_height - 0.5;
  }
  double LargestDimension() const {
    return std::max({ref_width, ref_height, src_width, src_height});
  }
  Scene Scaled(double s) const {
    Scene out = *this;
    out.T *= s;
    return out;
  }
  EpipolarPair Pair(torch::ScalarType dtype) const {
    return MakeEpipolarPair(MatrixTensor(K_ref, dtype), MatrixTensor(K_src, dtype),
                            MatrixTensor(R, dtype), VectorTensor(T, dtype), ref_height, ref_width);
  }
};

double LogUniform(std::mt19937_64& rng, double lo, double hi) {
  return std::exp(std::uniform_real_distribution<double>(std::log(lo), std::log(hi))(rng));
}

Matrix3d RandomIntrinsics(std::mt19937_64& rng, int width, int height) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double f = (0.6 + 1.4 * unit(rng)) * std::max(width, height);
  Matrix3d K = Matrix3d::Identity();
  K(0, 0) = f;
  K(1, 1) = f * (0.9 + 0.2 * unit(rng));
  K(0, 2) = width * (0.4 + 0.2 * unit(rng));
  K(1, 2) = height * (0.4 + 0.2 * unit(rng));
  return K;
}

Vector3d RandomUnitVector(std::mt19937_64& rng) {
  std::normal_distribution<double> normal;
  Vector3d v(normal(rng), normal(rng), normal(rng));
  return v.normalized();
}

Scene RandomScene(std::mt19937_64& rng, double baseline) {
  std::uniform_int_distribution<int> size(16, 768);
  Scene s;
  s.ref_width = size(rng);
  s.ref_height = size(rng);
  s.src_width = size(rng);
  s.src_height = size(rng);
  s.K_ref = RandomIntrinsics(rng, s.ref_width, s.ref_height);
  s.K_src = RandomIntrinsics(rng, s.src_width, s.src_height);
  const double angle = std::uniform_real_distribution<double>(0.0, 40.0 * kPi / 180.0)(rng);
  s.R = Eigen::AngleAxisd(angle, RandomUnitVector(rng)).toRotationMatrix();
  s.T = baseline * RandomUnitVector(rng);
  return s;
}

// One reference pixel with a depth, and what Eigen says about it.
struct Sample {
  int x = 0, y = 0;
  double depth = 0;
  Vector2d src;         // exact source pixel
  double parallax = 0;  // S = |dp_src / d ln w| in pixels
};

// Samples of `scene` that pass the conditioning criterion for `tol` (see the
// file comment), at distinct pixels.
std::vector<Sample> ConditionedSamples(const Scene& scene, std::mt19937_64& rng, int attempts,
                                       double eps, double tol) {
  std::uniform_int_distribution<int> col(0, scene.ref_width - 1);
  std::uniform_int_distribution<int> row(0, scene.ref_height - 1);
  const double min_parallax = 10.0 * eps * scene.LargestDimension() / tol;
  std::set<std::pair<int, int>> used;
  std::vector<Sample> samples;
  for (int i = 0; i < attempts; ++i) {
    Sample s;
    s.x = col(rng);
    s.y = row(rng);
    s.depth = LogUniform(rng, 1e-2, 1e5);
    if (!used.insert({s.x, s.y}).second) continue;
    const Vector2d pixel(s.x, s.y);
    double z_src = 0;
    s.src = scene.Project(scene.BackProject(pixel, s.depth), &z_src);
    if (z_src <= 0 || !scene.InSource(s.src)) continue;
    // Central difference in ln w: w (1 +- h) is depth / (1 +- h).
    const double h = 1e-6;
    const Vector2d nearer = scene.ProjectDepth(pixel, s.depth / (1 + h));
    const Vector2d farther = scene.ProjectDepth(pixel, s.depth / (1 - h));
    s.parallax = (nearer - farther).norm() / (2 * h);
    if (s.parallax < min_parallax) continue;
    samples.push_back(s);
  }
  return samples;
}

// A [1,C,H,W] double image, zero except at the samples.
torch::Tensor SampleImage(const Scene& scene, const std::vector<Sample>& samples, int channels,
                          const std::function<std::vector<double>(const Sample&)>& value) {
  torch::Tensor image =
      torch::zeros({1, channels, scene.ref_height, scene.ref_width}, torch::kFloat64);
  auto acc = image.accessor<double, 4>();
  for (const Sample& s : samples) {
    const std::vector<double> v = value(s);
    for (int c = 0; c < channels; ++c) acc[0][c][s.y][s.x] = v[c];
  }
  return image;
}

// Random access to a [1,C,H,W] tensor (any dtype, any device) as doubles.
class ImageReader {
 public:
  explicit ImageReader(const torch::Tensor& image)
      : data_(AsDouble(image)), access_(data_.accessor<double, 4>()) {}
  double operator()(int channel, int row, int col) const { return access_[0][channel][row][col]; }

 private:
  torch::Tensor data_;
  at::TensorAccessor<double, 4> access_;
};

bool AllFinite(const torch::Tensor& t) { return torch::isfinite(t).all().item<bool>(); }

// A 64x48 reference view whose epipole falls exactly on pixel (20, 15): the
// source camera centre C projects there, K_ref's principal point is chosen so.
Scene EpipoleScene() {
  std::mt19937_64 rng(99);
  Scene s;
  s.ref_width = 64;
  s.ref_height = 48;
  s.src_width = 320;
  s.src_height = 240;
  s.K_ref = RandomIntrinsics(rng, s.ref_width, s.ref_height);
  s.K_src = RandomIntrinsics(rng, s.src_width, s.src_height);
  s.R = Eigen::AngleAxisd(0.3, Vector3d(0.2, 1.0, -0.4).normalized()).toRotationMatrix();
  const Vector3d centre(0.2, -0.1, 1.0);  // source camera centre, reference coordinates
  s.T = -s.R * centre;
  s.K_ref(0, 2) = 20 - s.K_ref(0, 0) * centre.x() / centre.z();
  s.K_ref(1, 2) = 15 - s.K_ref(1, 1) * centre.y() / centre.z();
  return s;
}
constexpr int kEpipoleX = 20, kEpipoleY = 15;

bool At(const torch::Tensor& mask, int row, int col) {
  return mask.index({0, 0, row, col}).item<bool>();
}

std::string DtypeName(const ::testing::TestParamInfo<torch::ScalarType>& info) {
  return info.param == torch::kFloat32 ? "Float32" : "Float64";
}

class GeometryPrecision : public ::testing::TestWithParam<torch::ScalarType> {};

// (1) projection, (2) triangulation of the exact match, (5) direction against
// Eigen's finite difference, over random cameras with baselines 1e-3..1e3 and
// depths 1e-2..1e5.
TEST_P(GeometryPrecision, RandomScenesMatchEigen) {
  const torch::ScalarType dtype = GetParam();
  const double eps = Epsilon(dtype);
  const double tol = DepthTolerance(dtype);
  std::mt19937_64 rng(20230207);

  int tested = 0;
  double smallest_tested_baseline = 1e300, largest_tested_baseline = 0;
  double worst_depth = 0, worst_pixel = 0, worst_direction = 0;
  for (int scene_index = 0; scene_index < 36; ++scene_index) {
    const double baseline = LogUniform(rng, 1e-3, 1e3);
    const Scene scene = RandomScene(rng, baseline);
    const std::vector<Sample> samples = ConditionedSamples(scene, rng, 200, eps, tol);
    if (samples.empty()) continue;
    tested += static_cast<int>(samples.size());
    smallest_tested_baseline = std::min(smallest_tested_baseline, baseline);
    largest_tested_baseline = std::max(largest_tested_baseline, baseline);

    const EpipolarPair pair = scene.Pair(dtype);
    const torch::Tensor inv_depth = SampleImage(scene, samples, 1, [](const Sample& s) {
                                      return std::vector<double>{1.0 / s.depth};
                                    }).to(dtype);
    const torch::Tensor src_xy = SampleImage(scene, samples, 2, [](const Sample& s) {
                                   return std::vector<double>{s.src.x(), s.src.y()};
                                 }).to(dtype);

    const SourcePixels projected = ProjectInverseDepth(pair, inv_depth);
    const InverseDepth triangulated = TriangulateInverseDepth(pair, src_xy);
    const EpipolarDirection direction = ComputeEpipolarDirection(pair);
    ASSERT_TRUE(AllFinite(projected.xy) && AllFinite(triangulated.inv_depth) &&
                AllFinite(direction.dir));

    const ImageReader xy(projected.xy);
    const ImageReader xy_valid(projected.valid);
    const ImageReader w(triangulated.inv_depth);
    const ImageReader w_valid(triangulated.valid);
    const ImageReader dir(direction.dir);
    const ImageReader dir_valid(direction.valid);
    for (const Sample& s : samples) {
      SCOPED_TRACE("scene " + std::to_string(scene_index) + " pixel (" + std::to_string(s.x) + "," +
                   std::to_string(s.y) + ") depth " + std::to_string(s.depth) + " baseline " +
                   std::to_string(baseline));
      // (1) Forward error bound of (sum)/(sum): a few dozen roundings of the
      // coordinates (C), amplified by the cancellation in z_src = (R X)_z + T_z.
      const Vector3d RX = scene.R * scene.BackProject(Vector2d(s.x, s.y), s.depth);
      const double cancellation =
          (std::abs(RX.z()) + std::abs(scene.T.z())) / std::abs(RX.z() + scene.T.z());
      const double pixel_tol = 64 * eps * scene.LargestDimension() * cancellation;
      ASSERT_TRUE(xy_valid(0, s.y, s.x));
      const double pixel_error = (Vector2d(xy(0, s.y, s.x), xy(1, s.y, s.x)) - s.src).norm();
      EXPECT_LE(pixel_error, pixel_tol);
      worst_pixel = std::max(worst_pixel, pixel_error / pixel_tol);

      // (2) Triangulating the exact match recovers the depth.
      ASSERT_TRUE(w_valid(0, s.y, s.x));
      const double depth_error = std::abs(w(0, s.y, s.x) * s.depth - 1.0);
      EXPECT_LE(depth_error, tol);
      worst_depth = std::max(worst_depth, depth_error);

      // (5) Direction = normalised chord between two projections (the
      // epipolar line is straight, so any chord has its direction), pointing
      // towards the nearer point.
      ASSERT_TRUE(dir_valid(0, s.y, s.x));
      const Vector2d pixel(s.x, s.y);
      const Vector2d chord =
          (scene.ProjectDepth(pixel, s.depth / 1.01) - scene.ProjectDepth(pixel, s.depth))
              .normalized();
      const double direction_error = (Vector2d(dir(0, s.y, s.x), dir(1, s.y, s.x)) - chord).norm();
      // The reference chord itself is only as good as its endpoints (rounded
      // to ~eps_64 * C) over its length (~1 % of the parallax S).
      const double chord_error = 16 * std::numeric_limits<double>::epsilon() *
                                 scene.LargestDimension() / (0.01 * s.parallax);
      EXPECT_LE(direction_error, tol + chord_error);
      worst_direction = std::max(worst_direction, direction_error);
    }
  }
  // The criterion must leave a real test: many samples, over the whole range
  // of baselines.
  EXPECT_GE(tested, 300);
  EXPECT_LT(smallest_tested_baseline, 1e-2);
  EXPECT_GT(largest_tested_baseline, 1e2);
  std::printf(
      "[ %s ] %d samples; worst relative depth error %.3g, direction error %.3g, "
      "pixel error / tolerance %.3g\n",
      DtypeName({GetParam(), 0}).c_str(), tested, worst_depth, worst_direction, worst_pixel);
}

// |dp_s/dw| against Eigen: the samples' parallax |dp_s / d ln w| (a central
// difference of two projections in double, h = 1e-6) over w. And 0 behind
// the source.
TEST(GeometryMatchShift, MatchesEigenDifferences) {
  std::mt19937_64 rng(20261206);
  int tested = 0;
  double worst = 0;
  for (int scene_index = 0; scene_index < 12; ++scene_index) {
    const Scene scene = RandomScene(rng, LogUniform(rng, 1e-2, 1e2));
    const std::vector<Sample> samples = ConditionedSamples(scene, rng, 100, 1e-15, 1e-9);
    if (samples.empty()) continue;
    const torch::Tensor inv_depth = SampleImage(scene, samples, 1, [](const Sample& s) {
      return std::vector<double>{1.0 / s.depth};
    });
    const ImageReader shift(MatchShiftPerInverseDepth(scene.Pair(torch::kFloat64), inv_depth));
    for (const Sample& s : samples) {
      const double expected = s.parallax * s.depth;
      const double error = std::abs(shift(0, s.y, s.x) / expected - 1.0);
      // The difference itself is only as good as its two projections
      // (rounded to ~eps_64 * C) over their distance (2e-6 of the parallax).
      const double tolerance =
          1e-9 + 16 * std::numeric_limits<double>::epsilon() * scene.LargestDimension() / (2e-6 * s.parallax);
      EXPECT_LE(error, tolerance) << "scene " << scene_index << " pixel (" << s.x << "," << s.y << ")";
      worst = std::max(worst, error / tolerance);
      ++tested;
    }
  }
  EXPECT_GE(tested, 100);
  std::printf("[ match shift ] %d samples; worst relative error / tolerance %.3g\n", tested, worst);

  // A source straight ahead of the reference (T = (0, 0, -2): the source
  // camera 2 units further along the axis): depths under 2 lie behind it.
  Scene ahead = RandomScene(rng, 1.0);
  ahead.R = Matrix3d::Identity();
  ahead.T = Vector3d(0, 0, -2);
  const torch::Tensor w = torch::full({1, 1, ahead.ref_height, ahead.ref_width}, 1.0, torch::kFloat64);
  EXPECT_TRUE(torch::equal(MatchShiftPerInverseDepth(ahead.Pair(torch::kFloat64), w), torch::zeros_like(w)));
  // Depth 4 lies in front: the match moves, except at the epipole (the
  // principal point, far from the corner).
  EXPECT_GT(MatchShiftPerInverseDepth(ahead.Pair(torch::kFloat64), w * 0.25)[0][0][0][0].item<double>(), 0.0);
}

TEST(GeometryInverseDepthBounds, AreOverTheUsablePixels) {
  torch::Tensor w = torch::tensor({0.5f, 0.2f, 0.9f, 0.0f, 3.0f, 0.1f, 0.4f, 0.7f}).view({2, 1, 2, 2});
  torch::Tensor usable = w > 0;
  usable[0][0][1][0] = false;  // 0.9 is not usable
  usable[1].fill_(false);      // an item without usable pixels
  const auto [low, high] = InverseDepthBounds(w, usable);
  ASSERT_EQ(low.sizes(), torch::IntArrayRef({2, 1, 1, 1}));
  EXPECT_FLOAT_EQ(low[0].item<float>(), 0.2f);
  EXPECT_FLOAT_EQ(high[0].item<float>(), 0.5f);
  EXPECT_TRUE(std::isinf(low[1].item<float>()));
  EXPECT_EQ(high[1].item<float>(), 0.0f);
}

// DistanceInsideSources against projections by hand (Eigen, double): two sources
// of a 30 x 40 reference, random inverse depths from 0.05 to 1.5, a few
// without depth; both outcomes occur at both margins.
TEST(GeometryDistanceInsideSources, MatchesProjectionsByHand) {
  constexpr int64_t kH = 30, kW = 40;
  Matrix3d K;
  K << 35, 0, 19.5, 0, 33, 14.5, 0, 0, 1;
  const Matrix3d K_src[2] = {K, Matrix3d(Eigen::DiagonalMatrix<double, 3>(1.1, 1.0, 1.0) * K)};
  const Matrix3d R[2] = {Matrix3d::Identity(), Eigen::AngleAxisd(0.08, Vector3d::UnitY()).toRotationMatrix()};
  const Vector3d T[2] = {Vector3d(-1.5, 0.1, 0.0), Vector3d(0.9, -0.6, 0.2)};
  const EpipolarPair pair = MakeEpipolarPair(
      torch::cat({MatrixTensor(K, torch::kFloat64), MatrixTensor(K, torch::kFloat64)}),
      torch::cat({MatrixTensor(K_src[0], torch::kFloat64), MatrixTensor(K_src[1], torch::kFloat64)}),
      torch::cat({MatrixTensor(R[0], torch::kFloat64), MatrixTensor(R[1], torch::kFloat64)}),
      torch::tensor({T[0].x(), T[0].y(), T[0].z(), T[1].x(), T[1].y(), T[1].z()}, torch::kFloat64).view({2, 3}),
      kH, kW);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> uniform(0.05, 1.5);
  torch::Tensor w = torch::zeros({1, 1, kH, kW}, torch::kFloat64);
  for (int64_t i = 0; i < kH; ++i) {
    for (int64_t j = 0; j < kW; ++j) w[0][0][i][j] = (i == 0 && j < 5) ? 0.0 : uniform(rng);
  }
  for (const double margin : {0.0, 4.0}) {
    const torch::Tensor seen = DistanceInsideSources(pair, w, 2, kH, kW) >= margin;
    ASSERT_EQ(seen.sizes(), torch::IntArrayRef({1, 1, kH, kW}));
    int64_t some = 0, none = 0;
    for (int64_t i = 0; i < kH; ++i) {
      for (int64_t j = 0; j < kW; ++j) {
        const double wij = w[0][0][i][j].item<double>();
        bool expected = false;
        for (int s = 0; s < 2 && wij > 0; ++s) {
          const Vector3d X = R[s] * (K.inverse() * Vector3d(j, i, 1) / wij) + T[s];
          if (X.z() <= 0) continue;
          const Vector3d p = K_src[s] * X;
          const double u = p.x() / p.z(), v = p.y() / p.z();
          expected = expected || (u >= margin && u <= kW - 1 - margin && v >= margin && v <= kH - 1 - margin);
        }
        EXPECT_EQ(seen[0][0][i][j].item<bool>(), expected) << i << "," << j << " margin " << margin;
        (expected ? some : none) += 1;
      }
    }
    EXPECT_GT(some, 100);
    EXPECT_GT(none, 100);
  }
  EXPECT_THROW(DistanceInsideSources(pair, w, 0, kH, kW), std::invalid_argument);
  EXPECT_THROW(DistanceInsideSources(pair, w, 3, kH, kW), std::invalid_argument);
  EXPECT_THROW(DistanceInsideSources(pair, w, 2, kH + 1, kW), std::invalid_argument);

  // CPU float maps take a loop of their own: the same distances as the
  // operations in double above, to float rounding, here for two batch items
  // (four pairs: the second item's sources swapped) so that the loop's
  // indexing of items and sources is checked too.
  const torch::Tensor w2 = torch::cat({w, w.flip({3})});
  const EpipolarPair pair2{torch::cat({pair.a, pair.a.flip({0})}), torch::cat({pair.b, pair.b.flip({0})})};
  const torch::Tensor in_double = DistanceInsideSources(pair2, w2, 2, kH, kW);
  const torch::Tensor in_float = DistanceInsideSources(
      EpipolarPair{pair2.a.to(torch::kFloat32), pair2.b.to(torch::kFloat32)}, w2.to(torch::kFloat32), 2, kH, kW);
  ASSERT_EQ(in_float.scalar_type(), torch::kFloat32);
  ASSERT_EQ(in_float.sizes(), in_double.sizes());
  int64_t finite = 0, outside = 0;
  for (int64_t k = 0; k < 2; ++k) {
    for (int64_t i = 0; i < kH; ++i) {
      for (int64_t j = 0; j < kW; ++j) {
        const double expected = in_double[k][0][i][j].item<double>();
        const double got = in_float[k][0][i][j].item<double>();
        if (std::isinf(expected)) {
          EXPECT_TRUE(std::isinf(got) && got < 0) << k << "," << i << "," << j;
          outside += 1;
        } else {
          EXPECT_NEAR(got, expected, 1e-4 * (1.0 + std::abs(expected))) << k << "," << i << "," << j;
          finite += 1;
        }
      }
    }
  }
  EXPECT_GT(finite, 1000);
  EXPECT_GE(outside, 10);  // the pixels without depth, in both items
}

// (3) E-flow: base point and direction held fixed; E-flow -> pixel -> inverse
// depth and pixel -> E-flow round trip exactly; |E-flow| is the distance Eigen
// measures between the two projections, positive towards nearer points.
TEST_P(GeometryPrecision, EflowRoundTrips) {
  const torch::ScalarType dtype = GetParam();
  const double eps = Epsilon(dtype);
  const double tol = DepthTolerance(dtype);
  std::mt19937_64 rng(77);
  int tested = 0;
  for (int scene_index = 0; scene_index < 24; ++scene_index) {
    const Scene scene = RandomScene(rng, LogUniform(rng, 1e-3, 1e3));
    std::vector<Sample> samples = ConditionedSamples(scene, rng, 200, eps, tol);
    // Base points: the same pixels at a depth off by up to +-20 %.
    std::uniform_real_distribution<double> factor(0.8, 1.2);
    std::vector<double> base_depth;
    std::vector<Sample> kept;
    for (const Sample& s : samples) {
      const double d = s.depth * factor(rng);
      double z_src = 0;
      const Vector2d base = scene.Project(scene.BackProject(Vector2d(s.x, s.y), d), &z_src);
      if (z_src <= 0 || !scene.InSource(base)) continue;
      kept.push_back(s);
      base_depth.push_back(d);
    }
    if (kept.empty()) continue;
    tested += static_cast<int>(kept.size());
    size_t k = 0;
    const torch::Tensor base_w = SampleImage(scene, kept, 1, [&](const Sample&) {
                                   return std::vector<double>{1.0 / base_depth[k++]};
                                 }).to(dtype);
    const torch::Tensor src_xy = SampleImage(scene, kept, 2, [](const Sample& s) {
                                   return std::vector<double>{s.src.x(), s.src.y()};
                                 }).to(dtype);

    const EpipolarPair pair = scene.Pair(dtype);
    const torch::Tensor base_xy = ProjectInverseDepth(pair, base_w).xy;
    const torch::Tensor dir = ComputeEpipolarDirection(pair).dir;
    const torch::Tensor eflow = SourcePixelToEflow(base_xy, dir, src_xy);
    const torch::Tensor back_xy = EflowToSourcePixel(base_xy, dir, eflow);
    const InverseDepth back_w = TriangulateInverseDepth(pair, back_xy);
    // The other way round, for arbitrary E-flows.
    const torch::Tensor any_eflow =
        torch::randn({1, 1, scene.ref_height, scene.ref_width}, torch::kFloat64).to(dtype) * 50;
    const torch::Tensor any_eflow_back =
        SourcePixelToEflow(base_xy, dir, EflowToSourcePixel(base_xy, dir, any_eflow));

    const ImageReader e(eflow);
    const ImageReader back(back_xy);
    const ImageReader w(back_w.inv_depth);
    const ImageReader w_valid(back_w.valid);
    const ImageReader e_any(any_eflow);
    const ImageReader e_any_back(any_eflow_back);
    const double pixel_tol = 64 * eps * scene.LargestDimension();
    for (size_t i = 0; i < kept.size(); ++i) {
      const Sample& s = kept[i];
      SCOPED_TRACE("scene " + std::to_string(scene_index) + " sample " + std::to_string(i));
      const Vector2d base = scene.ProjectDepth(Vector2d(s.x, s.y), base_depth[i]);
      const double sign = (s.depth < base_depth[i]) ? 1.0 : -1.0;  // nearer: positive
      // |E-flow| = distance along the line; its error is the base/direction
      // error (depth-test accuracy, relative to the parallax S) times the distance.
      const double distance = (s.src - base).norm();
      EXPECT_NEAR(e(0, s.y, s.x), sign * distance, pixel_tol + tol * (distance + s.parallax));
      EXPECT_NEAR(back(0, s.y, s.x), s.src.x(), pixel_tol + tol * (distance + s.parallax));
      EXPECT_NEAR(back(1, s.y, s.x), s.src.y(), pixel_tol + tol * (distance + s.parallax));
      ASSERT_TRUE(w_valid(0, s.y, s.x));
      EXPECT_NEAR(w(0, s.y, s.x) * s.depth, 1.0, 4 * tol);
      EXPECT_NEAR(e_any_back(0, s.y, s.x), e_any(0, s.y, s.x),
                  pixel_tol + 8 * eps * std::abs(e_any(0, s.y, s.x)));
    }
  }
  EXPECT_GE(tested, 150);
}

// (4) The same scene in millimetres, metres and kilometres: identical masks,
// E-flows and directions over the whole image, degenerate pixels included.
TEST_P(GeometryPrecision, SceneUnitDoesNotMatter) {
  const torch::ScalarType dtype = GetParam();
  const double eps = Epsilon(dtype);
  std::mt19937_64 rng(4242);
  int64_t compared_pixels = 0;
  for (int scene_index = 0; scene_index < 8; ++scene_index) {
    SCOPED_TRACE("scene " + std::to_string(scene_index));
    Scene scene = RandomScene(rng, LogUniform(rng, 1e-3, 1e3));
    scene.ref_width = 64;
    scene.ref_height = 48;
    scene.K_ref = RandomIntrinsics(rng, scene.ref_width, scene.ref_height);
    if (scene_index == 0) scene.T.setZero();       // zero baseline
    if (scene_index == 1) scene = EpipoleScene();  // epipole on pixel (20, 15)
    // Per-pixel depths spanning 1e-2..1e5, with some behind the camera (w < 0),
    // at infinity (w = 0) and NaN.
    torch::Tensor w_metres = torch::exp(
        torch::empty({1, 1, 48, 64}, torch::kFloat64).uniform_(std::log(1e-5), std::log(1e2)));
    w_metres.index_put_({0, 0, 0}, -w_metres.index({0, 0, 0}));
    w_metres.index_put_({0, 0, 1}, 0.0);
    w_metres.index_put_({0, 0, 2, 0}, std::numeric_limits<double>::quiet_NaN());
    // Base points at twice the depth.
    const torch::Tensor base_metres = w_metres * 0.5;
    const double pixel_tol = 64 * eps * std::max(scene.LargestDimension(), 64.0);

    struct Result {
      torch::Tensor eflow, dir, dir_valid, xy_valid, base_valid, w_valid, in_source;
    };
    auto inside_source = [&](const torch::Tensor& xy) {
      const torch::Tensor x = xy.select(1, 0), y = xy.select(1, 1);
      return ((x >= -0.5) & (x <= scene.src_width - 0.5) & (y >= -0.5) &
              (y <= scene.src_height - 0.5))
          .unsqueeze(1);
    };
    auto run = [&](double unit) {
      const EpipolarPair pair = scene.Scaled(unit).Pair(dtype);
      const torch::Tensor w = (w_metres / unit).to(dtype);
      const SourcePixels src = ProjectInverseDepth(pair, w);
      const SourcePixels base = ProjectInverseDepth(pair, (base_metres / unit).to(dtype));
      const EpipolarDirection dir = ComputeEpipolarDirection(pair);
      const InverseDepth tri = TriangulateInverseDepth(pair, src.xy);
      return Result{SourcePixelToEflow(base.xy, dir.dir, src.xy),
                    dir.dir,
                    dir.valid,
                    src.valid,
                    base.valid,
                    tri.valid,
                    src.valid & base.valid & inside_source(src.xy) & inside_source(base.xy)};
    };
    const Result metres = run(1.0);
    // The epipolar line of a pixel runs through the source epipole e (image of
    // the reference centre) and the pixel's vanishing point v; with both known
    // to ~eps * C, its direction is known to ~eps * C / |e - v| (ill-conditioned
    // next to the epipole, where v -> e).
    torch::Tensor direction_tol = torch::empty({1, 1, 48, 64}, torch::kFloat64);
    auto tol_at = direction_tol.accessor<double, 4>();
    const Vector3d e_h = scene.K_src * scene.T;
    for (int y = 0; y < 48; ++y) {
      for (int x = 0; x < 64; ++x) {
        const Vector3d v_h = scene.K_src * scene.R * scene.K_ref.inverse() * Vector3d(x, y, 1.0);
        // |e - v| in homogeneous form, without dividing by a zero z.
        const double separation = (e_h.head<2>() * v_h.z() - v_h.head<2>() * e_h.z()).norm() /
                                  std::abs(e_h.z() * v_h.z());
        tol_at[0][0][y][x] = 16 * eps * (1 + scene.LargestDimension() / separation);
      }
    }
    for (double unit : {1e-3, 1e3}) {
      SCOPED_TRACE("unit " + std::to_string(unit));
      const Result other = run(unit);
      EXPECT_TRUE(torch::equal(other.dir_valid, metres.dir_valid));
      EXPECT_TRUE(torch::equal(other.xy_valid, metres.xy_valid));
      EXPECT_TRUE(torch::equal(other.base_valid, metres.base_valid));
      EXPECT_TRUE(torch::equal(other.w_valid, metres.w_valid));
      const torch::Tensor dir_error =
          (AsDouble(other.dir) - AsDouble(metres.dir)).abs() / direction_tol;
      EXPECT_LE(torch::where(metres.dir_valid, dir_error, torch::zeros_like(dir_error))
                    .max()
                    .item<double>(),
                1.0);
      // E-flows where the network would use them (both points inside the
      // source image). Rescaling rounds T and w (a few eps relative), which
      // moves each point by a few eps times its coordinates and its parallax
      // (of the order of the E-flow itself).
      const torch::Tensor compared = metres.in_source & metres.dir_valid;
      compared_pixels += compared.sum().item<int64_t>();
      const torch::Tensor eflow_error = (AsDouble(other.eflow) - AsDouble(metres.eflow)).abs() /
                                        (pixel_tol + 64 * eps * AsDouble(metres.eflow).abs());
      EXPECT_LE(
          torch::where(compared, eflow_error, torch::zeros_like(eflow_error)).max().item<double>(),
          1.0);
    }
    // Sanity of the masks themselves: w < 0 and NaN are invalid; where the
    // baseline is zero no direction and no depth exists.
    EXPECT_FALSE(metres.xy_valid.index({0, 0, 0}).any().item<bool>());
    EXPECT_FALSE(metres.xy_valid.index({0, 0, 2, 0}).item<bool>());
    if (scene_index == 1) {
      EXPECT_FALSE(At(metres.dir_valid, kEpipoleY, kEpipoleX));
      EXPECT_EQ(metres.dir_valid.logical_not().sum().item<int64_t>(), 1);
    }
    if (scene_index == 0) {
      EXPECT_FALSE(metres.dir_valid.any().item<bool>());
      EXPECT_FALSE(metres.w_valid.any().item<bool>());
    } else {
      EXPECT_TRUE(metres.dir_valid.any().item<bool>());
      EXPECT_TRUE(metres.w_valid.any().item<bool>());
    }
  }
  EXPECT_GE(compared_pixels, 1000);
}

// (6) Degenerate configurations: finite outputs, valid == false.
TEST_P(GeometryPrecision, DegenerateCasesAreFiniteAndInvalid) {
  const torch::ScalarType dtype = GetParam();
  const Scene scene = EpipoleScene();
  const EpipolarPair pair = scene.Pair(dtype);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();

  // Pixel exactly at the epipole: no direction, no depth; its neighbours are fine.
  const EpipolarDirection dir = ComputeEpipolarDirection(pair);
  ASSERT_TRUE(AllFinite(dir.dir));
  EXPECT_FALSE(At(dir.valid, kEpipoleY, kEpipoleX));
  EXPECT_EQ(
      dir.dir.index({0, torch::indexing::Slice(), kEpipoleY, kEpipoleX}).abs().sum().item<double>(),
      0.0);
  EXPECT_TRUE(At(dir.valid, kEpipoleY, kEpipoleX + 1));
  EXPECT_TRUE(At(dir.valid, kEpipoleY + 1, kEpipoleX));
  EXPECT_EQ(dir.valid.logical_not().sum().item<int64_t>(), 1);

  // Pixels of one row, each used for one degenerate case. The source camera
  // centre has z = 1 in reference coordinates, so depth 0.5 is in front of the
  // reference camera but behind the source; depth -2 is behind both (z_src /
  // z_ref is then positive: only the sign of w shows it).
  const int py = 30, px = 40;
  auto z_source = [&](int col, double depth) {
    return scene.ToSource(scene.BackProject(Vector2d(col, py), depth)).z();
  };
  auto mirror_image = [&](int col, double depth) {  // projection through z < 0
    return scene.ProjectDepth(Vector2d(col, py), depth);
  };
  auto vanishing_point = [&](int col) {
    const Vector3d h = scene.K_src * scene.R * scene.K_ref.inverse() * Vector3d(col, py, 1.0);
    EXPECT_GT(h.z(), 0);  // in front of the source camera
    return Vector2d(h.head<2>() / h.z());
  };
  ASSERT_LT(z_source(px, 0.5), 0);
  ASSERT_LT(z_source(px + 1, 0.5), 0);
  ASSERT_LT(z_source(px + 1, -2.0), 0);

  // Projection: w < 0, w behind the source, NaN and inf are invalid; w = 0 is
  // the vanishing point (a valid point at infinity, see geometry.h).
  torch::Tensor w = torch::full({1, 1, 48, 64}, 0.25, torch::kFloat64);
  w.index_put_({0, 0, py, px}, 1.0 / 0.5);
  w.index_put_({0, 0, py, px + 1}, -0.5);
  w.index_put_({0, 0, py, px + 2}, nan);
  w.index_put_({0, 0, py, px + 3}, inf);
  w.index_put_({0, 0, py, px + 4}, 0.0);
  const SourcePixels projected = ProjectInverseDepth(pair, w.to(dtype));
  ASSERT_TRUE(AllFinite(projected.xy));
  for (int dx = 0; dx < 4; ++dx) {
    SCOPED_TRACE("projection dx " + std::to_string(dx));
    EXPECT_FALSE(At(projected.valid, py, px + dx));
    EXPECT_EQ(
        projected.xy.index({0, torch::indexing::Slice(), py, px + dx}).abs().sum().item<double>(),
        0.0);
  }
  ASSERT_TRUE(At(projected.valid, py, px + 4));
  const double pixel_tol = 64 * Epsilon(dtype) * scene.LargestDimension();
  EXPECT_NEAR(projected.xy.index({0, 0, py, px + 4}).item<double>(), vanishing_point(px + 4).x(),
              pixel_tol);
  EXPECT_NEAR(projected.xy.index({0, 1, py, px + 4}).item<double>(), vanishing_point(px + 4).y(),
              pixel_tol);

  // Triangulation: the mirror images of points behind the source or behind
  // both cameras, the vanishing point (w = 0), NaN and inf matches, and any
  // match of the epipole's ray are all invalid.
  torch::Tensor src = torch::zeros({1, 2, 48, 64}, torch::kFloat64);
  auto put = [&](int col, const Vector2d& uv) {
    src.index_put_({0, 0, py, col}, uv.x());
    src.index_put_({0, 1, py, col}, uv.y());
  };
  put(px, mirror_image(px, 0.5));
  put(px + 1, mirror_image(px + 1, -2.0));
  put(px + 2, vanishing_point(px + 2));
  put(px + 3, Vector2d(nan, 100.0));
  put(px + 4, Vector2d(100.0, inf));
  // The epipole's own ray: any match.
  src.index_put_({0, 0, kEpipoleY, kEpipoleX}, 100.0);
  src.index_put_({0, 1, kEpipoleY, kEpipoleX}, 80.0);
  const InverseDepth tri = TriangulateInverseDepth(pair, src.to(dtype));
  ASSERT_TRUE(AllFinite(tri.inv_depth));
  for (int dx = 0; dx < 5; ++dx) {
    SCOPED_TRACE("triangulation dx " + std::to_string(dx));
    EXPECT_FALSE(At(tri.valid, py, px + dx));
    EXPECT_EQ(tri.inv_depth.index({0, 0, py, px + dx}).item<double>(), 0.0);
  }
  EXPECT_FALSE(At(tri.valid, kEpipoleY, kEpipoleX));
  // Control: the true match of an ordinary point is valid.
  const Vector2d good = scene.ProjectDepth(Vector2d(10, 40), 3.0);
  src.index_put_({0, 0, 40, 10}, good.x());
  src.index_put_({0, 1, 40, 10}, good.y());
  const InverseDepth tri_good = TriangulateInverseDepth(pair, src.to(dtype));
  EXPECT_TRUE(At(tri_good.valid, 40, 10));
  EXPECT_NEAR(tri_good.inv_depth.index({0, 0, 40, 10}).item<double>(), 1.0 / 3.0,
              DepthTolerance(dtype) / 3.0);

  // Zero baseline: no direction and no depth anywhere; projection is a homography.
  Scene still = scene;
  still.T.setZero();
  const EpipolarPair still_pair = still.Pair(dtype);
  const EpipolarDirection still_dir = ComputeEpipolarDirection(still_pair);
  const InverseDepth still_tri = TriangulateInverseDepth(still_pair, src.to(dtype));
  EXPECT_TRUE(AllFinite(still_dir.dir) && AllFinite(still_tri.inv_depth));
  EXPECT_FALSE(still_dir.valid.any().item<bool>());
  EXPECT_FALSE(still_tri.valid.any().item<bool>());
  EXPECT_EQ(still_dir.dir.abs().sum().item<double>(), 0.0);

  // Non-finite or singular cameras: everything finite and invalid.
  std::vector<EpipolarPair> broken;
  broken.push_back(MakeEpipolarPair(MatrixTensor(scene.K_ref, dtype),
                                    MatrixTensor(scene.K_src, dtype), MatrixTensor(scene.R, dtype),
                                    VectorTensor(Vector3d(nan, 0, 1), dtype), 48, 64));
  broken.push_back(MakeEpipolarPair(MatrixTensor(Matrix3d::Zero(), dtype),
                                    MatrixTensor(scene.K_src, dtype), MatrixTensor(scene.R, dtype),
                                    VectorTensor(scene.T, dtype), 48, 64));
  Matrix3d K_inf = scene.K_ref;
  K_inf(0, 0) = inf;
  broken.push_back(MakeEpipolarPair(MatrixTensor(K_inf, dtype), MatrixTensor(scene.K_src, dtype),
                                    MatrixTensor(scene.R, dtype), VectorTensor(scene.T, dtype), 48,
                                    64));
  for (size_t i = 0; i < broken.size(); ++i) {
    SCOPED_TRACE("broken camera " + std::to_string(i));
    EXPECT_TRUE(AllFinite(broken[i].a) && AllFinite(broken[i].b));
    const SourcePixels p = ProjectInverseDepth(broken[i], w.to(dtype));
    const EpipolarDirection d = ComputeEpipolarDirection(broken[i]);
    const InverseDepth t = TriangulateInverseDepth(broken[i], src.to(dtype));
    EXPECT_TRUE(AllFinite(p.xy) && AllFinite(d.dir) && AllFinite(t.inv_depth));
    EXPECT_FALSE(p.valid.any().item<bool>());
    EXPECT_FALSE(d.valid.any().item<bool>());
    EXPECT_FALSE(t.valid.any().item<bool>());
  }
}

// (7) Gradients with respect to inverse depth, source pixel, E-flow and logits
// are finite everywhere, degenerate pixels included, and correct where valid.
TEST_P(GeometryPrecision, GradientsAreFiniteEverywhere) {
  const torch::ScalarType dtype = GetParam();
  const Scene scene = EpipoleScene();
  Scene still = scene;
  still.T.setZero();
  // Batch of two pairs: the epipole scene and the same cameras without baseline.
  const EpipolarPair pair = MakeEpipolarPair(
      MatrixTensor(scene.K_ref, dtype).repeat({2, 1, 1}),
      MatrixTensor(scene.K_src, dtype).repeat({2, 1, 1}),
      MatrixTensor(scene.R, dtype).repeat({2, 1, 1}),
      torch::cat({VectorTensor(scene.T, dtype), VectorTensor(still.T, dtype)}), 48, 64);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  torch::manual_seed(5);
  torch::Tensor w0 = torch::rand({2, 1, 48, 64}, torch::kFloat64) * 2 -
                     0.5;  // some < 0, some behind the source (> 1)
  w0.index_put_({torch::indexing::Slice(), 0, 0, 0}, 0.0);
  w0.index_put_({torch::indexing::Slice(), 0, 0, 1}, nan);
  w0.index_put_({torch::indexing::Slice(), 0, kEpipoleY, kEpipoleX}, 0.3);
  torch::Tensor src0 = torch::rand({2, 2, 48, 64}, torch::kFloat64) * 320;
  src0.index_put_({torch::indexing::Slice(), 0, 0, 2}, nan);
  const torch::Tensor inv_depth = w0.to(dtype).requires_grad_(true);
  const torch::Tensor src_xy = src0.to(dtype).requires_grad_(true);
  const torch::Tensor eflow =
      torch::randn({2, 1, 48, 64}, torch::kFloat64).to(dtype).requires_grad_(true);
  torch::Tensor logits0 = torch::randn({2, 3, 48, 64}, torch::kFloat64) * 10;
  logits0.index_put_({0, 0, 5, 5}, 1e30);  // huge logits on an invalid pair must not overflow
  logits0.index_put_({0, 1, 5, 6}, nan);
  const torch::Tensor logits = logits0.to(dtype).requires_grad_(true);

  const SourcePixels projected = ProjectInverseDepth(pair, inv_depth);
  const EpipolarDirection dir = ComputeEpipolarDirection(pair);
  const torch::Tensor moved = EflowToSourcePixel(projected.xy, dir.dir, eflow);
  const InverseDepth tri_moved = TriangulateInverseDepth(pair, moved);
  const InverseDepth tri = TriangulateInverseDepth(pair, src_xy);
  const torch::Tensor back = SourcePixelToEflow(projected.xy, dir.dir, src_xy);
  torch::Tensor valid = torch::stack(
      {tri.valid.squeeze(1), tri_moved.valid.squeeze(1), torch::rand({2, 48, 64}) > 0.5}, 1);
  valid.index_put_({0, 0, 5, 5}, false);
  valid.index_put_({0, torch::indexing::Slice(), 7, 7}, false);  // no valid pair at all
  const FusedInverseDepth fused = FuseInverseDepths(
      torch::cat({tri.inv_depth, tri_moved.inv_depth, inv_depth}, 1), logits, valid);
  const torch::Tensor loss =
      projected.xy.sum() + tri.inv_depth.sum() + tri_moved.inv_depth.sum() + back.sum() +
      fused.inv_depth.sum() +
      (fused.weights * torch::arange(3, logits.options()).view({1, 3, 1, 1})).sum();
  const auto grads = torch::autograd::grad({loss}, {inv_depth, src_xy, eflow, logits});
  for (size_t i = 0; i < grads.size(); ++i) {
    SCOPED_TRACE("gradient " + std::to_string(i));
    EXPECT_TRUE(AllFinite(grads[i]));
    EXPECT_GT(grads[i].abs().sum().item<double>(), 0.0);  // not killed everywhere
  }
  EXPECT_TRUE(AllFinite(fused.inv_depth) && AllFinite(fused.weights));
  EXPECT_FALSE(fused.valid.index({0, 0, 7, 7}).item<bool>());
  EXPECT_EQ(fused.weights.index({0, 0, 5, 5}).item<double>(), 0.0);
}

// d(projection)/dw by autograd against Eigen's central difference in double,
// and d(triangulated w)/d(match along the line) = 1 / |dp/dw|.
TEST(GeometryGradients, MatchEigenDerivatives) {
  const Scene scene = EpipoleScene();
  const EpipolarPair pair = scene.Pair(torch::kFloat64);
  const int px = 40, py = 30;
  const double depth = 3.0;
  torch::Tensor w = torch::full({1, 1, 48, 64}, 1.0 / depth, torch::kFloat64).requires_grad_(true);
  const SourcePixels projected = ProjectInverseDepth(pair, w);
  const auto gx = torch::autograd::grad({projected.xy.select(1, 0).sum()}, {w}, {},
                                        /*retain_graph=*/true)[0];
  const auto gy = torch::autograd::grad({projected.xy.select(1, 1).sum()}, {w})[0];
  const double h = 1e-6;
  const Vector2d dp_dw = (scene.ProjectDepth(Vector2d(px, py), 1.0 / (1.0 / depth + h)) -
                          scene.ProjectDepth(Vector2d(px, py), 1.0 / (1.0 / depth - h))) /
                         (2 * h);
  EXPECT_NEAR(gx.index({0, 0, py, px}).item<double>(), dp_dw.x(), 1e-6 * dp_dw.norm());
  EXPECT_NEAR(gy.index({0, 0, py, px}).item<double>(), dp_dw.y(), 1e-6 * dp_dw.norm());

  torch::Tensor src = projected.xy.detach().clone().requires_grad_(true);
  const InverseDepth tri = TriangulateInverseDepth(pair, src);
  ASSERT_TRUE(At(tri.valid, py, px));
  const auto dw_dsrc = torch::autograd::grad({tri.inv_depth.sum()}, {src})[0];
  const Vector2d grad(dw_dsrc.index({0, 0, py, px}).item<double>(),
                      dw_dsrc.index({0, 1, py, px}).item<double>());
  EXPECT_NEAR(grad.dot(dp_dw.normalized()) * dp_dw.norm(), 1.0, 1e-6);
}

// (8) Fusion: softmax over valid pairs only, checked by hand.
TEST_P(GeometryPrecision, FusionWeightsByHand) {
  const torch::ScalarType dtype = GetParam();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  // Pixel 0: logits (0, ln 3) on valid pairs, a huge logit on an invalid one:
  //   weights 1/4, 3/4, 0; fused 0.2 / 4 + 0.6 * 3 / 4 = 0.5.
  // Pixel 1: no valid pair: weights 0, fused 0, invalid.
  // Pixel 2: logits 1000, 0, 1000 (overflow without the shift); inverse depths 1, 2, 3:
  //   weights 1/2, e^-1000 ~ 0, 1/2; fused 2.
  // Pixel 3: a NaN logit on a pair marked valid is ignored: weight 1 on the other.
  const torch::Tensor inv =
      torch::tensor({0.2, 1.0, 1.0, 0.7, 0.6, nan, 2.0, 0.9, 5.0, 2.0, 3.0, 0.4}, torch::kFloat64)
          .view({1, 3, 1, 4})
          .to(dtype);
  const torch::Tensor logits =
      torch::tensor({0.0, 50.0, 1000.0, nan, std::log(3.0), 1.0, 0.0, 2.0, 100.0, 1.0, 1000.0, 0.0},
                    torch::kFloat64)
          .view({1, 3, 1, 4})
          .to(dtype)
          .requires_grad_(true);
  const torch::Tensor valid =
      torch::tensor({true, false, true, true, true, false, true, true, false, false, true, false})
          .view({1, 3, 1, 4});
  const FusedInverseDepth fused = FuseInverseDepths(inv, logits, valid);
  const double tol = 8 * Epsilon(dtype);
  auto weight = [&](int n, int x) { return fused.weights.index({0, n, 0, x}).item<double>(); };
  auto value = [&](int x) { return fused.inv_depth.index({0, 0, 0, x}).item<double>(); };
  EXPECT_NEAR(weight(0, 0), 0.25, tol);
  EXPECT_NEAR(weight(1, 0), 0.75, tol);
  EXPECT_EQ(weight(2, 0), 0.0);
  EXPECT_NEAR(value(0), 0.5, tol);
  for (int n = 0; n < 3; ++n) EXPECT_EQ(weight(n, 1), 0.0);
  EXPECT_EQ(value(1), 0.0);
  EXPECT_NEAR(weight(0, 2), 0.5, tol);
  EXPECT_NEAR(weight(2, 2), 0.5, tol);
  EXPECT_NEAR(value(2), 2.0, 2 * tol);
  EXPECT_EQ(weight(0, 3), 0.0);
  EXPECT_NEAR(weight(1, 3), 1.0, tol);
  EXPECT_NEAR(value(3), 0.9, tol);
  const torch::Tensor expected_valid = torch::tensor({true, false, true, true}).view({1, 1, 1, 4});
  EXPECT_TRUE(torch::equal(fused.valid, expected_valid));
  const auto grad = torch::autograd::grad({fused.inv_depth.sum()}, {logits})[0];
  EXPECT_TRUE(AllFinite(grad));
  // d fused / d logit_i = w_i (v_i - fused): 0.25 * (0.2 - 0.5) at pixel 0.
  EXPECT_NEAR(grad.index({0, 0, 0, 0}).item<double>(), 0.25 * (0.2 - 0.5), 16 * Epsilon(dtype));
}

// Fusion weights against a softmax computed independently, over random masks.
TEST_P(GeometryPrecision, FusionWeightsSumToOneOverValidSources) {
  const torch::ScalarType dtype = GetParam();
  torch::manual_seed(11);
  const torch::Tensor inv = torch::rand({2, 5, 6, 7}, torch::kFloat64);
  const torch::Tensor logits = torch::randn({2, 5, 6, 7}, torch::kFloat64) * 5;
  const torch::Tensor valid = torch::rand({2, 5, 6, 7}) > 0.6;
  const FusedInverseDepth fused = FuseInverseDepths(inv.to(dtype), logits.to(dtype), valid);
  const auto l = logits.accessor<double, 4>();
  const auto v = inv.accessor<double, 4>();
  const auto m = valid.accessor<bool, 4>();
  const ImageReader fused_depth(fused.inv_depth);
  int all_invalid = 0;
  for (int b = 0; b < 2; ++b) {
    const ImageReader weights(fused.weights.select(0, b).unsqueeze(0));
    const ImageReader fused_b(fused.inv_depth.select(0, b).unsqueeze(0));
    const ImageReader ok(fused.valid.select(0, b).unsqueeze(0));
    for (int y = 0; y < 6; ++y) {
      for (int x = 0; x < 7; ++x) {
        double total = 0, mean = 0;
        for (int n = 0; n < 5; ++n) {
          if (m[b][n][y][x]) total += std::exp(l[b][n][y][x]);
        }
        for (int n = 0; n < 5; ++n) {
          const double expected = m[b][n][y][x] ? std::exp(l[b][n][y][x]) / total : 0.0;
          EXPECT_NEAR(weights(n, y, x), expected, 16 * Epsilon(dtype));
          mean += expected * v[b][n][y][x];
        }
        EXPECT_EQ(ok(0, y, x) != 0, total > 0);
        if (total == 0) ++all_invalid;
        EXPECT_NEAR(fused_b(0, y, x), total > 0 ? mean : 0.0, 16 * Epsilon(dtype));
      }
    }
  }
  EXPECT_GT(all_invalid, 0);  // the random mask includes pixels without any valid pair
  const torch::Tensor sums = fused.weights.sum(1, true);
  EXPECT_TRUE(torch::allclose(AsDouble(sums), AsDouble(fused.valid), 0, 16 * Epsilon(dtype)));
}

// The stage intrinsics against an independent construction: a point projected
// at full resolution to continuous pixel-index coordinates, then mapped to the
// coarse grid (coarse pixel j covers fine pixels j*f .. j*f + f - 1, so its
// centre is the fine coordinate j*f + (f - 1) / 2).
TEST_P(GeometryPrecision, ScaleIntrinsicsMatchesCoarseGrid) {
  const torch::ScalarType dtype = GetParam();
  std::mt19937_64 rng(3);
  for (double factor : {2.0, 4.0, 16.0, 3.0}) {
    const Matrix3d K = RandomIntrinsics(rng, 1600, 1152);
    const torch::Tensor scaled = ScaleIntrinsics(MatrixTensor(K, dtype), factor);
    Matrix3d K_coarse;
    const torch::Tensor s = AsDouble(scaled);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) K_coarse(r, c) = s.index({0, r, c}).item<double>();
    for (int i = 0; i < 20; ++i) {
      const Vector3d X(LogUniform(rng, 0.1, 10) - 5, LogUniform(rng, 0.1, 10) - 5,
                       LogUniform(rng, 1, 100));
      const Vector3d fine_h = K * X;
      const Vector2d fine = fine_h.head<2>() / fine_h.z();
      const Vector2d expected = (fine - Vector2d::Constant((factor - 1) / 2)) / factor;
      const Vector3d coarse_h = K_coarse * X;
      const Vector2d coarse = coarse_h.head<2>() / coarse_h.z();
      EXPECT_NEAR((coarse - expected).norm(), 0.0, 64 * Epsilon(dtype) * 1600);
    }
  }
  EXPECT_THROW(ScaleIntrinsics(MatrixTensor(Matrix3d::Identity(), dtype), 0.0),
               std::invalid_argument);
  EXPECT_THROW(ScaleIntrinsics(torch::zeros({3}, torch::kFloat64).to(dtype), 4.0),
               std::invalid_argument);
}

TEST_P(GeometryPrecision, InverseDepthRange) {
  const torch::ScalarType dtype = GetParam();
  const auto opts = torch::TensorOptions().dtype(dtype);
  const torch::Tensor d_min = torch::tensor({2.0, 0.5}, opts);
  const torch::Tensor d_max = torch::tensor({10.0, std::numeric_limits<double>::infinity()}, opts);

  torch::Generator gen = at::detail::createCPUGenerator(123);
  const torch::Tensor a = RandomInverseDepth(d_min, d_max, 40, 50, gen);
  torch::Generator same = at::detail::createCPUGenerator(123);
  torch::Generator other = at::detail::createCPUGenerator(124);
  EXPECT_TRUE(torch::equal(a, RandomInverseDepth(d_min, d_max, 40, 50, same)));
  EXPECT_FALSE(torch::equal(a, RandomInverseDepth(d_min, d_max, 40, 50, other)));
  ASSERT_EQ(a.sizes(), (std::vector<int64_t>{2, 1, 40, 50}));
  EXPECT_EQ(a.scalar_type(), dtype);
  // Sample 0 in [1/10, 1/2], sample 1 in [0, 2] (d_max = inf: no far limit);
  // uniform: the mean of 2000 draws is within 4 standard errors of the centre.
  const torch::Tensor a0 = AsDouble(a[0]), a1 = AsDouble(a[1]);
  EXPECT_GE(a0.min().item<double>(), 0.1);
  EXPECT_LE(a0.max().item<double>(), 0.5);
  EXPECT_GE(a1.min().item<double>(), 0.0);
  EXPECT_LE(a1.max().item<double>(), 2.0);
  EXPECT_NEAR(a0.mean().item<double>(), 0.3, 4 * 0.4 / std::sqrt(12.0 * 2000));
  EXPECT_NEAR(a1.mean().item<double>(), 1.0, 4 * 2.0 / std::sqrt(12.0 * 2000));
  EXPECT_NO_THROW(RandomInverseDepth(d_min, d_max, 4, 5));  // default generator

  // Normalisation by hand for d in [2, 10]: w = 1/10 -> 0, 1/2 -> 1, not clipped outside.
  const torch::Tensor lo = torch::tensor({2.0}, opts), hi = torch::tensor({10.0}, opts);
  const torch::Tensor w = torch::tensor({0.1, 0.5, 1.0, 0.0}, opts).view({1, 1, 1, 4});
  const torch::Tensor n = NormalizeInverseDepth(w, lo, hi);
  const torch::Tensor expected =
      torch::tensor({0.0, 1.0, 2.25, -0.25}, torch::kFloat64).view({1, 1, 1, 4});
  EXPECT_TRUE(torch::allclose(AsDouble(n), expected, 0, 8 * Epsilon(dtype)));
  EXPECT_TRUE(torch::allclose(AsDouble(DenormalizeInverseDepth(n, lo, hi)), AsDouble(w), 0,
                              8 * Epsilon(dtype)));

  // The result follows the inverse depth's dtype, whatever the range's.
  EXPECT_EQ(NormalizeInverseDepth(w, lo.to(torch::kFloat64), hi.to(torch::kFloat64)).scalar_type(),
            dtype);

  // Bad ranges are rejected.
  EXPECT_THROW(RandomInverseDepth(torch::tensor({0.0}, opts), hi, 4, 4), std::invalid_argument);
  EXPECT_THROW(RandomInverseDepth(torch::tensor({20.0}, opts), hi, 4, 4), std::invalid_argument);
  EXPECT_THROW(NormalizeInverseDepth(w, hi, hi), std::invalid_argument);
  EXPECT_THROW(RandomInverseDepth(lo, torch::tensor({10.0, 20.0}, opts), 4, 4),
               std::invalid_argument);
}

// A band of rows gets the coefficients of those rows of the whole image, to
// the bit (the fine stage in bands relies on it), and PixelGrid's rows
// start at first_row.
TEST(GeometryShapes, ABandOfRowsHasTheWholeImagesCoefficients) {
  const torch::Tensor K = torch::tensor({500.0f, 0.0f, 319.5f, 0.0f, 480.0f, 239.5f, 0.0f, 0.0f, 1.0f}).view({1, 3, 3});
  const torch::Tensor R = torch::tensor({0.99f, 0.0f, 0.141f, 0.0f, 1.0f, 0.0f, -0.141f, 0.0f, 0.99f}).view({1, 3, 3});
  const torch::Tensor T = torch::tensor({-0.3f, 0.02f, 0.05f}).view({1, 3});
  const EpipolarPair whole = MakeEpipolarPair(K, K, R, T, 480, 640);
  const EpipolarPair band = MakeEpipolarPair(K, K, R, T, 37, 640, 211);
  EXPECT_TRUE(torch::equal(band.a, whole.a.narrow(2, 211, 37)));
  EXPECT_TRUE(torch::equal(band.b, whole.b));
  const torch::Tensor grid = PixelGrid(2, 3, torch::kFloat32, 5);
  EXPECT_EQ(grid[0][1][0][2].item<float>(), 5.0f);  // y of row 0
  EXPECT_EQ(grid[0][1][1][2].item<float>(), 6.0f);
  EXPECT_EQ(grid[0][0][1][2].item<float>(), 2.0f);  // x unchanged
  EXPECT_THROW(PixelGrid(2, 3, torch::kFloat32, -1), std::invalid_argument);
}

TEST(GeometryShapes, PixelGridAndInputValidation) {
  const torch::Tensor grid = PixelGrid(3, 4, torch::kFloat32);
  ASSERT_EQ(grid.sizes(), (std::vector<int64_t>{1, 2, 3, 4}));
  for (int y = 0; y < 3; ++y) {
    for (int x = 0; x < 4; ++x) {
      EXPECT_EQ(grid.index({0, 0, y, x}).item<float>(), x);
      EXPECT_EQ(grid.index({0, 1, y, x}).item<float>(), y);
    }
  }
  EXPECT_THROW(PixelGrid(0, 4, torch::kFloat32), std::invalid_argument);

  const torch::Tensor K = torch::eye(3, torch::kFloat64).unsqueeze(0);
  const torch::Tensor T = torch::zeros({1, 3}, torch::kFloat64);
  const EpipolarPair pair = MakeEpipolarPair(K.repeat({2, 1, 1}), K, K, T, 5, 6);
  EXPECT_EQ(pair.a.sizes(), (std::vector<int64_t>{2, 3, 5, 6}));
  EXPECT_EQ(pair.b.sizes(), (std::vector<int64_t>{2, 3, 1, 1}));
  EXPECT_THROW(MakeEpipolarPair(K, K, K, T.view({3}), 5, 6), std::invalid_argument);
  EXPECT_THROW(MakeEpipolarPair(K, K.to(torch::kFloat32), K, T, 5, 6), std::invalid_argument);
  EXPECT_THROW(MakeEpipolarPair(K.repeat({2, 1, 1}), K.repeat({3, 1, 1}), K, T, 5, 6),
               std::invalid_argument);
  EXPECT_THROW(ProjectInverseDepth(pair, torch::zeros({2, 2, 5, 6}, torch::kFloat64)),
               std::invalid_argument);
  EXPECT_THROW(TriangulateInverseDepth(pair, torch::zeros({2, 1, 5, 6}, torch::kFloat64)),
               std::invalid_argument);
  EXPECT_THROW(FuseInverseDepths(torch::zeros({1, 2, 3, 3}), torch::zeros({1, 2, 3, 3}),
                                 torch::zeros({1, 2, 3, 3})),
               std::invalid_argument);  // valid must be bool
}

// The same code on CUDA gives the CPU's masks and (to float32 rounding) values.
TEST(GeometryDevices, CudaMatchesCpu) {
  if (!torch::cuda::is_available()) GTEST_SKIP() << "no CUDA device";
  const Scene scene = EpipoleScene();
  for (torch::ScalarType dtype : {torch::kFloat32, torch::kFloat64}) {
    auto to_cuda = [](const torch::Tensor& t) { return t.to(torch::kCUDA); };
    const EpipolarPair cpu = scene.Pair(dtype);
    const EpipolarPair gpu = MakeEpipolarPair(
        to_cuda(MatrixTensor(scene.K_ref, dtype)), to_cuda(MatrixTensor(scene.K_src, dtype)),
        to_cuda(MatrixTensor(scene.R, dtype)), to_cuda(VectorTensor(scene.T, dtype)), 48, 64);
    torch::manual_seed(1);
    const torch::Tensor w = torch::rand({1, 1, 48, 64}, torch::kFloat64).to(dtype) * 2 - 0.5;
    const SourcePixels p_cpu = ProjectInverseDepth(cpu, w);
    const SourcePixels p_gpu = ProjectInverseDepth(gpu, to_cuda(w));
    const InverseDepth t_cpu = TriangulateInverseDepth(cpu, p_cpu.xy);
    const InverseDepth t_gpu = TriangulateInverseDepth(gpu, p_gpu.xy);
    EXPECT_TRUE(p_gpu.xy.is_cuda());
    EXPECT_TRUE(torch::equal(p_cpu.valid, p_gpu.valid.cpu()));
    EXPECT_TRUE(torch::equal(t_cpu.valid, t_gpu.valid.cpu()));
    const double tol = dtype == torch::kFloat32 ? 1e-3 : 1e-9;
    EXPECT_TRUE(torch::allclose(AsDouble(p_cpu.xy), AsDouble(p_gpu.xy), tol, tol));
    EXPECT_TRUE(torch::allclose(AsDouble(t_cpu.inv_depth), AsDouble(t_gpu.inv_depth), tol, tol));
    torch::Generator gen = at::detail::createCPUGenerator(7);
    const torch::Tensor d =
        torch::tensor({1.0}, torch::TensorOptions().dtype(dtype).device(torch::kCUDA));
    EXPECT_TRUE(RandomInverseDepth(d, d * 10, 4, 4, gen).is_cuda());
  }
}

INSTANTIATE_TEST_SUITE_P(Dtypes, GeometryPrecision,
                         ::testing::Values(torch::kFloat32, torch::kFloat64), DtypeName);

}  // namespace
}  // namespace dispmvs::model
