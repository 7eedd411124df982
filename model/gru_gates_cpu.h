#pragma once
// The GRU's element-wise gate arithmetic fused into two CPU passes, for
// inference.
//
// Between its convolutions a SepConvGru step computes
//   z, r = sigmoid(conv_zr + context terms),  r * hidden  (the q input),
//   hidden' = (1 - z) hidden + z tanh(conv_q + context terms).
// Written with ATen ops that is about ten passes over maps of 48-96
// channels, several of them widening or rounding bf16, which LibTorch 1.13
// does element by element: at the fine stage of 640x480 they took about as
// long as the gate convolutions themselves. Here each of the two lines is
// one pass reading the convolution output (bf16 or fp32) and writing fp32
// (or the bf16 input buffer of the next convolution).
//
// sigmoid and tanh are evaluated from one exponential, exp(r) on
// |r| <= ln2/2 by its Taylor series to degree 7 (remainder below 1e-8
// relative) scaled by 2^n: within a few float ulps of std::exp, so the
// results match the ATen path to about 1e-6 (update_block_test). bf16
// rounding is round-to-nearest-even, as LibTorch's. No autograd.

#include <torch/torch.h>

namespace dispmvs::model {

// Whether the fused passes can serve these maps: CPU, no autograd, fp32
// hidden state, fp32 or bf16 convolution outputs.
bool CanUseFusedGates(const torch::Tensor& conv_output, const torch::Tensor& hidden);

// zr_pre [B',2H,h,w] the z and r convolution (fp32 or bf16, contiguous);
// zr_terms [R,2H,h,w] the context's share, per reference (pairs
// r*(B'/R).. share reference r's; h and w dense, any channel and batch
// stride); hidden [B',H,h,w] fp32 contiguous. Writes r * hidden into
// channels 0..H-1 of gate_input [B',C,h,w] (contiguous, fp32 or bf16) and
// returns z [B',H,h,w] fp32. Throws std::invalid_argument on bad shapes.
torch::Tensor FusedUpdateAndResetGates(const torch::Tensor& zr_pre, const torch::Tensor& zr_terms,
                                       const torch::Tensor& hidden, torch::Tensor& gate_input);

// q_pre [B',H,h,w] the q convolution, q_terms [R,H,h,w] its context share
// (as above), hidden and z [B',H,h,w] fp32 contiguous: returns the new
// hidden state (1 - z) hidden + z tanh(q_pre + q_terms), fp32.
torch::Tensor FusedCandidateBlend(const torch::Tensor& q_pre, const torch::Tensor& q_terms,
                                  const torch::Tensor& hidden, const torch::Tensor& z);

// The passes' sigmoid and tanh on one float, exposed for their tests.
float FastSigmoid(float x);
float FastTanh(float x);

}  // namespace dispmvs::model
