#include "model/config.h"

#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

namespace dispmvs::model {
namespace {

// EXPECT_THROW plus a check that the message names `needle`.
template <class F>
void ExpectInvalid(F f, const std::string& needle) {
  try {
    f();
    ADD_FAILURE() << "no exception, expected one naming " << needle;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(ModelConfigTest, PaperMatchesTheRelease) {
  const ModelConfig c = ModelConfig::Paper();
  EXPECT_EQ(c.match_coarse_channels, 128);
  EXPECT_EQ(c.match_fine_channels, 96);
  // Context 256 / 192 channels, split evenly into hidden state and input.
  EXPECT_EQ(c.hidden_coarse + c.context_input_coarse, 256);
  EXPECT_EQ(c.hidden_fine + c.context_input_fine, 192);
  EXPECT_EQ(c.coarse_levels, 4);
  EXPECT_EQ(c.coarse_samples, 9);
  EXPECT_EQ(c.fine_levels, 2);
  EXPECT_EQ(c.fine_samples, 5);
  EXPECT_EQ(c.coarse_iterations, 8);
  EXPECT_EQ(c.fine_iterations, 2);
  EXPECT_TRUE(c.deformable_context_decoder);
  EXPECT_NO_THROW(c.Check());
}

TEST(ModelConfigTest, SmallIsNarrowerButSearchesTheSame) {
  const ModelConfig paper = ModelConfig::Paper();
  const ModelConfig small = ModelConfig::Small();
  EXPECT_NO_THROW(small.Check());
  EXPECT_NE(small.name, paper.name);
  EXPECT_LT(small.match_coarse_channels, paper.match_coarse_channels);
  EXPECT_LT(small.match_fine_channels, paper.match_fine_channels);
  EXPECT_LT(small.encoder_base_channels, paper.encoder_base_channels);
  EXPECT_LT(small.hidden_coarse, paper.hidden_coarse);
  EXPECT_LT(small.hidden_fine, paper.hidden_fine);
  EXPECT_EQ(small.coarse_levels, paper.coarse_levels);
  EXPECT_EQ(small.coarse_samples, paper.coarse_samples);
  EXPECT_EQ(small.fine_levels, paper.fine_levels);
  EXPECT_EQ(small.fine_samples, paper.fine_samples);
  EXPECT_EQ(small.coarse_iterations, paper.coarse_iterations);
  EXPECT_EQ(small.fine_iterations, paper.fine_iterations);
}

// Model v2 at the small size: the small network with the match start and half
// the paper's coarse iterations, everything else as Small().
TEST(ModelConfigTest, SmallV2StartsFromTheMatchWithFourCoarseIterations) {
  const ModelConfig small = ModelConfig::Small();
  const ModelConfig v2 = ModelConfig::SmallV2();
  EXPECT_NO_THROW(v2.Check());
  EXPECT_EQ(v2.init, ModelConfig::Init::kMatch);
  EXPECT_EQ(small.init, ModelConfig::Init::kRandom);
  EXPECT_EQ(v2.coarse_iterations, 4);
  EXPECT_EQ(v2.fine_iterations, small.fine_iterations);
  ModelConfig same = v2;
  same.name = small.name;
  same.init = small.init;
  same.coarse_iterations = small.coarse_iterations;
  EXPECT_EQ(same.ToMetadata(), small.ToMetadata());
}

TEST(ModelConfigTest, ByNameGivesTheNamedConfigurations) {
  // Every name gives the factory's configuration, field for field (the
  // benchmark once built small_v2 by hand and ran 8 coarse iterations).
  EXPECT_EQ(ModelConfig::ByName("paper").ToMetadata(), ModelConfig::Paper().ToMetadata());
  EXPECT_EQ(ModelConfig::ByName("small").ToMetadata(), ModelConfig::Small().ToMetadata());
  EXPECT_EQ(ModelConfig::ByName("small_v2").ToMetadata(), ModelConfig::SmallV2().ToMetadata());
  EXPECT_EQ(ModelConfig::ByName("small_v2").coarse_iterations, 4);
  const ModelConfig paper_v2 = ModelConfig::ByName("paper_v2");
  EXPECT_EQ(paper_v2.name, "paper_v2");
  EXPECT_EQ(paper_v2.init, ModelConfig::Init::kMatch);
  ModelConfig as_paper = paper_v2;
  as_paper.name = "paper";
  as_paper.init = ModelConfig::Init::kRandom;
  EXPECT_EQ(as_paper.ToMetadata(), ModelConfig::Paper().ToMetadata());
  ExpectInvalid([] { ModelConfig::ByName("Small"); }, "got 'Small'");
  ExpectInvalid([] { ModelConfig::ByName(""); }, "small_v2");
}

TEST(ModelConfigTest, CheckNamesTheBadField) {
  ModelConfig c;
  c.match_fine_channels = 0;
  ExpectInvalid([&] { c.Check(); }, "match_fine_channels");

  c = ModelConfig{};
  c.coarse_levels = 0;
  ExpectInvalid([&] { c.Check(); }, "coarse_levels");

  c = ModelConfig{};
  c.fine_samples = 4;  // even
  ExpectInvalid([&] { c.Check(); }, "fine_samples");

  c = ModelConfig{};
  c.coarse_samples = -3;
  ExpectInvalid([&] { c.Check(); }, "coarse_samples");

  c = ModelConfig{};
  c.fine_iterations = 0;
  ExpectInvalid([&] { c.Check(); }, "fine_iterations");

  c = ModelConfig{};
  c.hidden_coarse = int64_t{1} << 40;  // would build an absurdly large module
  ExpectInvalid([&] { c.Check(); }, "hidden_coarse");

  c = ModelConfig{};
  c.name.clear();
  ExpectInvalid([&] { c.Check(); }, "name");
}

TEST(ModelConfigTest, MetadataRoundTrip) {
  ModelConfig c = ModelConfig::Small();
  c.name = "custom \"quoted\" name";
  c.coarse_iterations = 11;
  c.fine_samples = 7;
  c.deformable_context_decoder = false;
  const auto metadata = c.ToMetadata();
  EXPECT_EQ(metadata.at("coarse_iterations"), "11");
  EXPECT_EQ(metadata.at("deformable_context_decoder"), "false");
  const ModelConfig back = ModelConfig::FromMetadata(metadata);
  EXPECT_EQ(back.name, c.name);
  EXPECT_EQ(back.ToMetadata(), metadata);
  EXPECT_FALSE(back.deformable_context_decoder);
  EXPECT_EQ(back.fine_samples, 7);

  const ModelConfig paper = ModelConfig::FromMetadata(ModelConfig::Paper().ToMetadata());
  EXPECT_EQ(paper.ToMetadata(), ModelConfig::Paper().ToMetadata());
}

TEST(ModelConfigTest, FromMetadataRejectsMissingAndMalformedKeys) {
  const auto good = ModelConfig::Paper().ToMetadata();

  auto missing = good;
  missing.erase("fine_levels");
  ExpectInvalid([&] { ModelConfig::FromMetadata(missing); }, "fine_levels");

  for (const std::string bad : {"", "12a", " 12", "1.5", "0x10", "-", "99999999999999999999999"}) {
    auto malformed = good;
    malformed["hidden_fine"] = bad;
    ExpectInvalid([&] { ModelConfig::FromMetadata(malformed); }, "hidden_fine");
  }

  auto bad_bool = good;
  bad_bool["deformable_context_decoder"] = "1";
  ExpectInvalid([&] { ModelConfig::FromMetadata(bad_bool); }, "deformable_context_decoder");

  // Well-formed but invalid values are caught by Check().
  auto even = good;
  even["coarse_samples"] = "8";
  ExpectInvalid([&] { ModelConfig::FromMetadata(even); }, "coarse_samples");

  // Unrelated keys (e.g. training notes) are ignored.
  auto extra = good;
  extra["trained_on"] = "dtu";
  EXPECT_NO_THROW(ModelConfig::FromMetadata(extra));
}

}  // namespace
}  // namespace dispmvs::model
