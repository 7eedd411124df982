#include "model/precision.h"

#include <limits>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

#include "model/update_block.h"

namespace dispmvs::model {
namespace {

// bf16 keeps 8 significant bits: rounding to nearest moves a value by at most
// 2^-9 of itself.
constexpr double kBf16Rounding = 1.0 / 512.0;

TEST(PrecisionTest, ResolvesTheNamesAndAutoByDevice) {
  EXPECT_EQ(ResolvePrecision("fp32", torch::kCPU), Precision::kFloat32);
  EXPECT_EQ(ResolvePrecision("bf16", torch::kCPU), Precision::kBFloat16);
  EXPECT_EQ(ResolvePrecision("auto", torch::kCPU),
            CpuHasNativeBf16() ? Precision::kBFloat16 : Precision::kFloat32);
  // CUDA is not measured yet: auto keeps fp32 there (the text only is read).
  EXPECT_EQ(ResolvePrecision("auto", torch::Device(torch::kCUDA, 0)), Precision::kFloat32);
  EXPECT_STREQ(PrecisionName(Precision::kBFloat16), "bf16");
  EXPECT_STREQ(PrecisionName(Precision::kFloat32), "fp32");
  try {
    ResolvePrecision("float16", torch::kCPU, "--precision");
    FAIL() << "float16 accepted";
  } catch (const std::invalid_argument& error) {
    EXPECT_EQ(std::string(error.what()),
              "--precision must be auto, fp32 or bf16, got 'float16'");
  }
}

// The bf16 convolution against a double-precision one of the bf16-rounded
// operands: the products of two bf16 values are exact in fp32 and summed in
// fp32, so what is left is the output's rounding to bf16, at most twice
// (LibTorch 1.13 on this CPU measures up to 1.9 x 2^-9 of the value: the
// sum is rounded before the bias is added, and again after).
TEST(PrecisionTest, Bf16ConvolutionIsTheRoundedOperandsConvolution) {
  torch::manual_seed(3);
  const torch::Tensor x = torch::randn({2, 12, 9, 11});
  const torch::Tensor weight = torch::randn({7, 12, 1, 5});
  const torch::Tensor bias = torch::randn({7});
  const torch::Tensor out = Conv2dIn(Precision::kBFloat16, x, weight, bias, {0, 2});
  EXPECT_EQ(out.scalar_type(), torch::kFloat);
  const auto rounded = [](const torch::Tensor& t) {
    return t.to(torch::kBFloat16).to(torch::kDouble);
  };
  const torch::Tensor reference =
      torch::conv2d(rounded(x), rounded(weight), rounded(bias), 1, torch::IntArrayRef{0, 2});
  const torch::Tensor error = (out.to(torch::kDouble) - reference).abs();
  EXPECT_TRUE((error <= 2 * kBf16Rounding * reference.abs() + 1e-4).all().item<bool>())
      << error.max().item<double>();
  // Not the fp32 convolution: the operands were rounded.
  const torch::Tensor fp32 = Conv2dIn(Precision::kFloat32, x, weight, bias, {0, 2});
  EXPECT_TRUE(torch::equal(fp32, torch::conv2d(x, weight, bias, 1, torch::IntArrayRef{0, 2})));
  EXPECT_GT((fp32 - out).abs().max().item<double>(), 1e-4);
  // A bf16 input gives a bf16 output (chains of convolutions stay in bf16).
  EXPECT_EQ(Conv2dIn(Precision::kBFloat16, InPrecision(Precision::kBFloat16, x), weight, bias,
                     {0, 2})
                .scalar_type(),
            torch::kBFloat16);
  EXPECT_EQ(InPrecision(Precision::kFloat32, x).scalar_type(), torch::kFloat);
}

// The module form keeps the module's stride and padding.
TEST(PrecisionTest, ModuleConvolutionKeepsItsStrideAndPadding) {
  torch::manual_seed(4);
  torch::nn::Conv2d conv(torch::nn::Conv2dOptions(5, 6, 3).stride(2).padding(1));
  const torch::Tensor x = torch::randn({1, 5, 13, 10});
  const torch::Tensor fp32 = conv->forward(x);
  EXPECT_TRUE(torch::equal(Conv2dIn(Precision::kFloat32, conv, x), fp32));
  const torch::Tensor bf16 = Conv2dIn(Precision::kBFloat16, conv, x);
  ASSERT_EQ(bf16.sizes(), fp32.sizes());
  const auto rounded = [](const torch::Tensor& t) {
    return t.detach().to(torch::kBFloat16).to(torch::kDouble);
  };
  const torch::Tensor reference =
      torch::conv2d(rounded(x), rounded(conv->weight), rounded(conv->bias), 2, 1);
  const torch::Tensor error = (bf16.detach().to(torch::kDouble) - reference).abs();
  EXPECT_TRUE((error <= 2 * kBf16Rounding * reference.abs() + 1e-4).all().item<bool>());

  torch::nn::Conv2d reflect(torch::nn::Conv2dOptions(5, 6, 3).padding(1).padding_mode(torch::kReflect));
  EXPECT_THROW(Conv2dIn(Precision::kBFloat16, reflect, x), std::invalid_argument);
}

// The update block in bf16 stays close to its fp32 self at the shipped
// small configuration's fine-stage widths, and its state stays fp32.
TEST(PrecisionTest, Bf16UpdateBlockFollowsTheFp32Block) {
  torch::NoGradGuard no_grad;
  torch::manual_seed(5);
  UpdateBlock block(/*correlation_channels=*/10, /*hidden=*/48, /*context=*/48, /*factor=*/4);
  const int64_t pairs = 3, h = 12, w = 16;
  const torch::Tensor hidden = torch::randn({pairs, 48, h, w}).tanh();
  const torch::Tensor context = torch::randn({1, 48, h, w}).relu();
  const torch::Tensor cost = torch::randn({pairs, 10, h, w});
  const torch::Tensor eflow = 3 * torch::randn({pairs, 1, h, w});

  const UpdateBlockOutput fp32 = block->forward(hidden, block->ContextTerms(context), cost, eflow);
  const torch::Tensor fp32_mask = block->MaskLogits(fp32.hidden);
  block->set_precision(Precision::kBFloat16);
  EXPECT_EQ(block->precision(), Precision::kBFloat16);
  const UpdateBlockOutput bf16 = block->forward(hidden, block->ContextTerms(context), cost, eflow);
  const torch::Tensor bf16_mask = block->MaskLogits(bf16.hidden);
  for (const torch::Tensor& t : {bf16.hidden, bf16.delta_eflow, bf16.weight_logit, bf16_mask}) {
    EXPECT_EQ(t.scalar_type(), torch::kFloat);
  }
  // Every layer rounds its operands and output (relative 2^-9 each); through
  // the block's depth of about ten layers the errors stay a few percent of
  // each output's spread, far below what separates a good update from a
  // bad one, and not zero (bf16 did run).
  const auto relative = [](const torch::Tensor& a, const torch::Tensor& b) {
    return ((a - b).abs().max() / b.std()).item<double>();
  };
  for (const auto& [name, a, b] :
       {std::tuple<const char*, torch::Tensor, torch::Tensor>{"hidden", bf16.hidden, fp32.hidden},
        {"delta", bf16.delta_eflow, fp32.delta_eflow},
        {"logit", bf16.weight_logit, fp32.weight_logit},
        {"mask", bf16_mask, fp32_mask}}) {
    const double r = relative(a, b);
    EXPECT_LT(r, 0.05) << name;
    EXPECT_GT(r, 1e-5) << name;
  }
}

}  // namespace
}  // namespace dispmvs::model
