#pragma once
// Pinhole camera of the generator.
//
// Pixel convention (the network's, see model/geometry.h): the centre of pixel
// (row i, col j) is at (x, y) = (j, i). A camera-frame point (X, Y, Z), Z > 0,
// projects to x = fx X/Z + cx, y = fy Y/Z + cy. COLMAP's convention puts the
// top-left pixel centre at (0.5, 0.5) instead: add 0.5 to cx, cy to convert.
// Camera frame: x right, y down, z forward (as in COLMAP).

#include "synth/vec3.h"

namespace dispmvs::synth {

struct PinholeCamera {
  double fx = 1, fy = 1, cx = 0, cy = 0;
  Mat3 rotation;     // world -> camera
  Vec3 translation;  // world -> camera: X_cam = rotation * X_world + translation

  Vec3 Center() const { return -1.0 * (Transposed(rotation) * translation); }
  Vec3 ToCamera(const Vec3& world) const { return rotation * world + translation; }

  // Camera at `eye` looking at `target`, with image "up" (-y) as close to
  // `up` as possible.
  static PinholeCamera LookAt(const Vec3& eye, const Vec3& target, const Vec3& up) {
    const Vec3 z = Normalized(target - eye);
    Vec3 x = Cross(z, up);  // right = forward x up (y = z x x then points down)
    if (Norm(x) < 1e-9) x = Cross(z, Vec3{1, 0, 0});  // looking straight along `up`
    if (Norm(x) < 1e-9) x = Cross(z, Vec3{0, 1, 0});
    x = Normalized(x);
    const Vec3 y = Cross(z, x);
    PinholeCamera cam;
    cam.rotation = Mat3::FromRows(x, y, z);
    cam.translation = -1.0 * (cam.rotation * eye);
    return cam;
  }
};

}  // namespace dispmvs::synth
