#include "synth/generator.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <tuple>

#include "synth/raycast.h"
#include "synth/rng.h"
#include "synth/scene_builder.h"
#include "synth/texture.h"

namespace dispmvs::synth {
namespace {

// Independent random streams, so that e.g. the drawn scale does not change
// which scene a seed gives.
enum Stream : uint64_t { kRigStream = 1, kSceneStream = 2, kPhotometryStream = 3, kScaleStream = 4, kMaterialStream = 5,
                        kJpegStream = 6 };

RigKind DrawRig(const SynthConfig& c, Rng& rng) {
  const double weights[kNumRigKinds] = {c.p_table, c.p_walkthrough, c.p_turntable, c.p_outdoor};
  double total = 0;
  for (double w : weights) total += w;
  double pick = rng.Uniform() * total;
  for (int k = 0; k < kNumRigKinds; ++k) {
    if (weights[k] > 0 && pick < weights[k]) return static_cast<RigKind>(k);
    pick -= weights[k];
  }
  // Rounding left `pick` at the top: the last rig with positive weight.
  for (int k = kNumRigKinds - 1; k >= 0; --k)
    if (weights[k] > 0) return static_cast<RigKind>(k);
  throw std::logic_error("DrawRig: no rig has positive probability");
}

torch::Tensor IntrinsicsMatrix(const PinholeCamera& cam) {
  return torch::tensor({cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0}, torch::kDouble).view({3, 3});
}

torch::Tensor WorldToCamera(const PinholeCamera& cam, double scale) {
  torch::Tensor m = torch::eye(4, torch::kDouble);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m[r][c] = cam.rotation(r, c);
    m[r][3] = scale * cam.translation[r];
  }
  return m;
}

// Photometry ranges at difficulty d: every range pulled towards its neutral
// value (1 for gain, gamma and white balance; 0 for noise and blur) by d.
PhotometryRanges EasierPhotometry(const PhotometryRanges& r, double d) {
  const auto towards_one = [&](double x) { return 1.0 + d * (x - 1.0); };
  PhotometryRanges out = r;
  out.gain_min = towards_one(r.gain_min);
  out.gain_max = towards_one(r.gain_max);
  out.gamma_min = towards_one(r.gamma_min);
  out.gamma_max = towards_one(r.gamma_max);
  out.white_balance_jitter = d * r.white_balance_jitter;
  out.noise_sigma_max = d * r.noise_sigma_max;
  out.blur_sigma_max = d * r.blur_sigma_max;
  out.vignetting_max = d * r.vignetting_max;
  return out;
}

// Per-primitive values a view's pixels look up by the primitive they hit,
// with one more entry at the end for pixels that hit nothing.
struct PrimitiveTables {
  torch::Tensor texture;               // [P+1] int64, -1 last
  torch::Tensor specular, shininess;   // [P+1] floating, 0 last; undefined when no primitive is glossy
};

PrimitiveTables MakePrimitiveTables(const SynthScene& s, const torch::TensorOptions& real) {
  std::vector<int64_t> texture_ids;
  std::vector<double> specular, shininess;
  bool glossy = false;
  for (const Primitive& p : s.scene.primitives) {
    texture_ids.push_back(p.texture);
    specular.push_back(p.specular);
    shininess.push_back(p.shininess);
    glossy = glossy || p.specular > 0;
  }
  texture_ids.push_back(-1);
  specular.push_back(0);
  shininess.push_back(1);
  PrimitiveTables tables;
  tables.texture = torch::tensor(texture_ids, torch::kLong).to(real.device());
  if (glossy) {
    tables.specular = torch::tensor(specular, torch::kDouble).to(real);
    tables.shininess = torch::tensor(shininess, torch::kDouble).to(real);
  }
  return tables;
}

// Radiance [3,H,W] of the hits [H,W] of one view: Lambertian, plus the
// glossy primitives' highlights.
torch::Tensor ShadeHits(const SynthScene& s, const SynthConfig& config, const RayHits& hits,
                        const PrimitiveTables& tables) {
  const int64_t height = hits.depth.size(0), width = hits.depth.size(1);
  const torch::Tensor flat_primitive = hits.primitive.reshape({-1});
  const torch::Tensor entry = torch::where(flat_primitive >= 0, flat_primitive, tables.texture.size(0) - 1);
  const torch::Tensor texture = tables.texture.index_select(0, entry);
  const torch::Tensor albedo = EvaluateAlbedo(s.scene.textures, texture, hits.uv.reshape({-1, 2}), s.scene.empty_color,
                                              config.photos.get())
                                   .t()
                                   .reshape({3, height, width});
  torch::Tensor radiance = ShadeLambertian(albedo, hits.normal, s.scene.light_direction, s.scene.ambient);
  if (tables.specular.defined()) {
    const torch::Tensor specular = tables.specular.index_select(0, entry).view({height, width});
    const torch::Tensor shininess = tables.shininess.index_select(0, entry).view({height, width});
    const torch::Tensor view = -hits.direction / hits.direction.norm(2, 2, true);  // towards the camera
    radiance = radiance + ShadeSpecular(hits.normal, view, s.scene.light_direction, specular, shininess).unsqueeze(0);
  }
  return radiance;
}

}  // namespace

void SynthConfig::Check() const {
  auto fail = [](const std::string& what) { throw std::invalid_argument("SynthConfig: " + what); };
  if (height < 8 || width < 8 || height > 8192 || width > 8192) fail("height and width must be in [8, 8192]");
  if (num_views < 2 || num_views > 64) fail("num_views must be in [2, 64]");
  const double p[] = {p_table, p_walkthrough, p_turntable, p_outdoor};
  double total = 0;
  for (double x : p) {
    if (!(x >= 0) || !std::isfinite(x)) fail("rig probabilities must be finite and >= 0");
    total += x;
  }
  if (!(total > 0)) fail("at least one rig probability must be positive");
  if (min_objects < 0 || max_objects < min_objects || max_objects > 1000) fail("need 0 <= min_objects <= max_objects <= 1000");
  if (!(scale_min > 0) || !(scale_max >= scale_min) || !std::isfinite(scale_max)) fail("need 0 < scale_min <= scale_max < inf");
  if (!(intrinsics.fov_min_deg >= 5) || !(intrinsics.fov_max_deg >= intrinsics.fov_min_deg) ||
      !(intrinsics.fov_max_deg <= 150)) {
    fail("field of view range must lie in [5, 150] degrees");
  }
  if (!(intrinsics.focal_jitter >= 0 && intrinsics.focal_jitter < 0.5) ||
      !(intrinsics.principal_jitter >= 0 && intrinsics.principal_jitter < 0.1)) {
    fail("focal_jitter must be in [0, 0.5) and principal_jitter in [0, 0.1)");
  }
  const PhotometryRanges& ph = photometry;
  if (!(ph.gain_min > 0 && ph.gain_max >= ph.gain_min && ph.gain_max < 100 && ph.gamma_min > 0.1 &&
        ph.gamma_max >= ph.gamma_min && ph.gamma_max < 10 && ph.white_balance_jitter >= 0 &&
        ph.white_balance_jitter < 1 && ph.noise_sigma_max >= 0 && ph.noise_sigma_max < 1 &&
        ph.blur_sigma_max >= 0 && ph.blur_sigma_max <= 10 && ph.vignetting_max >= 0 && ph.vignetting_max <= 0.9)) {
    fail("photometry ranges out of bounds");
  }
  const bool jpeg_off = jpeg_quality_min == 0 && jpeg_quality_max == 0;
  if (!jpeg_off && !(jpeg_quality_min >= 1 && jpeg_quality_max >= jpeg_quality_min && jpeg_quality_max <= 100)) {
    fail("JPEG quality range must be 1 <= min <= max <= 100 (or both 0: none), got " +
         std::to_string(jpeg_quality_min) + ", " + std::to_string(jpeg_quality_max));
  }
  if (dtype != torch::kFloat && dtype != torch::kDouble) fail("dtype must be float32 or float64");
  if (!(difficulty >= 0 && difficulty <= 1)) fail("difficulty must be in [0, 1]");
  if (!(photo_probability >= 0 && photo_probability <= 1)) fail("photo_probability must be in [0, 1]");
  if (photos) CheckPhotoSet(*photos);
  if (!(specular_probability >= 0 && specular_probability <= 1)) fail("specular_probability must be in [0, 1]");
  if (supersampling < 1 || supersampling > 7 || supersampling % 2 == 0) {
    fail("supersampling must be odd and in [1, 7], got " + std::to_string(supersampling));
  }
  if (march_steps < 1 || march_steps > 256 || bisection_steps < 0 || bisection_steps > 64) {
    fail("march_steps must be in [1, 256] and bisection_steps in [0, 64]");
  }
}

SynthScene DrawScene(const SynthConfig& config, uint64_t seed) {
  config.Check();
  Rng root(seed);
  Rng rig_rng = root.Fork(kRigStream), scene_rng = root.Fork(kSceneStream);
  Rng photometry_rng = root.Fork(kPhotometryStream), scale_rng = root.Fork(kScaleStream);

  SynthScene out;
  out.rig = DrawRig(config, rig_rng);
  IntrinsicsRanges intrinsics = config.intrinsics;
  intrinsics.height = config.height;
  intrinsics.width = config.width;
  const Rig rig = MakeRig(out.rig, config.num_views, intrinsics, rig_rng);
  const double d = config.difficulty;
  int objects = static_cast<int>(scene_rng.Int(config.min_objects, config.max_objects));
  if (d < 1) objects = static_cast<int>(std::lround(objects * (0.4 + 0.6 * d)));
  PhotoTextureChoice photos;
  photos.num_photos = config.photos ? static_cast<int>(config.photos->size()) : 0;
  photos.photo_probability = config.photo_probability;
  out.scene = BuildScene(rig, objects, config.height, config.width, scene_rng, photos);
  out.cameras = rig.cameras;
  const PhotometryRanges photometry = d < 1 ? EasierPhotometry(config.photometry, d) : config.photometry;
  for (int v = 0; v < config.num_views; ++v) out.photometry.push_back(RandomPhotometry(photometry, photometry_rng));
  if (config.jpeg_quality_max > 0) {
    // Own stream: compressed scenes keep every other draw of the plain ones.
    // A lower difficulty moves the range towards 100, the least compression.
    const auto easier = [&](int q) { return static_cast<int>(std::lround(100 - d * (100 - q))); };
    Rng jpeg_rng = root.Fork(kJpegStream);
    for (ViewPhotometry& p : out.photometry) {
      p.jpeg_quality = static_cast<int>(jpeg_rng.Int(easier(config.jpeg_quality_min), easier(config.jpeg_quality_max)));
    }
  }
  if (d < 1) {
    const Vec3 reference_centre = out.cameras[0].Center();
    const double baseline = 0.35 + 0.65 * d;
    for (size_t v = 1; v < out.cameras.size(); ++v) {
      PinholeCamera& cam = out.cameras[v];
      const Vec3 centre = reference_centre + baseline * (cam.Center() - reference_centre);
      cam.translation = -1.0 * (cam.rotation * centre);
    }
    out.scene.ambient += 0.5 * (1.0 - d) * (1.0 - out.scene.ambient);
  }
  if (config.specular_probability > 0) {
    Rng material_rng = root.Fork(kMaterialStream);
    for (Primitive& p : out.scene.primitives) {
      if (!material_rng.Bernoulli(config.specular_probability)) continue;
      p.specular = material_rng.Uniform(0.15, 0.6);
      p.shininess = material_rng.LogUniform(8, 256);
    }
  }
  if (config.background_at_infinity && out.rig == RigKind::kOutdoor) {
    for (Primitive& p : out.scene.primitives) p.at_infinity = p.inside && p.shape == Shape::kSphere;
  }
  out.scale = scale_rng.LogUniform(config.scale_min, config.scale_max);
  return out;
}

SynthSample RenderSample(const SynthScene& s, const SynthConfig& config, torch::Device device) {
  config.Check();
  const int64_t views = static_cast<int64_t>(s.cameras.size());
  if (views < 1 || s.photometry.size() != s.cameras.size()) {
    throw std::invalid_argument("RenderSample: need one photometry per camera and at least one camera");
  }
  RaycastOptions options;
  options.device = device;
  options.dtype = config.dtype;
  options.march_steps = config.march_steps;
  options.bisection_steps = config.bisection_steps;
  const auto real = torch::TensorOptions().dtype(config.dtype).device(device);

  const PrimitiveTables tables = MakePrimitiveTables(s, real);

  std::vector<torch::Tensor> images, depths, intrinsics, extrinsics;
  for (int64_t v = 0; v < views; ++v) {
    const PinholeCamera& cam = s.cameras[static_cast<size_t>(v)];
    const RayHits hits = CastImage(s.scene, cam, config.height, config.width, options);
    // The colour is the mean radiance of s x s rays per pixel; the depth
    // stays that of the centre ray (bit for bit that of s = 1). Each of the
    // s^2 - 1 other offsets is one more image-sized cast by a camera whose
    // principal point moves the other way, rather than one cast of an image
    // s times larger: the same rays, in tensors that stay small.
    torch::Tensor radiance = ShadeHits(s, config, hits, tables);
    const int n = config.supersampling;
    for (int a = 0; a < n; ++a) {
      for (int b = 0; b < n; ++b) {
        if (2 * a == n - 1 && 2 * b == n - 1) continue;  // the centre ray, cast above
        PinholeCamera offset = cam;
        offset.cx = cam.cx - (b - 0.5 * (n - 1)) / n;
        offset.cy = cam.cy - (a - 0.5 * (n - 1)) / n;
        radiance += ShadeHits(s, config, CastImage(s.scene, offset, config.height, config.width, options), tables);
      }
    }
    if (n > 1) radiance /= static_cast<double>(n * n);
    images.push_back(ApplyPhotometry(radiance, s.photometry[static_cast<size_t>(v)]));
    depths.push_back((hits.depth * s.scale).unsqueeze(0));
    intrinsics.push_back(IntrinsicsMatrix(cam));
    extrinsics.push_back(WorldToCamera(cam, s.scale));
  }
  SynthSample sample;
  sample.images = torch::stack(images);
  sample.depths = torch::stack(depths);
  sample.intrinsics = torch::stack(intrinsics).to(real);
  sample.world_to_camera = torch::stack(extrinsics).to(real);
  std::tie(sample.depth_min, sample.depth_max) = RobustDepthRange(sample.depths[0]);
  sample.scale = s.scale;
  sample.rig = RigName(s.rig);
  return sample;
}

SynthSample GenerateSample(const SynthConfig& config, uint64_t seed, torch::Device device) {
  return RenderSample(DrawScene(config, seed), config, device);
}

std::pair<double, double> RobustDepthRange(const torch::Tensor& depth, double q_low, double q_high) {
  if (!(0 <= q_low && q_low <= q_high && q_high <= 1)) throw std::invalid_argument("RobustDepthRange: bad quantiles");
  const torch::Tensor flat = depth.reshape({-1}).to(torch::kCPU, torch::kDouble);
  const torch::Tensor positive = std::get<0>(torch::sort(flat.masked_select(flat > 0)));
  const int64_t n = positive.numel();
  if (n == 0) return {0.0, 0.0};
  auto at = [&](double q) {
    const int64_t rank = std::clamp<int64_t>(static_cast<int64_t>(std::llround(q * static_cast<double>(n - 1))), 0, n - 1);
    return positive[rank].item<double>();
  };
  return {at(q_low), at(q_high)};
}

}  // namespace dispmvs::synth
