#include "model/correlation_cpu.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

#include "model/cpu_clones.h"

namespace dispmvs::model {
namespace {

// Partial sums kept in a fixed-width inner loop, which the compiler
// vectorises without having to reassociate a float reduction.
constexpr int64_t kLanes = 16;

// sum_c ref[c] * (w[0] s0[c] + w[1] s1[c] + w[2] s2[c] + w[3] s3[c]): the
// dot product of the reference feature with the bilinear blend of the four
// corner features (cpu_clones.h: also built for AVX2 and AVX-512).
DISPMVS_CPU_CLONES float BlendedDot(const float* ref, const float* s0, const float* s1, const float* s2,
                 const float* s3, float w0, float w1, float w2, float w3, int64_t channels) {
  float lanes[kLanes] = {};
  int64_t c = 0;
  for (; c + kLanes <= channels; c += kLanes) {
    for (int64_t j = 0; j < kLanes; ++j) {
      const int64_t i = c + j;
      lanes[j] += ref[i] * (w0 * s0[i] + w1 * s1[i] + w2 * s2[i] + w3 * s3[i]);
    }
  }
  float sum = 0.0f;
  for (; c < channels; ++c) sum += ref[c] * (w0 * s0[c] + w1 * s1[c] + w2 * s2[c] + w3 * s3[c]);
  for (int64_t j = 0; j < kLanes; ++j) sum += lanes[j];
  return sum;
}

struct Level {
  const float* data;  // [H, W, C] of one batch item at a time (offset per item)
  int64_t height, width, item_stride;
};

// The bilinear footprint of a sample at level pixel (x, y): each corner's
// offset in the level's [H, W, C] item (-1 outside the map, where zero
// padding reads 0) and its weight. False when no corner can be inside (or a
// coordinate is non-finite, for which every comparison is false): the
// sample is 0 and passes no gradient.
struct Footprint {
  int64_t offset[4];
  float weight[4];
};
bool BilinearFootprint(const Level& level, float x, float y, int64_t channels, Footprint* f) {
  if (!(x > -1.0f && x < static_cast<float>(level.width) && y > -1.0f &&
        y < static_cast<float>(level.height))) {
    return false;
  }
  const float x0f = std::floor(x), y0f = std::floor(y);
  const float fx = x - x0f, fy = y - y0f;
  const int64_t x0 = static_cast<int64_t>(x0f), y0 = static_cast<int64_t>(y0f);
  const auto offset = [&](int64_t cx, int64_t cy) -> int64_t {
    return cx >= 0 && cx < level.width && cy >= 0 && cy < level.height
               ? (cy * level.width + cx) * channels
               : -1;
  };
  f->offset[0] = offset(x0, y0);
  f->offset[1] = offset(x0 + 1, y0);
  f->offset[2] = offset(x0, y0 + 1);
  f->offset[3] = offset(x0 + 1, y0 + 1);
  f->weight[0] = (1.0f - fx) * (1.0f - fy);
  f->weight[1] = fx * (1.0f - fy);
  f->weight[2] = (1.0f - fx) * fy;
  f->weight[3] = fx * fy;
  return true;
}

// <ref, bilinear(level, (x, y))> with zero padding: corners outside the map
// read the zero row.
float SampleDot(const Level& level, const float* item, const float* ref, const float* zeros,
                float x, float y, int64_t channels) {
  Footprint f;
  if (!BilinearFootprint(level, x, y, channels, &f)) return 0.0f;
  const auto corner = [&](int i) { return f.offset[i] >= 0 ? item + f.offset[i] : zeros; };
  return BlendedDot(ref, corner(0), corner(1), corner(2), corner(3), f.weight[0], f.weight[1],
                    f.weight[2], f.weight[3], channels);
}

// out += g * (w0 s0 + w1 s1 + w2 s2 + w3 s3): a sample's gradient to the
// reference feature.
DISPMVS_CPU_CLONES void AddBlend(float* out, float g, const float* s0, const float* s1,
                                 const float* s2, const float* s3, float w0, float w1, float w2,
                                 float w3, int64_t channels) {
  for (int64_t c = 0; c < channels; ++c) {
    out[c] += g * (w0 * s0[c] + w1 * s1[c] + w2 * s2[c] + w3 * s3[c]);
  }
}

// out += a * x: a sample's gradient to one corner's source feature.
DISPMVS_CPU_CLONES void AddScaled(float* out, float a, const float* x, int64_t channels) {
  for (int64_t c = 0; c < channels; ++c) out[c] += a * x[c];
}

void Require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("FusedCorrelationLookup: " + what);
}

bool IsCpuFloat(const torch::Tensor& t) {
  return t.defined() && t.device().is_cpu() && t.scalar_type() == torch::kFloat32;
}

// A reference pixel's samples on one level, in level-l pixels: the centre
// (match + 0.5) / 2^l - 0.5 and the line direction; sample k sits at
// centre + (k - (samples-1)/2) * dir, the ATen path's arithmetic in the same
// order (correlation.h).
struct LevelLine {
  float cx, cy, dx, dy;
  void At(int64_t k, float half_span, float* x, float* y) const {
    const float offset = static_cast<float>(k) - half_span;
    *x = cx + offset * dx;
    *y = cy + offset * dy;
  }
};

// The checked inputs of a lookup, as raw pointers for the passes.
struct Problem {
  std::vector<Level> levels;
  int64_t batch = 0, channels = 0, h = 0, w = 0, samples = 0;
  torch::Tensor match, dir;  // [B,2,h,w] contiguous float
  const float* match_p = nullptr;
  const float* dir_p = nullptr;
  const float* ref = nullptr;
  int64_t ref_stride[4] = {};

  int64_t outputs() const { return static_cast<int64_t>(levels.size()) * samples; }
  float half_span() const { return 0.5f * static_cast<float>(samples - 1); }
  // Reference pixel (b, i, j)'s features into `out` (C floats, any strides).
  void LoadRef(int64_t b, int64_t i, int64_t j, float* out) const {
    const float* p = ref + b * ref_stride[0] + i * ref_stride[2] + j * ref_stride[3];
    for (int64_t c = 0; c < channels; ++c) out[c] = p[c * ref_stride[1]];
  }
  // Reference pixel `pixel` (i * w + j) of pair b on level l: the line its
  // samples lie on, computed once for all of them.
  LevelLine Line(int64_t b, int64_t pixel, size_t l) const {
    const int64_t x_index = (b * 2) * h * w + pixel, y_index = x_index + h * w;
    const float scale = static_cast<float>(int64_t{1} << l);
    return {(match_p[x_index] + 0.5f) / scale - 0.5f, (match_p[y_index] + 0.5f) / scale - 0.5f,
            dir_p[x_index], dir_p[y_index]};
  }
};

Problem CheckProblem(const std::vector<torch::Tensor>& levels_hwc,
                     const torch::Tensor& ref_features, const torch::Tensor& match,
                     const torch::Tensor& dir, int64_t samples) {
  Require(!levels_hwc.empty(), "need at least one level");
  Require(levels_hwc.size() <= 16, "at most 16 levels");
  Require(samples >= 1, "samples must be >= 1");
  Require(IsCpuFloat(ref_features) && ref_features.dim() == 4,
          "ref_features must be a CPU float [B,C,h,w] tensor");
  Problem p;
  p.batch = ref_features.size(0);
  p.channels = ref_features.size(1);
  p.h = ref_features.size(2);
  p.w = ref_features.size(3);
  p.samples = samples;
  for (const torch::Tensor& l : levels_hwc) {
    Require(IsCpuFloat(l) && l.dim() == 4 && l.size(0) == p.batch && l.size(3) == p.channels &&
                l.is_contiguous(),
            "each level must be a contiguous CPU float [B,H,W,C] with the reference's B and C");
    p.levels.push_back({l.data_ptr<float>(), l.size(1), l.size(2), l.stride(0)});
  }
  const std::vector<int64_t> grid2{p.batch, 2, p.h, p.w};
  Require(match.defined() && match.sizes() == torch::IntArrayRef(grid2) && dir.defined() &&
              dir.sizes() == torch::IntArrayRef(grid2),
          "match and dir must be [B,2,h,w] on the reference grid");
  p.match = match.detach().to(torch::kFloat32).contiguous();
  p.dir = dir.detach().to(torch::kFloat32).contiguous();
  p.match_p = p.match.data_ptr<float>();
  p.dir_p = p.dir.data_ptr<float>();
  p.ref = ref_features.data_ptr<float>();
  for (int d = 0; d < 4; ++d) p.ref_stride[d] = ref_features.stride(d);
  return p;
}

// The lookup: [B, levels*samples, h, w].
torch::Tensor LookupPass(const Problem& p, const torch::TensorOptions& options) {
  const int64_t outputs = p.outputs(), plane = p.h * p.w;
  torch::Tensor out = torch::empty({p.batch, outputs, p.h, p.w}, options);
  float* out_p = out.data_ptr<float>();
  const std::vector<float> zeros(static_cast<size_t>(p.channels), 0.0f);
  const float channel_count = static_cast<float>(p.channels);
  const float half_span = p.half_span();
  // One task per image row of one pair: rows are independent.
  at::parallel_for(0, p.batch * p.h, 1, [&](int64_t begin, int64_t end) {
    std::vector<float> ref(static_cast<size_t>(p.channels));
    for (int64_t row = begin; row < end; ++row) {
      const int64_t b = row / p.h, i = row % p.h;
      for (int64_t j = 0; j < p.w; ++j) {
        p.LoadRef(b, i, j, ref.data());
        const int64_t pixel = i * p.w + j;
        for (size_t l = 0; l < p.levels.size(); ++l) {
          const Level& level = p.levels[l];
          const float* item = level.data + b * level.item_stride;
          const LevelLine line = p.Line(b, pixel, l);
          for (int64_t k = 0; k < p.samples; ++k) {
            float x = 0.0f, y = 0.0f;
            line.At(k, half_span, &x, &y);
            const float value =
                SampleDot(level, item, ref.data(), zeros.data(), x, y, p.channels);
            out_p[(b * outputs + static_cast<int64_t>(l) * p.samples + k) * plane + pixel] =
                value / channel_count;
          }
        }
      }
    }
  });
  return out;
}

struct LookupGradients {
  std::vector<torch::Tensor> levels_hwc;  // [B,H_l,W_l,C] each
  torch::Tensor ref;                      // [B,C,h,w] (channels-last strides)
};

// The lookup's gradients w.r.t. the levels and the reference features, for
// grad_cost [B, levels*samples, h, w]: every sample's bilinear weights
// scatter grad * ref into its four source corners and gather grad *
// source into the reference pixel. One task per pair: a pair's samples may
// land on any of its source pixels, and no two tasks write the same one.
LookupGradients LookupGradientPass(const Problem& p, const torch::Tensor& grad_cost) {
  const torch::Tensor grad = grad_cost.to(torch::kFloat32).contiguous();
  const float* grad_p = grad.data_ptr<float>();
  LookupGradients out;
  std::vector<float*> grad_levels;
  for (const Level& level : p.levels) {
    out.levels_hwc.push_back(
        torch::zeros({p.batch, level.height, level.width, p.channels}, grad.options()));
    grad_levels.push_back(out.levels_hwc.back().data_ptr<float>());
  }
  const torch::Tensor grad_ref_hwc = torch::empty({p.batch, p.h, p.w, p.channels}, grad.options());
  float* grad_ref_p = grad_ref_hwc.data_ptr<float>();
  const int64_t outputs = p.outputs(), plane = p.h * p.w;
  const std::vector<float> zeros(static_cast<size_t>(p.channels), 0.0f);
  const float channel_count = static_cast<float>(p.channels);
  const float half_span = p.half_span();
  at::parallel_for(0, p.batch, 1, [&](int64_t begin, int64_t end) {
    std::vector<float> ref(static_cast<size_t>(p.channels));
    for (int64_t b = begin; b < end; ++b) {
      for (int64_t pixel = 0; pixel < plane; ++pixel) {
        p.LoadRef(b, pixel / p.w, pixel % p.w, ref.data());
        float* grad_ref = grad_ref_p + (b * plane + pixel) * p.channels;
        std::fill(grad_ref, grad_ref + p.channels, 0.0f);
        for (size_t l = 0; l < p.levels.size(); ++l) {
          const Level& level = p.levels[l];
          const float* item = level.data + b * level.item_stride;
          float* grad_item = grad_levels[l] + b * level.item_stride;
          const LevelLine line = p.Line(b, pixel, l);
          for (int64_t k = 0; k < p.samples; ++k) {
            const float g =
                grad_p[(b * outputs + static_cast<int64_t>(l) * p.samples + k) * plane + pixel] /
                channel_count;
            if (g == 0.0f) continue;
            float x = 0.0f, y = 0.0f;
            line.At(k, half_span, &x, &y);
            Footprint f;
            if (!BilinearFootprint(level, x, y, p.channels, &f)) continue;
            const auto corner = [&](int c) {
              return f.offset[c] >= 0 ? item + f.offset[c] : zeros.data();
            };
            AddBlend(grad_ref, g, corner(0), corner(1), corner(2), corner(3), f.weight[0],
                     f.weight[1], f.weight[2], f.weight[3], p.channels);
            for (int c = 0; c < 4; ++c) {
              if (f.offset[c] < 0) continue;
              AddScaled(grad_item + f.offset[c], g * f.weight[c], ref.data(), p.channels);
            }
          }
        }
      }
    }
  });
  out.ref = grad_ref_hwc.permute({0, 3, 1, 2});
  return out;
}

// The lookup as an autograd node: gradients to the levels and the
// reference features; none to match and dir (CanUseFusedCorrelation keeps
// lookups that need them on the ATen path).
class LookupFunction : public torch::autograd::Function<LookupFunction> {
 public:
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, torch::TensorList levels_hwc,
                               const torch::Tensor& ref_features, const torch::Tensor& match,
                               const torch::Tensor& dir, int64_t samples) {
    const std::vector<torch::Tensor> levels(levels_hwc.begin(), levels_hwc.end());
    std::vector<torch::Tensor> saved = levels;
    saved.insert(saved.end(), {ref_features, match, dir});
    ctx->save_for_backward(saved);
    ctx->saved_data["samples"] = samples;
    return LookupPass(CheckProblem(levels, ref_features, match, dir, samples),
                      ref_features.options());
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grad_outputs) {
    const std::vector<torch::Tensor> saved = ctx->get_saved_variables();
    const size_t count = saved.size() - 3;
    const std::vector<torch::Tensor> levels(saved.begin(),
                                            saved.begin() + static_cast<std::ptrdiff_t>(count));
    const Problem p = CheckProblem(levels, saved[count], saved[count + 1], saved[count + 2],
                                   ctx->saved_data["samples"].toInt());
    LookupGradients grads = LookupGradientPass(p, grad_outputs.at(0));
    // One gradient per forward argument: each level, ref, match, dir, samples.
    torch::autograd::variable_list out = std::move(grads.levels_hwc);
    out.insert(out.end(), {grads.ref, torch::Tensor(), torch::Tensor(), torch::Tensor()});
    return out;
  }
};

}  // namespace

bool FusedCorrelationTakes(const torch::Tensor& features) { return IsCpuFloat(features); }

bool CanUseFusedCorrelation(const torch::Tensor& source_features,
                            const torch::Tensor& ref_features, const torch::Tensor& match,
                            const torch::Tensor& dir) {
  const bool position_gradient =
      torch::GradMode::is_enabled() && ((match.defined() && match.requires_grad()) ||
                                        (dir.defined() && dir.requires_grad()));
  return IsCpuFloat(source_features) && IsCpuFloat(ref_features) && !position_gradient;
}

torch::Tensor FusedCorrelationLookup(const std::vector<torch::Tensor>& levels_hwc,
                                     const torch::Tensor& ref_features,
                                     const torch::Tensor& match, const torch::Tensor& dir,
                                     int64_t samples) {
  bool wants_gradient = ref_features.defined() && ref_features.requires_grad();
  for (const torch::Tensor& level : levels_hwc) {
    wants_gradient |= level.defined() && level.requires_grad();
  }
  if (!torch::GradMode::is_enabled() || !wants_gradient) {
    return LookupPass(CheckProblem(levels_hwc, ref_features, match, dir, samples),
                      ref_features.options());
  }
  Require(!(match.defined() && match.requires_grad()) && !(dir.defined() && dir.requires_grad()),
          "no gradient w.r.t. match or dir (use the ATen ops for that)");
  return LookupFunction::apply(torch::TensorList(levels_hwc), ref_features, match, dir, samples);
}

}  // namespace dispmvs::model
