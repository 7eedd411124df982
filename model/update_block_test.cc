#include "model/update_block.h"

#include <cmath>
#include <stdexcept>

#include <gtest/gtest.h>

namespace dispmvs::model {
namespace {

double Sigmoid(double x) { return 1.0 / (1.0 + std::exp(-x)); }

TEST(UpdateBlockTest, OutputShapes) {
  torch::manual_seed(1);
  UpdateBlock block(/*correlation_channels=*/10, /*hidden=*/8, /*context=*/6, /*factor=*/4);
  const int64_t batch = 3, h = 5, w = 7;
  const UpdateBlockOutput out =
      block->forward(torch::randn({batch, 8, h, w}).tanh(), torch::randn({batch, 6, h, w}).relu(),
                     torch::randn({batch, 10, h, w}), torch::randn({batch, 1, h, w}));
  EXPECT_EQ(out.hidden.sizes(), torch::IntArrayRef({batch, 8, h, w}));
  EXPECT_EQ(out.delta_eflow.sizes(), torch::IntArrayRef({batch, 1, h, w}));
  EXPECT_EQ(out.weight_logit.sizes(), torch::IntArrayRef({batch, 1, h, w}));
  EXPECT_EQ(block->MaskLogits(out.hidden).sizes(), torch::IntArrayRef({batch, 9 * 16, h, w}));
  // The new hidden state is a convex mix of the old one (in (-1,1)) and tanh.
  EXPECT_TRUE((out.hidden.abs() < 1).all().item<bool>());
}

// With zero kernels the gates are constants set by the biases, so two GRU
// steps can be computed by hand: h1 = (1-z1) h + z1 tanh(q1),
// h2 = (1-z2) h1 + z2 tanh(q2).
TEST(UpdateBlockTest, SepConvGruFollowsTheGruEquations) {
  SepConvGru gru(/*hidden=*/2, /*input=*/3);
  torch::NoGradGuard no_grad;
  const double bz1 = 0.3, br1 = -0.2, bq1 = 0.7, bz2 = -1.1, br2 = 0.4, bq2 = -0.5;
  for (auto& p : gru->named_parameters()) {
    const std::string& name = p.key();
    if (name.find("weight") != std::string::npos) {
      p.value().zero_();
      continue;
    }
    const double v = name == "convz1.bias" ? bz1 : name == "convr1.bias" ? br1
                   : name == "convq1.bias" ? bq1 : name == "convz2.bias" ? bz2
                   : name == "convr2.bias" ? br2 : bq2;
    p.value().fill_(v);
  }
  const torch::Tensor hidden = torch::full({1, 2, 3, 3}, 0.25f);
  const torch::Tensor out = gru->forward(hidden, torch::randn({1, 3, 3, 3}));
  const double z1 = Sigmoid(bz1), z2 = Sigmoid(bz2);
  const double h1 = (1 - z1) * 0.25 + z1 * std::tanh(bq1);
  const double h2 = (1 - z2) * h1 + z2 * std::tanh(bq2);
  EXPECT_TRUE(torch::allclose(out, torch::full_like(out, h2), 1e-6, 1e-6));
}

// 1x5 then 5x1. Within a pass the candidate conv reads the reset gate, itself
// a conv, so one pass reaches 2 + 2 pixels along its axis: a change at one
// pixel spreads along its row first, then down the columns, reaching exactly
// its 9x9 neighbourhood (a 5x5 kernel GRU would reach 17x17 in two steps).
TEST(UpdateBlockTest, SepConvGruIsSeparable) {
  SepConvGru gru(4, 2);
  for (const auto& p : gru->named_parameters()) {
    if (p.key().find("weight") == std::string::npos) continue;
    const bool horizontal = p.key().find('1') != std::string::npos;
    EXPECT_EQ(p.value().size(2), horizontal ? 1 : 5) << p.key();
    EXPECT_EQ(p.value().size(3), horizontal ? 5 : 1) << p.key();
  }

  torch::manual_seed(3);
  torch::NoGradGuard no_grad;
  const torch::Tensor hidden = torch::randn({1, 4, 13, 13}).tanh();
  torch::Tensor input = torch::randn({1, 2, 13, 13});
  const torch::Tensor before = gru->forward(hidden, input);
  input.index_put_({0, torch::indexing::Slice(), 6, 6}, 10.0);
  const torch::Tensor changed =
      ((gru->forward(hidden, input) - before).abs().amax(1) > 1e-7).squeeze(0);
  for (int64_t y = 0; y < 13; ++y)
    for (int64_t x = 0; x < 13; ++x) {
      if (std::abs(y - 6) > 4 || std::abs(x - 6) > 4) {
        EXPECT_FALSE(changed[y][x].item<bool>()) << y << "," << x;
      }
    }
  EXPECT_TRUE(changed[2][2].item<bool>());  // corners of the 9x9 window
  EXPECT_TRUE(changed[10][10].item<bool>());
}

TEST(UpdateBlockTest, GradientReachesEveryParameter) {
  torch::manual_seed(5);
  UpdateBlock block(6, 4, 3, 2);
  const UpdateBlockOutput out =
      block->forward(torch::randn({2, 4, 6, 6}).tanh(), torch::randn({2, 3, 6, 6}).relu(),
                     torch::randn({2, 6, 6, 6}), torch::randn({2, 1, 6, 6}));
  (out.delta_eflow.square().sum() + out.weight_logit.square().sum() +
   block->MaskLogits(out.hidden).square().sum())
      .backward();
  for (const auto& p : block->named_parameters()) {
    ASSERT_TRUE(p.value().grad().defined()) << p.key();
    EXPECT_GT(p.value().grad().abs().sum().item<float>(), 0.0f) << p.key();
  }
}

// Chunks of pairs give every pair its own inputs and outputs: each pair's
// output equals the one-call output, whatever the chunk size (7 pairs in
// chunks of 1, 2, 3 and all).
TEST(UpdateBlockTest, UpdateInChunksMatchesOneCall) {
  torch::manual_seed(4);
  UpdateBlock block(/*correlation_channels=*/10, /*hidden=*/8, /*context=*/6, /*factor=*/4);
  torch::NoGradGuard no_grad;
  const int64_t pairs = 7, h = 6, w = 5;
  const torch::Tensor hidden = torch::randn({pairs, 8, h, w}).tanh();
  const torch::Tensor context = torch::randn({pairs, 6, h, w}).relu();
  const torch::Tensor cost = torch::randn({pairs, 10, h, w});
  const torch::Tensor eflow = torch::randn({pairs, 1, h, w});
  const UpdateBlockOutput whole = block->forward(hidden, context, cost, eflow);
  for (const int64_t max_pixels : {int64_t{1}, 2 * h * w, 3 * h * w + 1, 100 * h * w}) {
    const UpdateBlockOutput chunked = UpdateInChunks(block, hidden, context, cost, eflow, max_pixels);
    EXPECT_TRUE(torch::allclose(chunked.hidden, whole.hidden, 1e-5, 1e-6)) << max_pixels;
    EXPECT_TRUE(torch::allclose(chunked.delta_eflow, whole.delta_eflow, 1e-5, 1e-6)) << max_pixels;
    EXPECT_TRUE(torch::allclose(chunked.weight_logit, whole.weight_logit, 1e-5, 1e-6)) << max_pixels;
  }
  EXPECT_THROW(UpdateInChunks(block, torch::Tensor(), context, cost, eflow, 1), std::invalid_argument);
}

TEST(UpdateBlockTest, RejectsBadInput) {
  EXPECT_THROW(UpdateBlock(0, 4, 3, 4), std::invalid_argument);
  EXPECT_THROW(UpdateBlock(5, 4, 3, 0), std::invalid_argument);
  UpdateBlock block(5, 4, 3, 4);
  const torch::Tensor h = torch::zeros({1, 4, 3, 3});
  EXPECT_THROW(block->forward(h, torch::zeros({1, 2, 3, 3}), torch::zeros({1, 5, 3, 3}),
                              torch::zeros({1, 1, 3, 3})),
               std::invalid_argument);
  EXPECT_THROW(block->forward(h, torch::zeros({1, 3, 3, 3}), torch::zeros({1, 5, 3, 3}),
                              torch::zeros({1, 1, 3, 4})),
               std::invalid_argument);
  EXPECT_THROW(block->MaskLogits(torch::zeros({1, 5, 3, 3})), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
