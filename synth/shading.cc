#include "synth/shading.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "synth/hash_noise.h"
#include "synth/jpeg.h"
#include "synth/rng.h"

namespace dispmvs::synth {
namespace {

// Separable Gaussian blur of [3,H,W] with edge replication.
torch::Tensor GaussianBlur(const torch::Tensor& image, double sigma) {
  const int64_t radius = std::max<int64_t>(1, static_cast<int64_t>(std::ceil(2.5 * sigma)));
  std::vector<double> taps;
  double sum = 0;
  for (int64_t k = -radius; k <= radius; ++k) {
    taps.push_back(std::exp(-0.5 * static_cast<double>(k * k) / (sigma * sigma)));
    sum += taps.back();
  }
  for (double& tap : taps) tap /= sum;
  const torch::Tensor kernel = torch::tensor(taps, torch::kDouble).to(image.options());
  const int64_t size = 2 * radius + 1;
  namespace F = torch::nn::functional;
  torch::Tensor x = F::pad(image.unsqueeze(0), F::PadFuncOptions({radius, radius, radius, radius})
                                                   .mode(torch::kReplicate));
  x = F::conv2d(x, kernel.view({1, 1, 1, size}).expand({3, 1, 1, size}), F::Conv2dFuncOptions().groups(3));
  x = F::conv2d(x, kernel.view({1, 1, size, 1}).expand({3, 1, size, 1}), F::Conv2dFuncOptions().groups(3));
  return x.squeeze(0);
}

}  // namespace

void ViewPhotometry::Check() const {
  const bool ok = gain > 0 && gain < 100 && gamma > 0.1 && gamma < 10 && noise_sigma >= 0 &&
                  noise_sigma < 1 && blur_sigma >= 0 && blur_sigma <= 10 && white_balance[0] > 0 &&
                  white_balance[1] > 0 && white_balance[2] > 0 && vignetting >= 0 && vignetting <= 0.9 &&
                  jpeg_quality >= 0 && jpeg_quality <= 100;
  if (!ok) throw std::invalid_argument("ViewPhotometry: value out of range");
}

ViewPhotometry RandomPhotometry(const PhotometryRanges& ranges, Rng& rng) {
  ViewPhotometry p;
  p.gain = rng.LogUniform(ranges.gain_min, ranges.gain_max);
  for (double& w : p.white_balance) w = rng.Uniform(1 - ranges.white_balance_jitter, 1 + ranges.white_balance_jitter);
  p.gamma = rng.LogUniform(ranges.gamma_min, ranges.gamma_max);
  p.noise_sigma = rng.Uniform(0, ranges.noise_sigma_max);
  p.blur_sigma = rng.Uniform(0, ranges.blur_sigma_max);
  p.noise_seed = static_cast<uint32_t>(rng.NextU64() >> 32);
  // Drawn last and only when enabled: without it every other draw, and so
  // every scene, is what it was before the knob existed.
  if (ranges.vignetting_max > 0) p.vignetting = rng.Uniform(0, ranges.vignetting_max);
  return p;
}

PhotometryRanges WidePhotometry() {
  PhotometryRanges r;
  r.gain_min = 0.5;
  r.gain_max = 2.0;
  r.white_balance_jitter = 0.15;
  r.gamma_min = 0.7;
  r.gamma_max = 1.4;
  r.vignetting_max = 0.4;
  return r;
}

torch::Tensor ShadeLambertian(const torch::Tensor& albedo, const torch::Tensor& normal, const Vec3& light,
                              double ambient) {
  if (albedo.dim() != 3 || albedo.size(0) != 3 || normal.dim() != 3 || normal.size(2) != 3 ||
      normal.size(0) != albedo.size(1) || normal.size(1) != albedo.size(2)) {
    throw std::invalid_argument("ShadeLambertian: expected albedo [3,H,W] and normal [H,W,3]");
  }
  const torch::Tensor l = torch::tensor({light.x, light.y, light.z}, torch::kDouble).to(normal.options());
  const torch::Tensor cosine = torch::clamp_min((normal * l).sum(2), 0);  // [H,W]
  return albedo * (ambient + (1.0 - ambient) * cosine).unsqueeze(0);
}

torch::Tensor ShadeSpecular(const torch::Tensor& normal, const torch::Tensor& view, const Vec3& light,
                            const torch::Tensor& specular, const torch::Tensor& shininess) {
  if (normal.dim() != 3 || normal.size(2) != 3 || view.sizes() != normal.sizes() || specular.dim() != 2 ||
      specular.size(0) != normal.size(0) || specular.size(1) != normal.size(1) ||
      shininess.sizes() != specular.sizes()) {
    throw std::invalid_argument("ShadeSpecular: expected normal and view [H,W,3], specular and shininess [H,W]");
  }
  const torch::Tensor l = torch::tensor({light.x, light.y, light.z}, torch::kDouble).to(normal.options());
  const torch::Tensor half = view + l;  // [H,W,3], unit after the division below
  const torch::Tensor half_unit = half / torch::clamp_min(half.norm(2, 2, true), 1e-12);
  const torch::Tensor n_dot_h = torch::clamp_min((normal * half_unit).sum(2), 0);
  const torch::Tensor lit = (normal * l).sum(2) > 0;
  return torch::where(lit, specular * torch::pow(n_dot_h, shininess), torch::zeros_like(specular));
}

torch::Tensor ApplyPhotometry(const torch::Tensor& radiance, const ViewPhotometry& photometry) {
  photometry.Check();
  if (radiance.dim() != 3 || radiance.size(0) != 3) throw std::invalid_argument("ApplyPhotometry: expected [3,H,W]");
  torch::Tensor x = radiance;
  if (photometry.blur_sigma > 0.05) x = GaussianBlur(x, photometry.blur_sigma);
  const auto& wb = photometry.white_balance;
  x = x * (torch::tensor({wb[0], wb[1], wb[2]}, torch::kDouble).to(x.options()).view({3, 1, 1}) * photometry.gain);
  if (photometry.vignetting > 0) {
    // rho^2 about the centre of the pixel grid ((w - 1) / 2, (h - 1) / 2), 1 at the corner pixels' centres.
    const int64_t h = x.size(1), w = x.size(2);
    const double cy = 0.5 * static_cast<double>(h - 1), cx = 0.5 * static_cast<double>(w - 1);
    const double corner2 = std::max(cx * cx + cy * cy, 1e-12);
    const torch::Tensor dy = torch::arange(h, x.options()).sub(cy).view({h, 1});
    const torch::Tensor dx = torch::arange(w, x.options()).sub(cx).view({1, w});
    x = x * (1.0 - photometry.vignetting * (dy * dy + dx * dx) / corner2).unsqueeze(0);
  }
  if (photometry.noise_sigma > 0) {
    // Noise keyed by (pixel, channel) and the view's seed: reproducible on any device.
    const int64_t h = x.size(1), w = x.size(2);
    const auto long_options = x.options().dtype(torch::kLong);
    // Lattice x = column + channel * 2^14 (images are at most 16384 wide), y = row.
    const torch::Tensor col = torch::arange(w, long_options).view({1, 1, w});
    const torch::Tensor channel = torch::arange(3, long_options).view({3, 1, 1}) * 16384;
    const torch::Tensor row = torch::arange(h, long_options).view({1, h, 1}).expand({3, h, w});
    x = x + photometry.noise_sigma * HashNormal((col + channel).expand({3, h, w}), row,
                                                photometry.noise_seed, x.scalar_type());
  }
  x = torch::pow(torch::clamp(x, 0, 1), 1.0 / photometry.gamma);
  if (photometry.jpeg_quality > 0) x = JpegRoundTrip(x, photometry.jpeg_quality);
  return x;
}

}  // namespace dispmvs::synth
