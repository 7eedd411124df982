#include "synth/scene.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace dispmvs::synth {
namespace {

bool Finite(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

}  // namespace

double Primitive::HeightFieldTop() const {
  double top = std::abs(wave.amplitude);
  for (const HeightBump& b : bumps) top += std::max(b.amplitude, 0.0);
  return top;
}

double Primitive::HeightFieldBottom() const {
  double bottom = -std::abs(wave.amplitude);
  for (const HeightBump& b : bumps) bottom += std::min(b.amplitude, 0.0);
  // A solid block needs some thickness below the lowest possible surface.
  return bottom - 0.1 * std::max(half_size.x, half_size.y);
}

double Primitive::BoundingRadius() const {
  switch (shape) {
    case Shape::kSphere: return half_size.x;
    case Shape::kQuad: return std::hypot(half_size.x, half_size.y);
    case Shape::kBox: return Norm(half_size);
    case Shape::kCylinder: return std::hypot(half_size.x, half_size.z);  // hypot(radius, half height)
    case Shape::kHeightField: {
      const double z = std::max(std::abs(HeightFieldTop()), std::abs(HeightFieldBottom()));
      return std::sqrt(half_size.x * half_size.x + half_size.y * half_size.y + z * z);
    }
  }
  return Norm(half_size);
}

std::vector<Vec3> Primitive::BoundingCorners() const {
  double hx = half_size.x, hy = half_size.y, z_lo = -half_size.z, z_hi = half_size.z;
  switch (shape) {
    case Shape::kQuad: z_lo = z_hi = 0; break;
    case Shape::kSphere: hy = hx; z_lo = -hx; z_hi = hx; break;
    case Shape::kCylinder: hy = hx; break;
    case Shape::kHeightField: z_lo = HeightFieldBottom(); z_hi = HeightFieldTop(); break;
    case Shape::kBox: break;
  }
  std::vector<Vec3> corners;
  for (int i = 0; i < 8; ++i) {
    const Vec3 local{(i & 1) ? hx : -hx, (i & 2) ? hy : -hy, (i & 4) ? z_hi : z_lo};
    corners.push_back(center + rotation * local);
  }
  return corners;
}

void Scene::Check() const {
  for (size_t i = 0; i < primitives.size(); ++i) {
    const Primitive& p = primitives[i];
    const std::string name = "Scene: primitive " + std::to_string(i) + " (" + ShapeName(p.shape) + ")";
    if (!Finite(p.center) || !Finite(p.half_size)) throw std::invalid_argument(name + " has non-finite geometry");
    // The sizes each shape reads (see scene.h) must be positive.
    const bool uses_y = p.shape != Shape::kSphere && p.shape != Shape::kCylinder;
    const bool uses_z = p.shape == Shape::kBox || p.shape == Shape::kCylinder;
    const bool sizes_ok = p.half_size.x > 0 && (!uses_y || p.half_size.y > 0) && (!uses_z || p.half_size.z > 0);
    if (!sizes_ok) throw std::invalid_argument(name + " has a non-positive size");
    if (!(p.uv_unit > 0) || !std::isfinite(p.uv_unit)) throw std::invalid_argument(name + " has a bad uv_unit");
    if (p.texture < 0 || p.texture >= static_cast<int>(textures.size())) {
      throw std::invalid_argument(name + " uses texture " + std::to_string(p.texture) + " of " +
                                  std::to_string(textures.size()));
    }
    const Mat3 should_be_identity = Transposed(p.rotation) * p.rotation;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        if (!(std::abs(should_be_identity(r, c) - (r == c ? 1.0 : 0.0)) < 1e-6)) {
          throw std::invalid_argument(name + " has a rotation that is not orthonormal");
        }
    if (p.inside && p.shape != Shape::kBox && p.shape != Shape::kSphere) {
      throw std::invalid_argument(name + ": only boxes and spheres can be enclosures");
    }
    if (p.at_infinity && !(p.inside && p.shape == Shape::kSphere)) {
      throw std::invalid_argument(name + ": only a sphere enclosure can be at infinity");
    }
    for (const HeightBump& b : p.bumps)
      if (!(b.sigma > 0) || !std::isfinite(b.amplitude)) throw std::invalid_argument(name + " has a bad bump");
  }
  if (std::abs(Norm(light_direction) - 1.0) > 1e-6) throw std::invalid_argument("Scene: light direction is not unit");
  if (!(ambient >= 0 && ambient <= 1)) throw std::invalid_argument("Scene: ambient must be in [0, 1]");
}

Scene ScaleScene(const Scene& scene, double scale) {
  if (!(scale > 0) || !std::isfinite(scale)) throw std::invalid_argument("ScaleScene: scale must be positive and finite");
  Scene out = scene;
  for (Primitive& p : out.primitives) {
    p.center = scale * p.center;
    p.half_size = scale * p.half_size;
    p.uv_unit *= scale;
    for (HeightBump& b : p.bumps) {
      b.x *= scale;
      b.y *= scale;
      b.amplitude *= scale;
      b.sigma *= scale;
    }
    p.wave.amplitude *= scale;
    p.wave.kx /= scale;
    p.wave.ky /= scale;
  }
  return out;
}

std::string ShapeName(Shape shape) {
  switch (shape) {
    case Shape::kQuad: return "quad";
    case Shape::kBox: return "box";
    case Shape::kSphere: return "sphere";
    case Shape::kCylinder: return "cylinder";
    case Shape::kHeightField: return "height field";
  }
  return "unknown";
}

}  // namespace dispmvs::synth
