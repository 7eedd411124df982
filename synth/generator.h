#pragma once
// One training sample: a random scene, V = 1 + N views of it, their images
// and exact depth maps.
//
// Pipeline: DrawScene picks everything random with scalar code on the CPU
// (rig, cameras, objects, textures, glossy materials, light, per-view
// photometry and JPEG quality, metric scale); RenderSample then ray-casts
// and shades every view on the requested device (with `supersampling`,
// several rays per pixel) and applies its photometry. The scene is built and rendered at unit scale; the metric scale
// multiplies only the outputs that carry a length (depths, camera
// translations, depth range). So a sample at scale 1e-3 and at 1e3 from the
// same seed has identical images and depths that differ by exactly that
// factor (up to one float rounding), and a network trained on such samples
// cannot rely on the unit.
//
// Determinism: the same (config, seed) gives the same tensors bit for bit on
// the same device (no device random generator is used: noise is hashed).

#include <torch/torch.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "synth/camera.h"
#include "synth/rigs.h"
#include "synth/scene.h"
#include "synth/shading.h"
#include "synth/texture.h"

namespace dispmvs::synth {

struct SynthConfig {
  int64_t height = 256, width = 320;
  int num_views = 5;  // reference + sources, >= 2
  // Relative probabilities of the rigs (need not sum to 1, at least one > 0).
  double p_table = 0.3, p_walkthrough = 0.25, p_turntable = 0.2, p_outdoor = 0.25;
  int min_objects = 8, max_objects = 24;  // free objects per scene (uniform count)
  double scale_min = 1e-3, scale_max = 1e3;  // metric scale, log-uniform
  IntrinsicsRanges intrinsics;  // its height/width are overridden by the fields above
  PhotometryRanges photometry;
  torch::ScalarType dtype = torch::kFloat;  // of images, depths and camera tensors
  int march_steps = 32, bisection_steps = 12;  // height-field ray marching (see raycast.h)
  // Photographs for photo textures (texture.h), shared, not copied; each
  // texture is one with photo_probability. Null or empty: procedural only,
  // and the scenes are exactly those of a configuration without photos.
  std::shared_ptr<const PhotoSet> photos;
  double photo_probability = 0.5;
  // Difficulty in [0, 1] (a curriculum knob): 1 is the full generator (and
  // gives exactly the scenes of a configuration without the knob); lower
  // values make every scene easier with the same random draws:
  //  * baseline: source camera centres moved towards the reference's, to
  //    0.35 + 0.65 d of their distance (orientations kept);
  //  * occlusion: free objects scaled to 0.4 + 0.6 d of the drawn count;
  //  * lighting: the ambient term raised by (1 - d) / 2 of what is left to 1
  //    (softer shadows, fewer dark regions);
  //  * darkness, contrast and sensor: the per-view gain, gamma and white-
  //    balance ranges narrowed around 1, noise and blur scaled by d.
  double difficulty = 1.0;
  // Rays per pixel along each axis (odd, 1 to 7). A camera integrates light
  // over each pixel's area, so a texture finer than the pixel grid blurs
  // into its mean; one ray through the pixel centre instead picks one point
  // of it, which changes from view to view (aliasing): a far textured wall
  // then shows unrelated noise in two views, and no matcher can place it to
  // a fraction of a pixel. With s > 1 a pixel's colour is the mean radiance
  // of s x s rays on a regular grid inside it (offsets (k - (s - 1) / 2) / s,
  // k = 0..s-1, a box filter), before the view's photometry, as a sensor
  // collects light before its response curve. Depth, and everything but the
  // colour, stays that of the centre ray (s is odd so that one of the s x s
  // rays is the centre one), so depths are those of s = 1. 1 (the default)
  // renders exactly the images of a configuration without the knob; the
  // cost of rendering grows as s^2.
  int supersampling = 1;
  // Share of the primitives with a glossy coat (Primitive::specular): each
  // is glossy with this probability, of strength uniform in [0.15, 0.6] and
  // shininess log-uniform in [8, 256] (a broad sheen to a tight highlight),
  // drawn from a stream of their own. Real surfaces (paint, varnish, plastic,
  // tiles) are not Lambertian: a highlight stands at another place on the
  // surface in each view. 0 (the default) renders exactly the images of a
  // configuration without the knob.
  double specular_probability = 0;
  // JPEG quality of each view drawn uniformly (integers) in [min, max] and
  // applied last in its photometry (ViewPhotometry::jpeg_quality), from a
  // random stream of its own, so that compressed scenes are the plain ones
  // compressed, whatever the photometry ranges; both 0 (the default): none.
  int jpeg_quality_min = 0, jpeg_quality_max = 0;
  // The outdoor rig's sky (its background sphere, 700-1200 units away)
  // drawn at infinity (Primitive::at_infinity): no parallax at all between
  // views, and no depth there (0, "no surface"), as a real sky has none, so
  // training does not supervise it and the depth range ignores it. Off (the
  // default), the sky is a finite sphere with a ground-truth depth and about
  // a pixel of parallax. Draws nothing: the scenes are otherwise those of a
  // configuration without the knob, and other rigs are unchanged.
  bool background_at_infinity = false;

  // Throws std::invalid_argument on sizes, counts or ranges that make no sense.
  void Check() const;
};

struct SynthSample {
  torch::Tensor images;           // [V,3,H,W] in [0,1]; view 0 is the reference
  torch::Tensor intrinsics;       // [V,3,3], pixel-index convention (pixel (i,j) centre at (j,i))
  torch::Tensor world_to_camera;  // [V,4,4], metric (translations scaled)
  torch::Tensor depths;           // [V,1,H,W] camera-frame z, 0 where no surface
  // Robust depth range of the reference view: the 2nd and 98th percentiles
  // of its positive depths (0, 0 if it has none). Like the range of a
  // sparse reconstruction: plausible, not a hard bound.
  double depth_min = 0, depth_max = 0;
  double scale = 1;  // the metric scale applied
  std::string rig;   // RigName() of the rig used
};

// Everything random about a sample, at unit scale.
struct SynthScene {
  RigKind rig = RigKind::kTable;
  Scene scene;
  std::vector<PinholeCamera> cameras;  // [0] is the reference
  std::vector<ViewPhotometry> photometry;
  double scale = 1;
};

SynthScene DrawScene(const SynthConfig& config, uint64_t seed);
SynthSample RenderSample(const SynthScene& scene, const SynthConfig& config, torch::Device device);
SynthSample GenerateSample(const SynthConfig& config, uint64_t seed, torch::Device device);

// The robust depth range used for SynthSample: the q_low and q_high
// quantiles (nearest rank) of the positive values of `depth`; {0, 0} if none.
std::pair<double, double> RobustDepthRange(const torch::Tensor& depth, double q_low = 0.02, double q_high = 0.98);

}  // namespace dispmvs::synth
