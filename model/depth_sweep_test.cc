#include "model/depth_sweep.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "model/geometry.h"
#include "model/photometric_refinement.h"
#include "model/window_mean.h"

namespace dispmvs::model {
namespace {

constexpr int64_t kHeight = 48, kWidth = 80, kRadius = 3;
constexpr double kFocal = 50, kPlaneZ = 4, kBaseline = 1;

double Texture(double x, double y) {
  return 0.5 + 0.15 * std::sin(5.0 * x + 1.3 * y) + 0.12 * std::sin(-2.1 * x + 6.3 * y + 0.5) +
         0.1 * std::sin(9.1 * x + 7.7 * y + 1.0);
}

// A textured fronto-parallel plane Z = 4 seen by the reference at the origin
// and by a source kBaseline to its right (no rotation), both rendered here
// by intersecting each pixel's ray with the plane: the true inverse depth is
// 0.25 everywhere and the sweep's geometry is checked against it.
struct SweepScene {
  torch::Tensor reference, source;  // [1,1,H,W] grey
  torch::Tensor K, R, T;            // [1,3,3], [1,3,3], [1,3]: reference to source
};

torch::Tensor RenderPlane(double camera_x) {
  torch::Tensor image = torch::zeros({1, 1, kHeight, kWidth}, torch::kFloat32);
  auto pixels = image.accessor<float, 4>();
  const double cx = 0.5 * (kWidth - 1), cy = 0.5 * (kHeight - 1);
  for (int64_t i = 0; i < kHeight; ++i) {
    for (int64_t j = 0; j < kWidth; ++j) {
      pixels[0][0][i][j] = static_cast<float>(
          Texture(camera_x + (j - cx) / kFocal * kPlaneZ, (i - cy) / kFocal * kPlaneZ));
    }
  }
  return image;
}

SweepScene MakeSweepScene() {
  SweepScene scene;
  scene.reference = RenderPlane(0.0);
  scene.source = RenderPlane(kBaseline);
  scene.K = torch::tensor({kFocal, 0.0, 0.5 * (kWidth - 1), 0.0, kFocal, 0.5 * (kHeight - 1), 0.0, 0.0, 1.0})
                .view({1, 3, 3});
  scene.R = torch::eye(3).unsqueeze(0);
  scene.T = torch::tensor({-kBaseline, 0.0, 0.0}).view({1, 3});  // X_s = X_r - (kBaseline, 0, 0)
  return scene;
}

torch::Tensor Sweep(const SweepScene& scene, const torch::Tensor& start, int64_t max_hypotheses,
                    double step_pixels) {
  const EpipolarPair pair = MakeEpipolarPair(scene.K, scene.K, scene.R, scene.T, kHeight, kWidth);
  const torch::Tensor mean = WindowMean(scene.reference, kRadius);
  const torch::Tensor var = torch::clamp_min(WindowMean(scene.reference * scene.reference, kRadius) - mean * mean, 0);
  return SweepInverseDepth(scene.source, scene.reference, mean, var, pair.a, pair.b, start,
                           torch::ones_like(start, torch::kBool), kRadius, max_hypotheses, step_pixels);
}

// Pixels whose window, aggregation and median stay clear of the border and
// whose true match (5 pixels to the left at w = 0.25: f B w = 12.5 px)
// lies inside the source with its window.
torch::Tensor Interior() {
  const int64_t margin = kRadius + kSweepAggregationRadius + kSweepMedianRadius;
  torch::Tensor inside = torch::zeros({1, 1, kHeight, kWidth}, torch::kBool);
  inside.narrow(2, margin, kHeight - 2 * margin).narrow(3, margin + 13, kWidth - 2 * margin - 13).fill_(true);
  return inside;
}

// A start that is wrong everywhere (uniform in inverse depth over
// [0.1, 0.49], the truth 0.25): the sweep finds the plane from the range
// alone. The match moves f B = 50 pixels per unit of inverse depth, so
// 2-pixel steps over the span 0.39 (19.5 pixels) are 10 hypotheses
// 0.1 + 0.039 (k + 0.5): 0.2365 is the nearest to the truth (0.7 pixels
// off), 0.2755 the next (1.3 pixels).
TEST(DepthSweepTest, FindsThePlaneFromARangeAlone) {
  const SweepScene scene = MakeSweepScene();
  torch::manual_seed(3);
  torch::Tensor start = 0.1 + 0.39 * torch::rand({1, 1, kHeight, kWidth});
  start.view(-1)[0] = 0.1;  // the range exactly [0.1, 0.49]
  start.view(-1)[1] = 0.49;
  const torch::Tensor candidate = Sweep(scene, start, 64, 2.0);
  const torch::Tensor inside = candidate.masked_select(Interior());
  // Measured: all of the interior at 0.2365.
  EXPECT_GT(((inside - 0.2365).abs() < 1e-5).to(torch::kFloat32).mean().item<float>(), 0.95);
  EXPECT_GT((start.masked_select(Interior()) - 0.25).abs().median().item<float>(), 0.05);
  EXPECT_TRUE((candidate > 0).all().item<bool>());

  // The cap: 4 hypotheses, 0.14875, 0.24625, 0.34375, 0.44125.
  const torch::Tensor capped = Sweep(scene, start, 4, 2.0).masked_select(Interior());
  EXPECT_GT(((capped - 0.24625).abs() < 1e-5).to(torch::kFloat32).mean().item<float>(), 0.95);
}

TEST(DepthSweepTest, NothingWithoutHypothesesOrParallax) {
  const SweepScene scene = MakeSweepScene();
  const torch::Tensor start = torch::full({1, 1, kHeight, kWidth}, 0.25f);
  // A constant start has no range: fewer than 2 hypotheses.
  EXPECT_TRUE(torch::equal(Sweep(scene, start, 64, 2.0), torch::zeros_like(start)));
  torch::Tensor ranged = start.clone();
  ranged.view(-1)[0] = 0.5;
  EXPECT_TRUE(torch::equal(Sweep(scene, ranged, 0, 2.0), torch::zeros_like(start)));
  EXPECT_TRUE(torch::equal(Sweep(scene, ranged, 1, 2.0), torch::zeros_like(start)));
  // Span 0.25 at 50 px per unit: 12.5 px, so steps of 10 px give 2.
  EXPECT_TRUE((Sweep(scene, ranged, 64, 10.0) > 0).all().item<bool>());
  EXPECT_TRUE(torch::equal(Sweep(scene, ranged, 64, 20.0), torch::zeros_like(start)));
}

TEST(DepthSweepTest, ChecksItsInputs) {
  const SweepScene scene = MakeSweepScene();
  const EpipolarPair pair = MakeEpipolarPair(scene.K, scene.K, scene.R, scene.T, kHeight, kWidth);
  const torch::Tensor start = torch::full({1, 1, kHeight, kWidth}, 0.25f);
  const torch::Tensor usable = torch::ones_like(start, torch::kBool);
  const torch::Tensor& img = scene.reference;
  const auto throws = [&](const std::function<void()>& call, const std::string& words) {
    try {
      call();
      ADD_FAILURE() << "no exception; expected one naming " << words;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
  };
  throws([&] { SweepInverseDepth(img, img, img, img, pair.a, pair.b, start, usable, 3, -1, 2.0); },
         "max_hypotheses");
  throws([&] { SweepInverseDepth(img, img, img, img, pair.a, pair.b, start, usable, 3, 8, 0.0); }, "step_pixels");
  throws([&] { SweepInverseDepth(img, img, img, img, pair.a, pair.b, start, usable, 0, 8, 2.0); }, "radius");
  throws([&] { SweepInverseDepth(img.narrow(3, 0, 8), img, img, img, pair.a, pair.b, start, usable, 3, 8, 2.0); },
         "start's shape");
  throws([&] { SweepInverseDepth(img, img, img, img, pair.a, pair.b, start, start, 3, 8, 2.0); }, "usable");
  throws([&] { SweepInverseDepth(img, img, img, img, pair.a.narrow(1, 0, 2), pair.b, start, usable, 3, 8, 2.0); },
         "a must be");
  throws([&] { WindowMedianLevel(torch::zeros({1, 1, 4, 4}), torch::ones({1, 1, 4, 4}, torch::kBool), 2, 1); },
         "levels must be");
  throws([&] { WindowMedianLevel(torch::zeros({1, 1, 4, 4}, torch::kLong), torch::ones({1, 1, 4, 4}), 2, 1); },
         "mask must be");
}

// Against the lower median of each window's masked levels, taken directly
// by sorting (the window clipped at the border).
TEST(DepthSweepTest, WindowMedianLevelIsTheMedianOfEachWindow) {
  torch::manual_seed(11);
  constexpr int64_t kRows = 9, kCols = 13, kLevels = 7;
  for (const int64_t radius : {0, 1, 2, 4}) {
    const torch::Tensor levels = torch::randint(kLevels, {2, 1, kRows, kCols}, torch::kLong);
    torch::Tensor mask = torch::rand({2, 1, kRows, kCols}) > 0.3;
    mask.narrow(2, 0, 3).narrow(3, 0, 3).fill_(false);  // a corner with no counted pixel at radius 0, 1
    const torch::Tensor got = WindowMedianLevel(levels, mask, kLevels, radius);
    const auto la = levels.accessor<int64_t, 4>();
    const auto ma = mask.accessor<bool, 4>();
    const auto ga = got.accessor<int64_t, 4>();
    for (int64_t n = 0; n < 2; ++n) {
      for (int64_t i = 0; i < kRows; ++i) {
        for (int64_t j = 0; j < kCols; ++j) {
          std::vector<int64_t> window;
          for (int64_t y = std::max<int64_t>(0, i - radius); y <= std::min(kRows - 1, i + radius); ++y) {
            for (int64_t x = std::max<int64_t>(0, j - radius); x <= std::min(kCols - 1, j + radius); ++x) {
              if (ma[n][0][y][x]) window.push_back(la[n][0][y][x]);
            }
          }
          int64_t expected = -1;
          if (!window.empty()) {
            std::sort(window.begin(), window.end());
            expected = window[(window.size() - 1) / 2];
          }
          ASSERT_EQ(ga[n][0][i][j], expected) << "radius " << radius << " at " << n << "," << i << "," << j;
        }
      }
    }
  }
}

// In the refinement, with the search alone (no propagation to spread the
// right depth), a block at twice the true inverse depth is beyond the search
// (its matches are 12.5 pixels off); the sweep gives it the plane.
TEST(DepthSweepTest, RefinementTakesTheSweepWhereItCorrelatesBetter) {
  const SweepScene scene = MakeSweepScene();
  // [B,V,3,H,W], intrinsics [B,V,3,3], world = reference camera.
  const torch::Tensor images =
      torch::stack({scene.reference.expand({1, 3, kHeight, kWidth}), scene.source.expand({1, 3, kHeight, kWidth})}, 1);
  const torch::Tensor intrinsics = torch::stack({scene.K, scene.K}, 1);
  torch::Tensor source_pose = torch::eye(4);
  source_pose.index_put_({0, 3}, -kBaseline);
  const torch::Tensor extrinsics = torch::stack({torch::eye(4), source_pose}).unsqueeze(0);
  torch::Tensor block = torch::zeros({1, 1, kHeight, kWidth}, torch::kBool);
  block.narrow(2, 14, 20).narrow(3, 34, 30).fill_(true);
  const torch::Tensor truth = torch::full({1, 1, kHeight, kWidth}, kPlaneZ);
  const torch::Tensor start = torch::where(block, truth * 0.5, truth * 1.02);
  const torch::Tensor valid = torch::ones_like(start, torch::kBool);
  PhotometricRefinementOptions options;
  options.propagation_rounds = 0;  // the search alone, at full resolution
  options.steps = 6;
  PhotometricRefinementOptions without = options;
  without.sweep_hypotheses = 0;
  const auto block_error = [&](const PhotometricRefinementOptions& o) {
    const PhotometricRefinement out = RefineDepthPhotometrically(images, intrinsics, extrinsics, start, valid, o);
    return ((out.depth - truth) / truth).abs().masked_select(block).median().item<float>();
  };
  // Measured: 50 % without the sweep (the block stays), 0.33 % with it.
  EXPECT_GT(block_error(without), 0.3);
  EXPECT_LT(block_error(options), 0.01);
}

}  // namespace
}  // namespace dispmvs::model
