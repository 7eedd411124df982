// Hash noise, procedural textures and the per-view camera response.

#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "synth/generator.h"
#include "synth/hash_noise.h"
#include "synth/jpeg.h"
#include "synth/raycast.h"
#include "synth/rng.h"
#include "synth/shading.h"
#include "synth/texture.h"

namespace dispmvs::synth {
namespace {

// A 256 x 256 block of lattice coordinates (starting at negative values).
std::pair<torch::Tensor, torch::Tensor> Lattice() {
  const torch::Tensor r = torch::arange(-100, 156, torch::kLong);
  auto grid = torch::meshgrid({r, r}, "ij");
  return {grid[1], grid[0]};
}

TEST(HashNoiseTest, HashUnitIsUniformAndDecorrelated) {
  const auto [ix, iy] = Lattice();
  const torch::Tensor h = HashUnit(ix, iy, 123, torch::kDouble);
  EXPECT_TRUE(torch::equal(h, HashUnit(ix, iy, 123, torch::kDouble)));
  EXPECT_GE(h.min().item<double>(), 0.0);
  EXPECT_LT(h.max().item<double>(), 1.0);
  // 65536 samples: std of the mean is 0.0011, of a decile's share 0.0012.
  EXPECT_NEAR(h.mean().item<double>(), 0.5, 0.005);
  const torch::Tensor bins = torch::floor(h * 10).to(torch::kLong).reshape({-1}).bincount({}, 10);
  for (int b = 0; b < 10; ++b) EXPECT_NEAR(bins[b].item<double>() / 65536.0, 0.1, 0.006) << "bin " << b;
  // Neighbours and other seeds are uncorrelated (std of a correlation ~0.004).
  auto correlation = [](const torch::Tensor& a, const torch::Tensor& b) {
    const torch::Tensor x = a - a.mean(), y = b - b.mean();
    return ((x * y).mean() / (x.std(false) * y.std(false))).item<double>();
  };
  EXPECT_LT(std::abs(correlation(h.slice(1, 0, 255), h.slice(1, 1, 256))), 0.02);
  EXPECT_LT(std::abs(correlation(h.slice(0, 0, 255), h.slice(0, 1, 256))), 0.02);
  EXPECT_LT(std::abs(correlation(h, HashUnit(ix, iy, 124, torch::kDouble))), 0.02);
}

TEST(HashNoiseTest, ValueNoiseInterpolatesTheLattice) {
  const auto [ix, iy] = Lattice();
  const torch::Tensor u = ix.to(torch::kDouble), v = iy.to(torch::kDouble);
  // At lattice points: the lattice value itself.
  EXPECT_TRUE(torch::allclose(ValueNoise(u, v, 9), HashUnit(ix, iy, 9, torch::kDouble), 0, 1e-15));
  // At cell centres the smoothstep weight is 1/2: the mean of the 4 corners.
  const torch::Tensor corners = (HashUnit(ix, iy, 9, torch::kDouble) + HashUnit(ix + 1, iy, 9, torch::kDouble) +
                                 HashUnit(ix, iy + 1, 9, torch::kDouble) + HashUnit(ix + 1, iy + 1, 9, torch::kDouble)) /
                                4;
  EXPECT_TRUE(torch::allclose(ValueNoise(u + 0.5, v + 0.5, 9), corners, 0, 1e-12));
  const torch::Tensor f = FractalNoise(u * 0.37, v * 0.37, 9, 5);
  EXPECT_GE(f.min().item<double>(), 0.0);
  EXPECT_LT(f.max().item<double>(), 1.0);
  EXPECT_THROW(FractalNoise(u, v, 9, 0), std::invalid_argument);
}

TEST(HashNoiseTest, HashNormalIsStandardNormal) {
  const auto [ix, iy] = Lattice();
  const torch::Tensor n = HashNormal(ix, iy, 77, torch::kDouble);
  EXPECT_NEAR(n.mean().item<double>(), 0.0, 0.02);       // std of the mean 0.004
  EXPECT_NEAR(n.std().item<double>(), 1.0, 0.015);       // std of the std 0.003
  EXPECT_NEAR((n.abs() < 1).to(torch::kDouble).mean().item<double>(), 0.6827, 0.01);
}

// A [N,2] grid of UVs over [0, extent)^2 with `count`^2 samples.
torch::Tensor UvGrid(int64_t count, double extent) {
  const torch::Tensor r = torch::arange(count, torch::kDouble) * (extent / count);
  auto grid = torch::meshgrid({r, r}, "ij");
  return torch::stack({grid[1].reshape({-1}), grid[0].reshape({-1})}, 1);
}

TextureSpec Spec(Pattern pattern, double detail) {
  TextureSpec spec;
  spec.pattern = pattern;
  spec.color_a = {0.1, 0.2, 0.3};
  spec.color_b = {0.9, 0.7, 0.5};
  spec.frequency = 2;
  spec.angle = 0.3;
  spec.detail = detail;
  spec.seed = 5;
  return spec;
}

TEST(TextureTest, PatternsHaveTheirStructure) {
  const torch::Tensor uv = UvGrid(128, 4.0);
  const torch::Tensor ids = torch::zeros({uv.size(0)}, torch::kLong);
  auto grey_std = [&](const TextureSpec& spec) {
    return EvaluateAlbedo({spec}, ids, uv).mean(1).std().item<double>();
  };
  // Textured patterns vary; the flat one (with its tiny detail) barely does.
  for (Pattern p : {Pattern::kNoise, Pattern::kPolygons, Pattern::kStripes, Pattern::kBricks, Pattern::kChecker}) {
    EXPECT_GT(grey_std(Spec(p, 0.2)), 0.05) << "pattern " << static_cast<int>(p);
  }
  EXPECT_LT(grey_std(Spec(Pattern::kFlat, 0.02)), 0.01);
  // Without detail, polygons and stripes are piecewise constant with hard
  // edges: few distinct values (about one per cell) on 16384 samples.
  for (Pattern p : {Pattern::kPolygons, Pattern::kStripes, Pattern::kChecker}) {
    const torch::Tensor albedo = EvaluateAlbedo({Spec(p, 0.0)}, ids, uv).select(1, 0).contiguous();
    std::set<double> distinct(albedo.data_ptr<double>(), albedo.data_ptr<double>() + albedo.numel());
    EXPECT_LT(distinct.size(), 200u) << "pattern " << static_cast<int>(p);
    EXPECT_GT(distinct.size(), 3u) << "pattern " << static_cast<int>(p);
  }
  // The checkerboard alternates between its two colours (with jitter): the
  // grey levels of the two parities are far apart.
  const torch::Tensor checker = EvaluateAlbedo({Spec(Pattern::kChecker, 0.0)}, ids, uv).mean(1);
  const torch::Tensor light = checker > checker.median();
  EXPECT_GT(checker.masked_select(light).mean().item<double>() - checker.masked_select(~light).mean().item<double>(),
            0.25);
}

TEST(TextureTest, AlbedoIsAPureFunctionOfTextureAndUv) {
  Rng rng(3);
  std::vector<TextureSpec> textures;
  for (int k = 0; k < 12; ++k) textures.push_back(RandomTexture(rng));
  const torch::Tensor uv = UvGrid(40, 3.0);
  const torch::Tensor ids = torch::arange(uv.size(0), torch::kLong).remainder(12);
  const torch::Tensor albedo = EvaluateAlbedo(textures, ids, uv);
  EXPECT_GE(albedo.min().item<double>(), 0.0);
  EXPECT_LE(albedo.max().item<double>(), 1.0);
  // Any order, any batch: the same value per (texture, uv).
  const torch::Tensor perm = torch::randperm(uv.size(0), torch::kLong);
  EXPECT_TRUE(torch::equal(EvaluateAlbedo(textures, ids.index_select(0, perm), uv.index_select(0, perm)),
                           albedo.index_select(0, perm)));
  const torch::Tensor part = EvaluateAlbedo(textures, ids.slice(0, 0, 100), uv.slice(0, 0, 100));
  EXPECT_TRUE(torch::equal(part, albedo.slice(0, 0, 100)));
  // -1: no surface, the given colour.
  const torch::Tensor none = EvaluateAlbedo(textures, torch::full({2}, -1, torch::kLong), uv.slice(0, 0, 2), {0.25, 0.5, 0.75});
  EXPECT_TRUE(torch::equal(none, torch::tensor({0.25, 0.5, 0.75}, torch::kDouble).expand({2, 3})));
  EXPECT_THROW(EvaluateAlbedo(textures, torch::full({2}, 12, torch::kLong), uv.slice(0, 0, 2)), std::invalid_argument);
  EXPECT_THROW(EvaluateAlbedo(textures, ids, uv.slice(0, 0, 5)), std::invalid_argument);
}

// The same surface point seen from two cameras: the source ray through the
// exact projection of a reference hit lands on the same primitive with the
// same UV, so the albedo is the same; the recorded images still differ.
TEST(TextureTest, CorrespondingPointsHaveTheSameAlbedoInEveryView) {
  SynthConfig config;
  config.height = 40;
  config.width = 56;
  config.num_views = 2;
  config.p_walkthrough = config.p_turntable = config.p_outdoor = 0;  // table rig
  const SynthScene s = DrawScene(config, 11);
  RaycastOptions options;
  options.dtype = torch::kDouble;
  const RayHits ref = CastImage(s.scene, s.cameras[0], config.height, config.width, options);
  const PinholeCamera& src = s.cameras[1];
  // Project every reference hit into the source (double, scalar code).
  std::vector<double> xy, source_z;
  std::vector<int64_t> ref_index;
  const Mat3 to_world = Transposed(s.cameras[0].rotation);
  const auto depth = ref.depth.reshape({-1});
  for (int64_t k = 0; k < depth.numel(); ++k) {
    const double z = depth[k].item<double>();
    const double x = static_cast<double>(k % config.width), y = static_cast<double>(k / config.width);
    const Vec3 cam_point{(x - s.cameras[0].cx) / s.cameras[0].fx * z, (y - s.cameras[0].cy) / s.cameras[0].fy * z, z};
    const Vec3 p = src.ToCamera(to_world * (cam_point - s.cameras[0].translation));
    const double u = src.fx * p.x / p.z + src.cx, v = src.fy * p.y / p.z + src.cy;
    if (p.z <= 0 || u < 0 || v < 0 || u > config.width - 1 || v > config.height - 1) continue;
    xy.insert(xy.end(), {u, v});
    source_z.push_back(p.z);
    ref_index.push_back(k);
  }
  const RayHits hit = CastPixels(s.scene, src, torch::tensor(xy, torch::kDouble).view({-1, 2}), options);
  const torch::Tensor index = torch::tensor(ref_index, torch::kLong);
  const torch::Tensor ref_prim = ref.primitive.reshape({-1}).index_select(0, index);
  const torch::Tensor ref_uv = ref.uv.reshape({-1, 2}).index_select(0, index);
  // Visible in the source: the same primitive, at the same depth (not
  // another face of it, not something in front).
  const torch::Tensor expected_z = torch::tensor(source_z, torch::kDouble);
  const torch::Tensor visible = (hit.primitive == ref_prim) & ((hit.depth - expected_z).abs() < 1e-9 * expected_z);
  ASSERT_GT(visible.sum().item<int64_t>(), 300);
  const torch::Tensor uv_a = ref_uv.index({visible}), uv_b = hit.uv.index({visible});
  EXPECT_LT((uv_a - uv_b).abs().max().item<double>(), 1e-7);
  auto texture_of = [&](const torch::Tensor& prim) {
    std::vector<int64_t> ids;
    for (const Primitive& p : s.scene.primitives) ids.push_back(p.texture);
    return torch::tensor(ids, torch::kLong).index_select(0, prim);
  };
  const torch::Tensor tex = texture_of(ref_prim.index({visible}));
  const torch::Tensor albedo_a = EvaluateAlbedo(s.scene.textures, tex, uv_a);
  const torch::Tensor albedo_b = EvaluateAlbedo(s.scene.textures, tex, uv_b);
  // Equal unless a hard edge passes within 1e-7 UV of a sample.
  EXPECT_LE((albedo_a - albedo_b).abs().gt(1e-5).any(1).sum().item<int64_t>(), 1);
  EXPECT_GT(albedo_a.std().item<double>(), 0.02);  // the scene is textured
}

TEST(ShadingTest, LambertianByHand) {
  const torch::Tensor albedo = torch::full({3, 1, 4}, 0.5, torch::kDouble);
  const Vec3 light = Normalized({0, 0.6, 0.8});
  // Normals: towards the light, perpendicular, away, none.
  const torch::Tensor normal =
      torch::tensor({0.0, 0.6, 0.8, 1.0, 0.0, 0.0, 0.0, -0.6, -0.8, 0.0, 0.0, 0.0}, torch::kDouble).view({1, 4, 3});
  const torch::Tensor shaded = ShadeLambertian(albedo, normal, light, 0.3);
  const double expected[4] = {0.5, 0.5 * 0.3, 0.5 * 0.3, 0.5 * 0.3};
  for (int c = 0; c < 3; ++c)
    for (int k = 0; k < 4; ++k) EXPECT_NEAR(shaded[c][0][k].item<double>(), expected[k], 1e-12);
  // 60 degrees from the light: ambient + (1 - ambient) cos 60.
  const torch::Tensor tilted = torch::tensor({0.0, 0.6 * 0.5 + 0.8 * std::sqrt(0.75), 0.8 * 0.5 - 0.6 * std::sqrt(0.75)},
                                             torch::kDouble).view({1, 1, 3});
  EXPECT_NEAR(ShadeLambertian(torch::full({3, 1, 1}, 1.0, torch::kDouble), tilted, light, 0.3)[0][0][0].item<double>(),
              0.3 + 0.7 * 0.5, 1e-12);
  EXPECT_THROW(ShadeLambertian(albedo, normal.view({4, 1, 3}), light, 0.3), std::invalid_argument);
}

// Blinn-Phong by hand: light and view both along the normal (the half
// vector is the normal: the full strength); the view 60 degrees off (the
// half vector 30 degrees off: cos(30)^s); the light behind the surface
// (nothing); no surface (nothing).
TEST(ShadingTest, SpecularByHand) {
  const Vec3 light{0, 0, 1};
  const double c60 = 0.5, s60 = std::sqrt(0.75);
  const torch::Tensor normal =
      torch::tensor({0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0}, torch::kDouble).view({1, 4, 3});
  const torch::Tensor view =
      torch::tensor({0.0, 0.0, 1.0, s60, 0.0, c60, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0}, torch::kDouble).view({1, 4, 3});
  const torch::Tensor specular = torch::full({1, 4}, 0.4, torch::kDouble);
  const torch::Tensor shininess = torch::full({1, 4}, 20.0, torch::kDouble);
  const torch::Tensor highlight = ShadeSpecular(normal, view, light, specular, shininess);
  EXPECT_NEAR(highlight[0][0].item<double>(), 0.4, 1e-12);
  EXPECT_NEAR(highlight[0][1].item<double>(), 0.4 * std::pow(std::cos(M_PI / 6), 20.0), 1e-12);
  EXPECT_EQ(highlight[0][2].item<double>(), 0.0);
  EXPECT_EQ(highlight[0][3].item<double>(), 0.0);
  EXPECT_THROW(ShadeSpecular(normal, view.view({4, 1, 3}), light, specular, shininess), std::invalid_argument);
}

TEST(ShadingTest, GainWhiteBalanceGammaByHand) {
  const torch::Tensor radiance = torch::rand({3, 5, 6}, torch::kDouble);
  ViewPhotometry p;
  p.gain = 1.3;
  p.white_balance = {0.95, 1.0, 1.05};
  p.gamma = 1.2;
  const torch::Tensor image = ApplyPhotometry(radiance, p);
  for (int c = 0; c < 3; ++c) {
    for (int i = 0; i < 5; ++i) {
      for (int j = 0; j < 6; ++j) {
        const double x = std::clamp(radiance[c][i][j].item<double>() * 1.3 * p.white_balance[c], 0.0, 1.0);
        EXPECT_NEAR(image[c][i][j].item<double>(), std::pow(x, 1 / 1.2), 1e-12);
      }
    }
  }
}

TEST(ShadingTest, BlurKeepsFlatImagesAndMassNoiseHasItsSigma) {
  ViewPhotometry blur;
  blur.blur_sigma = 0.8;
  const torch::Tensor flat = torch::full({3, 20, 30}, 0.4, torch::kDouble);
  EXPECT_TRUE(torch::allclose(ApplyPhotometry(flat, blur), flat, 0, 1e-12));
  torch::Tensor dot = torch::zeros({3, 20, 30}, torch::kDouble);
  dot.index_put_({torch::indexing::Slice(), 10, 15}, 0.9);
  const torch::Tensor blurred = ApplyPhotometry(dot, blur);
  EXPECT_NEAR(blurred[0].sum().item<double>(), 0.9, 1e-9);       // mass kept away from the border
  EXPECT_LT(blurred[0][10][15].item<double>(), 0.9 * 0.5);        // and spread out
  EXPECT_NEAR(blurred[0][10][14].item<double>(), blurred[0][10][16].item<double>(), 1e-15);  // symmetric

  ViewPhotometry noisy;
  noisy.noise_sigma = 0.02;
  noisy.noise_seed = 4;
  const torch::Tensor grey = torch::full({3, 128, 128}, 0.5, torch::kDouble);
  const torch::Tensor noise = ApplyPhotometry(grey, noisy) - 0.5;
  EXPECT_NEAR(noise.mean().item<double>(), 0.0, 0.001);
  EXPECT_NEAR(noise.std().item<double>(), 0.02, 0.001);
  // Channels get independent noise; a different seed gives different noise.
  EXPECT_FALSE(torch::equal(noise[0], noise[1]));
  noisy.noise_seed = 5;
  EXPECT_FALSE(torch::equal(ApplyPhotometry(grey, noisy) - 0.5, noise));
  noisy.gamma = -1;
  EXPECT_THROW(ApplyPhotometry(grey, noisy), std::invalid_argument);
}

TEST(ShadingTest, RandomPhotometryStaysInItsRanges) {
  Rng rng(8);
  const PhotometryRanges ranges;
  for (int k = 0; k < 200; ++k) {
    const ViewPhotometry p = RandomPhotometry(ranges, rng);
    EXPECT_GE(p.gain, ranges.gain_min);
    EXPECT_LE(p.gain, ranges.gain_max);
    EXPECT_GE(p.gamma, ranges.gamma_min);
    EXPECT_LE(p.gamma, ranges.gamma_max);
    EXPECT_LE(p.noise_sigma, ranges.noise_sigma_max);
    EXPECT_LE(p.blur_sigma, ranges.blur_sigma_max);
    for (double w : p.white_balance) EXPECT_NEAR(w, 1.0, ranges.white_balance_jitter);
  }
}

// Vignetting by hand: radiance x (1 - v rho^2) before noise and gamma, rho
// the distance from the grid's centre over the corner pixels' distance.
TEST(ShadingTest, VignettingByHand) {
  const torch::Tensor radiance = torch::rand({3, 7, 10}, torch::kDouble);
  ViewPhotometry p;
  p.gain = 1.1;
  p.gamma = 1.3;
  p.vignetting = 0.4;
  const torch::Tensor image = ApplyPhotometry(radiance, p);
  const double corner = std::hypot(4.5, 3.0);
  for (int c = 0; c < 3; ++c) {
    for (int i = 0; i < 7; ++i) {
      for (int j = 0; j < 10; ++j) {
        const double rho = std::hypot(j - 4.5, i - 3.0) / corner;
        const double x = std::clamp(radiance[c][i][j].item<double>() * 1.1 * (1 - 0.4 * rho * rho), 0.0, 1.0);
        EXPECT_NEAR(image[c][i][j].item<double>(), std::pow(x, 1 / 1.3), 1e-12);
      }
    }
  }
  // The corners lose exactly v; the centre keeps its value.
  ViewPhotometry vignetting_only;
  vignetting_only.vignetting = 0.4;
  const torch::Tensor flat = ApplyPhotometry(torch::full({3, 9, 9}, 0.5, torch::kDouble), vignetting_only);
  EXPECT_NEAR(flat[1][0][0].item<double>(), 0.5 * 0.6, 1e-12);
  EXPECT_NEAR(flat[1][8][8].item<double>(), 0.5 * 0.6, 1e-12);
  EXPECT_NEAR(flat[1][4][4].item<double>(), 0.5, 1e-12);
  p.vignetting = 0.95;
  EXPECT_THROW(ApplyPhotometry(radiance, p), std::invalid_argument);
}

// Vignetting is drawn only when enabled, after every other draw: with it off
// the draws (so the scenes) are those of before the knob; with it on a
// view's other values are unchanged and its vignetting is in range.
TEST(ShadingTest, VignettingDrawLeavesTheOtherDraws) {
  PhotometryRanges off;
  PhotometryRanges on = off;
  on.vignetting_max = 0.4;
  Rng a(11), b(11);
  for (int k = 0; k < 50; ++k) {
    Rng a_view = a.Fork(static_cast<uint64_t>(k)), b_view = b.Fork(static_cast<uint64_t>(k));
    const ViewPhotometry p = RandomPhotometry(off, a_view), q = RandomPhotometry(on, b_view);
    EXPECT_EQ(p.vignetting, 0.0);
    EXPECT_GE(q.vignetting, 0.0);
    EXPECT_LE(q.vignetting, 0.4);
    EXPECT_EQ(p.gain, q.gain);
    EXPECT_EQ(p.gamma, q.gamma);
    EXPECT_EQ(p.white_balance, q.white_balance);
    EXPECT_EQ(p.noise_seed, q.noise_seed);
  }
  // The wide ranges contain the defaults and pass the generator's checks.
  const PhotometryRanges wide = WidePhotometry();
  EXPECT_LE(wide.gain_min, off.gain_min);
  EXPECT_GE(wide.gain_max, off.gain_max);
  EXPECT_GE(wide.white_balance_jitter, off.white_balance_jitter);
  EXPECT_GT(wide.vignetting_max, 0.0);
  SynthConfig config;
  config.photometry = wide;
  EXPECT_NO_THROW(config.Check());
  config.photometry.vignetting_max = 1.0;
  EXPECT_THROW(config.Check(), std::invalid_argument);
}

// ApplyPhotometry compresses last, after the tone curve (the draw of the
// quality is DrawScene's: GeneratorTest.JpegQualityCompressesEachViewOnItsOwn).
TEST(ShadingTest, JpegIsAppliedLast) {
  ViewPhotometry exact;
  exact.gain = 1.2;
  exact.gamma = 1.1;
  exact.noise_sigma = 0.01;
  ViewPhotometry compressed = exact;
  compressed.jpeg_quality = 70;
  const torch::Tensor radiance = torch::rand({3, 24, 40}, torch::kDouble);
  EXPECT_TRUE(torch::equal(ApplyPhotometry(radiance, compressed), JpegRoundTrip(ApplyPhotometry(radiance, exact), 70)));
  compressed.jpeg_quality = 101;
  EXPECT_THROW(ApplyPhotometry(radiance, compressed), std::invalid_argument);
  compressed.jpeg_quality = -1;
  EXPECT_THROW(compressed.Check(), std::invalid_argument);
}

// 1 - |(t mod 2) - 1| in plain double arithmetic.
double MirrorReference(double t) {
  const double m = t - 2.0 * std::floor(t / 2.0);
  return 1.0 - std::abs(m - 1.0);
}

// Bilinear interpolation of channel c of a [3,H,W] photo at pixel (x, y).
double BilinearReference(const torch::Tensor& photo, int c, double x, double y) {
  const auto a = photo.accessor<double, 3>();
  const int64_t h = photo.size(1), w = photo.size(2);
  const int64_t x0 = std::min<int64_t>(static_cast<int64_t>(std::floor(x)), w - 2);
  const int64_t y0 = std::min<int64_t>(static_cast<int64_t>(std::floor(y)), h - 2);
  const double fx = x - static_cast<double>(x0), fy = y - static_cast<double>(y0);
  return (1 - fx) * (1 - fy) * a[c][y0][x0] + fx * (1 - fy) * a[c][y0][x0 + 1] +
         (1 - fx) * fy * a[c][y0 + 1][x0] + fx * fy * a[c][y0 + 1][x0 + 1];
}

// A photo texture reads its photo as texture.h says: rotated, scaled
// coordinates, mirrored repeats, aspect kept, bilinear interpolation; with a
// zero detail amplitude the albedo is exactly the photo's colour.
TEST(TextureTest, PhotoTextureReadsThePhotoWithMirroredRepeats) {
  torch::manual_seed(3);
  const PhotoSet photos{torch::rand({3, 4, 6}, torch::kDouble), torch::rand({3, 5, 5}, torch::kDouble)};
  TextureSpec spec;
  spec.photo = 0;
  spec.frequency = 1.7;
  spec.angle = 0.4;
  spec.detail = 0;
  const torch::Tensor uv = torch::tensor({{0.1, 0.2}, {0.9, -0.35}, {1.6, 0.3}, {-2.2, 3.1}, {0.0, 0.0}},
                                         torch::kDouble);
  const torch::Tensor texture = torch::zeros({uv.size(0)}, torch::kLong);
  const torch::Tensor albedo = EvaluateAlbedo({spec}, texture, uv, {0, 0, 0}, &photos);
  const double w = 6, h = 4;
  for (int64_t i = 0; i < uv.size(0); ++i) {
    const double u = uv[i][0].item<double>(), v = uv[i][1].item<double>();
    const double ru = (u * std::cos(spec.angle) + v * std::sin(spec.angle)) * spec.frequency;
    const double rv = (v * std::cos(spec.angle) - u * std::sin(spec.angle)) * spec.frequency;
    const double x = MirrorReference(ru) * (w - 1), y = MirrorReference(rv * w / h) * (h - 1);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(albedo[i][c].item<double>(), BilinearReference(photos[0], c, x, y), 1e-12)
          << "point " << i << " channel " << c;
    }
  }
  // A photo index the set does not hold is refused, as is no set at all.
  spec.photo = 2;
  EXPECT_THROW(EvaluateAlbedo({spec}, texture, uv, {0, 0, 0}, &photos), std::invalid_argument);
  spec.photo = 0;
  EXPECT_THROW(EvaluateAlbedo({spec}, texture, uv), std::invalid_argument);
  EXPECT_THROW(CheckPhotoSet({torch::rand({4, 4})}), std::invalid_argument);
  EXPECT_NO_THROW(CheckPhotoSet(photos));
}

// Photos change the scenes only when used: a zero probability (or no
// photos) draws exactly the procedural scene; probability 1 makes every
// texture a photo texture, and the images change.
TEST(TextureTest, PhotoTexturesInTheGenerator) {
  SynthConfig config;
  config.height = 48;
  config.width = 64;
  config.num_views = 2;
  const SynthSample plain = GenerateSample(config, 77, torch::kCPU);
  auto photos = std::make_shared<PhotoSet>();
  torch::manual_seed(4);
  photos->push_back(torch::rand({3, 30, 40}));
  photos->push_back(torch::rand({3, 20, 20}));
  config.photos = photos;
  config.photo_probability = 0;
  EXPECT_TRUE(torch::equal(GenerateSample(config, 77, torch::kCPU).images, plain.images));

  config.photo_probability = 1;
  const SynthScene scene = DrawScene(config, 77);
  std::set<int> used;
  for (const TextureSpec& spec : scene.scene.textures) {
    EXPECT_GE(spec.photo, 0);
    EXPECT_LT(spec.photo, 2);
    used.insert(spec.photo);
  }
  EXPECT_EQ(used.size(), 2u);
  const SynthSample with_photos = RenderSample(scene, config, torch::kCPU);
  EXPECT_FALSE(torch::equal(with_photos.images, plain.images));
  EXPECT_TRUE(torch::isfinite(with_photos.images).all().item<bool>());
  config.photo_probability = 1.5;
  EXPECT_THROW(config.Check(), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::synth
