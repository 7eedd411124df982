#include "synth/texture.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "synth/hash_noise.h"
#include "synth/rng.h"

namespace dispmvs::synth {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kDetailOctaves = 4;

torch::Tensor Fract(const torch::Tensor& x) { return x - torch::floor(x); }

// Grey level in [0, 1) per integer cell.
torch::Tensor CellValue(const torch::Tensor& cu, const torch::Tensor& cv, uint32_t seed,
                        torch::ScalarType dtype) {
  return HashUnit(cu.to(torch::kLong), cv.to(torch::kLong), seed, dtype);
}

// Voronoi cells: each lattice cell holds one jittered site; a point takes the
// grey level of its nearest site. Cell borders are straight, so the regions
// are convex polygons with hard edges.
torch::Tensor Polygons(const torch::Tensor& u, const torch::Tensor& v, uint32_t seed) {
  const auto dtype = u.scalar_type();
  const torch::Tensor iu = torch::floor(u).to(torch::kLong), iv = torch::floor(v).to(torch::kLong);
  torch::Tensor best_d2 = torch::full_like(u, 1e9);
  torch::Tensor best_u = iu, best_v = iv;
  for (int64_t du = -1; du <= 1; ++du) {
    for (int64_t dv = -1; dv <= 1; ++dv) {
      const torch::Tensor cu = iu + du, cv = iv + dv;
      // One 32-bit hash per cell: its low and high 16 bits place the site.
      const torch::Tensor bits = HashCellBits(cu, cv, seed);
      const torch::Tensor site_u = cu.to(dtype) + torch::bitwise_and(bits, 0xFFFF).to(dtype) * (1.0 / 65536);
      const torch::Tensor site_v = cv.to(dtype) + torch::div(bits, 65536, "floor").to(dtype) * (1.0 / 65536);
      const torch::Tensor d2 = (u - site_u).square() + (v - site_v).square();
      const torch::Tensor closer = d2 < best_d2;
      best_d2 = torch::where(closer, d2, best_d2);
      best_u = torch::where(closer, cu, best_u);
      best_v = torch::where(closer, cv, best_v);
    }
  }
  return HashUnit(best_u, best_v, seed + 2u, dtype);
}

// Pattern value p in [0, 1] of one texture at (u, v) (already scaled by the
// texture frequency where the pattern has cells).
torch::Tensor PatternValue(const TextureSpec& spec, const torch::Tensor& u, const torch::Tensor& v) {
  const auto dtype = u.scalar_type();
  const double c = std::cos(spec.angle), s = std::sin(spec.angle);
  const torch::Tensor ru = (u * c + v * s) * spec.frequency;  // rotated, scaled coordinates
  const torch::Tensor rv = (v * c - u * s) * spec.frequency;
  switch (spec.pattern) {
    case Pattern::kNoise:
      // Stretch the noise histogram a little: raw fBm clusters around 0.5.
      return torch::clamp((FractalNoise(ru, rv, spec.seed, spec.octaves) - 0.5) * 2.2 + 0.5, 0, 1);
    case Pattern::kPolygons:
      return Polygons(ru, rv, spec.seed);
    case Pattern::kStripes:
      return CellValue(torch::floor(ru), torch::zeros_like(ru), spec.seed, dtype);
    case Pattern::kBricks: {
      const torch::Tensor row = torch::floor(rv);
      // Odd rows shift by half a brick; bricks are twice as long as high.
      const torch::Tensor along = ru * 0.5 + 0.5 * torch::remainder(row, 2.0);
      const torch::Tensor col = torch::floor(along);
      const torch::Tensor mortar = (Fract(along) < 0.05) | (Fract(rv) < 0.1);
      const torch::Tensor brick = spec.jitter * CellValue(col, row, spec.seed, dtype);
      return torch::where(mortar, torch::ones_like(ru), brick);
    }
    case Pattern::kChecker: {
      const torch::Tensor cu = torch::floor(ru), cv = torch::floor(rv);
      const torch::Tensor parity = torch::remainder(cu + cv, 2.0);
      const torch::Tensor jitter = spec.jitter * (CellValue(cu, cv, spec.seed, dtype) - 0.5);
      return torch::clamp(parity * 0.8 + 0.1 + jitter, 0, 1);
    }
    case Pattern::kGradient:
      return 0.5 + 0.5 * torch::sin(ru * (2 * kPi));
    case Pattern::kFlat:
      return torch::zeros_like(ru);
  }
  throw std::logic_error("PatternValue: unknown pattern");
}

// Mirrored repeat of t onto [0, 1]: 1 - |(t mod 2) - 1|.
torch::Tensor MirroredRepeat(const torch::Tensor& t) {
  return 1.0 - (torch::remainder(t, 2.0) - 1.0).abs();
}

// The base colour [n,3] of a photo texture at (u, v) (see texture.h).
torch::Tensor PhotoColor(const TextureSpec& spec, const torch::Tensor& photo, const torch::Tensor& u,
                         const torch::Tensor& v) {
  const double c = std::cos(spec.angle), s = std::sin(spec.angle);
  const torch::Tensor ru = (u * c + v * s) * spec.frequency;
  const torch::Tensor rv = (v * c - u * s) * spec.frequency;
  const double height = static_cast<double>(photo.size(1));
  const double width = static_cast<double>(photo.size(2));
  // grid_sample with align_corners=true: -1 and 1 are the centres of the
  // first and last pixels, i.e. pixel x = (g + 1) / 2 * (W - 1).
  const torch::Tensor gx = MirroredRepeat(ru) * 2.0 - 1.0;
  const torch::Tensor gy = MirroredRepeat(rv * (width / height)) * 2.0 - 1.0;
  const torch::Tensor grid = torch::stack({gx, gy}, -1).view({1, 1, -1, 2});
  const torch::Tensor image = photo.to(u.options()).unsqueeze(0);  // [1,3,H,W]
  namespace F = torch::nn::functional;
  const torch::Tensor sampled = F::grid_sample(
      image, grid,
      F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kBorder).align_corners(true));
  return sampled.view({3, -1}).t();  // [n,3]
}

std::array<double, 3> RandomColor(Rng& rng) {
  // A random hue at moderate saturation and a brightness spread like natural
  // reflectances (rarely pure black or white, which would clip).
  const double brightness = rng.Uniform(0.08, 0.9);
  std::array<double, 3> color;
  const double saturation = rng.Uniform(0.0, 0.6);
  for (double& channel : color) channel = brightness * (1.0 - saturation * rng.Uniform());
  return color;
}

}  // namespace

TextureSpec RandomTexture(Rng& rng) {
  TextureSpec spec;
  spec.pattern = static_cast<Pattern>(rng.Int(0, kNumPatterns - 1));
  spec.color_a = RandomColor(rng);
  spec.color_b = RandomColor(rng);
  spec.angle = rng.Uniform(0, kPi);
  spec.octaves = static_cast<int>(rng.Int(3, 6));
  spec.jitter = rng.Uniform(0.1, 0.6);
  spec.seed = static_cast<uint32_t>(rng.NextU64() >> 32);
  switch (spec.pattern) {
    case Pattern::kNoise: spec.frequency = rng.LogUniform(1, 8); break;
    case Pattern::kPolygons: spec.frequency = rng.LogUniform(1.5, 10); break;
    case Pattern::kStripes: spec.frequency = rng.LogUniform(2, 16); break;
    case Pattern::kBricks: spec.frequency = rng.LogUniform(3, 12); break;
    case Pattern::kChecker: spec.frequency = rng.LogUniform(2, 12); break;
    case Pattern::kGradient: spec.frequency = rng.LogUniform(0.1, 0.6); break;
    case Pattern::kFlat: spec.frequency = 1; break;
  }
  const bool low_texture = spec.pattern == Pattern::kFlat || spec.pattern == Pattern::kGradient;
  spec.detail = low_texture ? rng.Uniform(0.0, 0.03) : rng.Uniform(0.05, 0.35);
  spec.detail_frequency = rng.LogUniform(4, 32);
  return spec;
}

TextureSpec RandomPhotoTexture(Rng& rng, int num_photos) {
  if (num_photos < 1) throw std::invalid_argument("RandomPhotoTexture: no photos");
  TextureSpec spec;
  spec.photo = static_cast<int>(rng.Int(0, num_photos - 1));
  spec.frequency = rng.LogUniform(0.5, 3);
  spec.angle = rng.Uniform(0, 2 * kPi);
  spec.detail = rng.Uniform(0.0, 0.1);
  spec.detail_frequency = rng.LogUniform(4, 32);
  spec.seed = static_cast<uint32_t>(rng.NextU64() >> 32);
  return spec;
}

void CheckPhotoSet(const PhotoSet& photos) {
  for (size_t i = 0; i < photos.size(); ++i) {
    const torch::Tensor& p = photos[i];
    if (!p.defined() || p.dim() != 3 || p.size(0) != 3 || p.size(1) < 2 || p.size(2) < 2 ||
        !p.is_floating_point() || !p.device().is_cpu()) {
      throw std::invalid_argument("photo " + std::to_string(i) +
                                  ": expected a floating [3,H,W] CPU tensor with H, W >= 2");
    }
  }
}

torch::Tensor EvaluateAlbedo(const std::vector<TextureSpec>& textures,
                             const torch::Tensor& texture, const torch::Tensor& uv,
                             const std::array<double, 3>& empty_color, const PhotoSet* photos) {
  if (texture.dim() != 1 || uv.dim() != 2 || uv.size(1) != 2 || uv.size(0) != texture.size(0)) {
    throw std::invalid_argument("EvaluateAlbedo: expected texture [N] and uv [N,2]");
  }
  const auto options = uv.options();
  torch::Tensor albedo = torch::tensor({empty_color[0], empty_color[1], empty_color[2]}, options)
                             .expand({texture.size(0), 3})
                             .contiguous();
  if (texture.numel() == 0) return albedo;
  const int64_t max_id = texture.max().item<int64_t>();
  const int64_t min_id = texture.min().item<int64_t>();
  if (min_id < -1 || max_id >= static_cast<int64_t>(textures.size())) {
    throw std::invalid_argument("EvaluateAlbedo: texture index out of range [-1, " +
                                std::to_string(textures.size()) + ")");
  }
  // Base colour: one pass per texture over the points that use it, so each
  // pattern's parameters stay plain scalars.
  for (int64_t t = 0; t <= max_id; ++t) {
    const torch::Tensor index = torch::nonzero(texture == t).squeeze(1);
    if (index.numel() == 0) continue;
    const TextureSpec& spec = textures[static_cast<size_t>(t)];
    const torch::Tensor points = uv.index_select(0, index);
    if (spec.photo >= 0) {
      if (photos == nullptr || spec.photo >= static_cast<int>(photos->size())) {
        throw std::invalid_argument("EvaluateAlbedo: texture " + std::to_string(t) + " uses photo " +
                                    std::to_string(spec.photo) + ", which the photo set does not hold");
      }
      albedo.index_copy_(0, index,
                         PhotoColor(spec, (*photos)[static_cast<size_t>(spec.photo)],
                                    points.select(1, 0), points.select(1, 1)));
      continue;
    }
    const torch::Tensor p = PatternValue(spec, points.select(1, 0), points.select(1, 1)).unsqueeze(1);  // [n,1]
    const torch::Tensor a = torch::tensor({spec.color_a[0], spec.color_a[1], spec.color_a[2]}, options);
    const torch::Tensor b = torch::tensor({spec.color_b[0], spec.color_b[1], spec.color_b[2]}, options);
    albedo.index_copy_(0, index, a + (b - a) * p);
  }
  // Detail layer: the same kind of noise for every texture, so it runs once
  // over all surface points with per-point frequency, seed and amplitude
  // (per-texture passes would repeat its ~100 tensor ops per texture).
  const torch::Tensor surface = torch::nonzero(texture >= 0).squeeze(1);
  if (surface.numel() > 0) {
    std::vector<double> frequency, amplitude;
    std::vector<int64_t> seed;
    for (const TextureSpec& spec : textures) {
      frequency.push_back(spec.detail_frequency);
      amplitude.push_back(spec.detail);
      seed.push_back(static_cast<int64_t>(spec.seed ^ 0xA5A5A5A5u));
    }
    const torch::Tensor id = texture.index_select(0, surface);
    const torch::Tensor f = torch::tensor(frequency, torch::kDouble).to(options).index_select(0, id);
    const torch::Tensor amp = torch::tensor(amplitude, torch::kDouble).to(options).index_select(0, id);
    const torch::Tensor s = torch::tensor(seed, torch::kLong).to(options.device()).index_select(0, id);
    const torch::Tensor points = uv.index_select(0, surface);
    const torch::Tensor detail = FractalNoise(points.select(1, 0) * f, points.select(1, 1) * f, s, kDetailOctaves);
    const torch::Tensor gain = (1.0 + amp * 2.0 * (detail - 0.5)).unsqueeze(1);
    albedo.index_copy_(0, surface, torch::clamp(albedo.index_select(0, surface) * gain, 0, 1));
  }
  return albedo;
}

}  // namespace dispmvs::synth
