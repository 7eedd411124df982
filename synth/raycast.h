#pragma once
// Batched analytic ray casting of a Scene in LibTorch (CPU or CUDA: the
// device and dtype come from RaycastOptions).
//
// Rays: pixel (x, y) (pixel-index convention, see camera.h) of a camera casts
// the ray X(t) = C + t R^T (K^-1 (x, y, 1)^T). Its direction has camera-frame
// z = 1, so the ray parameter t of a hit IS the hit's depth (camera-frame z,
// as COLMAP and MVS use), not a distance along a unit ray.
//
// Quads, boxes, spheres and cylinders are intersected in closed form (the
// quadratics in the numerically stable "closest point" form, so far-away
// spheres keep their precision in float32). Height fields are ray-marched
// in RaycastOptions::march_steps equal steps across their bounding block;
// the first step below the surface z = h(x, y) brackets the hit, which
// `bisection_steps` bisections and one final secant step refine. The
// bracket is then (segment length) / march_steps / 2^bisection_steps
// (about 2e-5 of the block with the defaults) and the secant step leaves
// an error of order curvature x bracket^2: float32 rounding dominates.
// A crest narrower than one march step that a ray only grazes can be
// missed: generated bumps have sigma >= 1/15 of the block width, more than
// a march step, so this only happens at grazing silhouettes; images and
// depths come from the same cast, so they stay consistent even there.
//
// Each primitive is only tested against the pixels inside the image-space
// bounding rectangle of its bounding box, which keeps the cost near
// (pixels x primitives per pixel) rather than (pixels x primitives).

#include <torch/torch.h>

#include "synth/camera.h"
#include "synth/scene.h"

namespace dispmvs::synth {

struct RaycastOptions {
  torch::Device device = torch::kCPU;
  torch::ScalarType dtype = torch::kFloat;
  int march_steps = 32;
  int bisection_steps = 12;
};

struct RayHits {
  // [...]: camera-frame z of the nearest hit; 0 where nothing is hit and
  // where the hit is on a primitive at infinity (Primitive::at_infinity: a
  // sky, which has no depth; its other fields are set as for any hit).
  torch::Tensor depth;
  torch::Tensor primitive;  // [...] int64: index into Scene::primitives; -1 where nothing is hit
  torch::Tensor uv;         // [...,2]: surface UV of the hit (0 where nothing is hit)
  torch::Tensor normal;     // [...,3]: unit world normal, turned towards the camera (0 where nothing is hit)
  // [...,3]: world direction of the ray (its camera-frame z is 1; not unit),
  // for every ray, hit or not: what view-dependent shading looks along.
  torch::Tensor direction;
};

// Every pixel of a height x width image: results have leading shape [H,W].
RayHits CastImage(const Scene& scene, const PinholeCamera& camera, int64_t height, int64_t width,
                  const RaycastOptions& options = {});

// Arbitrary (sub-)pixel positions xy [N,2] (x, y): results have leading shape [N].
RayHits CastPixels(const Scene& scene, const PinholeCamera& camera, const torch::Tensor& xy,
                   const RaycastOptions& options = {});

}  // namespace dispmvs::synth
