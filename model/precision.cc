#include "model/precision.h"

#include <stdexcept>

#if defined(__x86_64__) || defined(__i386__)
#include <cpuid.h>
#endif

namespace dispmvs::model {

const char* PrecisionName(Precision precision) {
  return precision == Precision::kBFloat16 ? "bf16" : "fp32";
}

bool CpuHasNativeBf16() {
#if defined(__x86_64__) || defined(__i386__)
  unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
  if (__get_cpuid_max(0, nullptr) < 7) return false;
  // Leaf 7, sub-leaf 0: EDX bit 22 is AMX-BF16.
  __cpuid_count(7, 0, eax, ebx, ecx, edx);
  const bool amx_bf16 = (edx >> 22) & 1u;
  const unsigned max_subleaf = eax;
  // Leaf 7, sub-leaf 1: EAX bit 5 is AVX512_BF16.
  bool avx512_bf16 = false;
  if (max_subleaf >= 1) {
    __cpuid_count(7, 1, eax, ebx, ecx, edx);
    avx512_bf16 = (eax >> 5) & 1u;
  }
  return amx_bf16 || avx512_bf16;
#else
  return false;
#endif
}

Precision ResolvePrecision(const std::string& text, const torch::Device& device,
                           const std::string& what) {
  if (text == "fp32") return Precision::kFloat32;
  if (text == "bf16") return Precision::kBFloat16;
  if (text == "auto") {
    return device.is_cpu() && CpuHasNativeBf16() ? Precision::kBFloat16 : Precision::kFloat32;
  }
  throw std::invalid_argument(what + " must be auto, fp32 or bf16, got '" + text + "'");
}

torch::Tensor InPrecision(Precision precision, const torch::Tensor& x) {
  return precision == Precision::kBFloat16 ? x.to(torch::kBFloat16) : x;
}

namespace {

// conv2d with x, weight and bias rounded to bf16, the result in x's dtype.
torch::Tensor Bf16Conv2d(const torch::Tensor& x, const torch::Tensor& weight,
                         const torch::Tensor& bias, torch::IntArrayRef stride,
                         torch::IntArrayRef padding, torch::IntArrayRef dilation, int64_t groups) {
  const auto low = torch::kBFloat16;
  return torch::conv2d(x.to(low), weight.to(low), bias.defined() ? bias.to(low) : bias, stride,
                       padding, dilation, groups)
      .to(x.scalar_type());
}

}  // namespace

torch::Tensor Conv2dIn(Precision precision, const torch::Tensor& x, const torch::Tensor& weight,
                       const torch::Tensor& bias, torch::IntArrayRef padding) {
  if (precision == Precision::kFloat32) return torch::conv2d(x, weight, bias, 1, padding);
  return Bf16Conv2d(x, weight, bias, 1, padding, 1, 1);
}

torch::Tensor Conv2dIn(Precision precision, const torch::nn::Conv2d& conv, const torch::Tensor& x) {
  if (precision == Precision::kFloat32) return conv.ptr()->forward(x);
  const auto& options = conv->options;
  const auto* padding = c10::get_if<torch::ExpandingArray<2>>(&options.padding());
  if (padding == nullptr || !c10::holds_alternative<torch::enumtype::kZeros>(options.padding_mode())) {
    throw std::invalid_argument("Conv2dIn: the module's padding must be explicit sizes of zeros");
  }
  return Bf16Conv2d(x, conv->weight, conv->bias, options.stride(), *padding, options.dilation(),
                    options.groups());
}

}  // namespace dispmvs::model
