#include "synth/rigs.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "synth/rng.h"

namespace dispmvs::synth {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
const Vec3 kUp{0, 0, 1};

// Offset index of source k = 1, 2, 3, ...: +1, -1, +2, -2, ... so sources
// surround the reference instead of all lying on one side.
int AlternatingOffset(int k) { return (k % 2 == 1) ? (k + 1) / 2 : -(k / 2); }

void DrawIntrinsics(PinholeCamera& cam, double fov_deg, const IntrinsicsRanges& r, Rng& rng) {
  const double focal = 0.5 * static_cast<double>(r.width) / std::tan(0.5 * fov_deg * kDeg);
  cam.fx = focal * (1 + rng.Uniform(-r.focal_jitter, r.focal_jitter));
  cam.fy = focal * (1 + rng.Uniform(-r.focal_jitter, r.focal_jitter));
  auto clipped_normal = [&rng] { return std::clamp(rng.Normal(), -3.0, 3.0); };
  cam.cx = 0.5 * static_cast<double>(r.width - 1) + clipped_normal() * r.principal_jitter * r.width;
  cam.cy = 0.5 * static_cast<double>(r.height - 1) + clipped_normal() * r.principal_jitter * r.height;
}

Primitive Enclosure(Shape shape, const Vec3& center, const Vec3& half_size, double uv_unit) {
  Primitive p;
  p.shape = shape;
  p.center = center;
  p.half_size = half_size;
  p.inside = true;
  p.uv_unit = uv_unit;
  return p;
}

Primitive FlatQuad(const Vec3& center, double half_x, double half_y, double uv_unit) {
  Primitive p;
  p.shape = Shape::kQuad;
  p.center = center;
  p.half_size = {half_x, half_y, 0};
  p.uv_unit = uv_unit;
  return p;
}

Vec3 OnSphere(double radius, double azimuth, double elevation) {
  return {radius * std::cos(elevation) * std::cos(azimuth), radius * std::cos(elevation) * std::sin(azimuth),
          radius * std::sin(elevation)};
}

Vec3 Jitter(double amount, Rng& rng) {
  return {rng.Uniform(-amount, amount), rng.Uniform(-amount, amount), rng.Uniform(-amount, amount)};
}

// Direction of a camera with the given yaw (about z, 0 = +y) and pitch.
Vec3 Heading(double yaw, double pitch) {
  return {std::sin(yaw) * std::cos(pitch), std::cos(yaw) * std::cos(pitch), std::sin(pitch)};
}

Rig TableRig(int num_views, Rng& rng) {
  Rig rig;
  const double distance = rng.Uniform(2, 4);
  const Vec3 target{0, 0, 0.3};
  const double azimuth = rng.Uniform(0, 2 * kPi), elevation = rng.Uniform(20, 65) * kDeg;
  rig.cameras.push_back(PinholeCamera::LookAt(target + OnSphere(distance, azimuth, elevation),
                                              target + Jitter(0.15, rng), kUp));
  for (int k = 1; k < num_views; ++k) {
    const double sign = AlternatingOffset(k) > 0 ? 1 : -1;
    const double a = azimuth + sign * rng.Uniform(5, 25) * kDeg;
    const double e = std::clamp(elevation + rng.Uniform(-12, 12) * kDeg, 10 * kDeg, 80 * kDeg);
    const double d = distance * rng.Uniform(0.85, 1.15);
    rig.cameras.push_back(PinholeCamera::LookAt(target + OnSphere(d, a, e), target + Jitter(0.15, rng), kUp));
  }
  const double table = rng.Uniform(2, 5);
  Primitive top;
  top.shape = Shape::kBox;
  top.center = {0, 0, -0.05};
  top.half_size = {table, table * rng.Uniform(0.6, 1.0), 0.05};
  top.uv_unit = rng.Uniform(0.5, 2);
  rig.environment.push_back(top);
  rig.environment.push_back(Enclosure(Shape::kSphere, {0, 0, 0}, {25, 25, 25}, 3));
  rig.object_depth_min = 0.5 * distance;
  rig.object_depth_max = 1.1 * distance;
  return rig;
}

Rig WalkThroughRig(int num_views, Rng& rng) {
  Rig rig;
  const double half_width = rng.Uniform(1.5, 4), height = rng.Uniform(2.5, 4);
  const double eye_height = rng.Uniform(1.2, 1.8);
  const Vec3 eye{rng.Uniform(-0.3, 0.3) * half_width, 0, eye_height};
  const double yaw = rng.Uniform(-15, 15) * kDeg, pitch = rng.Uniform(-8, 5) * kDeg;
  rig.cameras.push_back(PinholeCamera::LookAt(eye, eye + Heading(yaw, pitch), kUp));
  const double step = rng.Uniform(0.15, 0.6);
  for (int k = 1; k < num_views; ++k) {
    const Vec3 along = static_cast<double>(AlternatingOffset(k)) * step * Heading(yaw, 0);
    const Vec3 position = eye + along + Vec3{0.05 * rng.Normal(), 0, 0.02 * rng.Normal()};
    const Vec3 heading = Heading(yaw + rng.Uniform(-5, 5) * kDeg, pitch + rng.Uniform(-3, 3) * kDeg);
    rig.cameras.push_back(PinholeCamera::LookAt(position, position + heading, kUp));
  }
  rig.environment.push_back(FlatQuad({0, 25, 0}, half_width, 36, rng.Uniform(0.5, 2)));
  // Walls and ceiling: a box seen from inside, its floor just below the floor quad.
  rig.environment.push_back(
      Enclosure(Shape::kBox, {0, 25, 0.5 * height - 0.01}, {half_width, 36, 0.5 * height + 0.01}, rng.Uniform(0.5, 2)));
  rig.object_depth_min = 0.8;
  rig.object_depth_max = 20;
  return rig;
}

Rig TurntableRig(int num_views, Rng& rng) {
  Rig rig;
  const double distance = rng.Uniform(2, 4), elevation = rng.Uniform(10, 40) * kDeg;
  const double azimuth = rng.Uniform(0, 2 * kPi), step = rng.Uniform(6, 15) * kDeg;
  const Vec3 target{0, 0, 0.3};
  for (int k = 0; k < num_views; ++k) {
    const double a = azimuth + static_cast<double>(AlternatingOffset(k)) * step;
    rig.cameras.push_back(PinholeCamera::LookAt(target + OnSphere(distance, a, elevation), target, kUp));
  }
  rig.environment.push_back(FlatQuad({0, 0, 0}, 6, 6, rng.Uniform(0.5, 2)));
  rig.environment.push_back(Enclosure(Shape::kSphere, {0, 0, 0}, {25, 25, 25}, 3));
  rig.object_depth_min = 0.6 * distance;
  rig.object_depth_max = 1.2 * distance;
  return rig;
}

Rig OutdoorRig(int num_views, Rng& rng) {
  Rig rig;
  const Vec3 eye{0, 0, rng.Uniform(1, 3)};
  const double yaw = rng.Uniform(0, 2 * kPi), pitch = rng.Uniform(-12, 3) * kDeg;
  rig.cameras.push_back(PinholeCamera::LookAt(eye, eye + Heading(yaw, pitch), kUp));
  for (int k = 1; k < num_views; ++k) {
    // Baselines of 0.2-2 units in a random horizontal direction: tiny
    // compared with the far background, as for a handheld outdoor capture.
    const double direction = rng.Uniform(0, 2 * kPi);
    const Vec3 position = eye + rng.Uniform(0.2, 2) * Heading(direction, 0) + Vec3{0, 0, 0.05 * rng.Normal()};
    const Vec3 heading = Heading(yaw + rng.Uniform(-3, 3) * kDeg, pitch + rng.Uniform(-2, 2) * kDeg);
    rig.cameras.push_back(PinholeCamera::LookAt(position, position + heading, kUp));
  }
  rig.environment.push_back(FlatQuad({0, 0, 0}, 3000, 3000, rng.Uniform(1, 4)));
  // Hills: height-field blocks ahead, sunk so only their tops show above the ground.
  const int hills = static_cast<int>(rng.Int(1, 2));
  for (int h = 0; h < hills; ++h) {
    Primitive hill;
    hill.shape = Shape::kHeightField;
    const double distance = rng.Uniform(150, 600);
    const Vec3 ahead = eye + distance * Heading(yaw + rng.Uniform(-25, 25) * kDeg, 0);
    hill.center = {ahead.x, ahead.y, 0};
    hill.rotation = AxisAngle(kUp, rng.Uniform(0, 2 * kPi));
    const double size = rng.Uniform(50, 200);
    hill.half_size = {size, size * rng.Uniform(0.5, 1), 0};
    const int bumps = static_cast<int>(rng.Int(2, 5));
    for (int b = 0; b < bumps; ++b) {
      hill.bumps.push_back({rng.Uniform(-0.6, 0.6) * size, rng.Uniform(-0.6, 0.6) * size,
                            rng.Uniform(0.05, 0.4) * size, rng.Uniform(0.15, 0.4) * size});
    }
    hill.wave = {0.02 * size, rng.Uniform(2, 6) / size, rng.Uniform(2, 6) / size, rng.Uniform(0, 2 * kPi)};
    hill.uv_unit = rng.Uniform(5, 20);
    rig.environment.push_back(hill);
  }
  const double radius = rng.Uniform(700, 1200);
  rig.environment.push_back(Enclosure(Shape::kSphere, {eye.x, eye.y, 0}, {radius, radius, radius}, 100));
  rig.object_depth_min = 1.5;
  rig.object_depth_max = 300;
  return rig;
}

}  // namespace

std::string RigName(RigKind kind) {
  switch (kind) {
    case RigKind::kTable: return "table";
    case RigKind::kWalkThrough: return "walkthrough";
    case RigKind::kTurntable: return "turntable";
    case RigKind::kOutdoor: return "outdoor";
  }
  return "unknown";
}

Rig MakeRig(RigKind kind, int num_views, const IntrinsicsRanges& intrinsics, Rng& rng) {
  if (num_views < 2) throw std::invalid_argument("MakeRig: need at least 2 views");
  Rig rig;
  switch (kind) {
    case RigKind::kTable: rig = TableRig(num_views, rng); break;
    case RigKind::kWalkThrough: rig = WalkThroughRig(num_views, rng); break;
    case RigKind::kTurntable: rig = TurntableRig(num_views, rng); break;
    case RigKind::kOutdoor: rig = OutdoorRig(num_views, rng); break;
  }
  rig.kind = kind;
  const double fov = rng.Uniform(intrinsics.fov_min_deg, intrinsics.fov_max_deg);
  for (PinholeCamera& cam : rig.cameras) DrawIntrinsics(cam, fov, intrinsics, rng);
  return rig;
}

}  // namespace dispmvs::synth
