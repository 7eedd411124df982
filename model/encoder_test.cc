#include "model/encoder.h"

#include <gtest/gtest.h>

#include <stdexcept>

namespace dispmvs::model {
namespace {

// Every parameter received a non-zero gradient from a random projection of
// both outputs.
void ExpectGradientsEverywhere(torch::nn::Module& module, const FeaturePyramid& out) {
  const torch::Tensor loss = (out.coarse * torch::randn_like(out.coarse)).sum() +
                             (out.fine * torch::randn_like(out.fine)).sum();
  loss.backward();
  for (const auto& item : module.named_parameters()) {
    ASSERT_TRUE(item.value().grad().defined()) << item.key();
    EXPECT_GT(item.value().grad().abs().sum().item<double>(), 0.0) << item.key();
  }
}

struct Size {
  int64_t height, width;
};

TEST(EncoderTest, OutputShapes) {
  torch::manual_seed(20);
  for (const ModelConfig& config : {ModelConfig::Small(), ModelConfig::Paper()}) {
    MatchingEncoder matching(config);
    ContextEncoder context(config);
    torch::NoGradGuard no_grad;
    for (const Size size : {Size{32, 48}, Size{64, 32}, Size{48, 80}}) {
      const torch::Tensor images = torch::rand({2, 3, size.height, size.width});
      const FeaturePyramid m = matching->forward(images);
      EXPECT_EQ(m.coarse.sizes(), (std::vector<int64_t>{2, config.match_coarse_channels,
                                                        size.height / 16, size.width / 16}))
          << config.name;
      EXPECT_EQ(m.fine.sizes(), (std::vector<int64_t>{2, config.match_fine_channels,
                                                      size.height / 4, size.width / 4}))
          << config.name;
      const FeaturePyramid c = context->forward(images);
      EXPECT_EQ(c.coarse.sizes(),
                (std::vector<int64_t>{2, config.hidden_coarse + config.context_input_coarse,
                                      size.height / 16, size.width / 16}))
          << config.name;
      EXPECT_EQ(c.fine.sizes(),
                (std::vector<int64_t>{2, config.hidden_fine + config.context_input_fine,
                                      size.height / 4, size.width / 4}))
          << config.name;
      EXPECT_TRUE(torch::isfinite(m.coarse).all().item<bool>());
      EXPECT_TRUE(torch::isfinite(c.fine).all().item<bool>());
    }
  }
}

TEST(EncoderTest, GradientsReachEveryParameter) {
  torch::manual_seed(21);
  const ModelConfig config = ModelConfig::Small();
  const torch::Tensor images = torch::rand({2, 3, 32, 48});
  MatchingEncoder matching(config);
  ExpectGradientsEverywhere(*matching, matching->forward(images));
  ContextEncoder context(config);
  ExpectGradientsEverywhere(*context, context->forward(images));
}

TEST(EncoderTest, ContextDecoderUsesDeformableConvOnlyWhenConfigured) {
  const auto has_offset_conv = [](const torch::nn::Module& module) {
    for (const auto& item : module.named_parameters()) {
      if (item.key().find("offset_conv") != std::string::npos) return true;
    }
    return false;
  };
  ModelConfig config = ModelConfig::Small();
  EXPECT_TRUE(has_offset_conv(*ContextEncoder(config)));
  EXPECT_FALSE(has_offset_conv(*MatchingEncoder(config)));
  config.deformable_context_decoder = false;
  ContextEncoder plain(config);
  EXPECT_FALSE(has_offset_conv(*plain));
  torch::NoGradGuard no_grad;
  EXPECT_EQ(plain->forward(torch::rand({1, 3, 32, 32})).fine.size(1),
            config.hidden_fine + config.context_input_fine);
}

TEST(EncoderTest, Deterministic) {
  const ModelConfig config = ModelConfig::Small();
  const torch::Tensor images = torch::rand({1, 3, 48, 64});
  torch::manual_seed(22);
  MatchingEncoder a(config);
  ContextEncoder ca(config);
  torch::manual_seed(22);
  MatchingEncoder b(config);
  ContextEncoder cb(config);
  torch::NoGradGuard no_grad;
  const FeaturePyramid first = a->forward(images);
  const FeaturePyramid again = a->forward(images);
  const FeaturePyramid twin = b->forward(images);
  EXPECT_TRUE(torch::equal(first.coarse, again.coarse));
  EXPECT_TRUE(torch::equal(first.fine, again.fine));
  EXPECT_TRUE(torch::equal(first.coarse, twin.coarse));
  EXPECT_TRUE(torch::equal(first.fine, twin.fine));
  EXPECT_TRUE(torch::equal(ca->forward(images).fine, cb->forward(images).fine));
}

TEST(EncoderTest, RejectsBadImagesAndConfigs) {
  MatchingEncoder matching(ModelConfig::Small());
  EXPECT_THROW(matching->forward(torch::rand({1, 1, 32, 32})), std::invalid_argument);
  EXPECT_THROW(matching->forward(torch::rand({3, 32, 32})), std::invalid_argument);
  ModelConfig bad = ModelConfig::Small();
  bad.encoder_base_channels = 0;
  EXPECT_THROW(MatchingEncoder{bad}, std::invalid_argument);
  EXPECT_THROW(ContextEncoder{bad}, std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
