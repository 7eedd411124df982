// Overfitting test: the whole network (encoders, correlation, GRU, geometry,
// fusion, upsampling, loss) must be able to learn one scene. A textured,
// slanted plane is rendered into three cameras with the exact plane-induced
// homography; a few hundred Adam steps on that one scene (from one fixed
// random initialisation) must bring the loss down by a large factor and the
// depth error to what MVS users would call working.

#include <cmath>
#include <iostream>
#include <vector>

#include <ATen/CPUGeneratorImpl.h>
#include <gtest/gtest.h>

#include "model/dispmvs_net.h"
#include "model/geometry.h"
#include "model/loss.h"

namespace dispmvs::model {
namespace {

namespace F = torch::nn::functional;

constexpr int64_t kSize = 64;        // image height and width
constexpr int64_t kSteps = 300;         // Adam steps
constexpr double kLearningRate = 1e-3;
// Sources sit +-0.8 units sideways of the reference, 4 units from the plane
// (baseline/depth 0.2, as in wide-baseline MVS rigs). At 64x64 the coarse
// stage is only 4x4, and a small baseline would leave it less than a pixel
// of epipolar search range.
constexpr double kBaseline = 0.8;
// Every step starts from this one random initialisation: the test overfits
// one (scene, initialisation) pair, the classic overfitting check that the
// whole chain can represent and learn the answer. (Learning to converge from
// any initialisation takes far more than a few hundred steps.)
constexpr uint64_t kInitSeed = 987654;

// The plane: X = origin + u * axis_u + v * axis_v, (u, v) in [-half, half]^2,
// carrying a procedural texture. Slanted 30 degrees about the y axis, centred
// 4 units in front of the reference camera.
struct Plane {
  torch::Tensor origin = torch::tensor({0.0, 0.0, 4.0}, torch::kDouble);
  torch::Tensor axis_u = torch::tensor({std::cos(0.5236), 0.0, std::sin(0.5236)}, torch::kDouble);
  torch::Tensor axis_v = torch::tensor({0.0, 1.0, 0.0}, torch::kDouble);
  double half = 4.0;
};

// Smooth random blobs at several scales plus stripes: enough texture for
// matching at 1/16 and at 1/4 resolution. [1,3,256,256] in [0,1].
torch::Tensor MakeTexture() {
  torch::manual_seed(1234);
  torch::Tensor texture = torch::zeros({1, 3, 256, 256});
  for (int64_t cells : {4, 16, 64}) {
    texture += F::interpolate(torch::rand({1, 3, cells, cells}),
                              F::InterpolateFuncOptions()
                                  .size(std::vector<int64_t>{256, 256})
                                  .mode(torch::kBilinear)
                                  .align_corners(false));
  }
  const torch::Tensor x = torch::arange(256, torch::kFloat).view({1, 1, 1, 256});
  texture += 0.5 * torch::sin(x * 0.35);
  return (texture - texture.min()) / (texture.max() - texture.min());
}

torch::Tensor Intrinsics() {
  return torch::tensor({{64.0, 0.0, 31.5}, {0.0, 64.0, 31.5}, {0.0, 0.0, 1.0}}, torch::kDouble);
}

// World-to-camera [4,4] of a camera at `centre` rotated by `yaw` about y.
torch::Tensor Extrinsics(double cx, double cy, double yaw) {
  const torch::Tensor R = torch::tensor({{std::cos(yaw), 0.0, -std::sin(yaw)},
                                         {0.0, 1.0, 0.0},
                                         {std::sin(yaw), 0.0, std::cos(yaw)}},
                                        torch::kDouble);
  const torch::Tensor centre = torch::tensor({cx, cy, 0.0}, torch::kDouble);
  torch::Tensor E = torch::eye(4, torch::kDouble);
  E.narrow(0, 0, 3).narrow(1, 0, 3).copy_(R);
  E.narrow(0, 0, 3).select(1, 3).copy_(-torch::matmul(R, centre));
  return E;
}

// All pixel centres of a kSize x kSize image as homogeneous columns [3, kSize^2]
// (row-major), optionally at 1/stride resolution expressed in full-resolution
// pixel-index coordinates: (c + 0.5) * stride - 0.5.
torch::Tensor PixelColumns(int64_t stride = 1) {
  const int64_t n = kSize / stride;
  const torch::Tensor c = (torch::arange(n, torch::kDouble) + 0.5) * stride - 0.5;
  const auto grid = torch::meshgrid({c, c}, "ij");  // rows, cols
  return torch::stack({grid[1].flatten(), grid[0].flatten(), torch::ones({n * n}, torch::kDouble)});
}

// Renders the plane into a camera: pixel ~ K (R X + T) = H (u, v, 1), so the
// texture coordinate of a pixel is H^-1 pixel.
torch::Tensor Render(const Plane& plane, const torch::Tensor& texture, const torch::Tensor& K,
                     const torch::Tensor& E) {
  const torch::Tensor R = E.narrow(0, 0, 3).narrow(1, 0, 3);
  const torch::Tensor T = E.narrow(0, 0, 3).select(1, 3);
  const torch::Tensor H = torch::matmul(
      K, torch::stack({torch::matmul(R, plane.axis_u), torch::matmul(R, plane.axis_v),
                       torch::matmul(R, plane.origin) + T},
                      1));
  const torch::Tensor uvw = torch::matmul(torch::inverse(H), PixelColumns());
  const torch::Tensor uv = (uvw.narrow(0, 0, 2) / uvw.narrow(0, 2, 1)) / plane.half;  // [-1,1]
  const torch::Tensor sample_grid = uv.t().reshape({1, kSize, kSize, 2}).to(torch::kFloat);
  return F::grid_sample(texture, sample_grid,
                        F::GridSampleFuncOptions().mode(torch::kBilinear).align_corners(false))
      .squeeze(0);
}

// Reference camera = world: depth along the ray K^-1 p~ to the plane n . X = c
// is c / (n . K^-1 p~). [1,1,kSize/stride,kSize/stride].
torch::Tensor ReferenceDepth(const Plane& plane, const torch::Tensor& K, int64_t stride = 1) {
  const int64_t n = kSize / stride;
  const torch::Tensor normal = torch::cross(plane.axis_u, plane.axis_v, 0);
  const double offset = torch::dot(normal, plane.origin).item<double>();
  const torch::Tensor rays = torch::matmul(torch::inverse(K), PixelColumns(stride));
  return (offset / torch::matmul(normal.unsqueeze(0), rays)).view({1, 1, n, n}).to(torch::kFloat);
}

// Mean absolute difference between the reference image and the source image
// warped into it with depth `depth` (reference camera = world). Checks the
// test's own rendering: small at the true depth, large at a wrong one.
double PhotometricError(const torch::Tensor& ref_image, const torch::Tensor& src_image,
                        const torch::Tensor& K, const torch::Tensor& E_src,
                        const torch::Tensor& depth) {
  const torch::Tensor pixels = PixelColumns();
  const torch::Tensor points = torch::matmul(torch::inverse(K), pixels) *
                               depth.to(torch::kDouble).flatten().unsqueeze(0);
  const torch::Tensor cam = torch::matmul(E_src.narrow(0, 0, 3).narrow(1, 0, 3), points) +
                            E_src.narrow(0, 0, 3).narrow(1, 3, 1);
  const torch::Tensor proj = torch::matmul(K, cam);
  const torch::Tensor xy = proj.narrow(0, 0, 2) / proj.narrow(0, 2, 1);
  const torch::Tensor sample_grid =
      ((2.0 * xy + 1.0) / static_cast<double>(kSize) - 1.0).t().reshape({1, kSize, kSize, 2});
  const torch::Tensor warped = F::grid_sample(
      src_image.unsqueeze(0), sample_grid.to(torch::kFloat),
      F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kBorder).align_corners(false));
  // Ignore a 6-pixel border where the warp may leave the source image.
  return (warped.squeeze(0) - ref_image)
      .abs()
      .narrow(1, 6, kSize - 12)
      .narrow(2, 6, kSize - 12)
      .mean()
      .item<double>();
}

// The rendered scene as network input, with its ground truth.
struct Scene {
  Plane plane;
  torch::Tensor K = Intrinsics();
  std::vector<torch::Tensor> extrinsics{Extrinsics(0.0, 0.0, 0.0), Extrinsics(kBaseline, 0.05, -kBaseline / 4),
                                        Extrinsics(-kBaseline, -0.05, kBaseline / 4)};
  std::vector<torch::Tensor> images;
  DispMvsInput input;
  torch::Tensor gt;

  Scene() {
    const torch::Tensor texture = MakeTexture();
    for (const auto& E : extrinsics) images.push_back(Render(plane, texture, K, E));
    const int64_t views = static_cast<int64_t>(images.size());
    input.images = torch::stack(images).unsqueeze(0);  // [1,V,3,H,W]
    input.intrinsics = K.to(torch::kFloat).expand({1, views, 3, 3}).clone();
    input.extrinsics = torch::stack(extrinsics).unsqueeze(0).to(torch::kFloat);
    input.depth_min = torch::full({1}, 2.0f);
    input.depth_max = torch::full({1}, 8.0f);
    gt = ReferenceDepth(plane, K);
  }
};

// The test's own rendering is right: warping a source into the reference
// with the true depth reproduces the reference image, a wrong depth does not.
TEST(OverfitTest, SceneIsPhotometricallyConsistent) {
  const Scene scene;
  ASSERT_GT(scene.gt.min().item<float>(), 2.5f);  // the plane fills the view, inside the hint
  ASSERT_LT(scene.gt.max().item<float>(), 7.0f);
  for (size_t v = 1; v < scene.images.size(); ++v) {
    const double at_gt =
        PhotometricError(scene.images[0], scene.images[v], scene.K, scene.extrinsics[v], scene.gt);
    const double off = PhotometricError(scene.images[0], scene.images[v], scene.K,
                                        scene.extrinsics[v], scene.gt * 1.1);
    EXPECT_LT(at_gt, 0.02) << v;
    EXPECT_GT(off, 3 * at_gt) << v;
  }
}

// The driver's conventions (relative poses from world-to-camera extrinsics,
// stage intrinsics) agree with an independent projection of the scene: at
// the fine stage (1/4) the true inverse depth lands on the true source pixel
// and triangulates back to itself.
TEST(OverfitTest, DriverGeometryMatchesTheRendering) {
  const Scene scene;
  const int64_t stride = DispMvsNetImpl::kFineStride;
  const int64_t n = kSize / stride;
  const torch::Tensor depth = ReferenceDepth(scene.plane, scene.K, stride).to(torch::kDouble);
  const RelativePoses poses = ReferenceToSourcePoses(scene.input.extrinsics.to(torch::kDouble));
  const torch::Tensor K_stage = ScaleIntrinsics(scene.K.unsqueeze(0), stride);
  for (int64_t v = 1; v < static_cast<int64_t>(scene.extrinsics.size()); ++v) {
    const EpipolarPair pair = MakeEpipolarPair(K_stage, K_stage, poses.R.select(1, v - 1),
                                               poses.T.select(1, v - 1), n, n);
    const SourcePixels projected = ProjectInverseDepth(pair, 1.0 / depth);
    ASSERT_TRUE(projected.valid.all().item<bool>());

    // Independent: full-resolution 3D point, source camera, back to 1/stride.
    const torch::Tensor& E = scene.extrinsics[static_cast<size_t>(v)];
    const torch::Tensor points =
        torch::matmul(torch::inverse(scene.K), PixelColumns(stride)) * depth.flatten().unsqueeze(0);
    const torch::Tensor proj = torch::matmul(
        scene.K, torch::matmul(E.narrow(0, 0, 3).narrow(1, 0, 3), points) +
                     E.narrow(0, 0, 3).narrow(1, 3, 1));
    const torch::Tensor expected =
        ((proj.narrow(0, 0, 2) / proj.narrow(0, 2, 1) + 0.5) / stride - 0.5).view({1, 2, n, n});
    EXPECT_LT((projected.xy - expected).abs().max().item<double>(), 1e-6) << v;

    const InverseDepth back = TriangulateInverseDepth(pair, expected);
    ASSERT_TRUE(back.valid.all().item<bool>());
    EXPECT_LT(((back.inv_depth * depth) - 1.0).abs().max().item<double>(), 1e-6) << v;
  }
}

TEST(OverfitTest, LearnsASlantedPlane) {
  const Scene scene;
  const DispMvsInput& input = scene.input;
  const torch::Tensor& gt = scene.gt;
  const torch::Tensor gt_valid = torch::ones_like(gt, torch::kBool);

  torch::manual_seed(0);
  DispMvsNet net(ModelConfig::Small());
  net->train();
  torch::optim::Adam optimizer(net->parameters(), torch::optim::AdamOptions(kLearningRate));
  std::vector<double> losses;        // SequenceLoss, all iterations
  std::vector<double> final_losses;  // L1 of the final (full-resolution) iteration only
  for (int64_t step = 0; step < kSteps; ++step) {
    torch::Generator gen = at::make_generator<at::CPUGeneratorImpl>(kInitSeed);
    const DispMvsOutput out = net->forward(input, gen);
    const torch::Tensor loss =
        SequenceLoss(out.inv_depths, gt, gt_valid, input.depth_min, input.depth_max);
    optimizer.zero_grad();
    loss.backward();
    // RAFT's training recipe clips the gradient norm at 1.
    torch::nn::utils::clip_grad_norm_(net->parameters(), 1.0);
    optimizer.step();
    losses.push_back(loss.item<double>());
    final_losses.push_back(
        SequenceLoss({out.inv_depths.back()}, gt, gt_valid, input.depth_min, input.depth_max)
            .item<double>());
    if (step % 25 == 0) {
      std::cout << "step " << step << " loss " << losses.back() << " final-iteration L1 "
                << final_losses.back() << std::endl;
    }
  }
  const auto mean = [](const std::vector<double>& v, size_t from, size_t to) {
    double s = 0;
    for (size_t i = from; i < to; ++i) s += v[i];
    return s / static_cast<double>(to - from);
  };
  const double first = mean(losses, 0, 10);
  const double last = mean(losses, losses.size() - 10, losses.size());
  std::cout << "loss: first 10 steps " << first << ", last 10 steps " << last << std::endl;
  const double first_final = mean(final_losses, 0, 10);
  const double last_final = mean(final_losses, final_losses.size() - 10, final_losses.size());
  std::cout << "final-iteration L1: first 10 steps " << first_final << ", last 10 steps "
            << last_final << std::endl;
  EXPECT_GT(first / last, 5.0);

  // Evaluate (eval mode, no gradients) from the training initialisation.
  net->eval();
  torch::NoGradGuard no_grad;
  const auto evaluate = [&](uint64_t seed, double& valid_fraction, double& mean_rel) {
    torch::Generator gen = at::make_generator<at::CPUGeneratorImpl>(seed);
    const DispMvsOutput out = net->forward(input, gen);
    valid_fraction = out.valid.to(torch::kFloat).mean().item<double>();
    mean_rel = ((out.depth - gt).abs() / gt).masked_select(out.valid).mean().item<double>();
  };
  double valid_fraction = 0, mean_rel = 0;
  evaluate(kInitSeed, valid_fraction, mean_rel);
  std::cout << "valid fraction " << valid_fraction << ", mean relative depth error " << mean_rel
            << std::endl;
  // For information only (not asserted): the same network from an
  // initialisation it was not trained from.
  double other_valid = 0, other_rel = 0;
  evaluate(kInitSeed + 1, other_valid, other_rel);
  std::cout << "from an unseen initialisation: valid fraction " << other_valid
            << ", mean relative depth error " << other_rel << std::endl;
  EXPECT_GT(valid_fraction, 0.95);
  // 3%: at 4 units that is 12 cm; MVS that is worse does not reconstruct a plane.
  EXPECT_LT(mean_rel, 0.03);
}

}  // namespace
}  // namespace dispmvs::model
