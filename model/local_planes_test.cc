#include "model/local_planes.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include <torch/torch.h>

namespace dispmvs::model {
namespace {

// Inverse depth on a tilted plane, the left half of the map a second plane
// 25 % nearer (a depth edge down the middle), with a percent of uniform
// noise on every pixel: what the search's per-pixel maxima look like.
struct Scene {
  torch::Tensor truth, noisy;
};

Scene MakeScene(int64_t h, int64_t width) {
  torch::manual_seed(11);
  const torch::Tensor y = torch::arange(h, torch::kFloat32).view({1, 1, h, 1}).expand({1, 1, h, width});
  const torch::Tensor x = torch::arange(width, torch::kFloat32).view({1, 1, 1, width}).expand({1, 1, h, width});
  const torch::Tensor far_plane = 0.5f + 0.002f * x - 0.001f * y;
  const torch::Tensor truth = torch::where(x < width / 2, 1.25f * far_plane, far_plane);
  const torch::Tensor noisy = truth * (1.0f + 0.01f * (2.0f * torch::rand({1, 1, h, width}) - 1.0f));
  return {truth.contiguous(), noisy.contiguous()};
}

torch::Tensor RelativeError(const torch::Tensor& w, const torch::Tensor& truth) {
  return torch::abs(w - truth) / truth;
}

TEST(LocalPlanes, AveragesTheScatterOutAndKeepsTheEdge) {
  const int64_t h = 40, width = 60, radius = 2;
  const Scene scene = MakeScene(h, width);
  const torch::Tensor all = torch::ones({1, 1, h, width}, torch::kBool);
  const LocalPlaneSnap snap = SnapToLocalPlanes(scene.noisy, all, all, radius, 0.03);

  // Away from the edge (windows on one plane), every pixel takes its plane:
  // a least-squares plane through 25 pixels with independent errors of
  // standard deviation 0.58 % is off by about a fifth of that.
  const torch::Tensor x = torch::arange(width).view({1, 1, 1, width}).expand({1, 1, h, width});
  const torch::Tensor inside = torch::abs(x.to(torch::kFloat32) - (width / 2 - 0.5f)) > radius + 1;
  EXPECT_TRUE(snap.snapped.masked_select(inside).all().item<bool>());
  const double before = RelativeError(scene.noisy, scene.truth).masked_select(inside).mean().item<double>();
  const double after = RelativeError(snap.w, scene.truth).masked_select(inside).mean().item<double>();
  EXPECT_GT(before, 0.004);  // uniform in +-1 %: mean 0.5 %
  EXPECT_LT(after, 0.4 * before) << "before " << before;

  // At the edge, windows mix the two planes (25 % apart): no pixel moves by
  // more than the bound, and every pixel stays nearer its own plane than
  // the other.
  const torch::Tensor change = RelativeError(snap.w, scene.noisy);
  EXPECT_LE(change.max().item<double>(), 0.03 + 1e-6);
  EXPECT_LT(RelativeError(snap.w, scene.truth).max().item<double>(), 0.05);
}

TEST(LocalPlanes, OnlyWhereAppliedAndFromTheSupport) {
  const int64_t h = 30, width = 30;
  const Scene scene = MakeScene(h, width);
  // The support excludes a block set 2 % off, as pixels that correlate
  // badly would be; the fit around it ignores them.
  torch::Tensor w = scene.noisy.clone();
  torch::Tensor support = torch::ones({1, 1, h, width}, torch::kBool);
  w.narrow(2, 10, 4).narrow(3, 20, 4).mul_(1.02f);
  support.narrow(2, 10, 4).narrow(3, 20, 4).fill_(false);
  torch::Tensor apply = torch::ones({1, 1, h, width}, torch::kBool);
  apply.narrow(2, 0, 5).fill_(false);
  const LocalPlaneSnap snap = SnapToLocalPlanes(w, support, apply, 3, 0.03);
  // Not applied: unchanged to the bit, and not marked.
  EXPECT_TRUE(torch::equal(snap.w.narrow(2, 0, 5), w.narrow(2, 0, 5)));
  EXPECT_FALSE(snap.snapped.narrow(2, 0, 5).any().item<bool>());
  // The block's pixels take the plane of the supported pixels around them:
  // within a third of a percent of the truth, though 2 % off before.
  const torch::Tensor block = RelativeError(snap.w, scene.truth).narrow(2, 10, 4).narrow(3, 20, 4);
  EXPECT_LT(block.max().item<double>(), 0.0035);
  // Non-positive inverse depths (invalid pixels) never change.
  torch::Tensor holes = w.clone();
  holes.narrow(2, 20, 2).narrow(3, 5, 2).fill_(0.0f);
  const LocalPlaneSnap with_holes = SnapToLocalPlanes(holes, support & (holes > 0), apply, 3, 0.03);
  EXPECT_TRUE((with_holes.w.narrow(2, 20, 2).narrow(3, 5, 2) == 0).all().item<bool>());
}

TEST(LocalPlanes, TheCpuLoopIsTheOperations) {
  // Double maps take the operations (LeastSquaresPlanes' and this step's);
  // float maps on the CPU the loops. The same pixels move, to the same
  // values within float precision.
  const int64_t h = 33, width = 47;
  const Scene scene = MakeScene(h, width);
  const torch::Tensor support = torch::rand({1, 1, h, width}) > 0.3f;
  const torch::Tensor apply = torch::rand({1, 1, h, width}) > 0.1f;
  const LocalPlaneSnap loop = SnapToLocalPlanes(scene.noisy, support, apply, 2, 0.005);
  const LocalPlaneSnap ops = SnapToLocalPlanes(scene.noisy.to(torch::kFloat64), support, apply, 2, 0.005);
  // A bound of half a percent against noise of +-1 %: some pixels move,
  // some do not, and few lie near the bound.
  const double moved = loop.snapped.to(torch::kFloat32).mean().item<double>();
  EXPECT_GT(moved, 0.2);
  EXPECT_LT(moved, 0.9);
  const torch::Tensor near_bound =
      torch::abs(torch::abs(ops.w - scene.noisy.to(torch::kFloat64)) / scene.noisy.to(torch::kFloat64) - 0.005) < 1e-5;
  EXPECT_LE((loop.snapped != ops.snapped).sum().item<int64_t>(), near_bound.sum().item<int64_t>() + 2);
  const torch::Tensor both = loop.snapped & ops.snapped;
  EXPECT_LT((loop.w.to(torch::kFloat64) - ops.w).abs().masked_select(both).max().item<double>(), 1e-5);
}

TEST(LocalPlanes, RejectsBadArguments) {
  const torch::Tensor w = torch::full({1, 1, 8, 8}, 0.5f);
  const torch::Tensor all = torch::ones({1, 1, 8, 8}, torch::kBool);
  EXPECT_THROW(SnapToLocalPlanes(w, all, all, 0, 0.03), std::invalid_argument);
  EXPECT_THROW(SnapToLocalPlanes(w, all, all, 2, 0.0), std::invalid_argument);
  EXPECT_THROW(SnapToLocalPlanes(w, all, all, 2, 1.5), std::invalid_argument);
  EXPECT_THROW(SnapToLocalPlanes(w, all, torch::ones({1, 1, 8, 7}, torch::kBool), 2, 0.03),
               std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
