#pragma once
// The synthetic scene of the example workspace: a textured ground plane
// (z = 0, world z pointing up) with a textured box standing on it, rotated
// about the vertical axis. Every surface is planar, so depth is exact and the
// inverse depth of each surface is an affine function of the pixel position
// in any pinhole view (which is what the example's test relies on).
//
// Shading is Lambertian under a fixed directional light, so a surface point
// has the same colour in every view (the brightness constancy that matching
// assumes). The texture is value noise summed over several octaves, so that
// there is detail to match at every scale from the box size down to a pixel.

#include <cstdint>
#include <optional>

#include <Eigen/Core>

namespace dispmvs::examples {

enum class Surface : int {
  kGround = 0,
  kBoxPlusX, kBoxMinusX, kBoxPlusY, kBoxMinusY, kBoxTop, kBoxBottom,
};

struct RayHit {
  double t = 0.0;            // hit = origin + t * direction
  Surface surface = Surface::kGround;
  Eigen::Vector3d normal;    // world frame, unit, facing the ray's origin
  Eigen::Vector2d texture_uv;  // surface coordinates in scene units
};

class ExampleScene {
 public:
  // `seed` only changes the texture.
  explicit ExampleScene(uint64_t seed);

  // Nearest hit with t > 0 of the ray origin + t * direction (direction need
  // not be unit length), or nothing if the ray escapes to the sky.
  std::optional<RayHit> Cast(const Eigen::Vector3d& origin,
                             const Eigen::Vector3d& direction) const;

  // Linear RGB in [0, 1] of a hit point (view independent).
  Eigen::Vector3d Shade(const RayHit& hit) const;
  static Eigen::Vector3d SkyColour() { return {0.75, 0.82, 0.95}; }

  // Surface parametrisations for sampling sparse points: a point on the box
  // face `surface`, from (a, b) in [0, 1]^2, and the face's area. The bottom
  // face is never visible and is not offered by FaceArea (returns 0).
  Eigen::Vector3d BoxFacePoint(Surface surface, double a, double b) const;
  double FaceArea(Surface surface) const;

 private:
  Eigen::Vector3d ToBox(const Eigen::Vector3d& world_point) const;
  Eigen::Vector3d FromBox(const Eigen::Vector3d& box_point) const;
  double Albedo(const Eigen::Vector2d& uv, int channel, Surface surface) const;

  uint64_t seed_;
  // Box: centre, half extents along its own axes, rotation about world z.
  Eigen::Vector3d box_centre_;
  Eigen::Vector3d box_half_extent_;
  Eigen::Matrix3d box_to_world_;
  Eigen::Vector3d light_direction_;  // unit, towards the light
};

}  // namespace dispmvs::examples
