// DepthEstimator with and without a depth-range hint, on weights written
// here from randomly initialised networks (accuracy is not the point: the
// shapes, the finiteness and which configurations accept no hint are).

#include "dense/depth_estimator.h"

#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <torch/torch.h>

#include "model/confidence_model.h"
#include "model/config.h"
#include "model/dispmvs_net.h"
#include "model/safetensors.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::dense {
namespace {

constexpr int kWidth = 64;
constexpr int kHeight = 48;

// Weights of a freshly initialised network of `config`, in `dir`.
std::string WriteRandomWeights(const model::ModelConfig& config, const testing::TempDir& dir) {
  torch::manual_seed(7);
  model::DispMvsNet net(config);
  const std::string path = (dir.path() / (config.name + ".safetensors")).string();
  model::SaveModuleWeights(*net, config, path);
  return path;
}

// A reference and two sources beside it (centres at x = 0, -0.3, 0.3), all
// looking along +z at a textured image; f = 60 px.
std::vector<ProblemView> SmallProblem() {
  std::vector<ProblemView> views;
  cv::RNG rng(3);
  for (const double x : {0.0, -0.3, 0.3}) {
    ProblemView view;
    view.image = cv::Mat(kHeight, kWidth, CV_32FC3);
    rng.fill(view.image, cv::RNG::UNIFORM, 0.0, 1.0);
    view.K << 60, 0, kWidth / 2.0, 0, 60, kHeight / 2.0, 0, 0, 1;
    view.R = Eigen::Matrix3d::Identity();
    view.t = Eigen::Vector3d(-x, 0, 0);
    views.push_back(view);
  }
  return views;
}

EstimatorOptions OptionsFor(const std::string& path) {
  EstimatorOptions options;
  options.model_path = path;
  options.threads = 1;  // the test machines are small and shared
  return options;
}

colmap_io::DepthRange Hint(double d_min, double d_max) {
  colmap_io::DepthRange hint;
  hint.d_min = d_min;
  hint.d_max = d_max;
  hint.valid = true;
  return hint;
}

void ExpectUsableEstimate(const DepthEstimate& estimate) {
  ASSERT_EQ(estimate.depth.width(), kWidth);
  ASSERT_EQ(estimate.depth.height(), kHeight);
  ASSERT_EQ(estimate.depth.channels(), 1);
  ASSERT_EQ(estimate.confidence.width(), kWidth);
  ASSERT_EQ(estimate.confidence.height(), kHeight);
  for (const float d : estimate.depth.values()) {
    ASSERT_TRUE(std::isfinite(d) && d >= 0.0f) << d;
  }
  for (const float c : estimate.confidence.values()) {
    ASSERT_TRUE(c >= 0.0f && c <= 1.0f) << c;
  }
}

TEST(DepthEstimatorTest, PaperWeightsNeedAHint) {
  const testing::TempDir dir;
  const std::string path = WriteRandomWeights(model::ModelConfig::Small(), dir);
  EXPECT_TRUE(DepthEstimator::CheckWeightsFile(path).needs_depth_range);
  DepthEstimator estimator(OptionsFor(path));
  EXPECT_TRUE(estimator.NeedsDepthRange());
  try {
    estimator.Estimate(SmallProblem(), std::nullopt, 1);
    FAIL() << "no hint accepted by weights that need one";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("--depth_min"), std::string::npos) << error.what();
  }
  // A given hint must still make sense.
  EXPECT_THROW(estimator.Estimate(SmallProblem(), Hint(5, 2), 1), std::invalid_argument);
  ExpectUsableEstimate(estimator.Estimate(SmallProblem(), Hint(2, 20), 1));
}

// Needs model v2's forward() (undefined depth_min/depth_max accepted when
// !NeedsDepthRange()).
TEST(DepthEstimatorTest, ModelV2WeightsRunWithoutAHint) {
  const testing::TempDir dir;
  const std::string path = WriteRandomWeights(model::ModelConfig::SmallV2(), dir);
  EXPECT_FALSE(DepthEstimator::CheckWeightsFile(path).needs_depth_range);
  DepthEstimator estimator(OptionsFor(path));
  EXPECT_FALSE(estimator.NeedsDepthRange());
  ExpectUsableEstimate(estimator.Estimate(SmallProblem(), std::nullopt, 1));
  // A hint is still accepted (and passed on).
  ExpectUsableEstimate(estimator.Estimate(SmallProblem(), Hint(2, 20), 1));
}

// Reused encoder features give the bits of freshly encoded ones: three
// problems over images 10, 11, 12 (each the reference once), where every
// image after its first use comes from the cache.
TEST(DepthEstimatorTest, ReusedEncoderFeaturesGiveTheSameMaps) {
  const testing::TempDir dir;
  const std::string path = WriteRandomWeights(model::ModelConfig::SmallV2(), dir);
  const std::vector<ProblemView> base = SmallProblem();
  auto problem = [&](std::vector<int> order, bool with_ids) {
    std::vector<ProblemView> views;
    for (const int i : order) {
      views.push_back(base[static_cast<std::size_t>(i)]);
      views.back().image_id = with_ids ? 10 + i : -1;
    }
    return views;
  };
  const std::vector<std::vector<int>> orders = {{0, 1, 2}, {1, 0, 2}, {2, 1, 0}};
  DepthEstimator fresh(OptionsFor(path));
  DepthEstimator reusing(OptionsFor(path));
  for (const auto& order : orders) {
    const DepthEstimate a = fresh.Estimate(problem(order, false), std::nullopt, 1);
    const DepthEstimate b = reusing.Estimate(problem(order, true), std::nullopt, 1);
    EXPECT_EQ(a.depth.values(), b.depth.values());
    EXPECT_EQ(a.confidence.values(), b.confidence.values());
  }
  EXPECT_EQ(fresh.encoder_use().encoded, 0);  // no ids: never cached
  EXPECT_EQ(reusing.encoder_use().encoded, 3);
  EXPECT_EQ(reusing.encoder_use().reused, 6);
  // Three images of 64x48: 64 coarse channels at 4x3 and 48 fine at 16x12.
  EXPECT_NEAR(reusing.encoder_use().peak_cache_mb, 3 * (64 * 12 + 48 * 192) * 4.0 / (1 << 20), 1e-9);

  // Without a budget nothing is kept; a negative one is refused.
  EstimatorOptions none = OptionsFor(path);
  none.feature_cache_mb = 0;
  DepthEstimator uncached(none);
  for (const auto& order : orders) uncached.Estimate(problem(order, true), std::nullopt, 1);
  EXPECT_EQ(uncached.encoder_use().encoded, 9);
  EXPECT_EQ(uncached.encoder_use().reused, 0);
  none.feature_cache_mb = -1;
  EXPECT_THROW(none.Check(), std::invalid_argument);
}

// The confidence map comes from the weights' confidence model where they
// carry one and the refinement runs; else, or with --confidence network,
// it is the network's. The depth is the same either way.
TEST(DepthEstimatorTest, ConfidenceModelOfTheWeightsGivesTheConfidenceMap) {
  const testing::TempDir dir;
  const std::string plain = WriteRandomWeights(model::ModelConfig::SmallV2(), dir);
  const std::string with_model = (dir.path() / "with_model.safetensors").string();
  // A model that reads the texture alone: sigmoid(0.5 + 0.1 * log texture),
  // different from any network confidence.
  model::ConfidenceModel confidence_model;
  confidence_model.coefficients = {0.5, 0, 0, 0, 0, 0, 0.1, 0};
  model::WriteConfidenceModel(plain, with_model, confidence_model);

  DepthEstimator network(OptionsFor(plain));
  EXPECT_FALSE(network.UsesConfidenceModel());
  DepthEstimator modelled(OptionsFor(with_model));
  EXPECT_TRUE(modelled.UsesConfidenceModel());
  EstimatorOptions asked_network = OptionsFor(with_model);
  asked_network.confidence = "network";
  EXPECT_FALSE(DepthEstimator(asked_network).UsesConfidenceModel());
  EstimatorOptions unrefined = OptionsFor(with_model);
  unrefined.refinement = "none";
  EXPECT_FALSE(DepthEstimator(unrefined).UsesConfidenceModel());

  const DepthEstimate a = network.Estimate(SmallProblem(), std::nullopt, 1);
  const DepthEstimate b = modelled.Estimate(SmallProblem(), std::nullopt, 1);
  ExpectUsableEstimate(b);
  EXPECT_EQ(a.depth.values(), b.depth.values());
  // The uniform-noise images are textured everywhere: every pixel with a
  // depth has the model's value, in (sigmoid(0.5 + 0.1 log 0.01), sigmoid(0.5)).
  int checked = 0;
  for (std::size_t i = 0; i < b.depth.values().size(); ++i) {
    if (b.depth.values()[i] <= 0) continue;
    EXPECT_GT(b.confidence.values()[i], 1 / (1 + std::exp(-(0.5 + 0.1 * std::log(0.01)))));
    EXPECT_LT(b.confidence.values()[i], 1 / (1 + std::exp(-0.5)));
    ++checked;
  }
  EXPECT_GT(checked, kWidth * kHeight / 2);
  EXPECT_NE(a.confidence.values(), b.confidence.values());

  EstimatorOptions bad = OptionsFor(with_model);
  bad.confidence = "peak";
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::dense
