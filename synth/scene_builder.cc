#include "synth/scene_builder.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "synth/rng.h"

namespace dispmvs::synth {
namespace {

constexpr double kPi = 3.14159265358979323846;

Mat3 RandomRotation(Rng& rng) {
  // Uniform axis (normalised Gaussian) and uniform angle: not the Haar
  // measure, but every orientation occurs, which is all the data needs.
  Vec3 axis{rng.Normal(), rng.Normal(), rng.Normal()};
  if (Norm(axis) < 1e-9) axis = {0, 0, 1};
  return AxisAngle(axis, rng.Uniform(0, 2 * kPi));
}

// An object of characteristic radius r centred at the local origin.
Primitive RandomObject(double r, Rng& rng) {
  Primitive p;
  const double pick = rng.Uniform();
  if (pick < 0.22) {
    p.shape = Shape::kQuad;
    p.half_size = {r * rng.Uniform(0.4, 1), r * rng.Uniform(0.4, 1), 0};
  } else if (pick < 0.40) {
    p.shape = Shape::kBox;
    p.half_size = {r * rng.Uniform(0.3, 1), r * rng.Uniform(0.3, 1), r * rng.Uniform(0.3, 1)};
  } else if (pick < 0.54) {
    // Thin structures: a board (one thin side) or a rod (two thin sides).
    p.shape = Shape::kBox;
    const double thin = r * rng.LogUniform(0.02, 0.1);
    const bool rod = rng.Bernoulli(0.5);
    p.half_size = {r, rod ? thin : r * rng.Uniform(0.3, 1), thin};
  } else if (pick < 0.70) {
    p.shape = Shape::kSphere;
    p.half_size = {r * rng.Uniform(0.4, 1), 0, 0};
    p.half_size.y = p.half_size.z = p.half_size.x;
  } else if (pick < 0.88) {
    p.shape = Shape::kCylinder;
    const bool pole = rng.Bernoulli(0.3);
    const double radius = pole ? r * rng.LogUniform(0.03, 0.1) : r * rng.Uniform(0.2, 0.8);
    p.half_size = {radius, radius, r * rng.Uniform(0.4, 1)};
  } else {
    p.shape = Shape::kHeightField;
    p.half_size = {r * rng.Uniform(0.6, 1), r * rng.Uniform(0.6, 1), 0};
    const int bumps = static_cast<int>(rng.Int(2, 5));
    for (int b = 0; b < bumps; ++b) {
      p.bumps.push_back({rng.Uniform(-0.8, 0.8) * r, rng.Uniform(-0.8, 0.8) * r,
                         rng.Uniform(-0.3, 0.4) * r, rng.Uniform(0.15, 0.5) * r});
    }
    p.wave = {rng.Uniform(0, 0.05) * r, rng.Uniform(3, 12) / r, rng.Uniform(3, 12) / r, rng.Uniform(0, 2 * kPi)};
  }
  p.rotation = RandomRotation(rng);
  p.uv_unit = r * rng.LogUniform(0.3, 1.5);
  return p;
}

// Scales a primitive's dimensions about its own centre.
void Shrink(Primitive& p, double factor) {
  const Vec3 center = p.center;
  Scene one;
  one.primitives.push_back(p);
  p = ScaleScene(one, factor).primitives[0];
  p.center = center;
}

TextureSpec DrawTexture(Rng& rng, const PhotoTextureChoice& photos) {
  if (photos.num_photos > 0 && photos.photo_probability > 0 &&
      rng.Uniform(0, 1) < photos.photo_probability) {
    return RandomPhotoTexture(rng, photos.num_photos);
  }
  return RandomTexture(rng);
}

}  // namespace

Scene BuildScene(const Rig& rig, int num_objects, int64_t height, int64_t width, Rng& rng,
                 const PhotoTextureChoice& photos) {
  if (rig.cameras.empty()) throw std::invalid_argument("BuildScene: the rig has no cameras");
  if (num_objects < 0) throw std::invalid_argument("BuildScene: negative object count");
  Scene scene;
  const double light_azimuth = rng.Uniform(0, 2 * kPi), light_elevation = rng.Uniform(20, 80) * kPi / 180;
  scene.light_direction = Normalized({std::cos(light_elevation) * std::cos(light_azimuth),
                                      std::cos(light_elevation) * std::sin(light_azimuth), std::sin(light_elevation)});
  scene.ambient = rng.Uniform(0.25, 0.6);
  scene.empty_color = {0.6, 0.7, 0.9};

  for (Primitive p : rig.environment) {
    p.texture = static_cast<int>(scene.textures.size());
    scene.textures.push_back(DrawTexture(rng, photos));
    scene.primitives.push_back(p);
  }

  const PinholeCamera& ref = rig.cameras[0];
  const Mat3 camera_to_world = Transposed(ref.rotation);
  for (int k = 0; k < num_objects; ++k) {
    const double x = rng.Uniform(-0.1, 1.1) * static_cast<double>(width - 1);
    const double y = rng.Uniform(-0.1, 1.1) * static_cast<double>(height - 1);
    const double depth = rng.LogUniform(rig.object_depth_min, rig.object_depth_max);
    const Vec3 ray{(x - ref.cx) / ref.fx, (y - ref.cy) / ref.fy, 1.0};
    Primitive p = RandomObject(depth * rng.LogUniform(0.04, 0.3), rng);
    p.center = ref.Center() + depth * (camera_to_world * ray);
    // Keep every camera clearly outside the object (and its near surfaces
    // at a distance): shrink it to 70% of the nearest camera distance.
    for (const PinholeCamera& cam : rig.cameras) {
      const double limit = 0.7 * Norm(cam.Center() - p.center);
      const double radius = p.BoundingRadius();
      if (radius > limit) Shrink(p, limit / radius);
    }
    p.texture = static_cast<int>(scene.textures.size());
    scene.textures.push_back(DrawTexture(rng, photos));
    scene.primitives.push_back(p);
  }
  scene.Check();
  return scene;
}

}  // namespace dispmvs::synth
