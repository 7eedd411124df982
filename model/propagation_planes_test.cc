#include "model/propagation_planes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <torch/torch.h>

namespace dispmvs::model {
namespace {

// Two batch items: a tilted plane with ripples (so the fit has residuals),
// holes of unusable pixels (scattered and a block, so some windows have a
// quarter or less usable and some only a line), and zero or negative
// values where unusable.
struct Map {
  torch::Tensor w, usable;
};

Map MakeMap(int64_t h, int64_t width, uint64_t seed = 5) {
  torch::manual_seed(seed);
  const torch::Tensor y = torch::arange(h, torch::kFloat32).view({1, 1, h, 1});
  const torch::Tensor x = torch::arange(width, torch::kFloat32).view({1, 1, 1, width});
  torch::Tensor w = torch::cat({0.4f + 0.002f * x - 0.001f * y + 0.01f * torch::sin(0.3f * x + 0.2f * y),
                                0.9f - 0.004f * x + 0.003f * y + 0.02f * torch::cos(0.5f * y)},
                               0);
  w = w + 0.001f * torch::rand({2, 1, h, width});
  torch::Tensor usable = torch::rand({2, 1, h, width}) > 0.3f;
  usable.narrow(2, h / 3, std::max<int64_t>(1, h / 3)).narrow(3, width / 4, std::max<int64_t>(1, width / 2)).fill_(false);
  // One usable column inside the block: windows there see a line.
  usable.narrow(2, h / 3, std::max<int64_t>(1, h / 3)).narrow(3, width / 2, 1).fill_(true);
  w = torch::where(usable, w, torch::where(torch::rand_like(w) > 0.5f, torch::zeros_like(w), -w));
  return {w, usable};
}

// The least-squares plane of every window, fitted directly: the normal
// equations of w = c + gx u + gy v over the usable pixels, in coordinates
// (u, v) relative to the window's pixel, solved in double by Cramer's rule.
// Acceptance as documented: more than a quarter of the window's pixels
// inside the image usable, and the determinant of the covariance of their
// coordinates above 1e-3.
struct DirectPlane {
  torch::Tensor value, gx, gy;  // double
};

DirectPlane DirectPlanes(const torch::Tensor& w, const torch::Tensor& usable, int64_t radius) {
  const int64_t batch = w.size(0), h = w.size(2), width = w.size(3);
  torch::Tensor value = torch::zeros({batch, 1, h, width}, torch::kFloat64);
  torch::Tensor gx = torch::zeros_like(value);
  torch::Tensor gy = torch::zeros_like(value);
  auto value_a = value.accessor<double, 4>();
  const auto w_a = w.accessor<float, 4>();
  const auto m_a = usable.accessor<bool, 4>();
  auto gx_a = gx.accessor<double, 4>();
  auto gy_a = gy.accessor<double, 4>();
  for (int64_t b = 0; b < batch; ++b) {
    for (int64_t i = 0; i < h; ++i) {
      for (int64_t j = 0; j < width; ++j) {
        double n = 0, su = 0, sv = 0, suu = 0, suv = 0, svv = 0, sw = 0, suw = 0, svw = 0;
        int64_t inside = 0;
        for (int64_t v = -radius; v <= radius; ++v) {
          for (int64_t u = -radius; u <= radius; ++u) {
            const int64_t yy = i + v, xx = j + u;
            if (yy < 0 || yy >= h || xx < 0 || xx >= width) continue;
            ++inside;
            if (!m_a[b][0][yy][xx]) continue;
            const double value = w_a[b][0][yy][xx];
            n += 1;
            su += u;
            sv += v;
            suu += u * u;
            suv += u * v;
            svv += v * v;
            sw += value;
            suw += u * value;
            svw += v * value;
          }
        }
        if (4 * n <= inside) continue;
        const double mu = su / n, mv = sv / n;
        const double cov_det = (suu / n - mu * mu) * (svv / n - mv * mv) - (suv / n - mu * mv) * (suv / n - mu * mv);
        if (cov_det <= 1e-3) continue;
        // | n  su  sv  | |c |   | sw  |
        // | su suu suv | |gx| = | suw |
        // | sv suv svv | |gy|   | svw |
        const auto det3 = [](double a, double b, double c, double d, double e, double f, double g, double hh,
                             double k) { return a * (e * k - f * hh) - b * (d * k - f * g) + c * (d * hh - e * g); };
        const double d = det3(n, su, sv, su, suu, suv, sv, suv, svv);
        // c: the plane at (u, v) = (0, 0), the window's own pixel.
        value_a[b][0][i][j] = det3(sw, su, sv, suw, suu, suv, svw, suv, svv) / d;
        gx_a[b][0][i][j] = det3(n, sw, sv, su, suw, suv, sv, svw, svv) / d;
        gy_a[b][0][i][j] = det3(n, su, sw, su, suu, suw, sv, suv, svw) / d;
      }
    }
  }
  return {value, gx, gy};
}

std::pair<torch::Tensor, torch::Tensor> DirectSlopes(const torch::Tensor& w, const torch::Tensor& usable,
                                                     int64_t radius) {
  const DirectPlane plane = DirectPlanes(w, usable, radius);
  return {plane.gx, plane.gy};
}

TEST(LeastSquaresSlopes, MatchesADirectFitOfEveryWindow) {
  for (const auto& [h, width, radius] : {std::tuple<int64_t, int64_t, int64_t>{37, 53, 3},
                                         {70, 41, 8},   // two bands of rows
                                         {5, 9, 4},     // windows wider than the image
                                         {150, 23, 1}}) {
    const Map map = MakeMap(h, width);
    const auto [gx, gy] = LeastSquaresSlopes(map.w, map.usable, radius);
    const auto [want_x, want_y] = DirectSlopes(map.w, map.usable, radius);
    ASSERT_EQ(gx.sizes(), map.w.sizes());
    ASSERT_EQ(gx.scalar_type(), torch::kFloat32);
    // Exactly zero where the direct fit declines, and the same slopes to
    // float precision elsewhere.
    EXPECT_TRUE(torch::equal(gx == 0, want_x == 0)) << h << "x" << width << " r " << radius;
    EXPECT_TRUE(torch::equal(gy == 0, want_y == 0)) << h << "x" << width << " r " << radius;
    const double scale = std::max(want_x.abs().max().item<double>(), want_y.abs().max().item<double>());
    EXPECT_LT((gx.to(torch::kFloat64) - want_x).abs().max().item<double>(), 1e-5 * scale);
    EXPECT_LT((gy.to(torch::kFloat64) - want_y).abs().max().item<double>(), 1e-5 * scale);
    // The map has windows of both kinds where its block of holes is larger
    // than a window.
    EXPECT_GT((want_x != 0).sum().item<int64_t>(), 0);
    if (h > 4 * radius) {
      EXPECT_GT((want_x == 0).sum().item<int64_t>(), 0) << h << "x" << width;
    }
  }
}

TEST(LeastSquaresPlanes, TheValueIsADirectFitsInterceptAtThePixel) {
  for (const auto& [h, width, radius] : {std::tuple<int64_t, int64_t, int64_t>{37, 53, 3},
                                         {70, 41, 8},
                                         {5, 9, 4}}) {
    const Map map = MakeMap(h, width, 11);
    const LeastSquaresPlane plane = LeastSquaresPlanes(map.w, map.usable, radius);
    const DirectPlane want = DirectPlanes(map.w, map.usable, radius);
    // The same slopes as LeastSquaresSlopes, bit for bit.
    const auto [gx, gy] = LeastSquaresSlopes(map.w, map.usable, radius);
    EXPECT_TRUE(torch::equal(plane.gx, gx));
    EXPECT_TRUE(torch::equal(plane.gy, gy));
    // 0 where the fit declines; the intercept to float precision elsewhere
    // (inverse depths of 0.3-1: a few float roundings of w).
    const torch::Tensor fitted = want.gx != 0;
    EXPECT_TRUE(torch::equal(plane.value == 0, ~fitted)) << h << "x" << width;
    EXPECT_LT((plane.value.to(torch::kFloat64) - want.value).abs().max().item<double>(), 1e-6);
    // The fit is not the pixel's own value: the map's ripples and noise
    // leave residuals, and unusable pixels (w <= 0) get the neighbours'.
    EXPECT_GT(((plane.value - map.w).abs() > 1e-4).logical_and(fitted).sum().item<int64_t>(), 0);
    const LeastSquaresPlane ops = LeastSquaresPlanesByOps(map.w, map.usable, radius);
    const torch::Tensor both = (plane.value != 0) & (ops.value != 0);
    EXPECT_LT(torch::where(both, (plane.value - ops.value).abs(), torch::zeros_like(ops.value)).max().item<double>(),
              1e-4);
  }
}

TEST(LeastSquaresSlopes, RecoversAnExactPlaneFarFromTheCentre) {
  // Inverse depth exactly affine in the pixel: every window's slopes are the
  // plane's, also at the corners of a large map, where the operations'
  // float moments lose digits to cancellation.
  const int64_t h = 480, width = 640;
  const torch::Tensor y = torch::arange(h, torch::kFloat64).view({1, 1, h, 1});
  const torch::Tensor x = torch::arange(width, torch::kFloat64).view({1, 1, 1, width});
  const torch::Tensor w = (0.5 + 1e-4 * x - 2e-4 * y).to(torch::kFloat32);
  const torch::Tensor usable = torch::ones_like(w, torch::kBool);
  const auto [gx, gy] = LeastSquaresSlopes(w, usable, 8);
  // Float rounding of w itself (about 3e-8) over a 17-pixel window: slopes
  // good to about 1e-8.
  EXPECT_LT((gx - 1e-4).abs().max().item<double>(), 2e-8);
  EXPECT_LT((gy + 2e-4).abs().max().item<double>(), 2e-8);
}

TEST(LeastSquaresSlopes, TheOperationsAgreeToFloatPrecision) {
  const Map map = MakeMap(61, 77, 9);
  for (const int64_t radius : {2, 8}) {
    const auto [gx, gy] = LeastSquaresSlopes(map.w, map.usable, radius);
    const auto [ops_x, ops_y] = LeastSquaresSlopesByOps(map.w, map.usable, radius);
    const torch::Tensor both = (gx != 0) & (ops_x != 0);
    // The same windows accepted, but for the rare one at the determinant's
    // threshold in float.
    EXPECT_LE(((gx != 0) != (ops_x != 0)).sum().item<int64_t>(), 2);
    const double scale = gx.abs().max().item<double>();
    EXPECT_LT(torch::where(both, (gx - ops_x).abs(), torch::zeros_like(gx)).max().item<double>(), 1e-2 * scale);
    EXPECT_LT(torch::where(both, (gy - ops_y).abs(), torch::zeros_like(gy)).max().item<double>(), 1e-2 * scale);
  }
}

TEST(LeastSquaresSlopes, RejectsBadInput) {
  const torch::Tensor w = torch::rand({1, 1, 8, 8});
  const torch::Tensor usable = torch::ones({1, 1, 8, 8}, torch::kBool);
  EXPECT_THROW(LeastSquaresSlopes(w, usable, 0), std::invalid_argument);
  EXPECT_THROW(LeastSquaresSlopes(w, torch::ones({1, 1, 8, 7}, torch::kBool), 2), std::invalid_argument);
  EXPECT_THROW(LeastSquaresSlopes(torch::rand({1, 2, 8, 8}), usable, 2), std::invalid_argument);
  EXPECT_THROW(LeastSquaresSlopes(torch::Tensor(), usable, 2), std::invalid_argument);
}

TEST(PlaneFromNeighbour, IsTheNeighboursPlaneComputedDirectly) {
  const Map map = MakeMap(23, 31);
  const torch::Tensor gx = 0.01f * torch::randn_like(map.w), gy = 0.01f * torch::randn_like(map.w);
  const int64_t h = 23, width = 31;
  for (const auto& [dx, dy] : {std::pair<int64_t, int64_t>{4, 0}, {-4, 0}, {0, 7}, {0, -7}, {3, -2},
                               {31, 0}, {0, -40}, {0, 0}}) {
    const torch::Tensor got = PlaneFromNeighbour(map.w, gx, gy, dx, dy);
    EXPECT_TRUE(torch::equal(got, PlaneFromNeighbourByOps(map.w, gx, gy, dx, dy))) << dx << "," << dy;
    const auto got_a = got.accessor<float, 4>();
    const auto w_a = map.w.accessor<float, 4>();
    const auto gx_a = gx.accessor<float, 4>();
    const auto gy_a = gy.accessor<float, 4>();
    for (int64_t b = 0; b < 2; ++b) {
      for (int64_t y = 0; y < h; ++y) {
        for (int64_t x = 0; x < width; ++x) {
          const int64_t nx = x + dx, ny = y + dy;
          double want = 0;
          if (nx >= 0 && nx < width && ny >= 0 && ny < h && w_a[b][0][ny][nx] > 0) {
            const double plane = static_cast<double>(w_a[b][0][ny][nx]) - dx * static_cast<double>(gx_a[b][0][ny][nx]) -
                                 dy * static_cast<double>(gy_a[b][0][ny][nx]);
            want = plane > 1e-6 ? plane : 0.0;
          }
          if (std::abs(want) <= 1e-6) {
            EXPECT_LE(got_a[b][0][y][x], 2e-6f);
          } else {
            EXPECT_NEAR(got_a[b][0][y][x], want, 1e-6 * std::max(1.0, std::abs(want)));
          }
        }
      }
    }
  }
}

TEST(PlaneFromNeighbour, RejectsMismatchedMaps) {
  const torch::Tensor w = torch::rand({1, 1, 8, 8});
  EXPECT_THROW(PlaneFromNeighbour(w, torch::rand({1, 1, 8, 9}), w, 1, 0), std::invalid_argument);
  EXPECT_THROW(PlaneFromNeighbour(w, w, torch::rand({2, 1, 8, 8}), 1, 0), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
