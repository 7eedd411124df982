#include "model/gru_gates_cpu.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <gtest/gtest.h>

namespace dispmvs::model {
namespace {

// Against the C library's functions in double precision, densely over the
// range where the gates are not saturated and sparsely beyond it.
TEST(GruGatesCpuTest, SigmoidAndTanhMatchTheLibraryFunctions) {
  double worst_sigmoid = 0, worst_tanh = 0;
  for (double x = -100.0; x <= 100.0; x += (std::abs(x) < 20.0 ? 1e-3 : 0.37)) {
    const float xf = static_cast<float>(x);
    const double exact_sigmoid = 1.0 / (1.0 + std::exp(-static_cast<double>(xf)));
    const double exact_tanh = std::tanh(static_cast<double>(xf));
    worst_sigmoid = std::max(worst_sigmoid, std::abs(FastSigmoid(xf) - exact_sigmoid));
    worst_tanh = std::max(worst_tanh, std::abs(FastTanh(xf) - exact_tanh));
  }
  // A few float ulps of values in (0, 1): std::exp-based float code is
  // within 6e-8 too.
  EXPECT_LT(worst_sigmoid, 3e-7);
  EXPECT_LT(worst_tanh, 3e-7);
  // Relative accuracy where sigmoid is tiny (its tail feeds products).
  for (const float x : {-20.0f, -40.0f, -80.0f}) {
    const double exact = 1.0 / (1.0 + std::exp(-static_cast<double>(x)));
    EXPECT_NEAR(FastSigmoid(x) / exact, 1.0, 1e-6) << x;
  }
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_FLOAT_EQ(FastSigmoid(inf), 1.0f);
  EXPECT_LT(FastSigmoid(-inf), 1e-37f);
  EXPECT_FLOAT_EQ(FastTanh(inf), 1.0f);
  EXPECT_FLOAT_EQ(FastTanh(-inf), -1.0f);
  EXPECT_TRUE(std::isnan(FastSigmoid(std::nanf(""))));
  EXPECT_TRUE(std::isnan(FastTanh(std::nanf(""))));
}

struct GateMaps {
  torch::Tensor zr_pre, q_pre, terms, hidden;
};

// 2 references of 3 pairs each; terms as the GRU passes them: narrowed
// views of one [R, 6H, h, w] map.
GateMaps MakeMaps(torch::ScalarType conv_dtype) {
  torch::manual_seed(11);
  const int64_t pairs = 6, hid = 5, h = 7, w = 9;
  GateMaps m;
  m.zr_pre = (torch::randn({pairs, 2 * hid, h, w}) * 3).to(conv_dtype);
  m.q_pre = (torch::randn({pairs, hid, h, w}) * 3).to(conv_dtype);
  m.terms = torch::randn({2, 6 * hid, h, w});
  m.hidden = torch::randn({pairs, hid, h, w}).tanh();
  return m;
}

// The ATen formulas of SepConvGru's step, per reference.
torch::Tensor PerPair(const torch::Tensor& terms, int64_t pairs) {
  return terms.repeat_interleave(pairs / terms.size(0), 0);
}

TEST(GruGatesCpuTest, FusedPassesMatchTheAtenFormulas) {
  torch::NoGradGuard no_grad;
  for (const torch::ScalarType dtype : {torch::kFloat32, torch::kBFloat16}) {
    const GateMaps m = MakeMaps(dtype);
    const int64_t pairs = m.hidden.size(0), hid = m.hidden.size(1);
    const torch::Tensor zr_terms = m.terms.narrow(1, 0, 2 * hid);
    const torch::Tensor q_terms = m.terms.narrow(1, 2 * hid, hid);
    ASSERT_TRUE(CanUseFusedGates(m.zr_pre, m.hidden));

    const torch::Tensor zr = torch::sigmoid(m.zr_pre.to(torch::kFloat32) + PerPair(zr_terms, pairs));
    const torch::Tensor z_expected = zr.narrow(1, 0, hid);
    const torch::Tensor reset_expected = (zr.narrow(1, hid, hid) * m.hidden).to(dtype);
    const torch::Tensor q = torch::tanh(m.q_pre.to(torch::kFloat32) + PerPair(q_terms, pairs));
    const torch::Tensor blend_expected = (1 - z_expected) * m.hidden + z_expected * q;

    // The buffer's other channels (the motion) must stay untouched.
    torch::Tensor gate_input = torch::full({pairs, 2 * hid, 7, 9}, 7.0f, torch::dtype(dtype));
    const torch::Tensor z = FusedUpdateAndResetGates(m.zr_pre, zr_terms, m.hidden, gate_input);
    EXPECT_LT((z - z_expected).abs().max().item<float>(), 3e-7f);
    const torch::Tensor reset = gate_input.narrow(1, 0, hid).to(torch::kFloat32);
    // fp32: a few ulps; bf16: equal unless a sigmoid ulp flips the rounding
    // (then one bf16 ulp, 2^-8 relative).
    const double reset_tolerance = dtype == torch::kFloat32 ? 1e-6 : 4e-3;
    EXPECT_TRUE(torch::allclose(reset, reset_expected.to(torch::kFloat32), reset_tolerance, 1e-7))
        << dtype;
    EXPECT_TRUE(torch::all(gate_input.narrow(1, hid, hid) == 7.0f).item<bool>()) << dtype;

    const torch::Tensor blend = FusedCandidateBlend(m.q_pre, q_terms, m.hidden, z);
    EXPECT_LT((blend - blend_expected).abs().max().item<float>(), 1e-6f) << dtype;
  }
}

TEST(GruGatesCpuTest, RejectsBadInput) {
  torch::NoGradGuard no_grad;
  const GateMaps m = MakeMaps(torch::kFloat32);
  const int64_t hid = m.hidden.size(1);
  const torch::Tensor zr_terms = m.terms.narrow(1, 0, 2 * hid);
  torch::Tensor buffer = torch::zeros({6, 2 * hid, 7, 9});
  torch::Tensor bf16_buffer = buffer.to(torch::kBFloat16);
  // zr channels, the reference count, the buffer's dtype, the hidden state.
  EXPECT_THROW(FusedUpdateAndResetGates(m.q_pre, zr_terms, m.hidden, buffer), std::invalid_argument);
  EXPECT_THROW(FusedUpdateAndResetGates(m.zr_pre, m.terms.narrow(0, 0, 1).repeat({4, 1, 1, 1})
                                                      .narrow(1, 0, 2 * hid),
                                        m.hidden, buffer),
               std::invalid_argument);
  EXPECT_THROW(FusedUpdateAndResetGates(m.zr_pre, zr_terms, m.hidden, bf16_buffer),
               std::invalid_argument);
  EXPECT_THROW(FusedCandidateBlend(m.q_pre, m.terms.narrow(1, 0, hid), m.hidden.transpose(2, 3),
                                   m.hidden),
               std::invalid_argument);
  // Autograd on: the fused passes are not offered.
  torch::AutoGradMode grad(true);
  EXPECT_FALSE(CanUseFusedGates(m.zr_pre, m.hidden));
}

}  // namespace
}  // namespace dispmvs::model
