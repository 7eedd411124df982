#include "model/update_block.h"

#include <cmath>
#include <map>
#include <string>
#include <stdexcept>

#include <gtest/gtest.h>

namespace dispmvs::model {
namespace {

double Sigmoid(double x) { return 1.0 / (1.0 + std::exp(-x)); }

// The GRU as the paper writes it, independently of SepConvGru's split: each
// gate one convolution over the whole concatenation [hidden, motion,
// context], with the module's own parameters. context is per pair.
torch::Tensor TextbookGru(SepConvGru& gru, torch::Tensor hidden, const torch::Tensor& motion,
                          const torch::Tensor& context) {
  std::map<std::string, torch::Tensor> p;
  for (const auto& item : gru->named_parameters()) p[item.key()] = item.value();
  const auto conv = [&](const std::string& name, const torch::Tensor& x) {
    const torch::Tensor& weight = p.at(name + ".weight");
    return torch::conv2d(x, weight, p.at(name + ".bias"), 1,
                         {weight.size(2) / 2, weight.size(3) / 2});
  };
  for (const std::string pass : {"1", "2"}) {
    const torch::Tensor hx = torch::cat({hidden, motion, context}, 1);
    const torch::Tensor z = torch::sigmoid(conv("convz" + pass, hx));
    const torch::Tensor r = torch::sigmoid(conv("convr" + pass, hx));
    const torch::Tensor q =
        torch::tanh(conv("convq" + pass, torch::cat({r * hidden, motion, context}, 1)));
    hidden = (1 - z) * hidden + z * q;
  }
  return hidden;
}

// Per-pair copies of per-reference maps [R, ...] -> [R*pairs, ...].
torch::Tensor PerPair(const torch::Tensor& x, int64_t pairs) {
  return x.repeat_interleave(pairs, 0);
}

TEST(UpdateBlockTest, OutputShapes) {
  torch::manual_seed(1);
  UpdateBlock block(/*correlation_channels=*/10, /*hidden=*/8, /*context=*/6, /*factor=*/4);
  const int64_t batch = 3, h = 5, w = 7;
  const UpdateBlockOutput out =
      block->forward(torch::randn({batch, 8, h, w}).tanh(),
                     block->ContextTerms(torch::randn({1, 6, h, w}).relu()),
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
  SepConvGru gru(/*hidden=*/2, /*motion=*/2, /*context=*/1);
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
  const torch::Tensor out = gru->forward(hidden, torch::randn({1, 2, 3, 3}),
                                        gru->ContextTerms(torch::randn({1, 1, 3, 3})));
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
  SepConvGru gru(/*hidden=*/4, /*motion=*/1, /*context=*/1);
  for (const auto& p : gru->named_parameters()) {
    if (p.key().find("weight") == std::string::npos) continue;
    const bool horizontal = p.key().find('1') != std::string::npos;
    EXPECT_EQ(p.value().size(2), horizontal ? 1 : 5) << p.key();
    EXPECT_EQ(p.value().size(3), horizontal ? 5 : 1) << p.key();
  }

  torch::manual_seed(3);
  torch::NoGradGuard no_grad;
  const torch::Tensor hidden = torch::randn({1, 4, 13, 13}).tanh();
  const torch::Tensor motion = torch::randn({1, 1, 13, 13});
  const torch::Tensor context = torch::randn({1, 1, 13, 13});
  const torch::Tensor before = gru->forward(hidden, motion, gru->ContextTerms(context));
  // A change in the motion input, then one in the context (which goes through
  // the precomputed terms), each at the centre.
  for (const bool in_context : {false, true}) {
    torch::Tensor m = motion.clone(), c = context.clone();
    (in_context ? c : m).index_put_({0, 0, 6, 6}, 10.0);
    const torch::Tensor changed =
        ((gru->forward(hidden, m, gru->ContextTerms(c)) - before).abs().amax(1) > 1e-7)
            .squeeze(0);
    for (int64_t y = 0; y < 13; ++y)
      for (int64_t x = 0; x < 13; ++x) {
        if (std::abs(y - 6) > 4 || std::abs(x - 6) > 4) {
          EXPECT_FALSE(changed[y][x].item<bool>()) << y << "," << x << " " << in_context;
        }
      }
    EXPECT_TRUE(changed[2][2].item<bool>()) << in_context;  // corners of the 9x9 window
    EXPECT_TRUE(changed[10][10].item<bool>()) << in_context;
  }
}

// The split (context's share once per reference, added to each pair's
// convolution of [hidden, motion]) is the textbook GRU over the whole
// concatenation, for 2 references of 3 pairs each with different contexts:
// a pair that read another reference's terms would be far off.
TEST(UpdateBlockTest, ContextTermsGiveTheTextbookGru) {
  torch::manual_seed(8);
  SepConvGru gru(/*hidden=*/6, /*motion=*/5, /*context=*/4);
  torch::NoGradGuard no_grad;
  for (auto& p : gru->parameters()) p.uniform_(-0.5, 0.5);  // biases matter too
  const int64_t references = 2, pairs = 3, h = 7, w = 9;
  const torch::Tensor hidden = torch::randn({references * pairs, 6, h, w}).tanh();
  const torch::Tensor motion = torch::randn({references * pairs, 5, h, w});
  const torch::Tensor context = torch::randn({references, 4, h, w}).relu();
  const torch::Tensor split = gru->forward(hidden, motion, gru->ContextTerms(context));
  const torch::Tensor textbook = TextbookGru(gru, hidden, motion, PerPair(context, pairs));
  EXPECT_LT((split - textbook).abs().max().item<float>(), 1e-5f);
  // The terms really carry each reference's context.
  const torch::Tensor swapped = TextbookGru(gru, hidden, motion, PerPair(context.flip(0), pairs));
  EXPECT_GT((split - swapped).abs().max().item<float>(), 1e-2f);

  EXPECT_THROW(gru->forward(hidden, motion, gru->ContextTerms(context.narrow(0, 0, 1)).repeat(
                                                {4, 1, 1, 1})),
               std::invalid_argument);  // 6 pairs over 4 references
  EXPECT_THROW(gru->ContextTerms(torch::zeros({1, 3, h, w})), std::invalid_argument);
  EXPECT_THROW(gru->forward(hidden, motion.narrow(1, 0, 4), gru->ContextTerms(context)),
               std::invalid_argument);
}

// Inference (autograd off) runs the GRU through ForwardInPlace, training
// through forward(): the same values, in fp32 to float rounding, and in bf16
// to what a gate input rounded the other way can move (2^-8 of an input of
// magnitude < 1 through weights of at most 0.3: below 2e-3; measured 2e-7).
TEST(UpdateBlockTest, InferencePathMatchesTrainingPath) {
  torch::manual_seed(9);
  UpdateBlock block(/*correlation_channels=*/10, /*hidden=*/8, /*context=*/6, /*factor=*/4);
  for (auto& p : block->parameters()) {
    torch::NoGradGuard no_grad;
    p.uniform_(-0.3, 0.3);
  }
  const int64_t references = 2, pairs = 6, h = 6, w = 7;
  const torch::Tensor hidden = torch::randn({pairs, 8, h, w}).tanh();
  const torch::Tensor context = torch::randn({references, 6, h, w}).relu();
  const torch::Tensor cost = torch::randn({pairs, 10, h, w});
  const torch::Tensor eflow = torch::randn({pairs, 1, h, w});
  for (const Precision precision : {Precision::kFloat32, Precision::kBFloat16}) {
    block->set_precision(precision);
    const UpdateBlockOutput training =
        block->forward(hidden, block->ContextTerms(context), cost, eflow);
    torch::NoGradGuard no_grad;
    const UpdateBlockOutput inference =
        block->forward(hidden, block->ContextTerms(context), cost, eflow);
    const float tolerance = precision == Precision::kFloat32 ? 1e-5f : 2e-3f;
    const char* name = PrecisionName(precision);
    EXPECT_LT((inference.hidden - training.hidden).abs().max().item<float>(), tolerance) << name;
    EXPECT_LT((inference.delta_eflow - training.delta_eflow).abs().max().item<float>(), tolerance)
        << name;
    EXPECT_LT((inference.weight_logit - training.weight_logit).abs().max().item<float>(),
              tolerance)
        << name;
    EXPECT_GT((inference.hidden - hidden).abs().max().item<float>(), 0.05f) << name;  // it moved
  }
  // Where the fused CPU passes do not apply (here a float64 block; on a GPU
  // every map), ForwardInPlace's ATen ops serve: the same values too.
  {
    UpdateBlock wide(/*correlation_channels=*/10, /*hidden=*/8, /*context=*/6, /*factor=*/4);
    wide->to(torch::kFloat64);
    const auto d = [](const torch::Tensor& t) { return t.to(torch::kFloat64); };
    const UpdateBlockOutput training =
        wide->forward(d(hidden), wide->ContextTerms(d(context)), d(cost), d(eflow));
    torch::NoGradGuard no_grad;
    const UpdateBlockOutput inference =
        wide->forward(d(hidden), wide->ContextTerms(d(context)), d(cost), d(eflow));
    EXPECT_LT((inference.hidden - training.hidden).abs().max().item<double>(), 1e-12);
    EXPECT_LT((inference.delta_eflow - training.delta_eflow).abs().max().item<double>(), 1e-12);
  }
  // The in-place path refuses autograd and a buffer of the wrong shape.
  SepConvGru gru(/*hidden=*/4, /*motion=*/4, /*context=*/3);
  torch::Tensor buffer = torch::zeros({2, 8, h, w});
  const torch::Tensor terms = gru->ContextTerms(torch::zeros({1, 3, h, w}));
  EXPECT_THROW(gru->ForwardInPlace(torch::zeros({2, 4, h, w}), buffer, terms), std::logic_error);
  torch::NoGradGuard no_grad;
  torch::Tensor narrow_buffer = torch::zeros({2, 7, h, w});
  EXPECT_THROW(gru->ForwardInPlace(torch::zeros({2, 4, h, w}), narrow_buffer, terms),
               std::invalid_argument);
  EXPECT_NO_THROW(gru->ForwardInPlace(torch::zeros({2, 4, h, w}), buffer, terms));
}

TEST(UpdateBlockTest, GradientReachesEveryParameter) {
  torch::manual_seed(5);
  UpdateBlock block(6, 4, 3, 2);
  const UpdateBlockOutput out =
      block->forward(torch::randn({2, 4, 6, 6}).tanh(),
                     block->ContextTerms(torch::randn({2, 3, 6, 6}).relu()),
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
// output equals the one-call output, whatever the chunk size (2 references
// of 4 pairs in chunks of 1, 2, 3 and all; chunks never straddle references).
TEST(UpdateBlockTest, UpdateInChunksMatchesOneCall) {
  torch::manual_seed(4);
  UpdateBlock block(/*correlation_channels=*/10, /*hidden=*/8, /*context=*/6, /*factor=*/4);
  torch::NoGradGuard no_grad;
  const int64_t references = 2, pairs = 8, h = 6, w = 5;
  const torch::Tensor hidden = torch::randn({pairs, 8, h, w}).tanh();
  const torch::Tensor terms = block->ContextTerms(torch::randn({references, 6, h, w}).relu());
  const torch::Tensor cost = torch::randn({pairs, 10, h, w});
  const torch::Tensor eflow = torch::randn({pairs, 1, h, w});
  const UpdateBlockOutput whole = block->forward(hidden, terms, cost, eflow);
  for (const int64_t max_pixels : {int64_t{1}, 2 * h * w, 3 * h * w + 1, 100 * h * w}) {
    const UpdateBlockOutput chunked = UpdateInChunks(block, hidden, terms, cost, eflow, max_pixels);
    EXPECT_TRUE(torch::allclose(chunked.hidden, whole.hidden, 1e-5, 1e-6)) << max_pixels;
    EXPECT_TRUE(torch::allclose(chunked.delta_eflow, whole.delta_eflow, 1e-5, 1e-6)) << max_pixels;
    EXPECT_TRUE(torch::allclose(chunked.weight_logit, whole.weight_logit, 1e-5, 1e-6)) << max_pixels;
  }
  EXPECT_THROW(UpdateInChunks(block, torch::Tensor(), terms, cost, eflow, 1), std::invalid_argument);
  EXPECT_THROW(UpdateInChunks(block, hidden.narrow(0, 0, 7), terms, cost.narrow(0, 0, 7),
                              eflow.narrow(0, 0, 7), 1),
               std::invalid_argument);  // 7 pairs over 2 references
}

TEST(UpdateBlockTest, RejectsBadInput) {
  EXPECT_THROW(UpdateBlock(0, 4, 3, 4), std::invalid_argument);
  EXPECT_THROW(UpdateBlock(5, 4, 3, 0), std::invalid_argument);
  EXPECT_THROW(SepConvGru(4, 0, 3), std::invalid_argument);
  UpdateBlock block(5, 4, 3, 4);
  const torch::Tensor h = torch::zeros({2, 4, 3, 3});
  const torch::Tensor terms = block->ContextTerms(torch::zeros({1, 3, 3, 3}));
  EXPECT_THROW(block->ContextTerms(torch::zeros({1, 2, 3, 3})), std::invalid_argument);
  EXPECT_THROW(block->forward(h, torch::zeros({1, 23, 3, 3}), torch::zeros({2, 5, 3, 3}),
                              torch::zeros({2, 1, 3, 3})),
               std::invalid_argument);  // terms must have 6 * hidden channels
  EXPECT_THROW(block->forward(h, terms.repeat({3, 1, 1, 1}), torch::zeros({2, 5, 3, 3}),
                              torch::zeros({2, 1, 3, 3})),
               std::invalid_argument);  // 2 pairs over 3 references
  EXPECT_THROW(block->forward(h, terms, torch::zeros({2, 5, 3, 3}), torch::zeros({2, 1, 3, 4})),
               std::invalid_argument);
  EXPECT_THROW(block->MaskLogits(torch::zeros({1, 5, 3, 3})), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
