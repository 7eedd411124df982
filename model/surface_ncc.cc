#include "model/surface_ncc.h"

#include <ATen/Parallel.h>

#include <cmath>
#include <stdexcept>
#include <string>

#include "model/window_mean.h"

namespace dispmvs::model {
namespace {

namespace F = torch::nn::functional;

void CheckShapes(const torch::Tensor& source, const torch::Tensor& reference,
                 const torch::Tensor& reference_mean, const torch::Tensor& reference_var,
                 const torch::Tensor& a, const torch::Tensor& b, const torch::Tensor& surface) {
  const auto fail = [](const std::string& what) {
    throw std::invalid_argument("CorrelateAlongSurface: " + what);
  };
  if (!source.defined() || source.dim() != 4 || source.size(1) != 1) fail("source must be [B*N,1,H,W]");
  const auto planes = source.sizes();
  for (const torch::Tensor* t : {&reference, &reference_mean, &reference_var}) {
    if (!t->defined() || t->sizes() != planes) fail("the reference tensors must be source's shape");
  }
  const std::vector<int64_t> pair_shape = {source.size(0), 3, source.size(2), source.size(3)};
  const std::vector<int64_t> constant_shape = {source.size(0), 3, 1, 1};
  if (!a.defined() || a.sizes() != torch::IntArrayRef(pair_shape) || !b.defined() ||
      (b.sizes() != a.sizes() && b.sizes() != torch::IntArrayRef(constant_shape))) {
    fail("a must be [B*N,3,H,W] and b [B*N,3,H,W] or [B*N,3,1,1]");
  }
  if (!surface.defined() || surface.dim() != 4 || surface.size(1) != 1 || surface.size(0) < 1 ||
      source.size(0) % surface.size(0) != 0 || surface.size(2) != source.size(2) ||
      surface.size(3) != source.size(3)) {
    fail("surface must be [B,1,H,W] with B dividing source's B*N");
  }
}

// The window products of one source: its sampled values v, v^2 and the
// reference times v ([3,H,W] at `products`), and where the match counts.
// b holds one vector per pixel (b_per_pixel) or one for the whole plane.
void SamplePlane(const float* source, const float* reference, const float* a, const float* b,
                 bool b_per_pixel, const float* surface, int64_t h, int64_t w, double margin,
                 float* products, bool* inside) {
  const int64_t hw = h * w;
  const int64_t b_step = b_per_pixel ? 1 : 0, b_channel = b_per_pixel ? hw : 1;
  const float half_w = 0.5f * static_cast<float>(w - 1), half_h = 0.5f * static_cast<float>(h - 1);
  const float limit_x = half_w - static_cast<float>(margin), limit_y = half_h - static_cast<float>(margin);
  for (int64_t p = 0; p < hw; ++p) {
    const float inverse_depth = surface[p];
    const int64_t q = p * b_step;
    const float px = a[p] + inverse_depth * b[q];
    const float py = a[hw + p] + inverse_depth * b[b_channel + q];
    const float pz = a[2 * hw + p] + inverse_depth * b[2 * b_channel + q];
    const bool in_front = pz > 0 && inverse_depth > 0;
    // Behind the source the match is taken as pixel (0, 0), as the
    // operations' path does; it does not count, but it is in its
    // neighbours' windows all the same.
    const float inverse_z = in_front ? 1.0f / pz : 0.0f;
    const float x = px * inverse_z, y = py * inverse_z;
    inside[p] = in_front && std::abs(x - half_w) <= limit_x && std::abs(y - half_h) <= limit_y;
    // Bilinear, zero outside the image (grid_sample with align_corners).
    float value = 0;
    if (std::isfinite(x) && std::isfinite(y)) {
      const float x0f = std::floor(x), y0f = std::floor(y);
      const int64_t x0 = static_cast<int64_t>(x0f), y0 = static_cast<int64_t>(y0f);
      const float fx = x - x0f, fy = y - y0f;
      const auto at = [&](int64_t yy, int64_t xx) {
        return (xx >= 0 && xx < w && yy >= 0 && yy < h) ? source[yy * w + xx] : 0.0f;
      };
      value = (1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1)) +
              fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1));
    }
    products[p] = value;
    products[hw + p] = value * value;
    products[2 * hw + p] = reference[p] * value;
  }
}

SurfaceCorrelation CorrelateAlongSurfaceCpu(const torch::Tensor& source, const torch::Tensor& reference,
                                            const torch::Tensor& reference_mean,
                                            const torch::Tensor& reference_var, const torch::Tensor& a,
                                            const torch::Tensor& b, const torch::Tensor& surface,
                                            int64_t radius, double margin) {
  const int64_t planes = source.size(0), h = source.size(2), w = source.size(3), hw = h * w;
  const int64_t n = planes / surface.size(0);
  const bool b_per_pixel = b.size(2) == h && b.size(3) == w && hw > 1;
  const int64_t b_plane = b_per_pixel ? 3 * hw : 3;
  const torch::Tensor src = source.contiguous(), ref = reference.contiguous();
  const torch::Tensor a_c = a.contiguous(), b_c = b.contiguous(), surface_c = surface.contiguous();
  torch::Tensor products = torch::empty({planes, 3, h, w}, source.options());
  torch::Tensor inside = torch::empty({planes, 1, h, w}, source.options().dtype(torch::kBool));
  at::parallel_for(0, planes, 1, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      SamplePlane(src.data_ptr<float>() + i * hw, ref.data_ptr<float>() + i * hw,
                  a_c.data_ptr<float>() + i * 3 * hw, b_c.data_ptr<float>() + i * b_plane, b_per_pixel,
                  surface_c.data_ptr<float>() + (i / n) * hw, h, w, margin,
                  products.data_ptr<float>() + i * 3 * hw, inside.data_ptr<bool>() + i * hw);
    }
  });
  const torch::Tensor means = WindowMean(products, radius);
  const torch::Tensor mean_c = reference_mean.contiguous(), var_c = reference_var.contiguous();
  SurfaceCorrelation result;
  result.ncc = torch::empty({planes, 1, h, w}, source.options());
  result.ok = torch::empty_like(inside);
  at::parallel_for(0, planes, 1, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const float* m = means.data_ptr<float>() + i * 3 * hw;
      const float* ref_mean = mean_c.data_ptr<float>() + i * hw;
      const float* ref_var = var_c.data_ptr<float>() + i * hw;
      const bool* in = inside.data_ptr<bool>() + i * hw;
      float* ncc = result.ncc.data_ptr<float>() + i * hw;
      bool* ok = result.ok.data_ptr<bool>() + i * hw;
      for (int64_t p = 0; p < hw; ++p) {
        const float s_mean = m[p];
        const float s_var = std::max(m[hw + p] - s_mean * s_mean, 0.0f);
        const float covariance = m[2 * hw + p] - ref_mean[p] * s_mean;
        ncc[p] = covariance / std::sqrt(std::max(ref_var[p] * s_var, 1e-12f));
        ok[p] = in[p] && s_var > 1e-10f;
      }
    }
  });
  return result;
}

}  // namespace

SurfaceCorrelation CorrelateAlongSurfaceByOps(const torch::Tensor& source, const torch::Tensor& reference,
                                              const torch::Tensor& reference_mean,
                                              const torch::Tensor& reference_var, const torch::Tensor& a,
                                              const torch::Tensor& b, const torch::Tensor& surface,
                                              int64_t radius, double margin) {
  CheckShapes(source, reference, reference_mean, reference_var, a, b, surface);
  const int64_t n = source.size(0) / surface.size(0);
  const int64_t h = source.size(2), w = source.size(3);
  const torch::Tensor per_source = surface.repeat_interleave(n, 0);
  const torch::Tensor projected = a + per_source * b;
  const torch::Tensor z = projected.narrow(1, 2, 1);
  const torch::Tensor in_front = (z > 0) & (per_source > 0);
  const torch::Tensor inverse_z = torch::where(in_front, z.reciprocal(), torch::zeros_like(z));
  const torch::Tensor x = projected.narrow(1, 0, 1) * inverse_z;
  const torch::Tensor y = projected.narrow(1, 1, 1) * inverse_z;
  const double half_w = 0.5 * static_cast<double>(w - 1), half_h = 0.5 * static_cast<double>(h - 1);
  const torch::Tensor inside = in_front & ((x - half_w).abs() <= half_w - margin) &
                               ((y - half_h).abs() <= half_h - margin);
  const double x_scale = 2.0 / static_cast<double>(std::max<int64_t>(w - 1, 1));
  const double y_scale = 2.0 / static_cast<double>(std::max<int64_t>(h - 1, 1));
  const torch::Tensor grid = torch::stack({x.squeeze(1) * x_scale - 1.0, y.squeeze(1) * y_scale - 1.0}, -1);
  const torch::Tensor sampled = F::grid_sample(
      source, grid,
      F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kZeros).align_corners(true));
  // The three window means in one pass.
  const torch::Tensor means = WindowMean(torch::cat({sampled, sampled * sampled, reference * sampled}, 1), radius);
  const torch::Tensor s_mean = means.narrow(1, 0, 1);
  const torch::Tensor s_var = torch::clamp_min(means.narrow(1, 1, 1) - s_mean * s_mean, 0);
  const torch::Tensor covariance = means.narrow(1, 2, 1) - reference_mean * s_mean;
  SurfaceCorrelation result;
  result.ncc = covariance * torch::rsqrt(torch::clamp_min(reference_var * s_var, 1e-12));
  result.ok = inside & (s_var > 1e-10);
  return result;
}

SurfaceCorrelation CorrelateAlongSurface(const torch::Tensor& source, const torch::Tensor& reference,
                                         const torch::Tensor& reference_mean,
                                         const torch::Tensor& reference_var, const torch::Tensor& a,
                                         const torch::Tensor& b, const torch::Tensor& surface,
                                         int64_t radius, double margin) {
  CheckShapes(source, reference, reference_mean, reference_var, a, b, surface);
  bool cpu_float = true;
  for (const torch::Tensor* t : {&source, &reference, &reference_mean, &reference_var, &a, &b, &surface}) {
    cpu_float = cpu_float && t->device().is_cpu() && t->scalar_type() == torch::kFloat32;
  }
  if (cpu_float) {
    return CorrelateAlongSurfaceCpu(source, reference, reference_mean, reference_var, a, b, surface, radius,
                                    margin);
  }
  return CorrelateAlongSurfaceByOps(source, reference, reference_mean, reference_var, a, b, surface, radius,
                                    margin);
}

}  // namespace dispmvs::model
