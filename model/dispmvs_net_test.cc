#include "model/dispmvs_net.h"

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <filesystem>
#include <string>
#include <thread>
#include <tuple>
#include <unistd.h>

#include <ATen/CPUGeneratorImpl.h>
#include <gtest/gtest.h>
#include <torch/cuda.h>

#include "model/loss.h"
#include "model/safetensors.h"

namespace dispmvs::model {
namespace {

// Random images and a valid rig: reference at the origin, sources shifted
// sideways (and slightly rotated) by a baseline ~10% of the scene depth.
DispMvsInput MakeInput(int64_t batch, int64_t sources, int64_t height, int64_t width,
                       uint64_t seed = 11) {
  torch::manual_seed(seed);
  const int64_t views = sources + 1;
  DispMvsInput in;
  in.images = torch::rand({batch, views, 3, height, width});
  torch::Tensor K = torch::zeros({3, 3});
  K[0][0] = 0.8f * width;
  K[1][1] = 0.8f * width;
  K[0][2] = (width - 1) / 2.0f;
  K[1][2] = (height - 1) / 2.0f;
  K[2][2] = 1.0f;
  in.intrinsics = K.expand({batch, views, 3, 3}).clone();
  in.extrinsics = torch::eye(4).expand({batch, views, 4, 4}).clone();
  for (int64_t v = 1; v < views; ++v) {
    const float angle = 0.02f * v;
    in.extrinsics.index_put_({torch::indexing::Slice(), v, 0, 0}, std::cos(angle));
    in.extrinsics.index_put_({torch::indexing::Slice(), v, 0, 2}, std::sin(angle));
    in.extrinsics.index_put_({torch::indexing::Slice(), v, 2, 0}, -std::sin(angle));
    in.extrinsics.index_put_({torch::indexing::Slice(), v, 2, 2}, std::cos(angle));
    in.extrinsics.index_put_({torch::indexing::Slice(), v, 0, 3}, -0.3f * v);
    in.extrinsics.index_put_({torch::indexing::Slice(), v, 1, 3}, 0.05f * v);
  }
  in.depth_min = torch::full({batch}, 2.0f);
  in.depth_max = torch::full({batch}, 6.0f);
  return in;
}

ModelConfig FastConfig() {
  ModelConfig c = ModelConfig::Small();
  c.coarse_iterations = 3;
  c.fine_iterations = 2;
  return c;
}

class DispMvsNetShapeTest
    : public ::testing::TestWithParam<std::tuple<int64_t, int64_t, int64_t>> {};

TEST_P(DispMvsNetShapeTest, OutputShapesAndRanges) {
  const auto [sources, height, width] = GetParam();
  const ModelConfig config = FastConfig();
  DispMvsNet net(config);
  const int64_t batch = 2;
  const DispMvsInput in = MakeInput(batch, sources, height, width);

  net->train();
  DispMvsOutput out = net->forward(in);
  ASSERT_EQ(out.inv_depths.size(),
            static_cast<size_t>(config.coarse_iterations + config.fine_iterations));
  for (const auto& inv : out.inv_depths) {
    EXPECT_EQ(inv.sizes(), torch::IntArrayRef({batch, 1, height, width}));
    EXPECT_TRUE(torch::isfinite(inv).all().item<bool>());
  }
  EXPECT_TRUE(torch::allclose(
      out.inv_depths.back(),
      torch::where(out.valid, 1.0 / out.depth, torch::zeros_like(out.depth)), 1e-5, 1e-7));

  torch::NoGradGuard no_grad;
  net->eval();
  out = net->forward(in);
  ASSERT_EQ(out.inv_depths.size(), 1u);
  for (const torch::Tensor& t : {out.depth, out.confidence, out.inv_depths[0]}) {
    EXPECT_EQ(t.sizes(), torch::IntArrayRef({batch, 1, height, width}));
    EXPECT_TRUE(torch::isfinite(t).all().item<bool>());
  }
  EXPECT_EQ(out.valid.sizes(), torch::IntArrayRef({batch, 1, height, width}));
  EXPECT_EQ(out.valid.scalar_type(), torch::kBool);
  EXPECT_TRUE((out.depth.masked_select(out.valid) > 0).all().item<bool>());
  EXPECT_TRUE((out.depth.masked_select(~out.valid) == 0).all().item<bool>());
  EXPECT_TRUE((out.confidence >= 0).all().item<bool>());
  EXPECT_TRUE((out.confidence <= 1).all().item<bool>());
  EXPECT_TRUE((out.confidence.masked_select(~out.valid) == 0).all().item<bool>());
}

INSTANTIATE_TEST_SUITE_P(SourcesAndSizes, DispMvsNetShapeTest,
                         ::testing::Values(std::make_tuple(1, 64, 64),
                                           std::make_tuple(2, 72, 100),
                                           std::make_tuple(4, 48, 80),
                                           std::make_tuple(2, 20, 33)));

TEST(DispMvsNetTest, DeterministicForAFixedSeed) {
  DispMvsNet net(FastConfig());
  net->eval();
  torch::NoGradGuard no_grad;
  const DispMvsInput in = MakeInput(1, 2, 48, 64);
  const auto run = [&](uint64_t seed) {
    torch::Generator gen = at::make_generator<at::CPUGeneratorImpl>(seed);
    return net->forward(in, gen);
  };
  const DispMvsOutput a = run(42);
  const DispMvsOutput b = run(42);
  const DispMvsOutput c = run(43);
  EXPECT_TRUE(torch::equal(a.depth, b.depth));
  EXPECT_TRUE(torch::equal(a.confidence, b.confidence));
  EXPECT_TRUE(torch::equal(a.valid, b.valid));
  // A different seed is a different random initialisation.
  EXPECT_FALSE(torch::equal(a.depth, c.depth));
}

TEST(DispMvsNetTest, GradientReachesEveryParameter) {
  DispMvsNet net(ModelConfig::Small());
  net->train();
  const DispMvsInput in = MakeInput(1, 2, 32, 48);
  const DispMvsOutput out = net->forward(in);
  const torch::Tensor gt = torch::full({1, 1, 32, 48}, 3.5f);
  const torch::Tensor valid = torch::ones({1, 1, 32, 48}, torch::kBool);
  SequenceLoss(out.inv_depths, gt, valid, in.depth_min, in.depth_max).backward();
  int64_t checked = 0;
  for (const auto& p : net->named_parameters()) {
    ASSERT_TRUE(p.value().grad().defined()) << p.key();
    EXPECT_GT(p.value().grad().abs().sum().item<double>(), 0.0) << p.key();
    ++checked;
  }
  EXPECT_GT(checked, 20);
}

ModelConfig FastV2Config() {
  ModelConfig c = FastConfig();
  c.init = ModelConfig::Init::kMatch;
  return c;
}

TEST(DispMvsNetV2Test, RunsWithoutADepthRangeDeterministically) {
  DispMvsNet net(FastV2Config());
  net->eval();
  torch::NoGradGuard no_grad;
  DispMvsInput in = MakeInput(2, 2, 48, 64);
  in.depth_min = torch::Tensor();
  in.depth_max = torch::Tensor();
  const DispMvsOutput a = net->forward(in);
  const DispMvsOutput b = net->forward(in);
  EXPECT_TRUE(torch::equal(a.depth, b.depth));  // no random draw anywhere
  EXPECT_TRUE(torch::isfinite(a.depth).all().item<bool>());
  EXPECT_GT(a.valid.to(torch::kFloat).mean().item<double>(), 0.5);
  EXPECT_TRUE(a.matching.empty());  // eval mode

  // The paper's design needs the hint, and says so.
  DispMvsNet paper(FastConfig());
  paper->eval();
  EXPECT_THROW(paper->forward(in), std::invalid_argument);
}

// What a caller that caches encoder features relies on: features from
// EncodeMatching, one view at a time, give the bits of a plain inference pass.
TEST(DispMvsNetInferenceTest, PrecomputedMatchingFeaturesGiveTheSameBits) {
  DispMvsNet net(FastV2Config());
  net->eval();
  torch::NoGradGuard no_grad;
  const int64_t batch = 2, views = 4, height = 40, width = 60;  // padded to 48x64
  const DispMvsInput in = MakeInput(batch, views - 1, height, width);
  const DispMvsOutput plain = net->forward(in);

  std::vector<torch::Tensor> coarse, fine;
  for (int64_t b = 0; b < batch; ++b) {
    for (int64_t v = 0; v < views; ++v) {  // each view alone, in index b*V + v
      const FeaturePyramid one = net->EncodeMatching(in.images[b][v].unsqueeze(0));
      ASSERT_EQ(one.coarse.sizes(), (std::vector<int64_t>{1, 64, 3, 4}));
      ASSERT_EQ(one.fine.sizes(), (std::vector<int64_t>{1, 48, 12, 16}));
      coarse.push_back(one.coarse);
      fine.push_back(one.fine);
    }
  }
  DispMvsInput cached = in;
  cached.matching_features = {torch::cat(coarse, 0), torch::cat(fine, 0)};
  const DispMvsOutput from_cache = net->forward(cached);
  EXPECT_TRUE(torch::equal(plain.depth, from_cache.depth));
  EXPECT_TRUE(torch::equal(plain.confidence, from_cache.confidence));
  EXPECT_TRUE(torch::equal(plain.valid, from_cache.valid));

  // Features of another view count, size or channel count are refused.
  DispMvsInput wrong = cached;
  wrong.matching_features.coarse = cached.matching_features.coarse.narrow(0, 0, 7);
  EXPECT_THROW(net->forward(wrong), std::invalid_argument);
  wrong = cached;
  wrong.matching_features.fine = cached.matching_features.fine.narrow(1, 0, 47);
  EXPECT_THROW(net->forward(wrong), std::invalid_argument);
  wrong = cached;
  wrong.matching_features.fine = torch::Tensor();
  EXPECT_THROW(net->forward(wrong), std::invalid_argument);
  EXPECT_THROW(net->EncodeMatching(in.images), std::invalid_argument);  // [B,V,3,H,W]
}

// Inference encodes the views one at a time and runs the fine stage's update
// block on a few sources at a time (to bound memory); the result must be the
// batched pass's, up to float rounding. 704x512 has a 176x128 fine stage, so
// its 3 (reference, source) pairs go through the block as 2 + 1.
TEST(DispMvsNetInferenceTest, ChunkedInferenceMatchesTheBatchedPass) {
  DispMvsNet net(FastV2Config());
  net->eval();
  const DispMvsInput in = MakeInput(1, 3, 512, 704);
  DispMvsOutput batched;
  {
    // With autograd on, forward() keeps one encoder call and one update
    // call per iteration: the reference.
    const torch::AutoGradMode grad(true);
    batched = net->forward(in);
  }
  torch::NoGradGuard no_grad;
  const DispMvsOutput chunked = net->forward(in);
  const torch::Tensor both = batched.valid & chunked.valid;
  EXPECT_GT(both.to(torch::kFloat).mean().item<double>(), 0.9);
  const torch::Tensor relative =
      ((batched.depth.detach() - chunked.depth).abs() / batched.depth.detach().clamp_min(1e-6))
          .masked_select(both);
  // Rounding differences can flip a pixel's path through the iterations, but
  // not many, and not far.
  EXPECT_GT((relative < 1e-4).to(torch::kFloat).mean().item<double>(), 0.999);
  EXPECT_TRUE(torch::equal(batched.valid, chunked.valid));
}

// The fine stage in bands of rows (set_fine_band_pixels) gives the
// whole-image pass's maps to float rounding, in both cell conventions and
// starts, with two samples. 250 rows pad to 256: a 64-row fine grid, bands
// of the smallest height (the halo, 27 rows for two fine iterations) make
// three (27, 27, 10), the last with the padding rows, and every band's
// halo is cut by an image border or reaches past a neighbour band. A halo
// smaller than the rows the updates read would differ by far more.
TEST(DispMvsNetInferenceTest, FineStageInBandsMatchesTheWholeImage) {
  for (const ModelConfig& config : {FastV2Config(), FastConfig()}) {
    DispMvsNet net(config);
    net->eval();
    torch::NoGradGuard no_grad;
    const DispMvsInput in = MakeInput(2, 2, 250, 60);
    const auto run = [&](int64_t band_pixels) {
      net->set_fine_band_pixels(band_pixels);
      torch::Generator gen = at::make_generator<at::CPUGeneratorImpl>(5);
      return net->forward(in, gen);
    };
    const DispMvsOutput whole = run(0);
    const DispMvsOutput bands = run(1);
    ASSERT_EQ(bands.depth.sizes(), whole.depth.sizes());
    ASSERT_EQ(bands.inv_depths.size(), 1u);
    EXPECT_TRUE(torch::equal(bands.valid, whole.valid)) << config.name;
    EXPECT_GT(whole.valid.to(torch::kFloat).mean().item<double>(), 0.5) << config.name;
    const auto relative = [](const torch::Tensor& x, const torch::Tensor& y) {
      return ((x - y).abs() / y.abs().clamp_min(1e-6)).max().item<double>();
    };
    EXPECT_LT(relative(bands.depth, whole.depth), 1e-5) << config.name;
    EXPECT_LT(relative(bands.inv_depths[0], whole.inv_depths.back()), 1e-5) << config.name;
    EXPECT_LT((bands.confidence - whole.confidence).abs().max().item<double>(), 1e-5) << config.name;
    // An image no taller than one band runs whole: the same bits.
    const DispMvsOutput one_band = run(int64_t{1} << 30);
    EXPECT_TRUE(torch::equal(one_band.depth, whole.depth)) << config.name;
  }
  DispMvsNet net(FastV2Config());
  EXPECT_THROW(net->set_fine_band_pixels(-1), std::invalid_argument);
}

TEST(DispMvsNetV2Test, TrainingReturnsBothStagesMatchingAndTheLossReachesEveryParameter) {
  DispMvsNet net(FastV2Config());
  net->train();
  const int64_t h = 32, w = 48, sources = 2;
  const DispMvsInput in = MakeInput(1, sources, h, w);
  const DispMvsOutput out = net->forward(in);
  ASSERT_EQ(out.matching.size(), 2u);
  EXPECT_EQ(out.matching[0].stride, 16);
  EXPECT_EQ(out.matching[1].stride, 4);
  EXPECT_EQ(out.matching[0].logits.size(0), sources);
  EXPECT_EQ(out.matching[0].logits.size(2), h / 16);
  EXPECT_EQ(out.matching[1].logits.size(1), FastV2Config().fine_samples);
  EXPECT_EQ(out.matching[1].logits.size(2), h / 4);
  // Every fine iteration's matches, per source, on the fine grid.
  ASSERT_EQ(static_cast<int64_t>(out.fine_source_xy.size()), FastV2Config().fine_iterations);
  for (const torch::Tensor& xy : out.fine_source_xy) {
    EXPECT_EQ(xy.sizes(), torch::IntArrayRef({sources, 2, h / 4, w / 4}));
  }

  // Ground truth: a fronto-parallel plane at depth 3.5 in every view is not
  // consistent, so give depth only to the reference (no occlusion check).
  torch::Tensor depths = torch::zeros({1, sources + 1, 1, h, w});
  depths.select(1, 0).fill_(3.5f);
  torch::Tensor loss = SequenceLoss(out.inv_depths, depths.select(1, 0), depths.select(1, 0) > 0,
                                    in.depth_min, in.depth_max);
  double counted = 0;
  for (const StageMatching& m : out.matching) {
    const auto truth = ComputeGroundTruthMatches(depths, in.intrinsics, in.extrinsics, m.stride,
                                                 m.logits.size(2), m.logits.size(3));
    const MatchingLossResult r = MatchingLoss(m, truth);
    counted += r.count;
    loss = loss + r.loss;
  }
  EXPECT_GT(counted, 0);
  const auto fine_truth = ComputeGroundTruthMatches(depths, in.intrinsics, in.extrinsics, 4, h / 4, w / 4);
  const SourceFlowLossResult flow = SourceFlowLoss(out.fine_source_xy, fine_truth);
  EXPECT_GT(flow.count, 0);
  loss = loss + flow.loss;
  loss.backward();
  for (const auto& p : net->named_parameters()) {
    ASSERT_TRUE(p.value().grad().defined()) << p.key();
    EXPECT_GT(p.value().grad().abs().sum().item<double>(), 0.0) << p.key();
  }
}

// R X_r + T must map a point's reference-camera coordinates to its
// source-camera coordinates, computed independently through the world frame.
TEST(DispMvsNetTest, ReferenceToSourcePosesComposeThroughTheWorld) {
  torch::manual_seed(2);
  const auto random_pose = [] {
    const torch::Tensor q = std::get<0>(torch::linalg::qr(torch::randn({3, 3}, torch::kDouble)));
    torch::Tensor E = torch::eye(4, torch::kDouble);
    E.narrow(0, 0, 3).narrow(1, 0, 3).copy_(q * torch::det(q));  // a proper rotation
    E.narrow(0, 0, 3).select(1, 3).copy_(torch::randn({3}, torch::kDouble));
    return E;
  };
  const torch::Tensor extrinsics =
      torch::stack({random_pose(), random_pose(), random_pose()}).unsqueeze(0);  // [1,3,4,4]
  const RelativePoses poses = ReferenceToSourcePoses(extrinsics);
  ASSERT_EQ(poses.R.sizes(), torch::IntArrayRef({1, 2, 3, 3}));
  ASSERT_EQ(poses.T.sizes(), torch::IntArrayRef({1, 2, 3}));
  const torch::Tensor world = torch::randn({3, 5}, torch::kDouble);
  const auto to_camera = [&](int64_t v) {
    const torch::Tensor E = extrinsics[0][v];
    return torch::matmul(E.narrow(0, 0, 3).narrow(1, 0, 3), world) + E.narrow(0, 0, 3).narrow(1, 3, 1);
  };
  for (int64_t i = 0; i < 2; ++i) {
    const torch::Tensor mapped =
        torch::matmul(poses.R[0][i], to_camera(0)) + poses.T[0][i].unsqueeze(1);
    EXPECT_TRUE(torch::allclose(mapped, to_camera(i + 1), 1e-9, 1e-9)) << i;
  }
  EXPECT_THROW(ReferenceToSourcePoses(torch::zeros({1, 1, 4, 4})), std::invalid_argument);
}

TEST(DispMvsNetTest, RejectsBadInput) {
  DispMvsNet net(FastConfig());
  torch::NoGradGuard no_grad;
  {
    DispMvsInput in = MakeInput(1, 1, 32, 32);
    in.images = in.images.narrow(1, 0, 1);  // no source view
    in.intrinsics = in.intrinsics.narrow(1, 0, 1);
    in.extrinsics = in.extrinsics.narrow(1, 0, 1);
    EXPECT_THROW(net->forward(in), std::invalid_argument);
  }
  {
    DispMvsInput in = MakeInput(1, 1, 32, 32);
    in.intrinsics = torch::zeros({1, 2, 3, 4});
    EXPECT_THROW(net->forward(in), std::invalid_argument);
  }
  {
    DispMvsInput in = MakeInput(1, 1, 32, 32);
    in.depth_min = torch::full({1}, 7.0f);  // above depth_max
    EXPECT_THROW(net->forward(in), std::invalid_argument);
  }
  {
    DispMvsInput in = MakeInput(1, 1, 32, 32);
    in.extrinsics[0][1][0][3] = std::nanf("");
    EXPECT_THROW(net->forward(in), std::invalid_argument);
  }
  {
    DispMvsInput in = MakeInput(1, 1, 32, 32);
    in.images = torch::rand({1, 2, 1, 32, 32});  // one channel
    EXPECT_THROW(net->forward(in), std::invalid_argument);
  }
}


// The stage breakdown of dispmvs_bench: attaching a timer changes nothing in
// the output, every stage gets time, and every section synchronises at both
// ends. How many sections a stage is split into is the network's business.
TEST(DispMvsNetStageTimerTest, TimesEveryStageWithoutChangingTheOutput) {
  const ModelConfig config = FastConfig();
  DispMvsNet net(config);
  net->eval();
  torch::NoGradGuard no_grad;
  const DispMvsInput in = MakeInput(1, 2, 48, 64);
  auto generator = [] { return at::make_generator<at::CPUGeneratorImpl>(5); };

  const DispMvsOutput plain = net->forward(in, generator());
  int synchronize_calls = 0;
  StageTimer timer([&] { ++synchronize_calls; });
  net->set_stage_timer(&timer);
  const DispMvsOutput timed = net->forward(in, generator());
  net->set_stage_timer(nullptr);
  EXPECT_TRUE(torch::equal(plain.depth, timed.depth));
  EXPECT_TRUE(torch::equal(plain.confidence, timed.confidence));

  long sections = 0;
  for (std::size_t s = 0; s < kNumNetStages; ++s) {
    const auto stage = static_cast<NetStage>(s);
    EXPECT_GT(timer.count(stage), 0) << NetStageName(stage);
    EXPECT_GT(timer.seconds(stage), 0.0) << NetStageName(stage);
    sections += timer.count(stage);
  }
  EXPECT_EQ(synchronize_calls, 2 * sections);

  // Detached: a further pass adds nothing.
  const double before = timer.total_seconds();
  net->forward(in, generator());
  EXPECT_EQ(timer.total_seconds(), before);
  timer.Reset();
  EXPECT_EQ(timer.total_seconds(), 0.0);
  EXPECT_EQ(timer.count(NetStage::kGeometry), 0);
}

// The training step, the inference pass, the coarse matching and the weights
// files on a device (CUDA where there is one; the CPU instance checks this
// harness): the same weights, input and seeded CPU generator give the CPU's
// results, and everything the network returns lives on the device. Loose
// agreement only: cuDNN may use TF32, and arg-max near-ties may break the
// other way.
class DispMvsNetDeviceTest : public ::testing::TestWithParam<std::tuple<std::string, bool>> {};

TEST_P(DispMvsNetDeviceTest, TrainingStepInferenceAndWeightsMatchTheCpu) {
  const auto [device_name, v2] = GetParam();
  const torch::Device device(device_name);
  if (device.is_cuda() && !torch::cuda::is_available()) GTEST_SKIP() << "no CUDA device";
  const ModelConfig config = v2 ? FastV2Config() : FastConfig();
  const int64_t h = 48, w = 64, sources = 2;
  torch::manual_seed(3);
  DispMvsNet cpu_net(config);
  torch::manual_seed(3);
  DispMvsNet net(config);
  net->to(device);
  const DispMvsInput cpu_in = MakeInput(1, sources, h, w);
  DispMvsInput in = cpu_in;
  for (torch::Tensor* t : {&in.images, &in.intrinsics, &in.extrinsics, &in.depth_min, &in.depth_max}) {
    *t = t->to(device);
  }
  // Depth only in the reference (a plane), so no occlusion check.
  torch::Tensor cpu_depths = torch::zeros({1, sources + 1, 1, h, w});
  cpu_depths.select(1, 0).fill_(3.5f);
  const auto on_device = [&](const torch::Tensor& t) { return t.defined() && t.device() == device; };

  struct Step {
    double loss = 0, grad_norm = 0, counted = 0;
  };
  const auto train_step = [&](DispMvsNet& n, const DispMvsInput& input) {
    const torch::Tensor depths = cpu_depths.to(input.images.device());
    n->train();
    n->zero_grad();
    const DispMvsOutput out = n->forward(input, at::make_generator<at::CPUGeneratorImpl>(5));
    for (const torch::Tensor& t : out.inv_depths) EXPECT_EQ(t.device(), input.images.device());
    torch::Tensor loss = SequenceLoss(out.inv_depths, depths.select(1, 0), depths.select(1, 0) > 0,
                                      input.depth_min, input.depth_max);
    Step step;
    EXPECT_EQ(out.matching.size(), v2 ? 2u : 0u);
    for (const StageMatching& m : out.matching) {
      const auto truth = ComputeGroundTruthMatches(depths, input.intrinsics, input.extrinsics, m.stride,
                                                   m.logits.size(2), m.logits.size(3));
      const MatchingLossResult r = MatchingLoss(m, truth);
      step.counted += r.count;
      loss = loss + r.loss;
    }
    loss.backward();
    step.loss = loss.item<double>();
    double squares = 0;
    for (const auto& p : n->named_parameters()) {
      EXPECT_TRUE(p.value().grad().defined() && p.value().grad().device() == p.value().device()) << p.key();
      if (p.value().grad().defined()) squares += p.value().grad().square().sum().item<double>();
    }
    step.grad_norm = std::sqrt(squares);
    return step;
  };
  const Step expected = train_step(cpu_net, cpu_in);
  const Step got = train_step(net, in);
  for (const auto& p : net->parameters()) EXPECT_TRUE(on_device(p));
  EXPECT_TRUE(std::isfinite(got.loss) && std::isfinite(got.grad_norm));
  EXPECT_NEAR(got.loss, expected.loss, 0.1 * std::abs(expected.loss));
  EXPECT_NEAR(got.grad_norm, expected.grad_norm, 0.2 * expected.grad_norm);
  EXPECT_NEAR(got.counted, expected.counted, 0.02 * expected.counted);

  torch::NoGradGuard no_grad;
  cpu_net->eval();
  net->eval();
  const DispMvsOutput cpu_out = cpu_net->forward(cpu_in, at::make_generator<at::CPUGeneratorImpl>(6));
  const DispMvsOutput out = net->forward(in, at::make_generator<at::CPUGeneratorImpl>(6));
  for (const torch::Tensor& t : {out.depth, out.valid, out.confidence, out.inv_depths.back()}) {
    EXPECT_TRUE(on_device(t));
  }
  // Depths agree (within 1 %) on most pixels that either pass predicts.
  const torch::Tensor depth = out.depth.cpu(), valid = out.valid.cpu();
  const torch::Tensor either = valid | cpu_out.valid;
  const torch::Tensor agree = valid & cpu_out.valid & ((depth - cpu_out.depth).abs() <= 0.01 * cpu_out.depth);
  ASSERT_GT(either.sum().item<int64_t>(), 0);
  EXPECT_GE(agree.sum().item<double>(), 0.9 * either.sum().item<double>());

  const StageMatching matching = net->CoarseMatching(in);
  for (const torch::Tensor& t : {matching.logits, matching.sample_eflow, matching.inside, matching.base_xy}) {
    EXPECT_TRUE(on_device(t));
  }
  const StageMatching cpu_matching = cpu_net->CoarseMatching(cpu_in);
  EXPECT_EQ(matching.logits.sizes(), cpu_matching.logits.sizes());
  const torch::Tensor same_peak = matching.logits.argmax(1).cpu() == cpu_matching.logits.argmax(1);
  EXPECT_GE(same_peak.to(torch::kDouble).mean().item<double>(), 0.9);

  // Weights written from the device read back on the CPU and on the device.
  const std::filesystem::path path = std::filesystem::temp_directory_path() /
                                     ("dispmvs_device_test_" + std::to_string(::getpid()) + ".safetensors");
  SaveModuleWeights(*net, config, path.string());
  DispMvsNet reread(config);
  LoadModuleWeights(*reread, path.string());
  const auto stored = net->named_parameters();
  for (const auto& p : reread->named_parameters()) {
    EXPECT_TRUE(torch::equal(p.value(), stored[p.key()].cpu())) << p.key();
  }
  reread->to(device);
  cpu_net->to(device);
  LoadModuleWeights(*cpu_net, path.string());  // into device parameters
  for (const auto& p : cpu_net->named_parameters()) {
    EXPECT_TRUE(on_device(p.value()));
    EXPECT_TRUE(torch::equal(p.value(), stored[p.key()])) << p.key();
  }
  std::filesystem::remove(path);
}

INSTANTIATE_TEST_SUITE_P(Devices, DispMvsNetDeviceTest,
                         ::testing::Combine(::testing::Values(std::string("cpu"), std::string("cuda")),
                                            ::testing::Bool()));

TEST(StageTimerTest, SectionsAddUpAndNullTimerIsANoOp) {
  StageTimer timer;
  {
    const StageTimer::Section section(&timer, NetStage::kUpdate);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  {
    const StageTimer::Section section(&timer, NetStage::kUpdate);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  { const StageTimer::Section section(nullptr, NetStage::kEncoders); }
  EXPECT_GE(timer.seconds(NetStage::kUpdate), 0.030);
  EXPECT_LT(timer.seconds(NetStage::kUpdate), 5.0);
  EXPECT_EQ(timer.count(NetStage::kUpdate), 2);
  EXPECT_EQ(timer.count(NetStage::kEncoders), 0);
  EXPECT_EQ(timer.total_seconds(), timer.seconds(NetStage::kUpdate));
  EXPECT_STREQ(NetStageName(NetStage::kCorrelation), "correlation");
}

}  // namespace
}  // namespace dispmvs::model
