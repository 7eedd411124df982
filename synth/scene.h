#pragma once
// Scene description: textured primitives in a world frame, and a light.
//
// Every primitive is defined in its own local frame, placed in the world by a
// rotation (local -> world) and a centre; `half_size` holds its dimensions:
//   kQuad        planar rectangle z = 0, |x| <= hx, |y| <= hy (both sides visible)
//   kBox         |x| <= hx, |y| <= hy, |z| <= hz (thin boxes make rods, boards, poles)
//   kSphere      radius hx (hy, hz unused)
//   kCylinder    axis z, radius hx, |z| <= hz, with caps (hy unused)
//   kHeightField a solid block over |x| <= hx, |y| <= hy whose top surface is
//                z = h(x, y) (a sum of Gaussian bumps and one sinusoid), and
//                whose bottom is z = HeightFieldBottom()
// `inside` marks an enclosure seen from within (a background box or sphere
// around everything): the ray hits its far side.
//
// UV coordinates are local surface coordinates (arc length on curved
// surfaces) divided by `uv_unit`, a length that scales with the scene, so a
// scene and its scaled copy have identical UVs and identical textures.

#include <array>
#include <string>
#include <vector>

#include "synth/texture.h"
#include "synth/vec3.h"

namespace dispmvs::synth {

enum class Shape { kQuad, kBox, kSphere, kCylinder, kHeightField };

struct HeightBump {
  double x = 0, y = 0;   // centre in local coordinates
  double amplitude = 0;  // may be negative (a dip)
  double sigma = 1;      // Gaussian width
};

struct HeightWave {
  double amplitude = 0;
  double kx = 0, ky = 0;  // angular wave vector (radians per unit length)
  double phase = 0;
};

struct Primitive {
  Shape shape = Shape::kBox;
  Mat3 rotation;   // local -> world
  Vec3 center;     // local origin in world coordinates
  Vec3 half_size{1, 1, 1};
  bool inside = false;
  // A sphere enclosure seen as if infinitely far away (a sky): every camera
  // sees it centred on its own centre, so where it shows depends on the
  // ray's direction alone (no parallax between views however far apart),
  // and it has no depth (the renderer reads 0 there, "no surface", as for
  // a real sky). Only a sphere enclosure (`inside`) can be.
  bool at_infinity = false;
  int texture = 0;       // index into Scene::textures
  // A glossy coat (shading.h, ShadeSpecular): a white Blinn-Phong highlight
  // of strength `specular` (0 = matte, the default) and exponent
  // `shininess`, added to the Lambertian radiance. It moves with the
  // viewpoint: what a matcher that assumes constant brightness gets wrong.
  double specular = 0;
  double shininess = 32;
  double uv_unit = 1.0;  // length of one UV unit
  // Height field only.
  std::vector<HeightBump> bumps;
  HeightWave wave;

  // Bounds of the height field's top surface h(x, y) over all (x, y):
  // conservative (the sum of each term's extreme values).
  double HeightFieldTop() const;
  double HeightFieldBottom() const;
  // Radius of a sphere around `center` that contains the primitive.
  double BoundingRadius() const;
  // The 8 corners of a local box containing the primitive, in world coordinates.
  std::vector<Vec3> BoundingCorners() const;
};

struct Scene {
  std::vector<Primitive> primitives;
  std::vector<TextureSpec> textures;
  Vec3 light_direction{0, 0, 1};  // unit vector towards the light (world frame)
  double ambient = 0.3;           // shading = ambient + (1 - ambient) max(0, n . l)
  std::array<double, 3> empty_color{0, 0, 0};  // albedo where a ray hits nothing

  // Throws std::invalid_argument naming the first bad primitive (non-positive
  // or non-finite size, unknown texture, non-orthonormal rotation).
  void Check() const;
};

// The scene with every length multiplied by `scale` (> 0): centres, sizes,
// height-field terms and UV units. Rotations, textures and light are unchanged.
Scene ScaleScene(const Scene& scene, double scale);

std::string ShapeName(Shape shape);

}  // namespace dispmvs::synth
