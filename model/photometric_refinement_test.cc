#include "model/photometric_refinement.h"

#include <gtest/gtest.h>

#include <cmath>
#include <utility>

#include <torch/torch.h>

namespace dispmvs::model {
namespace {

using torch::indexing::Slice;

constexpr int64_t kHeight = 48, kWidth = 64;
constexpr double kFocal = 50;

// A slanted textured plane Z = 4 + 0.3 X + 0.2 Y (world = reference camera)
// seen by the reference and two sources, rendered here by intersecting each
// pixel's ray with the plane (not through geometry.h): the refinement's
// projections are checked against an independent computation.
struct PlaneScene {
  torch::Tensor images;      // [1,3,3,H,W]
  torch::Tensor intrinsics;  // [1,3,3,3]
  torch::Tensor extrinsics;  // [1,3,4,4]
  torch::Tensor depth;       // [1,1,H,W] the reference's true depth
};

double Texture(double x, double y) {
  return 0.5 + 0.15 * std::sin(5.0 * x + 1.3 * y) + 0.12 * std::sin(-2.1 * x + 6.3 * y + 0.5) +
         0.1 * std::sin(9.1 * x + 7.7 * y + 1.0);
}

torch::Tensor RotationY(double degrees) {
  const double a = degrees * M_PI / 180.0;
  return torch::tensor({std::cos(a), 0.0, std::sin(a), 0.0, 1.0, 0.0, -std::sin(a), 0.0, std::cos(a)},
                       torch::kFloat64)
      .view({3, 3});
}

// World-to-camera [4,4] of a camera at `centre` with rotation R (X_cam = R (X - centre)).
torch::Tensor Pose(const torch::Tensor& R, const std::vector<double>& centre) {
  torch::Tensor pose = torch::eye(4, torch::kFloat64);
  pose.index_put_({Slice(0, 3), Slice(0, 3)}, R);
  pose.index_put_({Slice(0, 3), 3}, -torch::matmul(R, torch::tensor(centre, torch::kFloat64)));
  return pose;
}

// With a board: a second textured plane Z = board_z in front of the first,
// where X < kBoardEdgeX (world = reference camera): a depth edge.
constexpr double kBoardEdgeX = -0.2;

// Renders view (K, pose) by point sampling at pixel centres; also returns
// its depth (z in the camera). board_z > 0 adds the board.
std::pair<torch::Tensor, torch::Tensor> Render(const torch::Tensor& K, const torch::Tensor& pose,
                                               bool flat, double board_z = 0) {
  const auto Ka = K.accessor<double, 2>();
  const torch::Tensor R = pose.index({Slice(0, 3), Slice(0, 3)});
  const torch::Tensor centre = -torch::matmul(R.t(), pose.index({Slice(0, 3), 3}));
  const auto Ra = R.accessor<double, 2>();
  const auto Ca = centre.accessor<double, 1>();
  torch::Tensor image = torch::zeros({3, kHeight, kWidth}, torch::kFloat32);
  torch::Tensor depth = torch::zeros({kHeight, kWidth}, torch::kFloat32);
  for (int64_t i = 0; i < kHeight; ++i) {
    for (int64_t j = 0; j < kWidth; ++j) {
      // Camera ray (z = 1), then in world coordinates: R^T d.
      const double dc[3] = {(j - Ka[0][2]) / Ka[0][0], (i - Ka[1][2]) / Ka[1][1], 1.0};
      double d[3];
      for (int a = 0; a < 3; ++a) d[a] = Ra[0][a] * dc[0] + Ra[1][a] * dc[1] + Ra[2][a] * dc[2];
      double t = (4.0 + 0.3 * Ca[0] + 0.2 * Ca[1] - Ca[2]) / (d[2] - 0.3 * d[0] - 0.2 * d[1]);
      double x = Ca[0] + t * d[0], y = Ca[1] + t * d[1];
      double value = flat ? 0.5 : Texture(x, y);
      const double t_board = board_z > 0 ? (board_z - Ca[2]) / d[2] : -1.0;
      if (t_board > 0 && t_board < t && Ca[0] + t_board * d[0] < kBoardEdgeX) {
        t = t_board;
        x = Ca[0] + t * d[0];
        y = Ca[1] + t * d[1];
        value = Texture(1.3 * x + 2.0, 1.1 * y - 1.0);  // another pattern than the plane's
      }
      for (int c = 0; c < 3; ++c) image[c][i][j] = static_cast<float>(value);
      depth[i][j] = static_cast<float>(t);  // z in the camera: the ray's z is 1
    }
  }
  return {image, depth};
}

PlaneScene MakePlaneScene(bool flat = false, double board_z = 0) {
  const torch::Tensor K =
      torch::tensor({kFocal, 0.0, 31.5, 0.0, kFocal, 23.5, 0.0, 0.0, 1.0}, torch::kFloat64).view({3, 3});
  const std::vector<torch::Tensor> poses = {Pose(torch::eye(3, torch::kFloat64), {0, 0, 0}),
                                            Pose(RotationY(-4.0), {1.0, 0.0, 0.0}),
                                            Pose(RotationY(3.0), {-0.8, 0.3, 0.1})};
  std::vector<torch::Tensor> images;
  PlaneScene scene;
  for (size_t v = 0; v < poses.size(); ++v) {
    auto [image, depth] = Render(K, poses[v], flat, board_z);
    images.push_back(image);
    if (v == 0) scene.depth = depth.view({1, 1, kHeight, kWidth});
  }
  scene.images = torch::stack(images).unsqueeze(0);
  scene.intrinsics = K.to(torch::kFloat32).expand({1, 3, 3, 3}).contiguous();
  scene.extrinsics = torch::stack(poses).to(torch::kFloat32).unsqueeze(0);
  return scene;
}

torch::Tensor RelativeError(const torch::Tensor& depth, const torch::Tensor& truth) {
  return ((depth - truth) / truth).abs();
}

// Pixels at least `margin` from the reference's border.
torch::Tensor Interior(int64_t margin) {
  torch::Tensor inside = torch::zeros({1, 1, kHeight, kWidth}, torch::kBool);
  inside.index_put_({0, 0, Slice(margin, kHeight - margin), Slice(margin, kWidth - margin)}, true);
  return inside;
}

// The search alone, as it was the default before the coarse propagation:
// +-6 one-pixel steps around the start, no propagation, no sweep, no planes
// extended over unseen pixels. The tests
// of the search use it, so that what they measure is the search's own.
PhotometricRefinementOptions SearchOnly() {
  PhotometricRefinementOptions options;
  options.steps = 6;
  options.propagation_rounds = 0;
  options.sweep_hypotheses = 0;
  options.unseen_slope_radius = 0;
  options.trusted_plane_min_ncc = 0.0;
  options.local_plane_radius = 0;
  return options;
}

// Propagation at full resolution after the search, as PropagationRepairs...
// and PropagationKeeps... measure it.
PhotometricRefinementOptions FullResolutionPropagation(int64_t rounds) {
  PhotometricRefinementOptions options = SearchOnly();
  options.propagation_rounds = rounds;
  options.propagation_scale = 1;
  return options;
}

TEST(PhotometricRefinementTest, PullsADepthSeveralPixelsOffOntoTheTexturedPlane) {
  const PlaneScene scene = MakePlaneScene();
  const torch::Tensor valid = torch::ones_like(scene.depth, torch::kBool);
  // 12 % too far: the matches are 1 to 2 pixels off in the sources.
  const torch::Tensor start = scene.depth * 1.12;
  const PhotometricRefinement out =
      RefineDepthPhotometrically(scene.images, scene.intrinsics, scene.extrinsics, start, valid, SearchOnly());
  // Measured with the search alone (1-pixel steps): refined 0.947 of the
  // interior, median error 0.35 %, 0.90 within 1 %, from 12 % everywhere.
  // What remains is the parabola's bias between whole steps (quarter-pixel
  // steps give a median under 0.1 % here, at four times the cost).
  const torch::Tensor interior = Interior(6);
  const torch::Tensor error = RelativeError(out.depth, scene.depth).masked_select(interior);
  EXPECT_GT(out.refined.masked_select(interior).to(torch::kFloat32).mean().item<float>(), 0.9);
  EXPECT_LT(error.median().item<float>(), 0.005);
  EXPECT_GT((error < 0.01).to(torch::kFloat32).mean().item<float>(), 0.85);
  EXPECT_TRUE(out.valid.all().item<bool>());
  EXPECT_GT(out.score.masked_select(out.refined).min().item<float>(), 0.2);
  // Where it did not refine, the depth is the input's, bit for bit.
  EXPECT_TRUE(torch::equal(out.depth.masked_select(~out.refined), start.masked_select(~out.refined)));
}

TEST(PhotometricRefinementTest, LocalPlanesAverageOutTheSearchsScatter) {
  const PlaneScene scene = MakePlaneScene();
  const torch::Tensor valid = torch::ones_like(scene.depth, torch::kBool);
  const torch::Tensor start = scene.depth * 1.12;
  PhotometricRefinementOptions with_planes = SearchOnly();
  with_planes.local_plane_radius = 2;
  const PhotometricRefinement search =
      RefineDepthPhotometrically(scene.images, scene.intrinsics, scene.extrinsics, start, valid, SearchOnly());
  const PhotometricRefinement planes =
      RefineDepthPhotometrically(scene.images, scene.intrinsics, scene.extrinsics, start, valid, with_planes);
  const torch::Tensor interior = Interior(6);
  const torch::Tensor search_error = RelativeError(search.depth, scene.depth).masked_select(interior);
  const torch::Tensor planes_error = RelativeError(planes.depth, scene.depth).masked_select(interior);
  const auto within = [](const torch::Tensor& error, double bound) {
    return (error < bound).to(torch::kFloat32).mean().item<float>();
  };
  // Measured: the search alone median 0.35 %, 0.674 within 0.5 %; with
  // local planes (radius 2) median 0.19 %, 0.785 within 0.5 %: the
  // parabola's bias between whole steps varies along the plane, and the
  // plane through 25 pixels averages it.
  EXPECT_LT(planes_error.median().item<float>(), search_error.median().item<float>());
  EXPECT_GT(within(planes_error, 0.005), within(search_error, 0.005));
  // Only a move within the bound: no pixel is further than 3 % from where
  // the search left it.
  EXPECT_LE(RelativeError(planes.depth.reciprocal(), search.depth.reciprocal()).max().item<float>(), 0.03 + 1e-5);
}

// A board 2.6 in front of the plane (4 to 5 away): its edge runs down the
// reference near column 28. The start is what the network's 1/4 grid gives
// there: the true inverse depth averaged over 4x4 cells and upsampled, so
// that pixels near the edge start between the two surfaces. The search then
// picks the surface whose windows correlate best: near the edge the centred
// window straddles both, and a shifted one lies on the pixel's own.
TEST(PhotometricRefinementTest, ShiftedWindowsPutMorePixelsNearADepthEdgeOnTheirSurface) {
  const PlaneScene scene = MakePlaneScene(/*flat=*/false, /*board_z=*/2.6);
  const torch::Tensor valid = torch::ones_like(scene.depth, torch::kBool);
  const torch::Tensor inverse = scene.depth.reciprocal();
  const torch::Tensor start =
      torch::nn::functional::interpolate(torch::avg_pool2d(inverse, 4),
                                         torch::nn::functional::InterpolateFuncOptions()
                                             .size(std::vector<int64_t>{kHeight, kWidth})
                                             .mode(torch::kBilinear)
                                             .align_corners(false))
          .reciprocal();
  // The edge: where the true depth jumps between neighbouring columns.
  const torch::Tensor jump = (inverse.narrow(3, 1, kWidth - 1) - inverse.narrow(3, 0, kWidth - 1)).abs() > 0.05;
  torch::Tensor edge = torch::zeros({1, 1, kHeight, kWidth}, torch::kBool);
  edge.narrow(3, 0, kWidth - 1).logical_or_(jump);
  // Pixels within 4 columns of it, away from the top and bottom borders.
  const torch::Tensor near_edge =
      (torch::max_pool2d(edge.to(torch::kFloat32), {1, 9}, 1, {0, 4}) > 0) & Interior(6);
  ASSERT_GT(near_edge.sum().item<int64_t>(), 200);
  const torch::Tensor away = ~near_edge & Interior(6);
  // The share within 1 % of the true depth near the edge and away from it.
  const auto within_1_percent = [&](int64_t shift) {
    PhotometricRefinementOptions options = SearchOnly();
    options.window_shift = shift;
    const PhotometricRefinement out =
        RefineDepthPhotometrically(scene.images, scene.intrinsics, scene.extrinsics, start, valid, options);
    const torch::Tensor right = RelativeError(out.depth, scene.depth) < 0.01;
    return std::make_pair(right.masked_select(near_edge).to(torch::kFloat32).mean().item<float>(),
                          right.masked_select(away).to(torch::kFloat32).mean().item<float>());
  };
  const auto [centred_near, centred_away] = within_1_percent(0);
  const auto [shifted_near, shifted_away] = within_1_percent(2);
  // Measured: near the edge 0.244 with the centred window, 0.485 with the
  // shifted ones; away from it 0.928 and 0.999 (there the windows of the
  // pixels a few columns further still reach across the edge, and a source
  // sees the plane behind the board's edge partly hidden).
  EXPECT_GT(shifted_near, 1.5 * centred_near);
  EXPECT_GE(shifted_away, centred_away);
}

TEST(PhotometricRefinementTest, KeepsTheTrueDepth) {
  const PlaneScene scene = MakePlaneScene();
  const torch::Tensor valid = torch::ones_like(scene.depth, torch::kBool);
  const PhotometricRefinement out = RefineDepthPhotometrically(
      scene.images, scene.intrinsics, scene.extrinsics, scene.depth, valid, SearchOnly());
  // Measured: median 0.39 %, 0.93 within 1 % (the same bias between steps).
  const torch::Tensor error = RelativeError(out.depth, scene.depth).masked_select(Interior(6));
  EXPECT_LT(error.median().item<float>(), 0.005);
  EXPECT_GT((error < 0.01).to(torch::kFloat32).mean().item<float>(), 0.9);
}

TEST(PhotometricRefinementTest, LeavesTexturelessAndInvalidPixelsAlone) {
  const PlaneScene flat = MakePlaneScene(/*flat=*/true);
  torch::Tensor valid = torch::ones_like(flat.depth, torch::kBool);
  valid.index_put_({0, 0, Slice(0, 10), Slice()}, false);
  const torch::Tensor start = flat.depth * 1.1;
  const PhotometricRefinement out =
      RefineDepthPhotometrically(flat.images, flat.intrinsics, flat.extrinsics, start, valid, {});
  EXPECT_FALSE(out.refined.any().item<bool>());
  EXPECT_TRUE(torch::equal(out.valid, valid));
  EXPECT_TRUE(torch::equal(out.depth, torch::where(valid, start, torch::zeros_like(start))));

  // A textured scene: invalid pixels stay invalid, at 0.
  const PlaneScene scene = MakePlaneScene();
  const PhotometricRefinement textured = RefineDepthPhotometrically(
      scene.images, scene.intrinsics, scene.extrinsics, scene.depth * 1.1, valid, {});
  EXPECT_FALSE(textured.refined.masked_select(~valid).any().item<bool>());
  EXPECT_EQ(textured.depth.masked_select(~valid).abs().sum().item<float>(), 0.0f);
  EXPECT_TRUE(textured.refined.any().item<bool>());
}

TEST(PhotometricRefinementTest, OneSourceIsEnough) {
  const PlaneScene scene = MakePlaneScene();
  const torch::Tensor valid = torch::ones_like(scene.depth, torch::kBool);
  const PhotometricRefinement out = RefineDepthPhotometrically(
      scene.images.narrow(1, 0, 2), scene.intrinsics.narrow(1, 0, 2),
      scene.extrinsics.narrow(1, 0, 2), scene.depth * 0.92, valid, SearchOnly());
  // Source 1 sits at +x: the reference's left columns are outside it.
  const torch::Tensor seen = Interior(6) & (torch::arange(kWidth).view({1, 1, 1, kWidth}) >= 24);
  const torch::Tensor error = RelativeError(out.depth, scene.depth).masked_select(seen);
  EXPECT_LT(error.median().item<float>(), 0.006);  // measured 0.44 %, from 8 %
}

// The reference pixels of the block the two propagation tests put on a
// wrong surface.
torch::Tensor WrongBlock() {
  torch::Tensor block = torch::zeros({1, 1, kHeight, kWidth}, torch::kBool);
  block.index_put_({0, 0, Slice(16, 32), Slice(26, 46)}, true);
  return block;
}

// The start: half the true depth on the block, 3 % too far elsewhere.
torch::Tensor StartWithWrongBlock(const PlaneScene& scene, const torch::Tensor& block) {
  return torch::where(block, scene.depth * 0.5, scene.depth * 1.03);
}

// A block of the start at half the true depth: its matches are about ten
// pixels off, beyond the +-6 pixel search, so only propagation from the right
// depth around it can repair it.
TEST(PhotometricRefinementTest, PropagationRepairsABlockBeyondTheSearch) {
  const PlaneScene scene = MakePlaneScene();
  const torch::Tensor valid = torch::ones_like(scene.depth, torch::kBool);
  const torch::Tensor block = WrongBlock();
  const torch::Tensor start = StartWithWrongBlock(scene, block);
  const auto block_error = [&](const PhotometricRefinementOptions& options) {
    const PhotometricRefinement out =
        RefineDepthPhotometrically(scene.images, scene.intrinsics, scene.extrinsics, start, valid, options);
    return RelativeError(out.depth, scene.depth).masked_select(block).median().item<float>();
  };
  EXPECT_GT(block_error(SearchOnly()), 0.3);  // measured 0.50: the block stays where it was
  PhotometricRefinementOptions propagated = FullResolutionPropagation(2);
  propagated.propagation_distance = 16;
  EXPECT_LT(block_error(propagated), 0.005);  // measured 0.21 %
}

// The defaults: a sweep and propagation on images averaged over 2x2 blocks,
// before a +-3 step search at full resolution, then one round of
// propagation at full resolution. The block beyond the old search's reach
// is repaired by the coarse pass; the full-resolution round gives it the
// precision of full-resolution planes, which the search's parabola between
// whole steps alone does not reach. The round's gain is measured with the
// sweep off in both (the sweep alone already brings the coarse pass's block
// closer, depth_sweep_test.cc), then the defaults as they are.
TEST(PhotometricRefinementTest, DefaultsRepairTheBlockAtHalfResolution) {
  const PlaneScene scene = MakePlaneScene();
  const torch::Tensor valid = torch::ones_like(scene.depth, torch::kBool);
  const torch::Tensor block = WrongBlock();
  const torch::Tensor start = StartWithWrongBlock(scene, block);
  const PhotometricRefinementOptions defaults;
  ASSERT_EQ(defaults.propagation_scale, 2);
  ASSERT_EQ(defaults.full_resolution_rounds, 1);
  ASSERT_GT(defaults.sweep_hypotheses, 0);
  PhotometricRefinementOptions no_sweep = defaults;
  no_sweep.sweep_hypotheses = 0;
  // The centred window, as the round was measured: with the shifted windows
  // the coarse pass alone already leaves this block at 0.12 % and the round
  // (two levels) at 0.09 %, too close for the comparisons below.
  no_sweep.window_shift = 0;
  // The round alone: the long-range planes after it repair this block
  // without it too (below, with the defaults).
  no_sweep.trusted_plane_min_ncc = 0.0;
  PhotometricRefinementOptions coarse_only = no_sweep;
  coarse_only.full_resolution_rounds = 0;
  const auto refine = [&](const PhotometricRefinementOptions& options) {
    return RefineDepthPhotometrically(scene.images, scene.intrinsics, scene.extrinsics, start, valid, options);
  };
  // The round with two levels of jumps (16 and 8 pixels, the default until
  // the long-range planes came from four sides) and with the default one.
  PhotometricRefinementOptions two_levels = no_sweep;
  two_levels.full_resolution_levels = 2;
  const PhotometricRefinement with_round = refine(two_levels), one_level = refine(no_sweep),
                              without = refine(coarse_only);
  const torch::Tensor error = RelativeError(with_round.depth, scene.depth);
  const torch::Tensor error_one_level = RelativeError(one_level.depth, scene.depth);
  const torch::Tensor error_without = RelativeError(without.depth, scene.depth);
  // Measured (with the defaults' local planes): the block's median error
  // 0.13 % with two levels, 0.32 % with one (from 50 %; the search alone
  // leaves 50 %; without the full-resolution round 0.74 %), all of it
  // refined; the interior's median 0.19 % and 0.25 % (without: 0.32 %, from
  // 3 %).
  EXPECT_LT(error_without.masked_select(block).median().item<float>(), 0.03);
  EXPECT_LT(error.masked_select(block).median().item<float>(),
            0.6 * error_without.masked_select(block).median().item<float>());
  EXPECT_LT(error.masked_select(block).median().item<float>(), 0.008);
  EXPECT_LT(error_one_level.masked_select(block).median().item<float>(),
            error_without.masked_select(block).median().item<float>());
  EXPECT_LT(error_one_level.masked_select(block).median().item<float>(), 0.008);
  EXPECT_GT(with_round.refined.masked_select(block).to(torch::kFloat32).mean().item<float>(), 0.9);
  EXPECT_LT(error.masked_select(Interior(6)).median().item<float>(),
            error_without.masked_select(Interior(6)).median().item<float>());
  EXPECT_LT(error_one_level.masked_select(Interior(6)).median().item<float>(),
            error_without.masked_select(Interior(6)).median().item<float>());
  EXPECT_LT(error_without.masked_select(Interior(6)).median().item<float>(), 0.012);

  // The defaults, sweep and long-range planes on, with the centred window
  // as above. Measured: the block's median 0.031 %, all of it refined, the
  // interior's 0.058 % (before the long-range planes lent the plane fitted
  // through their anchors, not an anchor's own depth, with two
  // full-resolution levels: 0.57 % and 0.53 %; on this 24 x 32 coarse grid
  // the sweep's 9 x 9 median covers a third of the image). The whole scene
  // is one plane, so a plane fitted over many anchors is more precise than
  // what the search and propagation give each pixel.
  PhotometricRefinementOptions centred_defaults = defaults;
  centred_defaults.window_shift = 0;
  const PhotometricRefinement out = refine(centred_defaults);
  const torch::Tensor error_defaults = RelativeError(out.depth, scene.depth);
  EXPECT_LT(error_defaults.masked_select(block).median().item<float>(), 0.008);
  EXPECT_LT(error_defaults.masked_select(block).median().item<float>(),
            0.5 * error.masked_select(block).median().item<float>());
  EXPECT_GT(out.refined.masked_select(block).to(torch::kFloat32).mean().item<float>(), 0.9);
  EXPECT_LT(error_defaults.masked_select(Interior(6)).median().item<float>(), 0.008);
  // The defaults as they are, with the shifted windows. Measured: the
  // block's median 0.077 %, the interior's 0.091 %: on one perfect plane a
  // pixel may take the step that suits a window shifted two pixels away, a
  // bias under 0.1 % (docs/refinement-measurements.md, "Shifted windows").
  const PhotometricRefinement shifted = refine(defaults);
  const torch::Tensor error_shifted = RelativeError(shifted.depth, scene.depth);
  EXPECT_LT(error_shifted.masked_select(block).median().item<float>(), 0.002);
  EXPECT_LT(error_shifted.masked_select(Interior(6)).median().item<float>(), 0.002);
  EXPECT_GT(shifted.refined.masked_select(block).to(torch::kFloat32).mean().item<float>(), 0.9);
  // Pixels the refinement did not change keep the input's depth, bit for bit.
  EXPECT_TRUE(torch::equal(out.depth.masked_select(~out.refined), start.masked_select(~out.refined)));
  EXPECT_TRUE(torch::equal(shifted.depth.masked_select(~shifted.refined), start.masked_select(~shifted.refined)));
  EXPECT_TRUE(
      torch::equal(with_round.depth.masked_select(~with_round.refined), start.masked_select(~with_round.refined)));
}

// Where the coarse grid is too small for the NCC window (under 2r + 2
// pixels), propagation runs at full resolution instead: the same maps as
// propagation_scale 1, bit for bit.
TEST(PhotometricRefinementTest, CoarsePropagationFallsBackOnSmallImages) {
  const PlaneScene scene = MakePlaneScene();
  const auto crop = [](const torch::Tensor& t) { return t.narrow(-2, 8, 24).narrow(-1, 8, 28).contiguous(); };
  torch::Tensor intrinsics = scene.intrinsics.clone();
  intrinsics.index_put_({Slice(), Slice(), 0, 2}, 31.5 - 8);
  intrinsics.index_put_({Slice(), Slice(), 1, 2}, 23.5 - 8);
  const torch::Tensor images = crop(scene.images), start = crop(scene.depth) * 1.05;
  const torch::Tensor valid = torch::ones_like(start, torch::kBool);
  const PhotometricRefinementOptions full = FullResolutionPropagation(1);
  PhotometricRefinementOptions coarse = full;
  coarse.propagation_scale = 4;  // 24 x 28 pixels: 6 x 7 at 1/4, under 8
  const PhotometricRefinement a =
      RefineDepthPhotometrically(images, intrinsics, scene.extrinsics, start, valid, full);
  const PhotometricRefinement b =
      RefineDepthPhotometrically(images, intrinsics, scene.extrinsics, start, valid, coarse);
  EXPECT_TRUE(torch::equal(a.depth, b.depth));
  EXPECT_TRUE(torch::equal(a.output_score, b.output_score));
  EXPECT_TRUE(a.refined.any().item<bool>());
}

// On an exact plane the propagated candidates are the plane itself (inverse
// depth is affine in the pixel coordinates and the fitted slopes are exact),
// so propagation keeps the true depth where the search left it.
TEST(PhotometricRefinementTest, PropagationKeepsTheTrueDepth) {
  const PlaneScene scene = MakePlaneScene();
  const torch::Tensor valid = torch::ones_like(scene.depth, torch::kBool);
  const PhotometricRefinementOptions propagated = FullResolutionPropagation(2);
  const PhotometricRefinement out = RefineDepthPhotometrically(
      scene.images, scene.intrinsics, scene.extrinsics, scene.depth, valid, propagated);
  const torch::Tensor error = RelativeError(out.depth, scene.depth).masked_select(Interior(6));
  // Measured: median 0.19 %, 0.99 within 1 % (the search alone: 0.39 %, 0.93:
  // the planes fitted over 17 x 17 pixels are finer than its parabola).
  EXPECT_LT(error.median().item<float>(), 0.003);
  EXPECT_GT((error < 0.01).to(torch::kFloat32).mean().item<float>(), 0.95);
  EXPECT_TRUE(out.valid.all().item<bool>());
}

// A wrong block: 16 x 20 pixels at 0.6 times the true depth, every match
// there several pixels off, beyond the search. Without propagation the block
// stays; the long-range planes give every pixel of it the plane of the
// nearest pixels the search confirmed (NCC >= 0.9), fitted through them,
// and a plane is a plane however far it is extended. At 0.4 times the true depth the plane would
// take the block 2.5 times further: beyond kTrustedPlaneMaxDepthRatio, so it
// stays.
TEST(PhotometricRefinementTest, TrustedPlanesRepairABlockBeyondTheSearch) {
  const PlaneScene scene = MakePlaneScene();
  const torch::Tensor valid = torch::ones_like(scene.depth, torch::kBool);
  const torch::Tensor block = WrongBlock();
  const torch::Tensor start = torch::where(block, scene.depth * 0.6, scene.depth * 1.03);
  PhotometricRefinementOptions trusted = SearchOnly();
  trusted.trusted_plane_min_ncc = 0.9;
  const auto refine = [&](const PhotometricRefinementOptions& options) {
    return RefineDepthPhotometrically(scene.images, scene.intrinsics, scene.extrinsics, start, valid, options);
  };
  const PhotometricRefinement without = refine(SearchOnly()), with = refine(trusted);
  const torch::Tensor error_without = RelativeError(without.depth, scene.depth);
  const torch::Tensor error = RelativeError(with.depth, scene.depth);
  const torch::Tensor outside = Interior(6) & ~block;
  // Measured: the block's median error 40 % without, 0.086 % with, all of
  // it refined, 0.997 of it within 2 %; outside, the median 0.32 % -> 0.10 %
  // (the nearest anchor alone, trusted_plane_axis_anchors 0: 0.16 %, 0.997,
  // 0.11 %). When an anchor lent its own depth, 0.64 of the block was within
  // 2 % (median 0.93 %): the rest took the planes of pixels along the
  // block's border, whose windows straddle it and whose refined depth is
  // biased; the plane fitted through the anchors around them is not.
  // Required: the block within the 2 % the product is judged by, but for
  // its corners.
  EXPECT_GT(error_without.masked_select(block).median().item<float>(), 0.3f);
  EXPECT_GT((error.masked_select(block) < 0.02).to(torch::kFloat32).mean().item<float>(), 0.95f);
  EXPECT_LT(error.masked_select(block).median().item<float>(), 0.003f);
  EXPECT_GT(with.refined.masked_select(block).to(torch::kFloat32).mean().item<float>(), 0.9f);
  // Outside the block the search had it already: the same median, and the
  // pixels no step changed keep the input's depth.
  EXPECT_LT(error.masked_select(outside).median().item<float>(), 0.005f);
  EXPECT_TRUE(torch::equal(with.depth.masked_select(~with.refined), start.masked_select(~with.refined)));

  const torch::Tensor too_near = torch::where(block, scene.depth * 0.4, scene.depth * 1.03);
  const PhotometricRefinement bounded =
      RefineDepthPhotometrically(scene.images, scene.intrinsics, scene.extrinsics, too_near, valid, trusted);
  EXPECT_GT(RelativeError(bounded.depth, scene.depth).masked_select(block).median().item<float>(), 0.5f);
}

TEST(PhotometricRefinementTest, ChecksOptionsAndShapes) {
  const auto rejects = [](PhotometricRefinementOptions o, const std::string& field) {
    try {
      o.Check();
      ADD_FAILURE() << field << " accepted";
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find(field), std::string::npos) << error.what();
    }
  };
  PhotometricRefinementOptions o;
  o.window_radius = 0;
  rejects(o, "window_radius");
  o = {};
  o.window_shift = -1;
  rejects(o, "window_shift");
  o = {};
  o.window_shift = 4;  // beyond the window's radius (3): the window would not contain the pixel
  rejects(o, "window_shift");
  o = {};
  o.steps = 0;
  rejects(o, "steps");
  o = {};
  o.step_pixels = 0;
  rejects(o, "step_pixels");
  o = {};
  o.min_ncc = 1.5;
  rejects(o, "min_ncc");
  o = {};
  o.min_texture = -1;
  rejects(o, "min_texture");
  o = {};
  o.propagation_rounds = -1;
  rejects(o, "propagation_rounds");
  o = {};
  o.propagation_distance = 0;
  rejects(o, "propagation_distance");
  o = {};
  o.propagation_levels = 0;
  rejects(o, "propagation_levels");
  o = {};
  o.propagation_slope_radius = 0;
  rejects(o, "propagation_slope_radius");
  o = {};
  o.propagation_scale = 3;
  rejects(o, "propagation_scale");
  o = {};
  o.trusted_plane_min_ncc = 1.5;
  rejects(o, "trusted_plane_min_ncc");
  o = {};
  o.trusted_plane_min_ncc = -0.1;
  rejects(o, "trusted_plane_min_ncc");
  o = {};
  o.trusted_plane_axis_anchors = 3;
  rejects(o, "trusted_plane_axis_anchors");
  o = {};
  o.local_plane_radius = 17;
  rejects(o, "local_plane_radius");
  o = {};
  o.local_plane_max_change = 0.0;
  rejects(o, "local_plane_max_change");
  o = {};
  o.local_plane_max_change = 1.5;
  rejects(o, "local_plane_max_change");
  o = {};
  o.full_resolution_rounds = -1;
  rejects(o, "full_resolution_rounds");
  o = {};
  o.full_resolution_levels = 0;
  rejects(o, "full_resolution_levels");
  o = {};
  o.sweep_hypotheses = 1025;
  rejects(o, "sweep_hypotheses");
  o = {};
  o.sweep_step_pixels = 0;
  rejects(o, "sweep_step_pixels");
  EXPECT_NO_THROW(PhotometricRefinementOptions{}.Check());

  const PlaneScene scene = MakePlaneScene();
  const torch::Tensor valid = torch::ones_like(scene.depth, torch::kBool);
  EXPECT_THROW(RefineDepthPhotometrically(scene.images.narrow(1, 0, 1), scene.intrinsics,
                                          scene.extrinsics, scene.depth, valid, {}),
               std::invalid_argument);
  EXPECT_THROW(RefineDepthPhotometrically(scene.images, scene.intrinsics, scene.extrinsics,
                                          scene.depth.narrow(3, 0, 10), valid, {}),
               std::invalid_argument);
}

// A slanted textured plane Z = 4 + 0.3 X (world = reference camera) seen by
// the reference and by one source 1 unit to its right, both rendered here by
// intersecting rays with the plane. The source does not see the reference's
// left columns (its match lies left of the source image).
constexpr int64_t kSceneH = 48, kSceneW = 80;

// The view of a camera at (camera_x, 0, 0) looking down +Z, and its depth.
std::pair<torch::Tensor, torch::Tensor> RenderSlantedPlane(double camera_x) {
  torch::Tensor image = torch::zeros({3, kSceneH, kSceneW});
  torch::Tensor depth = torch::zeros({1, 1, kSceneH, kSceneW});
  const double cx = 0.5 * (kSceneW - 1), cy = 0.5 * (kSceneH - 1);
  for (int64_t i = 0; i < kSceneH; ++i) {
    for (int64_t j = 0; j < kSceneW; ++j) {
      const double dx = (j - cx) / kFocal, dy = (i - cy) / kFocal;
      // X = camera_x + t dx, Z = t on Z = 4 + 0.3 X.
      const double t = (4.0 + 0.3 * camera_x) / (1.0 - 0.3 * dx);
      const float value = static_cast<float>(Texture(camera_x + t * dx, t * dy));
      for (int c = 0; c < 3; ++c) image[c][i][j] = value;
      depth[0][0][i][j] = static_cast<float>(t);
    }
  }
  return {image, depth};
}

TEST(PhotometricRefinementTest, ExtendsThePlaneOverWhatNoSourceSees) {
  const auto [reference, truth] = RenderSlantedPlane(0.0);
  const auto [source, unused] = RenderSlantedPlane(1.0);
  const torch::Tensor images = torch::stack({reference, source}).unsqueeze(0);
  const torch::Tensor K =
      torch::tensor({kFocal, 0.0, 0.5 * (kSceneW - 1), 0.0, kFocal, 0.5 * (kSceneH - 1), 0.0, 0.0, 1.0},
                    torch::kFloat32)
          .view({3, 3});
  const torch::Tensor intrinsics = K.expand({1, 2, 3, 3}).contiguous();
  torch::Tensor extrinsics = torch::eye(4).expand({1, 2, 4, 4}).contiguous();
  extrinsics[0][1][0][3] = -1.0;  // X_source = X - (1, 0, 0)
  // Which reference pixels the source sees at the true depth, by hand: the
  // match's column j - kFocal / Z (no rotation) within the image.
  const torch::Tensor column = torch::arange(kSceneW).view({1, 1, 1, kSceneW}).to(torch::kFloat32);
  const torch::Tensor true_column = column - kFocal / truth;
  const torch::Tensor unseen = true_column < 0;
  const double unseen_share = unseen.to(torch::kFloat32).mean().item<double>();
  ASSERT_GT(unseen_share, 0.15);  // 15 of 80 columns
  // The start: the truth, but 20 % too near where the source does not see
  // (there its match lies further outside the source; inverse depth 25 %
  // off, within kUnseenMaxChange), and half the true depth in rows 40-47
  // there (100 % off: left alone).
  torch::Tensor start = torch::where(unseen, truth * 0.8, truth);
  torch::Tensor far_off = torch::zeros_like(unseen);
  far_off.index_put_({0, 0, Slice(40, kSceneH), Slice()}, true);
  far_off &= unseen;
  start = torch::where(far_off, truth * 0.5, start);
  const torch::Tensor near_off = unseen & ~far_off;
  const torch::Tensor valid = torch::ones_like(truth, torch::kBool);
  PhotometricRefinementOptions options;
  const PhotometricRefinement extended =
      RefineDepthPhotometrically(images, intrinsics, extrinsics, start, valid, options);
  options.unseen_slope_radius = 0;
  const PhotometricRefinement off = RefineDepthPhotometrically(images, intrinsics, extrinsics, start, valid, options);
  const torch::Tensor error_on = ((extended.depth - truth) / truth).abs();
  const torch::Tensor error_off = ((off.depth - truth) / truth).abs();
  // Off: the start stays where nothing is seen.
  EXPECT_TRUE(torch::allclose(off.depth.masked_select(unseen), start.masked_select(unseen)));
  // On: the plane, extended over up to 22 columns (the anchors start about
  // 8 columns inside the seen part) from slopes fitted over up to 33 x 33
  // refined pixels, whose own depth carries the search's bias between whole
  // steps (median 0.27 % here). Measured: median 0.73 %, worst 0.84 %, from
  // 20 %. Required: every such pixel within the 2 % the product is judged
  // by, most within 1 %.
  EXPECT_LT(error_on.masked_select(near_off).median().item<float>(), 0.01f);
  EXPECT_LT(error_on.masked_select(near_off).max().item<float>(), 0.02f);
  EXPECT_TRUE(extended.refined.masked_select(near_off).all().item<bool>());
  EXPECT_TRUE((extended.output_score.masked_select(near_off) == -1).all().item<bool>());
  // Too far from the plane to be a guess of it: kept.
  ASSERT_GT(far_off.sum().item<int64_t>(), 50);
  EXPECT_TRUE(torch::equal(extended.depth.masked_select(far_off), start.masked_select(far_off)));
  // Seen pixels: the same as without the extension.
  EXPECT_TRUE(torch::equal(extended.depth.masked_select(~unseen), off.depth.masked_select(~unseen)));
  EXPECT_LT(error_off.masked_select(~unseen).median().item<float>(), 0.005f);
}

}  // namespace
}  // namespace dispmvs::model
