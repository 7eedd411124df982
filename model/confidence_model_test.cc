#include "model/confidence_model.h"

#include <cmath>

#include <gtest/gtest.h>

#include "model/safetensors.h"
#include "tests/support/temp_dir.h"

namespace dispmvs::model {
namespace {

torch::Tensor RandomFeatures(int64_t m, uint64_t seed) {
  torch::manual_seed(seed);
  torch::Tensor x = torch::randn({m, kConfidenceFeatures}, torch::kFloat64);
  x.select(1, 0).fill_(1.0);
  return x;
}

TEST(ConfidenceModelTest, FitRecoversTheCoefficientsThatDrewTheLabels) {
  const std::vector<double> truth{-0.5, 1.5, -2.0, 0.7, 0.0, 1.0, -0.3, 0.4};
  const torch::Tensor x = RandomFeatures(200000, 3);
  const torch::Tensor p = torch::sigmoid(x.matmul(torch::tensor(truth, torch::kFloat64)));
  const torch::Tensor y = (torch::rand({x.size(0)}, torch::kFloat64) < p).to(torch::kFloat64);
  const ConfidenceModel fitted = FitConfidenceModel(x, y, /*ridge=*/1e-9);
  ASSERT_EQ(fitted.coefficients.size(), truth.size());
  // The standard error of each coefficient here is about 0.01.
  for (size_t i = 0; i < truth.size(); ++i) EXPECT_NEAR(fitted.coefficients[i], truth[i], 0.05) << i;

  // At the optimum the mean log-likelihood's gradient, computed here by
  // autograd rather than the fit's own formula, is the ridge's pull alone.
  torch::Tensor w = torch::tensor(fitted.coefficients, torch::kFloat64).requires_grad_(true);
  const torch::Tensor loss = torch::binary_cross_entropy_with_logits(x.matmul(w), y);
  loss.backward();
  EXPECT_LT(w.grad().abs().max().item<double>(), 1e-7);
}

TEST(ConfidenceModelTest, RidgeBoundsAFeatureThatSeparatesTheClasses) {
  torch::Tensor x = RandomFeatures(2000, 4);
  const torch::Tensor y = (x.select(1, 3) > 0).to(torch::kFloat64);  // feature 3 decides alone
  const ConfidenceModel fitted = FitConfidenceModel(x, y, /*ridge=*/1e-3);
  EXPECT_GT(fitted.coefficients[3], 5.0);
  EXPECT_TRUE(std::isfinite(fitted.coefficients[3]));
  EXPECT_THROW(FitConfidenceModel(x, torch::zeros({2000}), 1e-3), std::invalid_argument);
  EXPECT_THROW(FitConfidenceModel(x, torch::zeros({5}), 1e-3), std::invalid_argument);
}

TEST(ConfidenceModelTest, PredictionIsTheSigmoidOfTheWeightedFeatures) {
  ConfidenceModel model;
  model.coefficients = {0.1, -0.2, 0.3, -0.4, 0.5, -0.6, 0.7, -0.8};
  const torch::Tensor features = torch::randn({2, kConfidenceFeatures, 3, 4});
  const torch::Tensor predicted = PredictConfidence(model, features);
  ASSERT_EQ(predicted.sizes(), (std::vector<int64_t>{2, 1, 3, 4}));
  double z = 0;
  for (int64_t f = 0; f < kConfidenceFeatures; ++f) {
    z += model.coefficients[static_cast<size_t>(f)] * features[1][f][2][3].item<double>();
  }
  EXPECT_NEAR(predicted[1][0][2][3].item<double>(), 1 / (1 + std::exp(-z)), 1e-6);
  EXPECT_THROW(PredictConfidence(ConfidenceModel{}, features), std::invalid_argument);
  EXPECT_THROW(PredictConfidence(model, features.narrow(1, 0, 7)), std::invalid_argument);
}

TEST(ConfidenceModelTest, FeaturesReadTheRefinementPerPixelAndTheMapIsZeroWithoutSignalNear) {
  PhotometricRefinement r;
  // Pixel 0: refined, output NCC 0.8, best 0.8; pixel 1: kept, 0.5 at the
  // network's depth while 0.9 was found elsewhere; pixel 2: none computed.
  r.output_score = torch::tensor({0.8f, 0.5f, -1.0f}).view({1, 1, 1, 3});
  r.score = torch::tensor({0.8f, 0.9f, -1.0f}).view({1, 1, 1, 3});
  r.refined = torch::tensor({true, false, false}).view({1, 1, 1, 3});
  r.texture = torch::tensor({0.1f, 0.02f, 0.0f}).view({1, 1, 1, 3});
  r.signal_support = torch::tensor({1.0f, 0.25f, 0.0f}).view({1, 1, 1, 3});
  const torch::Tensor confidence = torch::tensor({0.9f, 0.6f, 0.99f}).view({1, 1, 1, 3});
  const torch::Tensor f = ConfidenceFeatures(confidence, r);
  ASSERT_EQ(f.sizes(), (std::vector<int64_t>{1, kConfidenceFeatures, 1, 3}));
  const auto at = [&](int64_t feature, int64_t pixel) { return f[0][feature][0][pixel].item<double>(); };
  const double expected[kConfidenceFeatures][3] = {
      {1, 1, 1},
      {0.9, 0.6, 0.99},
      {0.8, 0.5, 0},
      {1, 1, 0},
      {0, 0.4, 0},
      {1, 0, 0},
      {std::log(0.1), std::log(0.02), std::log(1e-3)},
      {0.64, 0.25, 0}};
  for (int64_t feature = 0; feature < kConfidenceFeatures; ++feature) {
    for (int64_t pixel = 0; pixel < 3; ++pixel) {
      EXPECT_NEAR(at(feature, pixel), expected[feature][pixel], 1e-6) << feature << " " << pixel;
    }
  }
  // The map: the model's prediction, 0 where no image signal is near.
  ConfidenceModel model;
  model.coefficients = {0.2, 1, 1, 0, 0, 0, 0, 0};
  const torch::Tensor map = ConfidenceMap(model, confidence, r);
  EXPECT_NEAR(map[0][0][0][0].item<double>(), 1 / (1 + std::exp(-(0.2 + 0.9 + 0.8))), 1e-6);
  EXPECT_NEAR(map[0][0][0][1].item<double>(), 1 / (1 + std::exp(-(0.2 + 0.6 + 0.5))), 1e-6);
  EXPECT_EQ(map[0][0][0][2].item<double>(), 0.0);
}

TEST(ConfidenceModelTest, TextRoundTripsExactlyAndRejectsBadInput) {
  ConfidenceModel model;
  model.coefficients = {1.0 / 3, -2e-17, 5, 0, -0.125, 1e300, 7.25, -2e-300};
  EXPECT_EQ(ConfidenceModel::FromText(model.ToText()).coefficients, model.coefficients);
  EXPECT_THROW(ConfidenceModel::FromText("1 2 3"), std::invalid_argument);
  EXPECT_THROW(ConfidenceModel::FromText("1 2 3 4 5 6 7 x"), std::invalid_argument);
  EXPECT_THROW(ConfidenceModel::FromText("1 2 3 4 5 6 7 nan"), std::invalid_argument);
  EXPECT_THROW(ConfidenceModel::FromText("1 2 3 4 5 6 7 8 9"), std::invalid_argument);
}

TEST(ConfidenceModelTest, WeightsFileCarriesTheModelAndKeepsEverythingElse) {
  testing::TempDir tmp;
  const std::string plain = (tmp.path() / "plain.safetensors").string();
  const std::string with = (tmp.path() / "with.safetensors").string();
  const NamedTensors tensors{{"a", torch::arange(6, torch::kFloat32).view({2, 3})}, {"b", torch::ones({4})}};
  SaveSafetensors(plain, tensors, {{"config", "small_v2"}});
  EXPECT_TRUE(ReadConfidenceModel(plain).empty());

  ConfidenceModel model;
  model.coefficients = {0.5, 1, 2, 3, 4, 5, 6, 7};
  WriteConfidenceModel(plain, with, model);
  EXPECT_EQ(ReadConfidenceModel(with).coefficients, model.coefficients);
  const SafetensorsFile file = LoadSafetensors(with);
  EXPECT_EQ(file.metadata.at("config"), "small_v2");
  ASSERT_EQ(file.tensors.size(), 2u);
  EXPECT_TRUE(torch::equal(file.tensors[0].second, tensors[0].second));
  EXPECT_TRUE(torch::equal(file.tensors[1].second, tensors[1].second));

  SaveSafetensors(with, tensors, {{kConfidenceModelKey, "1 2"}});
  EXPECT_THROW(ReadConfidenceModel(with), std::runtime_error);
}

}  // namespace
}  // namespace dispmvs::model
