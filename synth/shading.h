#pragma once
// Turning albedo and geometry into the image one camera records.
//
// Radiance is Lambertian under one directional light per scene plus an
// ambient term, so it is the same from every viewpoint, except on glossy
// primitives (Primitive::specular), whose highlight moves with the
// viewpoint; what also changes per view is the camera (ViewPhotometry): exposure gain and white balance,
// optical blur, sensor noise, the tone curve (gamma) and, where a view has a
// quality, JPEG compression (synth/jpeg.h). Those differences
// are what a learned matcher must see through; identical pixel values across
// views would let it cheat.
// Order, as in a camera: blur (optics) -> gain (exposure) and vignetting
// (the lens's radial fall-off) -> additive Gaussian noise (sensor) -> clamp
// to [0, 1] -> gamma (tone curve) -> JPEG file (8-bit, lossy).

#include <torch/torch.h>

#include <array>
#include <cstdint>

#include "synth/vec3.h"

namespace dispmvs::synth {

class Rng;

struct ViewPhotometry {
  double gain = 1.0;                           // exposure x gain
  std::array<double, 3> white_balance{1, 1, 1};  // per-channel gain
  double gamma = 1.0;                          // output = input^(1/gamma)
  double noise_sigma = 0.0;                    // std of the additive noise (image units)
  double blur_sigma = 0.0;                     // Gaussian blur std in pixels (0: none)
  uint32_t noise_seed = 0;
  // Radial fall-off: radiance x (1 - vignetting rho^2), rho the distance from
  // the image centre over the half-diagonal (so the corners lose `vignetting`).
  // Real pairs see the same surface at different image radii, so its
  // brightness differs between views by up to this much. In [0, 0.9].
  double vignetting = 0.0;
  // Quality (1-100) of the JPEG file the view is saved as, 0 = none (the
  // image stays in floating point). Each view is compressed on its own, so
  // two views of one surface carry different block artefacts.
  int jpeg_quality = 0;

  void Check() const;  // throws std::invalid_argument on values outside sane ranges
};

// Ranges RandomPhotometry draws from (uniformly; gain log-uniformly).
struct PhotometryRanges {
  double gain_min = 0.7, gain_max = 1.4;
  double white_balance_jitter = 0.06;  // each channel in [1 - j, 1 + j]
  double gamma_min = 0.8, gamma_max = 1.25;
  double noise_sigma_max = 0.02;
  double blur_sigma_max = 0.8;
  // Drawn uniformly in [0, max] per view. 0 (the default) draws nothing, so
  // scenes are exactly those of a configuration without vignetting.
  double vignetting_max = 0.0;
};

// Wider per-view differences than the defaults, as between two photographs
// taken minutes apart or by two cameras: exposure 0.5-2x, white balance
// +-15 % per channel, tone curve gamma 0.7-1.4 and vignetting up to 0.4
// (noise and blur as the defaults). The training knob `--photometry wide`.
PhotometryRanges WidePhotometry();

ViewPhotometry RandomPhotometry(const PhotometryRanges& ranges, Rng& rng);

// Lambertian radiance [3,H,W]: albedo * (ambient + (1 - ambient) max(0, n . l)).
// albedo [3,H,W]; normal [H,W,3] unit world normals, 0 where there is no
// surface (such pixels get albedo x ambient); light: unit vector towards it.
torch::Tensor ShadeLambertian(const torch::Tensor& albedo, const torch::Tensor& normal,
                              const Vec3& light, double ambient);

// The Blinn-Phong highlight [H,W]: specular * max(0, n . h)^shininess where
// n . l > 0 (0 elsewhere), h = (l + v) / |l + v|. normal, view [H,W,3]: unit
// world normals and unit vectors from the surface towards the camera (0
// where there is no surface: no highlight); specular, shininess [H,W] per
// pixel; light: unit vector towards it. The same white highlight is added to
// every channel (a dielectric coat reflects the light's colour).
torch::Tensor ShadeSpecular(const torch::Tensor& normal, const torch::Tensor& view, const Vec3& light,
                            const torch::Tensor& specular, const torch::Tensor& shininess);

// The recorded image [3,H,W] in [0, 1] for radiance [3,H,W].
torch::Tensor ApplyPhotometry(const torch::Tensor& radiance, const ViewPhotometry& photometry);

}  // namespace dispmvs::synth
