// GenerateSample end to end: determinism, units, multi-view geometric
// consistency of the ground truth, and per-view photometric variation.

#include "synth/generator.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <memory>
#include <set>
#include <string>
#include <tuple>

#include <torch/cuda.h>

#include "synth/jpeg.h"
#include "synth/raycast.h"

namespace dispmvs::synth {
namespace {

SynthConfig SmallConfig() {
  SynthConfig config;
  config.height = 48;
  config.width = 64;
  config.num_views = 3;
  config.min_objects = 6;
  config.max_objects = 10;
  return config;
}

SynthConfig OnlyRig(SynthConfig config, RigKind kind) {
  config.p_table = kind == RigKind::kTable;
  config.p_walkthrough = kind == RigKind::kWalkThrough;
  config.p_turntable = kind == RigKind::kTurntable;
  config.p_outdoor = kind == RigKind::kOutdoor;
  return config;
}

TEST(GeneratorTest, SameSeedSameTensorsBitForBit) {
  const SynthConfig config = SmallConfig();
  const SynthSample a = GenerateSample(config, 42, torch::kCPU);
  const SynthSample b = GenerateSample(config, 42, torch::kCPU);
  EXPECT_TRUE(torch::equal(a.images, b.images));
  EXPECT_TRUE(torch::equal(a.depths, b.depths));
  EXPECT_TRUE(torch::equal(a.intrinsics, b.intrinsics));
  EXPECT_TRUE(torch::equal(a.world_to_camera, b.world_to_camera));
  EXPECT_EQ(a.depth_min, b.depth_min);
  EXPECT_EQ(a.rig, b.rig);
  const SynthSample c = GenerateSample(config, 43, torch::kCPU);
  EXPECT_FALSE(torch::equal(a.images, c.images));
}

TEST(GeneratorTest, ShapesRangesAndConventions) {
  SynthConfig config = SmallConfig();
  for (int kind = 0; kind < kNumRigKinds; ++kind) {
    const SynthConfig c = OnlyRig(config, static_cast<RigKind>(kind));
    const SynthSample s = GenerateSample(c, 7 + kind, torch::kCPU);
    SCOPED_TRACE(s.rig);
    EXPECT_EQ(s.rig, RigName(static_cast<RigKind>(kind)));
    EXPECT_EQ(s.images.sizes(), (std::vector<int64_t>{3, 3, 48, 64}));
    EXPECT_EQ(s.depths.sizes(), (std::vector<int64_t>{3, 1, 48, 64}));
    EXPECT_EQ(s.intrinsics.sizes(), (std::vector<int64_t>{3, 3, 3}));
    EXPECT_EQ(s.world_to_camera.sizes(), (std::vector<int64_t>{3, 4, 4}));
    EXPECT_GE(s.images.min().item<float>(), 0.0f);
    EXPECT_LE(s.images.max().item<float>(), 1.0f);
    EXPECT_GE(s.depths.min().item<float>(), 0.0f);
    // Every rig has a background around everything: every ray hits something.
    EXPECT_GT(s.depths.min().item<float>(), 0.0f);
    EXPECT_GT(s.depth_min, 0.0);
    EXPECT_LT(s.depth_min, s.depth_max);
    for (int v = 0; v < 3; ++v) {
      const torch::Tensor K = s.intrinsics[v].to(torch::kDouble);
      // Principal point within 3 std of the pixel-index image centre.
      EXPECT_NEAR(K[0][2].item<double>(), 31.5, 3 * 0.02 * 64 + 1e-9);
      EXPECT_NEAR(K[1][2].item<double>(), 23.5, 3 * 0.02 * 48 + 1e-9);
      const torch::Tensor R = s.world_to_camera[v].slice(0, 0, 3).slice(1, 0, 3).to(torch::kDouble);
      EXPECT_TRUE(torch::allclose(R.matmul(R.t()), torch::eye(3, torch::kDouble), 0, 1e-6));
    }
  }
}

TEST(GeneratorTest, OutdoorDepthRangeSpansOrdersOfMagnitude) {
  SynthConfig config = OnlyRig(SmallConfig(), RigKind::kOutdoor);
  config.scale_min = config.scale_max = 1.0;
  for (uint64_t seed = 0; seed < 3; ++seed) {
    const SynthSample s = GenerateSample(config, seed, torch::kCPU);
    const double near = s.depths[0].masked_select(s.depths[0] > 0).min().item<double>();
    const double far = s.depths[0].max().item<double>();
    EXPECT_GT(far / near, 100.0) << "seed " << seed << " near " << near << " far " << far;
    EXPECT_LE(far, 1200.0 + 1e-3);  // the background sphere
  }
}

TEST(GeneratorTest, MetricScaleChangesOnlyLengths) {
  SynthConfig small = SmallConfig(), large = SmallConfig();
  small.scale_min = small.scale_max = 1e-3;
  large.scale_min = large.scale_max = 1e3;
  const SynthSample a = GenerateSample(small, 5, torch::kCPU);
  const SynthSample b = GenerateSample(large, 5, torch::kCPU);
  EXPECT_TRUE(torch::equal(a.images, b.images));
  EXPECT_TRUE(torch::equal(a.intrinsics, b.intrinsics));
  const double ratio = b.scale / a.scale;
  EXPECT_NEAR(ratio, 1e6, 1e-3);
  EXPECT_TRUE(torch::allclose(b.depths.to(torch::kDouble), a.depths.to(torch::kDouble) * ratio, 1e-6, 0));
  const auto ta = a.world_to_camera.slice(1, 0, 3).slice(2, 3, 4).to(torch::kDouble);
  const auto tb = b.world_to_camera.slice(1, 0, 3).slice(2, 3, 4).to(torch::kDouble);
  EXPECT_TRUE(torch::allclose(tb, ta * ratio, 1e-6, 1e-30));
  EXPECT_NEAR(b.depth_max / a.depth_max, ratio, 1e-6 * ratio);
}

// Back-projects reference pixels with their GT depth, moves the points into
// a source camera with the sample's own matrices (Eigen, double), and casts
// a ray through the exact sub-pixel projection in that source: where the
// point is not occluded the ray must stop at the point (relative 1e-4);
// it may stop earlier (occluded) but never later.
TEST(GeneratorTest, ReferenceDepthsReprojectOntoSourceSurfaces) {
  SynthConfig config = SmallConfig();
  config.num_views = 4;
  int total_visible = 0;
  for (int kind = 0; kind < kNumRigKinds; ++kind) {
    const SynthConfig c = OnlyRig(config, static_cast<RigKind>(kind));
    const SynthScene scene = DrawScene(c, 100 + kind);
    const SynthSample sample = RenderSample(scene, c, torch::kCPU);
    SCOPED_TRACE(sample.rig);
    const auto depth = sample.depths[0][0].to(torch::kDouble).contiguous();
    auto matrix = [](const torch::Tensor& t, int rows, int cols) {
      Eigen::MatrixXd m(rows, cols);
      const auto d = t.to(torch::kDouble).contiguous();
      for (int r = 0; r < rows; ++r)
        for (int k = 0; k < cols; ++k) m(r, k) = d[r][k].item<double>();
      return m;
    };
    const Eigen::Matrix3d K0 = matrix(sample.intrinsics[0], 3, 3);
    const Eigen::Matrix4d T0 = matrix(sample.world_to_camera[0], 4, 4);
    for (int v = 1; v < c.num_views; ++v) {
      const Eigen::Matrix3d Kv = matrix(sample.intrinsics[v], 3, 3);
      const Eigen::Matrix4d Tv = matrix(sample.world_to_camera[v], 4, 4);
      const Eigen::Matrix4d ref_to_src = Tv * T0.inverse();
      std::vector<double> xy, expected_z;
      for (int i = 0; i < c.height; i += 2) {
        for (int j = 0; j < c.width; j += 2) {
          const double z = depth[i][j].item<double>();
          const Eigen::Vector3d ray = K0.inverse() * Eigen::Vector3d(j, i, 1);
          const Eigen::Vector4d p = ref_to_src * (z * ray).homogeneous();
          if (p.z() <= 0) continue;
          const Eigen::Vector3d q = Kv * p.head<3>();
          const double x = q.x() / q.z(), y = q.y() / q.z();
          if (x < 0 || y < 0 || x > c.width - 1 || y > c.height - 1) continue;
          xy.push_back(x);
          xy.push_back(y);
          expected_z.push_back(p.z());
        }
      }
      ASSERT_GT(expected_z.size(), 50u) << "the source barely overlaps the reference";
      // The scene is at unit scale: cast there and scale the depth like the sample.
      const torch::Tensor pixels = torch::tensor(xy, torch::kDouble).view({-1, 2});
      RaycastOptions options;
      options.dtype = torch::kDouble;
      const RayHits hits = CastPixels(scene.scene, scene.cameras[static_cast<size_t>(v)], pixels, options);
      int visible = 0, beyond = 0;
      for (size_t k = 0; k < expected_z.size(); ++k) {
        const double got = hits.depth[static_cast<int64_t>(k)].item<double>() * sample.scale;
        const double want = expected_z[k];
        if (std::abs(got - want) <= 1e-4 * want) {
          ++visible;
        } else if (got > want) {
          ++beyond;
        }
      }
      // Float32 GT depth of the reference puts the point within ~1e-6 of
      // the surface; a ray passing it can only happen at a silhouette where
      // the reprojected point lands off the object by that much.
      EXPECT_LE(beyond, static_cast<int>(expected_z.size() / 100)) << "view " << v;
      EXPECT_GT(visible, static_cast<int>(expected_z.size() / 3)) << "view " << v;
      total_visible += visible;
    }
  }
  EXPECT_GT(total_visible, 1000);
}

TEST(GeneratorTest, ViewsDifferPhotometrically) {
  const SynthConfig config = SmallConfig();
  const SynthScene scene = DrawScene(config, 9);
  // Render the reference camera twice with each view's photometry: the same
  // pixels, different cameras' responses.
  SynthScene twice = scene;
  twice.cameras = {scene.cameras[0], scene.cameras[0]};
  twice.photometry = {scene.photometry[0], scene.photometry[1]};
  const SynthSample s = RenderSample(twice, config, torch::kCPU);
  EXPECT_TRUE(torch::equal(s.depths[0], s.depths[1]));
  EXPECT_GT((s.images[0] - s.images[1]).abs().mean().item<double>(), 0.005);
  // Same photometry twice: identical images.
  twice.photometry = {scene.photometry[0], scene.photometry[0]};
  const SynthSample same = RenderSample(twice, config, torch::kCPU);
  EXPECT_TRUE(torch::equal(same.images[0], same.images[1]));
}

TEST(GeneratorTest, ConfigCheckRejectsNonsense) {
  SynthConfig c = SmallConfig();
  EXPECT_NO_THROW(c.Check());
  c.num_views = 1;
  EXPECT_THROW(c.Check(), std::invalid_argument);
  c = SmallConfig();
  c.p_table = c.p_walkthrough = c.p_turntable = c.p_outdoor = 0;
  EXPECT_THROW(c.Check(), std::invalid_argument);
  c = SmallConfig();
  c.scale_min = 0;
  EXPECT_THROW(c.Check(), std::invalid_argument);
  c = SmallConfig();
  c.max_objects = c.min_objects - 1;
  EXPECT_THROW(c.Check(), std::invalid_argument);
  c = SmallConfig();
  c.height = 100000;
  EXPECT_THROW(GenerateSample(c, 1, torch::kCPU), std::invalid_argument);
}

TEST(GeneratorTest, DifficultyOneIsTheFullGeneratorAndLowerIsEasier) {
  SynthConfig config = SmallConfig();
  const SynthSample full = GenerateSample(config, 7, torch::kCPU);
  config.difficulty = 1.0;  // explicit: the same scenes bit for bit
  const SynthSample one = GenerateSample(config, 7, torch::kCPU);
  EXPECT_TRUE(torch::equal(full.images, one.images));
  EXPECT_TRUE(torch::equal(full.world_to_camera, one.world_to_camera));

  // Baselines shrink to 0.35 of the full ones at difficulty 0, same rig and
  // reference camera; photometry gets closer to neutral; ambient rises.
  double full_baseline = 0, easy_baseline = 0;
  double full_spread = 0, easy_spread = 0;
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    SynthConfig hard = SmallConfig(), easy = SmallConfig();
    easy.difficulty = 0.0;
    const SynthScene a = DrawScene(hard, seed), b = DrawScene(easy, seed);
    ASSERT_EQ(a.rig, b.rig);
    EXPECT_EQ(a.cameras[0].translation[0], b.cameras[0].translation[0]);
    EXPECT_GE(b.scene.ambient, a.scene.ambient);
    for (size_t v = 1; v < a.cameras.size(); ++v) {
      full_baseline += Norm(a.cameras[v].Center() - a.cameras[0].Center());
      easy_baseline += Norm(b.cameras[v].Center() - b.cameras[0].Center());
    }
    for (size_t v = 0; v < a.photometry.size(); ++v) {
      full_spread += std::abs(a.photometry[v].gain - 1.0);
      easy_spread += std::abs(b.photometry[v].gain - 1.0);
    }
  }
  EXPECT_NEAR(easy_baseline / full_baseline, 0.35, 1e-9);
  EXPECT_EQ(easy_spread, 0.0);  // gain range collapsed to 1
  EXPECT_GT(full_spread, 0.0);

  config.difficulty = 1.5;
  EXPECT_THROW(config.Check(), std::invalid_argument);
}

// Supersampling s: each pixel's colour is the mean radiance of the s x s
// rays at offsets (k - (s - 1) / 2) / s. Checked against an independent
// construction: an s = 1 render s times larger in each direction, by a
// camera whose pixel (s i + a, s j + b) looks through (j + (b - 1) / 3,
// i + (a - 1) / 3) of the original (s = 3), averaged over 3 x 3 blocks, with
// photometry that applies nothing.
TEST(GeneratorTest, SupersamplingAveragesSubPixelRaysAndKeepsTheDepth) {
  for (uint64_t seed : {3u, 11u}) {
    SynthConfig config = SmallConfig();
    SynthScene scene = DrawScene(config, seed);
    for (ViewPhotometry& p : scene.photometry) p = ViewPhotometry{};
    const SynthSample one = RenderSample(scene, config, torch::kCPU);
    config.supersampling = 3;
    const SynthSample three = RenderSample(scene, config, torch::kCPU);
    EXPECT_TRUE(torch::equal(one.depths, three.depths));  // the centre ray's, bit for bit
    EXPECT_TRUE(torch::equal(one.world_to_camera, three.world_to_camera));
    EXPECT_TRUE(torch::equal(one.intrinsics, three.intrinsics));

    SynthScene large = scene;
    for (PinholeCamera& cam : large.cameras) {
      cam.fx *= 3;
      cam.fy *= 3;
      cam.cx = 3 * cam.cx + 1;
      cam.cy = 3 * cam.cy + 1;
    }
    SynthConfig large_config = SmallConfig();
    large_config.height *= 3;
    large_config.width *= 3;
    const torch::Tensor expected =
        torch::avg_pool2d(RenderSample(large, large_config, torch::kCPU).images, {3, 3}, {3, 3});
    EXPECT_LT((three.images - expected).abs().max().item<double>(), 2e-5) << "seed " << seed;
    // Not the centre ray alone: the images differ where texture or edges are finer than a pixel.
    EXPECT_GT((three.images - one.images).abs().mean().item<double>(), 1e-3) << "seed " << seed;
  }
  SynthConfig bad = SmallConfig();
  for (int s : {0, 2, 9}) {
    bad.supersampling = s;
    EXPECT_THROW(bad.Check(), std::invalid_argument) << s;
  }
}

// What the knob is for: a texture far finer than the pixel grid. Point
// samples of it change from view to view, its mean does not; so two views of
// the same far wall, through their ground-truth correspondences, agree much
// better with s = 5 than with one ray per pixel.
TEST(GeneratorTest, SupersamplingMakesAFineFarTextureAgreeBetweenViews) {
  SynthConfig config = SmallConfig();
  config.height = 64;
  config.width = 64;
  config.num_views = 2;
  SynthScene scene;
  scene.scale = 1;
  TextureSpec fine;
  fine.pattern = Pattern::kChecker;
  fine.color_a = {0.1, 0.1, 0.1};
  fine.color_b = {0.9, 0.9, 0.9};
  fine.frequency = 400;  // cells per UV unit: about 4 per pixel at this distance
  fine.detail = 0;
  fine.jitter = 0;
  scene.scene.textures.push_back(fine);
  Primitive wall;
  wall.shape = Shape::kQuad;
  wall.texture = 0;
  wall.center = {0, 0, 10};
  wall.half_size = {8, 8, 0};
  wall.uv_unit = 16;
  scene.scene.primitives.push_back(wall);
  scene.scene.light_direction = Normalized(Vec3{0.2, -0.3, -1});
  scene.scene.ambient = 1.0;
  PinholeCamera cam = PinholeCamera::LookAt({0, 0, 0}, {0, 0, 10}, {0, -1, 0});
  cam.fx = cam.fy = 60;
  cam.cx = cam.cy = 31.5;
  PinholeCamera moved = PinholeCamera::LookAt({0.37, 0.11, 0}, {0.37, 0.11, 10}, {0, -1, 0});
  moved.fx = moved.fy = 60;
  moved.cx = moved.cy = 31.5;
  scene.cameras = {cam, moved};
  scene.photometry.assign(2, ViewPhotometry{});

  // The wall is fronto-parallel to both cameras: a pixel (x, y) of the first
  // view sees the point the second sees at (x - fx tx / Z, y - fy ty / Z).
  auto disagreement = [&](int s) {
    config.supersampling = s;
    const SynthSample sample = RenderSample(scene, config, torch::kCPU);
    const double dx = 60 * 0.37 / 10, dy = 60 * 0.11 / 10;  // 2.22 and 0.66 px
    const torch::Tensor grid = torch::stack(
        {(torch::arange(64, torch::kFloat).view({1, 64}).expand({64, 64}) - dx) / 31.5 - 1,
         (torch::arange(64, torch::kFloat).view({64, 1}).expand({64, 64}) - dy) / 31.5 - 1}, -1).unsqueeze(0);
    const torch::Tensor warped = torch::grid_sampler(sample.images[1].unsqueeze(0), grid, 0, 0, true)[0];
    return (warped - sample.images[0]).abs().narrow(1, 8, 48).narrow(2, 8, 48).mean().item<double>();
  };
  const double point = disagreement(1), box = disagreement(5);
  EXPECT_GT(point, 0.1);        // point samples of the checker: unrelated noise in the two views
  EXPECT_LT(box, 0.25 * point);  // the pixel means agree
}

// Glossy coats add a highlight and nothing else: depths and cameras stay,
// every pixel is at least as bright (photometry that applies nothing), some
// brighter, and where it is brighter differs between views (the highlight
// moves with the viewpoint). The materials' own random stream leaves every
// other draw as it was.
TEST(GeneratorTest, SpecularSurfacesAddViewDependentHighlightsOnly) {
  int glossy_scenes = 0;
  for (uint64_t seed : {5u, 6u, 7u}) {
    SynthConfig matte = SmallConfig(), glossy = SmallConfig();
    matte.num_views = glossy.num_views = 2;
    glossy.specular_probability = 1;
    SynthScene a = DrawScene(matte, seed), b = DrawScene(glossy, seed);
    for (auto* scene : {&a, &b}) {
      for (ViewPhotometry& p : scene->photometry) p = ViewPhotometry{};
    }
    for (const Primitive& p : b.scene.primitives) {
      EXPECT_GE(p.specular, 0.15);
      EXPECT_LE(p.specular, 0.6);
      EXPECT_GE(p.shininess, 8);
      EXPECT_LE(p.shininess, 256);
    }
    const SynthSample plain = RenderSample(a, matte, torch::kCPU), shiny = RenderSample(b, glossy, torch::kCPU);
    EXPECT_TRUE(torch::equal(plain.depths, shiny.depths));
    EXPECT_TRUE(torch::equal(plain.world_to_camera, shiny.world_to_camera));
    EXPECT_GE((shiny.images - plain.images).min().item<double>(), 0.0);
    const torch::Tensor brighter = (shiny.images - plain.images).amax(1) > 0.05;  // [V,H,W]
    if (brighter.any().item<bool>()) ++glossy_scenes;
    // The highlight's share of the pixels is not the same in both views.
    EXPECT_NE(brighter[0].sum().item<int64_t>(), brighter[1].sum().item<int64_t>()) << "seed " << seed;
  }
  EXPECT_GE(glossy_scenes, 2);
  SynthConfig bad = SmallConfig();
  bad.specular_probability = 1.5;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// The outdoor sky at infinity (SynthConfig::background_at_infinity): the sky
// loses its depth and nothing else does (but for the horizon, where ground
// as far as the sky meets it); a copy of the reference moved 40 units
// sideways (the rig's baselines are 0.2-2) without turning sees the sky in
// exactly the same pixels' colours, while the finite sky moves; other rigs
// stay bit for bit.
TEST(GeneratorTest, BackgroundAtInfinityHasNoDepthAndNoParallax) {
  const SynthConfig finite = OnlyRig(SmallConfig(), RigKind::kOutdoor);
  SynthConfig infinite = finite;
  infinite.background_at_infinity = true;
  int with_sky = 0;
  for (uint64_t seed : {3u, 4u, 5u}) {
    SCOPED_TRACE(seed);
    SynthScene a = DrawScene(finite, seed), b = DrawScene(infinite, seed);
    for (SynthScene* s : {&a, &b}) {
      s->cameras.resize(2);
      PinholeCamera moved = s->cameras[0];
      const Vec3 centre = moved.Center() + 40.0 * (Transposed(moved.rotation) * Vec3{1, 0, 0});
      moved.translation = -1.0 * (moved.rotation * centre);
      s->cameras[1] = moved;
      s->photometry.assign(2, ViewPhotometry{});
    }
    const SynthSample plain = RenderSample(a, finite, torch::kCPU), sky = RenderSample(b, infinite, torch::kCPU);
    EXPECT_TRUE(torch::equal(plain.world_to_camera, sky.world_to_camera));
    // The reference: no depth exactly where the finite sky was (hundreds of
    // units away), the same depth elsewhere but where the finite depth is as
    // far (the horizon, where sky and ground meet).
    const torch::Tensor no_depth = sky.depths[0] == 0;
    const int64_t sky_pixels = no_depth.sum().item<int64_t>();
    if (sky_pixels > no_depth.numel() / 20) ++with_sky;
    EXPECT_TRUE((plain.depths[0].masked_select(no_depth) > 300 * a.scale).all().item<bool>());
    const torch::Tensor changed = ~no_depth & (plain.depths[0] != sky.depths[0]);
    EXPECT_TRUE((plain.depths[0].masked_select(changed) > 300 * a.scale).all().item<bool>());
    if (sky_pixels == 0) continue;
    // Where both views see the sky, the same colours at the same pixels.
    const torch::Tensor both = ((sky.depths[0] == 0) & (sky.depths[1] == 0)).expand({3, -1, -1});
    EXPECT_TRUE(torch::equal(sky.images[0].masked_select(both), sky.images[1].masked_select(both)));
    const double finite_shift =
        (plain.images[0].masked_select(both) - plain.images[1].masked_select(both)).abs().mean().item<double>();
    EXPECT_GT(finite_shift, 1e-3);
  }
  EXPECT_GE(with_sky, 2);
  for (RigKind kind : {RigKind::kTable, RigKind::kWalkThrough, RigKind::kTurntable}) {
    SynthConfig off = OnlyRig(SmallConfig(), kind), on = off;
    on.background_at_infinity = true;
    const SynthSample x = GenerateSample(off, 11, torch::kCPU), y = GenerateSample(on, 11, torch::kCPU);
    EXPECT_TRUE(torch::equal(x.images, y.images));
    EXPECT_TRUE(torch::equal(x.depths, y.depths));
  }
}

// JPEG compression per view: the geometry and every other draw stay (all
// views' photometry: the qualities come from a stream of their own), each
// image is the uncompressed one through that view's JPEG round trip (a
// quality in the range per view), and lower difficulty compresses less.
TEST(GeneratorTest, JpegQualityCompressesEachViewOnItsOwn) {
  SynthConfig plain = SmallConfig(), jpeg = SmallConfig();
  jpeg.jpeg_quality_min = 40;
  jpeg.jpeg_quality_max = 90;
  const SynthScene a = DrawScene(plain, 9), b = DrawScene(jpeg, 9);
  ASSERT_EQ(a.photometry.size(), b.photometry.size());
  std::set<int> qualities;
  for (size_t v = 0; v < a.photometry.size(); ++v) {
    EXPECT_EQ(a.photometry[v].jpeg_quality, 0);
    EXPECT_GE(b.photometry[v].jpeg_quality, 40);
    EXPECT_LE(b.photometry[v].jpeg_quality, 90);
    qualities.insert(b.photometry[v].jpeg_quality);
    EXPECT_EQ(a.photometry[v].gain, b.photometry[v].gain);
    EXPECT_EQ(a.photometry[v].noise_seed, b.photometry[v].noise_seed);
  }
  EXPECT_GE(qualities.size(), 2u);
  const SynthSample exact = RenderSample(a, plain, torch::kCPU), compressed = RenderSample(b, jpeg, torch::kCPU);
  EXPECT_TRUE(torch::equal(exact.depths, compressed.depths));
  EXPECT_TRUE(torch::equal(exact.world_to_camera, compressed.world_to_camera));
  for (int64_t v = 0; v < exact.images.size(0); ++v) {
    const torch::Tensor expected =
        JpegRoundTrip(exact.images[v].to(torch::kDouble), b.photometry[static_cast<size_t>(v)].jpeg_quality);
    // Levels k / 255 held in float32: equal to float precision.
    const torch::Tensor off = (compressed.images[v].to(torch::kDouble) - expected).abs() * 255.0;
    EXPECT_LT(off.max().item<double>(), 1e-4);
    EXPECT_FALSE(torch::equal(compressed.images[v], exact.images[v]));
  }
  SynthConfig easier = jpeg;
  easier.difficulty = 0.5;
  for (const ViewPhotometry& p : DrawScene(easier, 9).photometry) EXPECT_GE(p.jpeg_quality, 70);  // 100 - 0.5 x 60
  SynthConfig bad = SmallConfig();
  for (const auto& [low, high] : {std::pair<int, int>{0, 80}, {90, 80}, {50, 101}}) {
    bad.jpeg_quality_min = low;
    bad.jpeg_quality_max = high;
    EXPECT_THROW(bad.Check(), std::invalid_argument) << low << "," << high;
  }
}

TEST(GeneratorTest, RobustDepthRangeIsNearestRankQuantile) {
  // Values 1..101 (and zeros, which are ignored): the 2nd percentile is the
  // value at rank round(0.02 * 100) = 2, i.e. 3; the 98th at rank 98, i.e. 99.
  torch::Tensor d = torch::cat({torch::arange(1, 102, torch::kDouble), torch::zeros({7}, torch::kDouble)});
  const auto [lo, hi] = RobustDepthRange(d.flip(0));
  EXPECT_EQ(lo, 3.0);
  EXPECT_EQ(hi, 99.0);
  const auto [zlo, zhi] = RobustDepthRange(torch::zeros({4}));
  EXPECT_EQ(zlo, 0.0);
  EXPECT_EQ(zhi, 0.0);
}

// Generation on a device (CUDA where there is one; the CPU instance checks
// this harness), with photo textures (CPU photos sampled on the device),
// sensor noise and blur: the cameras are the CPU's exactly, depths and
// images agree with the CPU's up to float rounding on all but a few pixels
// (a silhouette ray may hit the other surface).
class GeneratorDeviceTest : public ::testing::TestWithParam<std::tuple<std::string, int>> {};

TEST_P(GeneratorDeviceTest, SamplesMatchTheCpu) {
  const auto [device_name, kind] = GetParam();
  const torch::Device device(device_name);
  if (device.is_cuda() && !torch::cuda::is_available()) GTEST_SKIP() << "no CUDA device";
  SynthConfig config = OnlyRig(SmallConfig(), static_cast<RigKind>(kind));
  auto photos = std::make_shared<PhotoSet>();
  torch::manual_seed(4);
  photos->push_back(torch::rand({3, 30, 40}));
  config.photos = photos;
  config.photo_probability = 0.5;
  for (const uint64_t seed : {3u, 4u}) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const SynthSample expected = GenerateSample(config, seed, torch::kCPU);
    const SynthSample got = GenerateSample(config, seed, device);
    for (const torch::Tensor& t : {got.images, got.depths, got.intrinsics, got.world_to_camera}) {
      EXPECT_EQ(t.device(), device);
      EXPECT_EQ(t.scalar_type(), torch::kFloat);
    }
    EXPECT_TRUE(torch::equal(got.intrinsics.cpu(), expected.intrinsics));
    EXPECT_TRUE(torch::equal(got.world_to_camera.cpu(), expected.world_to_camera));
    EXPECT_EQ(got.rig, expected.rig);
    EXPECT_NEAR(got.depth_min, expected.depth_min, 1e-4 * expected.depth_min);
    EXPECT_NEAR(got.depth_max, expected.depth_max, 1e-4 * expected.depth_max);
    const torch::Tensor depth_ok =
        (got.depths.cpu() - expected.depths).abs() <= 1e-4 * expected.depths.abs() + 1e-30;
    EXPECT_GE(depth_ok.to(torch::kDouble).mean().item<double>(), 0.98);
    const torch::Tensor image_ok = (got.images.cpu() - expected.images).abs() <= 1e-2;
    EXPECT_GE(image_ok.to(torch::kDouble).mean().item<double>(), 0.98);
  }
}

INSTANTIATE_TEST_SUITE_P(DevicesAndRigs, GeneratorDeviceTest,
                         ::testing::Combine(::testing::Values(std::string("cpu"), std::string("cuda")),
                                            ::testing::Range(0, kNumRigKinds)));

}  // namespace
}  // namespace dispmvs::synth
