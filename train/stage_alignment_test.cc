// Half-pixel traps, pinned: the in-memory training samples, the network's
// stage grids and the matching loss's ground truth agree to well under a
// quarter of a stage pixel.
//
// For each stage stride s (1: full resolution; 4: fine; 16: coarse) the
// reference is read on the stage grid, cell (i, j) at full-resolution pixel
// (s*i, s*j), where the encoder's strided convolutions put it
// (StridedIntrinsics). Each cell is warped into the source with the ground-
// truth depth (ComputeGroundTruthMatches: stage coordinates, occlusion
// masked) and read there, at full resolution, shifted by a sub-pixel offset
// of the STAGE grid along x or y (s * offset full pixels). The photometric
// error must be smallest at offset 0. The same matches read with the block-
// centre convention (ScaleIntrinsics: cell j at s*j + (s-1)/2) must not be:
// that is the test's proof that it can fail.
//
// Both images are smoothed with a small Gaussian (sigma 1 pixel) against
// noise. A filter as wide as a stage cell is not used: on slanted surfaces
// its footprint differs between the views, which biases the comparison by a
// few pixels at 1/16 (seen with a 17x17 box: best at +0.25 along y).

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "model/matching_loss.h"
#include "synth/generator.h"

namespace dispmvs::train {
namespace {

namespace F = torch::nn::functional;

// [V,C,H,W] smoothed with a separable Gaussian of sigma 1 (7 taps, replicate
// padding; symmetric, so it moves nothing).
torch::Tensor Smooth(const torch::Tensor& images) {
  const torch::Tensor taps = torch::arange(-3, 4, images.options());
  torch::Tensor kernel = torch::exp(-0.5 * taps * taps);
  kernel = kernel / kernel.sum();
  const int64_t c = images.size(1);
  const torch::Tensor kx = kernel.view({1, 1, 1, 7}).expand({c, 1, 1, 7}).contiguous();
  const torch::Tensor ky = kernel.view({1, 1, 7, 1}).expand({c, 1, 7, 1}).contiguous();
  torch::Tensor x = F::pad(images, F::PadFuncOptions({3, 3, 3, 3}).mode(torch::kReplicate));
  x = F::conv2d(x, kx, F::Conv2dFuncOptions().groups(c));
  return F::conv2d(x, ky, F::Conv2dFuncOptions().groups(c));
}

torch::Tensor Sample(const torch::Tensor& image /*[1,C,h,w]*/, const torch::Tensor& xy /*[1,2,h,w]*/) {
  const double w = static_cast<double>(image.size(3)), h = static_cast<double>(image.size(2));
  const torch::Tensor gx = (2.0 * xy.select(1, 0) + 1.0) / w - 1.0;
  const torch::Tensor gy = (2.0 * xy.select(1, 1) + 1.0) / h - 1.0;
  return F::grid_sample(image, torch::stack({gx, gy}, -1),
                        F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kBorder).align_corners(false));
}

struct OffsetErrors {
  std::vector<double> offsets{-0.5, -0.25, 0.0, 0.25, 0.5};
  std::vector<double> along_x, along_y;
  // Where the error is smallest: the vertex of the least-squares parabola
  // through the five (offset, error) points, in stage pixels. More robust
  // than the arg-min when the curve is flat near its minimum (full
  // resolution, where a quarter pixel barely changes the error).
  double Vertex(const std::vector<double>& e) const {
    double sx2 = 0, sxe = 0, mean_x2 = 0;
    for (double x : offsets) mean_x2 += x * x / static_cast<double>(offsets.size());
    double sdd = 0, sde = 0;
    for (size_t i = 0; i < offsets.size(); ++i) {
      const double x = offsets[i];
      sx2 += x * x;
      sxe += x * e[i];
      sdd += (x * x - mean_x2) * (x * x - mean_x2);
      sde += (x * x - mean_x2) * e[i];
    }
    const double b = sxe / sx2, a = sde / sdd;  // offsets are symmetric about 0
    return a > 0 ? -b / (2 * a) : (b > 0 ? -1e9 : 1e9);  // no minimum: at an end
  }
};

// Mean absolute photometric error of the ground-truth warp into source 1,
// over several samples, for each offset; `convention_shift` is added to the
// source coordinates (0: strided cells; (1/s - 1)/2: block centres).
OffsetErrors WarpErrors(const std::vector<synth::SynthSample>& samples, int64_t s, double convention_shift) {
  OffsetErrors out;
  out.along_x.assign(out.offsets.size(), 0.0);
  out.along_y.assign(out.offsets.size(), 0.0);
  double count = 0;
  for (const auto& sample : samples) {
    const torch::Tensor images = Smooth(sample.images.to(torch::kFloat64));
    const int64_t H = images.size(2), W = images.size(3);
    const int64_t h = (H + s - 1) / s, w = (W + s - 1) / s;
    const auto gt = model::ComputeGroundTruthMatches(
        sample.depths.unsqueeze(0).to(torch::kFloat64), sample.intrinsics.unsqueeze(0).to(torch::kFloat64),
        sample.world_to_camera.unsqueeze(0).to(torch::kFloat64), s, h, w);
    const torch::Tensor xy = gt.xy.narrow(0, 0, 1) + convention_shift;  // source 1, stage pixels
    // Counted: visible, and a stage pixel away from the source border.
    const double sd = static_cast<double>(s);
    const torch::Tensor inside = (xy.select(1, 0) >= 1) & (xy.select(1, 0) * sd <= W - 1 - sd) &
                                 (xy.select(1, 1) >= 1) & (xy.select(1, 1) * sd <= H - 1 - sd);
    const torch::Tensor valid = (gt.valid.narrow(0, 0, 1).select(1, 0) & inside).to(torch::kFloat64);  // [1,h,w]
    const torch::Tensor ref = images.narrow(0, 0, 1).slice(2, 0, H, s).slice(3, 0, W, s);  // the stage grid
    const torch::Tensor src = images.narrow(0, 1, 1);
    for (size_t i = 0; i < out.offsets.size(); ++i) {
      for (int axis = 0; axis < 2; ++axis) {
        torch::Tensor shifted = xy.clone();
        shifted.select(1, axis).add_(out.offsets[i]);
        shifted = shifted * sd;  // stage -> full-resolution pixels
        const torch::Tensor error = (Sample(src, shifted) - ref).abs().mean(1);  // [1,h,w]
        (axis == 0 ? out.along_x : out.along_y)[i] += (error * valid).sum().item<double>();
      }
    }
    count += valid.sum().item<double>();
  }
  EXPECT_GT(count, 200) << "too few visible pixels at stride " << s;
  for (size_t i = 0; i < out.offsets.size(); ++i) {
    out.along_x[i] /= count;
    out.along_y[i] /= count;
  }
  return out;
}

std::vector<synth::SynthSample> Samples(int64_t height, int64_t width) {
  synth::SynthConfig config;
  config.height = height;
  config.width = width;
  config.num_views = 2;
  std::vector<synth::SynthSample> samples;
  for (uint64_t seed = 11; samples.size() < 4 && seed < 40; ++seed) {
    auto sample = synth::GenerateSample(config, seed, torch::kCPU);
    if (sample.rig == "table" || sample.rig == "turntable") samples.push_back(std::move(sample));
  }
  return samples;
}

void Print(const char* what, int64_t s, const OffsetErrors& e) {
  std::printf("[stage alignment] %s, stride %lld: error at offsets", what, static_cast<long long>(s));
  for (size_t i = 0; i < e.offsets.size(); ++i) std::printf(" %+.2f: x %.5f y %.5f;", e.offsets[i], e.along_x[i], e.along_y[i]);
  std::printf("\n");
}

TEST(StageAlignment, GroundTruthWarpIsBestAtZeroOffsetOnEveryStageGrid) {
  const auto samples = Samples(384, 512);
  ASSERT_GE(samples.size(), 2u);
  for (int64_t s : {1, 4, 16}) {
    const OffsetErrors strided = WarpErrors(samples, s, 0.0);
    Print("strided cells", s, strided);
    std::printf("[stage alignment] strided cells, stride %lld: best offset x %+.3f y %+.3f\n",
                static_cast<long long>(s), strided.Vertex(strided.along_x), strided.Vertex(strided.along_y));
    // Measured (4 table/turntable samples, 512x384): |x| <= 0.03 at every
    // stride, y +0.12 at full resolution and +0.04 at 1/4 and 1/16. The traps
    // this guards against are 0.375 (1/4) and 0.47 (1/16) stage pixels, or
    // 0.5 pixel at full resolution.
    EXPECT_LT(std::abs(strided.Vertex(strided.along_x)), 0.25) << "stride " << s;
    EXPECT_LT(std::abs(strided.Vertex(strided.along_y)), 0.25) << "stride " << s;
    if (s > 1) {
      // Block-centre convention on the same images: off by (s - 1) / (2 s)
      // stage pixels (0.375 at 1/4, 0.47 at 1/16), which the error sees.
      const OffsetErrors centred = WarpErrors(samples, s, 0.5 / static_cast<double>(s) - 0.5);
      Print("block centres", s, centred);
      std::printf("[stage alignment] block centres, stride %lld: best offset x %+.3f y %+.3f\n",
                  static_cast<long long>(s), centred.Vertex(centred.along_x), centred.Vertex(centred.along_y));
      EXPECT_GT(centred.Vertex(centred.along_x), 0.3) << "stride " << s;
      EXPECT_GT(centred.Vertex(centred.along_y), 0.3) << "stride " << s;
    }
  }
}

}  // namespace
}  // namespace dispmvs::train
