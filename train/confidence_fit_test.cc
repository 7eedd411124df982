#include "train/confidence_fit.h"

#include <sstream>

#include <gtest/gtest.h>

#include "model/config.h"
#include "train/validation.h"

namespace dispmvs::train {
namespace {

TEST(ConfidenceFitTest, ShareCorrectAtCoverageRanksByConfidence) {
  const torch::Tensor confidence = torch::tensor({0.9, 0.1, 0.5, 0.7});
  const torch::Tensor correct = torch::tensor({true, false, false, true});
  const auto shares = ShareCorrectAtCoverage(confidence, correct, {0.25, 0.5, 0.75, 1.0});
  ASSERT_EQ(shares.size(), 4u);
  EXPECT_DOUBLE_EQ(shares[0], 1.0);
  EXPECT_DOUBLE_EQ(shares[1], 1.0);
  EXPECT_DOUBLE_EQ(shares[2], 2.0 / 3);
  EXPECT_DOUBLE_EQ(shares[3], 0.5);
  // Equal confidences keep the pixels' order.
  const auto tied = ShareCorrectAtCoverage(torch::ones({4}), torch::tensor({0, 1, 1, 1}), {0.25, 0.5});
  EXPECT_DOUBLE_EQ(tied[0], 0.0);
  EXPECT_DOUBLE_EQ(tied[1], 0.5);
  EXPECT_EQ(ShareCorrectAtCoverage(torch::zeros({0}), torch::zeros({0}), {0.5}), std::vector<double>{0.0});
  EXPECT_THROW(ShareCorrectAtCoverage(confidence, correct, {0.0}), std::invalid_argument);
  EXPECT_THROW(ShareCorrectAtCoverage(confidence, correct.narrow(0, 0, 3), {0.5}), std::invalid_argument);
}

TrainOptions TinyFitOptions() {
  TrainOptions o;
  o.config = "small_v2";
  o.height = 48;
  o.width = 64;
  o.num_sources = 3;
  o.source_counts = {1, 3};
  o.threads = 1;
  o.num_validation_scenes = 2;
  o.eval_refinement = "ncc";
  return o;
}

TEST(ConfidenceFitTest, FitScenesAreTrainingDrawsWithTheSourceCountMix) {
  const TrainOptions o = TinyFitOptions();
  const auto scenes = ConfidenceFitScenes(o, 6, torch::kCPU);
  const auto validation = internal::ValidationScenes(o, torch::kCPU);
  ASSERT_EQ(scenes.size(), 6u);
  for (size_t i = 0; i < scenes.size(); ++i) {
    EXPECT_EQ(scenes[i].images.size(0), TrainingSourceCountAt(o, static_cast<int64_t>(i)) + 1);
    for (const auto& v : validation) EXPECT_FALSE(torch::equal(scenes[i].images[0], v.images[0]));
  }
}

TEST(ConfidenceFitTest, FitOnAnUntrainedNetworkGivesAModelAndCurvesOverTheSamePixels) {
  TrainOptions o = TinyFitOptions();
  model::DispMvsNet net(model::ModelConfig::SmallV2());
  const auto fit_scenes = ConfidenceFitScenes(o, 4, torch::kCPU);
  const auto validation = internal::ValidationScenes(o, torch::kCPU);
  std::ostringstream log;
  const ConfidenceFit fit = FitConfidenceOnScenes(net, fit_scenes, validation, o, log);
  EXPECT_NE(log.str().find("fit scene 4/4"), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("validation scene 2/2"), std::string::npos) << log.str();
  EXPECT_EQ(fit.model.coefficients.size(), static_cast<size_t>(model::kConfidenceFeatures));
  EXPECT_EQ(fit.fit_scenes, 4);
  EXPECT_GT(fit.fit_pixels, 0);
  for (const ConfidenceCurves* curves : {&fit.fit, &fit.validation}) {
    ASSERT_EQ(curves->network.size(), kConfidenceCoverages.size());
    ASSERT_EQ(curves->model.size(), kConfidenceCoverages.size());
    // At full coverage both confidences keep every pixel: the same share.
    EXPECT_DOUBLE_EQ(curves->network.back(), curves->model.back());
  }
  EXPECT_NEAR(fit.fit.model.back(), fit.fit_share_correct, 1e-12);
  // The model is fitted to these pixels: its ranking of them is at least as
  // good as a constant's at half coverage, up to chance.
  EXPECT_GE(fit.fit.model.front(), fit.fit_share_correct - 0.02);

  o.eval_refinement = "none";
  EXPECT_THROW(FitConfidenceOnScenes(net, fit_scenes, validation, o, log), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::train
