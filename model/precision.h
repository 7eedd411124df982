#pragma once
// The arithmetic the network's convolutions run in at inference, chosen at
// run time (--precision of the programs).
//
// bf16 convolutions are 1.5-4x faster than fp32 on a CPU with native bf16
// dot products (AVX-512 BF16 or AMX), the GRU update block as a whole about
// 1.4x (docs/benchmarks.md); where oneDNN has to emulate bf16 they are
// slower than fp32. Only the convolutions of the GRU update blocks take bf16
// inputs and weights (the encoders in bf16 measured no faster); their
// outputs come back as fp32 (after a conv -> relu -> conv chain at most), so
// the hidden state, the E-flow, the encoders' features, the correlation,
// triangulation and fusion all stay fp32 (bf16 keeps 8 bits of mantissa:
// too few for a position along an epipolar line or a depth).

#include <string>

#include <torch/torch.h>

namespace dispmvs::model {

enum class Precision { kFloat32, kBFloat16 };

// "fp32" / "bf16".
const char* PrecisionName(Precision precision);

// Whether this processor has native bf16 dot products (x86: AVX-512 BF16 or
// AMX-BF16, read from CPUID); false elsewhere.
bool CpuHasNativeBf16();

// The precision for `text` on `device`: "fp32", "bf16", or "auto" (bf16 on
// a CPU with native bf16, fp32 otherwise, CUDA included until it is
// measured there). Throws std::invalid_argument
// "<what> must be auto, fp32 or bf16, got '<text>'".
Precision ResolvePrecision(const std::string& text, const torch::Device& device,
                           const std::string& what = "precision");

// x in `precision`'s dtype (a no-op for kFloat32, and for an x already in
// bf16): for chains of convolutions that stay in bf16 between them.
torch::Tensor InPrecision(Precision precision, const torch::Tensor& x);

// conv2d of x with (weight, bias) at stride 1 and zero padding `padding`,
// in `precision`: for kBFloat16, x, weight and bias are rounded to bf16 and
// the result comes back in x's dtype (so an fp32 x gets an fp32 result, a
// bf16 x a bf16 one). bias may be undefined.
torch::Tensor Conv2dIn(Precision precision, const torch::Tensor& x, const torch::Tensor& weight,
                       const torch::Tensor& bias, torch::IntArrayRef padding);

// A Conv2d module's forward in `precision` (its own stride, padding,
// dilation and groups).
torch::Tensor Conv2dIn(Precision precision, const torch::nn::Conv2d& conv, const torch::Tensor& x);

}  // namespace dispmvs::model
