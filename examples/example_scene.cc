#include "examples/example_scene.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Geometry>

#include "synth/rng.h"

namespace dispmvs::examples {
namespace {

constexpr double kPi = 3.14159265358979323846;

// SplitMix64 rather than std::hash: identical on every platform, so the
// texture only depends on the seed.
using synth::SplitMix64;

double LatticeValue(int64_t ix, int64_t iy, uint64_t salt) {
  const uint64_t h =
      SplitMix64(SplitMix64(SplitMix64(salt) ^ static_cast<uint64_t>(ix)) ^ static_cast<uint64_t>(iy));
  return static_cast<double>(h >> 11) * 0x1.0p-53;  // [0, 1)
}

// Smoothly interpolated random values on the integer lattice.
double ValueNoise(const Eigen::Vector2d& p, uint64_t salt) {
  const double fx = std::floor(p.x());
  const double fy = std::floor(p.y());
  const auto ix = static_cast<int64_t>(fx);
  const auto iy = static_cast<int64_t>(fy);
  const double tx = p.x() - fx;
  const double ty = p.y() - fy;
  const double sx = tx * tx * (3.0 - 2.0 * tx);
  const double sy = ty * ty * (3.0 - 2.0 * ty);
  const double v00 = LatticeValue(ix, iy, salt);
  const double v10 = LatticeValue(ix + 1, iy, salt);
  const double v01 = LatticeValue(ix, iy + 1, salt);
  const double v11 = LatticeValue(ix + 1, iy + 1, salt);
  return (v00 * (1 - sx) + v10 * sx) * (1 - sy) + (v01 * (1 - sx) + v11 * sx) * sy;
}

// Octaves of value noise, each twice the frequency of the previous one and
// kOctaveGain times its amplitude, normalised to [0, 1]. A gain above the
// usual 0.5 keeps more fine detail (what stereo matching feeds on).
constexpr double kOctaveGain = 0.65;

double FractalNoise(const Eigen::Vector2d& p, double base_frequency, int octaves, uint64_t salt) {
  double sum = 0.0;
  double amplitude = 1.0;
  double total = 0.0;
  double frequency = base_frequency;
  for (int k = 0; k < octaves; ++k) {
    sum += amplitude * ValueNoise(p * frequency, salt + 0x1000u * static_cast<uint64_t>(k));
    total += amplitude;
    amplitude *= kOctaveGain;
    frequency *= 2.0;
  }
  return sum / total;
}

int SurfaceIndex(Surface surface) { return static_cast<int>(surface); }

}  // namespace

ExampleScene::ExampleScene(uint64_t seed)
    : seed_(seed),
      box_centre_(0.2, -0.1, 0.45),
      box_half_extent_(0.6, 0.4, 0.45),
      box_to_world_(Eigen::AngleAxisd(25.0 * kPi / 180.0, Eigen::Vector3d::UnitZ())),
      light_direction_(Eigen::Vector3d(0.4, -0.5, 0.8).normalized()) {}

Eigen::Vector3d ExampleScene::ToBox(const Eigen::Vector3d& world_point) const {
  return box_to_world_.transpose() * (world_point - box_centre_);
}

Eigen::Vector3d ExampleScene::FromBox(const Eigen::Vector3d& box_point) const {
  return box_to_world_ * box_point + box_centre_;
}

std::optional<RayHit> ExampleScene::Cast(const Eigen::Vector3d& origin,
                                         const Eigen::Vector3d& direction) const {
  std::optional<RayHit> nearest;

  // Ground plane z = 0, seen from above.
  if (origin.z() > 0.0 && direction.z() < 0.0) {
    RayHit hit;
    hit.t = -origin.z() / direction.z();
    hit.surface = Surface::kGround;
    hit.normal = Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d point = origin + hit.t * direction;
    hit.texture_uv = point.head<2>();
    nearest = hit;
  }

  // Box: slab test in the box frame. The entry face is the slab whose near
  // crossing is the latest; rays starting inside the box are not expected.
  const Eigen::Vector3d o = ToBox(origin);
  const Eigen::Vector3d d = box_to_world_.transpose() * direction;
  double t_enter = -std::numeric_limits<double>::infinity();
  double t_exit = std::numeric_limits<double>::infinity();
  int enter_axis = -1;
  double enter_sign = 0.0;
  bool misses = false;
  for (int axis = 0; axis < 3 && !misses; ++axis) {
    const double h = box_half_extent_[axis];
    if (d[axis] == 0.0) {
      misses = std::abs(o[axis]) > h;
      continue;
    }
    const double t_low = (-h - o[axis]) / d[axis];
    const double t_high = (h - o[axis]) / d[axis];
    const double t_near = std::min(t_low, t_high);
    if (t_near > t_enter) {
      t_enter = t_near;
      enter_axis = axis;
      enter_sign = d[axis] > 0.0 ? -1.0 : 1.0;  // moving +: enter through the - face
    }
    t_exit = std::min(t_exit, std::max(t_low, t_high));
  }
  if (!misses && enter_axis >= 0 && t_enter > 0.0 && t_enter <= t_exit &&
      (!nearest || t_enter < nearest->t)) {
    static constexpr Surface kFaces[3][2] = {{Surface::kBoxMinusX, Surface::kBoxPlusX},
                                              {Surface::kBoxMinusY, Surface::kBoxPlusY},
                                              {Surface::kBoxBottom, Surface::kBoxTop}};
    RayHit hit;
    hit.t = t_enter;
    hit.surface = kFaces[enter_axis][enter_sign > 0.0 ? 1 : 0];
    Eigen::Vector3d box_normal = Eigen::Vector3d::Zero();
    box_normal[enter_axis] = enter_sign;
    hit.normal = box_to_world_ * box_normal;
    // Texture coordinates: the two in-face box coordinates, offset per face so
    // that faces do not repeat each other's pattern.
    const Eigen::Vector3d p = o + t_enter * d;
    const int u_axis = enter_axis == 0 ? 1 : 0;
    const int v_axis = enter_axis == 2 ? 1 : 2;
    const double offset = 7.31 * SurfaceIndex(hit.surface);
    hit.texture_uv = Eigen::Vector2d(p[u_axis] + offset, p[v_axis] - 0.5 * offset);
    nearest = hit;
  }
  return nearest;
}

double ExampleScene::Albedo(const Eigen::Vector2d& uv, int channel, Surface surface) const {
  static constexpr double kBaseColour[7][3] = {
      {0.85, 0.78, 0.62},  // ground: sand
      {0.90, 0.45, 0.35}, {0.80, 0.50, 0.30}, {0.85, 0.40, 0.45},
      {0.75, 0.55, 0.35}, {0.95, 0.60, 0.40}, {0.50, 0.50, 0.50},
  };
  const int index = SurfaceIndex(surface);
  const uint64_t surface_salt = SplitMix64(seed_ * 31u + static_cast<uint64_t>(index));
  // Mostly shared luminance detail (6 octaves: features from 0.7 scene units
  // down to about 1/50, the size of a pixel at the far end of the views) plus
  // a coarser per-channel tint.
  const double luminance = FractalNoise(uv, 1.5, 6, surface_salt);
  const double tint =
      FractalNoise(uv, 1.0, 2, SplitMix64(surface_salt + 1u + static_cast<uint64_t>(channel)));
  double value = 0.5 + 2.2 * (0.75 * luminance + 0.25 * tint - 0.5);
  // A sparse grid of dark lines on the ground: sharp, unambiguous structure.
  if (surface == Surface::kGround) {
    const double lx = uv.x() * 2.0 - std::floor(uv.x() * 2.0);
    const double ly = uv.y() * 2.0 - std::floor(uv.y() * 2.0);
    if (lx < 0.03 || ly < 0.03) value *= 0.3;
  }
  return kBaseColour[index][channel] * std::clamp(value, 0.03, 1.0);
}

Eigen::Vector3d ExampleScene::Shade(const RayHit& hit) const {
  const double lambert = std::max(0.0, hit.normal.dot(light_direction_));
  const double light = 0.35 + 0.65 * lambert;
  Eigen::Vector3d colour;
  for (int c = 0; c < 3; ++c) {
    colour[c] = std::min(1.0, Albedo(hit.texture_uv, c, hit.surface) * light);
  }
  return colour;
}

Eigen::Vector3d ExampleScene::BoxFacePoint(Surface surface, double a, double b) const {
  const Eigen::Vector3d& h = box_half_extent_;
  const double u = 2.0 * a - 1.0;
  const double v = 2.0 * b - 1.0;
  Eigen::Vector3d p;
  switch (surface) {
    case Surface::kBoxPlusX: p = {h.x(), u * h.y(), v * h.z()}; break;
    case Surface::kBoxMinusX: p = {-h.x(), u * h.y(), v * h.z()}; break;
    case Surface::kBoxPlusY: p = {u * h.x(), h.y(), v * h.z()}; break;
    case Surface::kBoxMinusY: p = {u * h.x(), -h.y(), v * h.z()}; break;
    case Surface::kBoxTop: p = {u * h.x(), v * h.y(), h.z()}; break;
    case Surface::kBoxBottom: p = {u * h.x(), v * h.y(), -h.z()}; break;
    default: throw std::invalid_argument("BoxFacePoint: not a box face");
  }
  return FromBox(p);
}

double ExampleScene::FaceArea(Surface surface) const {
  const Eigen::Vector3d& h = box_half_extent_;
  switch (surface) {
    case Surface::kBoxPlusX:
    case Surface::kBoxMinusX: return 4.0 * h.y() * h.z();
    case Surface::kBoxPlusY:
    case Surface::kBoxMinusY: return 4.0 * h.x() * h.z();
    case Surface::kBoxTop: return 4.0 * h.x() * h.y();
    default: return 0.0;
  }
}

}  // namespace dispmvs::examples
