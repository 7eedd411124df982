#include "model/correlation_cpu.h"

#include <ATen/Parallel.h>

#include <cmath>
#include <stdexcept>
#include <string>

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

// <ref, bilinear(level, (x, y))> with zero padding: corners outside the map
// read the zero row. A sample with no corner inside (or a non-finite
// coordinate, for which every comparison is false) is 0.
float SampleDot(const Level& level, const float* item, const float* ref, const float* zeros,
                float x, float y, int64_t channels) {
  if (!(x > -1.0f && x < static_cast<float>(level.width) && y > -1.0f &&
        y < static_cast<float>(level.height))) {
    return 0.0f;
  }
  const float x0f = std::floor(x), y0f = std::floor(y);
  const float fx = x - x0f, fy = y - y0f;
  const int64_t x0 = static_cast<int64_t>(x0f), y0 = static_cast<int64_t>(y0f);
  const auto corner = [&](int64_t cx, int64_t cy) {
    return cx >= 0 && cx < level.width && cy >= 0 && cy < level.height
               ? item + (cy * level.width + cx) * channels
               : zeros;
  };
  return BlendedDot(ref, corner(x0, y0), corner(x0 + 1, y0), corner(x0, y0 + 1),
                    corner(x0 + 1, y0 + 1), (1.0f - fx) * (1.0f - fy), fx * (1.0f - fy),
                    (1.0f - fx) * fy, fx * fy, channels);
}

void Require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("FusedCorrelationLookup: " + what);
}

bool IsCpuFloat(const torch::Tensor& t) {
  return t.defined() && t.device().is_cpu() && t.scalar_type() == torch::kFloat32;
}

}  // namespace

bool CanUseFusedCorrelation(const torch::Tensor& source_features,
                            const torch::Tensor& ref_features) {
  return !torch::GradMode::is_enabled() && IsCpuFloat(source_features) &&
         IsCpuFloat(ref_features);
}

torch::Tensor FusedCorrelationLookup(const std::vector<torch::Tensor>& levels_hwc,
                                     const torch::Tensor& ref_features,
                                     const torch::Tensor& match, const torch::Tensor& dir,
                                     int64_t samples) {
  Require(!levels_hwc.empty(), "need at least one level");
  Require(samples >= 1, "samples must be >= 1");
  Require(IsCpuFloat(ref_features) && ref_features.dim() == 4,
          "ref_features must be a CPU float [B,C,h,w] tensor");
  const int64_t batch = ref_features.size(0), channels = ref_features.size(1);
  const int64_t h = ref_features.size(2), w = ref_features.size(3);
  std::vector<Level> levels;
  for (const torch::Tensor& l : levels_hwc) {
    Require(IsCpuFloat(l) && l.dim() == 4 && l.size(0) == batch && l.size(3) == channels &&
                l.is_contiguous(),
            "each level must be a contiguous CPU float [B,H,W,C] with the reference's B and C");
    levels.push_back({l.data_ptr<float>(), l.size(1), l.size(2), l.stride(0)});
  }
  const std::vector<int64_t> grid2{batch, 2, h, w};
  Require(match.defined() && match.sizes() == torch::IntArrayRef(grid2) && dir.defined() &&
              dir.sizes() == torch::IntArrayRef(grid2),
          "match and dir must be [B,2,h,w] on the reference grid");
  const torch::Tensor match_c = match.to(torch::kFloat32).contiguous();
  const torch::Tensor dir_c = dir.to(torch::kFloat32).contiguous();
  const float* match_p = match_c.data_ptr<float>();
  const float* dir_p = dir_c.data_ptr<float>();
  const float* ref_p = ref_features.data_ptr<float>();
  const int64_t rs0 = ref_features.stride(0), rs1 = ref_features.stride(1),
                rs2 = ref_features.stride(2), rs3 = ref_features.stride(3);

  const int64_t outputs = static_cast<int64_t>(levels.size()) * samples;
  torch::Tensor out = torch::empty({batch, outputs, h, w}, ref_features.options());
  float* out_p = out.data_ptr<float>();
  const int64_t plane = h * w;
  const std::vector<float> zeros(static_cast<size_t>(channels), 0.0f);
  const float half_span = 0.5f * static_cast<float>(samples - 1);
  const float channel_count = static_cast<float>(channels);

  // One task per image row of one pair: rows are independent.
  at::parallel_for(0, batch * h, 1, [&](int64_t begin, int64_t end) {
    std::vector<float> ref(static_cast<size_t>(channels));
    for (int64_t row = begin; row < end; ++row) {
      const int64_t b = row / h, i = row % h;
      for (int64_t j = 0; j < w; ++j) {
        for (int64_t c = 0; c < channels; ++c) {
          ref[static_cast<size_t>(c)] = ref_p[b * rs0 + c * rs1 + i * rs2 + j * rs3];
        }
        const int64_t pixel = i * w + j;
        const float mx = match_p[(b * 2) * plane + pixel];
        const float my = match_p[(b * 2 + 1) * plane + pixel];
        const float dx = dir_p[(b * 2) * plane + pixel];
        const float dy = dir_p[(b * 2 + 1) * plane + pixel];
        for (size_t l = 0; l < levels.size(); ++l) {
          const Level& level = levels[l];
          const float scale = static_cast<float>(int64_t{1} << l);
          // The ATen path's arithmetic, in the same order.
          const float cx = (mx + 0.5f) / scale - 0.5f;
          const float cy = (my + 0.5f) / scale - 0.5f;
          const float* item = level.data + b * level.item_stride;
          for (int64_t k = 0; k < samples; ++k) {
            const float offset = static_cast<float>(k) - half_span;
            const float value = SampleDot(level, item, ref.data(), zeros.data(),
                                          cx + offset * dx, cy + offset * dy, channels);
            out_p[(b * outputs + static_cast<int64_t>(l) * samples + k) * plane + pixel] =
                value / channel_count;
          }
        }
      }
    }
  });
  return out;
}

}  // namespace dispmvs::model
