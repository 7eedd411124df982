#include "model/gru_gates_cpu.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>

#include "model/cpu_clones.h"

namespace dispmvs::model {
namespace {

#define DISPMVS_INLINE inline __attribute__((always_inline))

DISPMVS_INLINE float BitsToFloat(uint32_t bits) {
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}

DISPMVS_INLINE uint32_t FloatToBits(float f) {
  uint32_t bits;
  std::memcpy(&bits, &f, sizeof bits);
  return bits;
}

// exp(x) = 2^n exp(r), n = round(x / ln2), r = x - n ln2 (ln2 split in a
// part exact in float and the rest), exp(r) by Taylor to degree 7 (Horner).
// x is clamped to [-87, 87], where 2^n is a normal float; NaN stays NaN
// (through r), and n is taken from a clamped copy so that no NaN reaches
// the integer conversion.
DISPMVS_INLINE float Exp(float x) {
  x = std::min(std::max(x, -87.0f), 87.0f);
  const float t = x * 1.44269504088896341f;
  const float t_safe = std::min(std::max(t, -126.0f), 126.0f);  // NaN -> -126 (std::max(NaN, a) is NaN; see below)
  const int32_t n = static_cast<int32_t>(t_safe + 128.5f) - 128;  // floor(t + 0.5)
  const float nf = static_cast<float>(n);
  const float r = (x - nf * 0.693359375f) + nf * 2.12194440e-4f;
  float p = 1.0f / 5040.0f;
  p = p * r + 1.0f / 720.0f;
  p = p * r + 1.0f / 120.0f;
  p = p * r + 1.0f / 24.0f;
  p = p * r + 1.0f / 6.0f;
  p = p * r + 0.5f;
  p = p * r + 1.0f;
  p = p * r + 1.0f;
  return p * BitsToFloat(static_cast<uint32_t>(n + 127) << 23);
}

DISPMVS_INLINE float Sigmoid(float x) { return 1.0f / (1.0f + Exp(-x)); }
DISPMVS_INLINE float Tanh(float x) { return 1.0f - 2.0f / (1.0f + Exp(2.0f * x)); }

DISPMVS_INLINE float Load(const float* p, int64_t i) { return p[i]; }
DISPMVS_INLINE float Load(const uint16_t* p, int64_t i) {
  return BitsToFloat(static_cast<uint32_t>(p[i]) << 16);
}

DISPMVS_INLINE void Store(float* p, int64_t i, float v) { p[i] = v; }
// Round to nearest even, NaN to a quiet NaN: c10::BFloat16's conversion.
DISPMVS_INLINE void Store(uint16_t* p, int64_t i, float v) {
  const uint32_t bits = FloatToBits(v);
  const uint32_t rounded = (bits + 0x7FFFu + ((bits >> 16) & 1u)) >> 16;
  p[i] = (bits & 0x7FFFFFFFu) > 0x7F800000u ? uint16_t{0x7FC0} : static_cast<uint16_t>(rounded);
}

// One row of n values of each map, per line of the header.
template <typename In>
DISPMVS_INLINE void UpdateGateRow(const In* pre, const float* term, float* z, int64_t n) {
  for (int64_t i = 0; i < n; ++i) z[i] = Sigmoid(Load(pre, i) + term[i]);
}
template <typename In, typename Out>
DISPMVS_INLINE void ResetRow(const In* pre, const float* term, const float* hidden, Out* out,
                             int64_t n) {
  for (int64_t i = 0; i < n; ++i) Store(out, i, Sigmoid(Load(pre, i) + term[i]) * hidden[i]);
}
template <typename In>
DISPMVS_INLINE void BlendRow(const In* pre, const float* term, const float* hidden, const float* z,
                             float* out, int64_t n) {
  for (int64_t i = 0; i < n; ++i) {
    const float q = Tanh(Load(pre, i) + term[i]);
    out[i] = (1.0f - z[i]) * hidden[i] + z[i] * q;
  }
}

DISPMVS_CPU_CLONES void UpdateGateRowF32(const float* pre, const float* term, float* z, int64_t n) {
  UpdateGateRow(pre, term, z, n);
}
DISPMVS_CPU_CLONES void UpdateGateRowBf16(const uint16_t* pre, const float* term, float* z,
                                          int64_t n) {
  UpdateGateRow(pre, term, z, n);
}
DISPMVS_CPU_CLONES void ResetRowF32(const float* pre, const float* term, const float* hidden,
                                    float* out, int64_t n) {
  ResetRow(pre, term, hidden, out, n);
}
DISPMVS_CPU_CLONES void ResetRowBf16(const uint16_t* pre, const float* term, const float* hidden,
                                     uint16_t* out, int64_t n) {
  ResetRow(pre, term, hidden, out, n);
}
DISPMVS_CPU_CLONES void BlendRowF32(const float* pre, const float* term, const float* hidden,
                                    const float* z, float* out, int64_t n) {
  BlendRow(pre, term, hidden, z, out, n);
}
DISPMVS_CPU_CLONES void BlendRowBf16(const uint16_t* pre, const float* term, const float* hidden,
                                     const float* z, float* out, int64_t n) {
  BlendRow(pre, term, hidden, z, out, n);
}

void Require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("GRU gates: " + what);
}

bool IsFloatOrBf16(const torch::Tensor& t) {
  return t.scalar_type() == torch::kFloat32 || t.scalar_type() == torch::kBFloat16;
}

// A [B',C,h,w] map of the pass: contiguous, on the CPU, fp32 or bf16.
void RequireMap(const torch::Tensor& t, const char* name, int64_t batch, int64_t channels,
                int64_t h, int64_t w) {
  Require(t.defined() && t.device().is_cpu() && IsFloatOrBf16(t) && t.dim() == 4 &&
              t.size(0) == batch && t.size(1) == channels && t.size(2) == h && t.size(3) == w &&
              t.is_contiguous(),
          std::string(name) + " must be a contiguous CPU fp32 or bf16 [" + std::to_string(batch) +
              "," + std::to_string(channels) + "," + std::to_string(h) + "," + std::to_string(w) +
              "] map");
}

// Per-reference terms [R,C,h,w] with dense rows (h, w), for B' pairs.
void RequireTerms(const torch::Tensor& t, int64_t batch, int64_t channels, int64_t h, int64_t w) {
  Require(t.defined() && t.device().is_cpu() && t.scalar_type() == torch::kFloat32 &&
              t.dim() == 4 && t.size(0) >= 1 && batch % t.size(0) == 0 && t.size(1) == channels &&
              t.size(2) == h && t.size(3) == w && t.stride(3) == 1 && t.stride(2) == w,
          "terms must be fp32 [R," + std::to_string(channels) + "," + std::to_string(h) + "," +
              std::to_string(w) + "] with dense rows and R dividing " + std::to_string(batch));
}

const uint16_t* Bf16Data(const torch::Tensor& t) {
  return static_cast<const uint16_t*>(t.data_ptr());
}

}  // namespace

float FastSigmoid(float x) { return Sigmoid(x); }
float FastTanh(float x) { return Tanh(x); }

bool CanUseFusedGates(const torch::Tensor& conv_output, const torch::Tensor& hidden) {
  return !torch::GradMode::is_enabled() && conv_output.defined() && hidden.defined() &&
         conv_output.device().is_cpu() && hidden.device().is_cpu() &&
         IsFloatOrBf16(conv_output) && hidden.scalar_type() == torch::kFloat32;
}

torch::Tensor FusedUpdateAndResetGates(const torch::Tensor& zr_pre, const torch::Tensor& zr_terms,
                                       const torch::Tensor& hidden, torch::Tensor& gate_input) {
  Require(hidden.defined() && hidden.dim() == 4 && hidden.scalar_type() == torch::kFloat32,
          "hidden must be an fp32 [B',H,h,w] map");
  const int64_t batch = hidden.size(0), hid = hidden.size(1), h = hidden.size(2),
                w = hidden.size(3);
  RequireMap(hidden, "hidden", batch, hid, h, w);
  RequireMap(zr_pre, "zr_pre", batch, 2 * hid, h, w);
  RequireTerms(zr_terms, batch, 2 * hid, h, w);
  Require(gate_input.defined() && gate_input.dim() == 4 && gate_input.size(1) >= hid,
          "gate_input must have at least H channels");
  RequireMap(gate_input, "gate_input", batch, gate_input.size(1), h, w);

  torch::Tensor z = torch::empty({batch, hid, h, w}, hidden.options());
  const int64_t plane = h * w, pairs_per_ref = batch / zr_terms.size(0);
  const bool pre_bf16 = zr_pre.scalar_type() == torch::kBFloat16;
  const bool out_bf16 = gate_input.scalar_type() == torch::kBFloat16;
  const float* terms = zr_terms.data_ptr<float>();
  const float* hidden_p = hidden.data_ptr<float>();
  float* z_p = z.data_ptr<float>();
  Require(pre_bf16 == out_bf16, "zr_pre and gate_input must share a dtype");
  const int64_t gate_channels = gate_input.size(1);
  // One task per (pair, channel) row of the 2H gate channels.
  at::parallel_for(0, batch * 2 * hid, 1, [&](int64_t begin, int64_t end) {
    for (int64_t row = begin; row < end; ++row) {
      const int64_t b = row / (2 * hid), c = row % (2 * hid);
      const float* term =
          terms + (b / pairs_per_ref) * zr_terms.stride(0) + c * zr_terms.stride(1);
      const int64_t pre_offset = row * plane;
      if (c < hid) {
        float* z_row = z_p + (b * hid + c) * plane;
        if (pre_bf16) {
          UpdateGateRowBf16(Bf16Data(zr_pre) + pre_offset, term, z_row, plane);
        } else {
          UpdateGateRowF32(zr_pre.data_ptr<float>() + pre_offset, term, z_row, plane);
        }
        continue;
      }
      const int64_t k = c - hid;
      const float* h_row = hidden_p + (b * hid + k) * plane;
      const int64_t out_offset = (b * gate_channels + k) * plane;
      if (pre_bf16 && out_bf16) {
        ResetRowBf16(Bf16Data(zr_pre) + pre_offset, term, h_row,
                     static_cast<uint16_t*>(gate_input.data_ptr()) + out_offset, plane);
      } else {
        ResetRowF32(zr_pre.data_ptr<float>() + pre_offset, term, h_row,
                    gate_input.data_ptr<float>() + out_offset, plane);
      }
    }
  });
  return z;
}

torch::Tensor FusedCandidateBlend(const torch::Tensor& q_pre, const torch::Tensor& q_terms,
                                  const torch::Tensor& hidden, const torch::Tensor& z) {
  Require(hidden.defined() && hidden.dim() == 4 && hidden.scalar_type() == torch::kFloat32,
          "hidden must be an fp32 [B',H,h,w] map");
  const int64_t batch = hidden.size(0), hid = hidden.size(1), h = hidden.size(2),
                w = hidden.size(3);
  RequireMap(hidden, "hidden", batch, hid, h, w);
  RequireMap(z, "z", batch, hid, h, w);
  Require(z.scalar_type() == torch::kFloat32, "z must be fp32");
  RequireMap(q_pre, "q_pre", batch, hid, h, w);
  RequireTerms(q_terms, batch, hid, h, w);

  torch::Tensor out = torch::empty_like(hidden);
  const int64_t plane = h * w, pairs_per_ref = batch / q_terms.size(0);
  const bool pre_bf16 = q_pre.scalar_type() == torch::kBFloat16;
  const float* terms = q_terms.data_ptr<float>();
  const float* hidden_p = hidden.data_ptr<float>();
  const float* z_p = z.data_ptr<float>();
  float* out_p = out.data_ptr<float>();
  at::parallel_for(0, batch * hid, 1, [&](int64_t begin, int64_t end) {
    for (int64_t row = begin; row < end; ++row) {
      const int64_t b = row / hid, c = row % hid;
      const float* term = terms + (b / pairs_per_ref) * q_terms.stride(0) + c * q_terms.stride(1);
      const int64_t offset = row * plane;
      if (pre_bf16) {
        BlendRowBf16(Bf16Data(q_pre) + offset, term, hidden_p + offset, z_p + offset,
                     out_p + offset, plane);
      } else {
        BlendRowF32(q_pre.data_ptr<float>() + offset, term, hidden_p + offset, z_p + offset,
                    out_p + offset, plane);
      }
    }
  });
  return out;
}

}  // namespace dispmvs::model
