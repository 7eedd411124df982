// Ray casting against independent double-precision computations (Eigen):
// every plane, quadratic and box face is intersected here from scratch,
// without the slab method or the closest-point form the caster uses.

#include "synth/raycast.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "synth/scene.h"

namespace dispmvs::synth {
namespace {

using Eigen::Vector3d;
constexpr double kInf = std::numeric_limits<double>::infinity();

Eigen::Matrix3d ToEigen(const Mat3& m) {
  Eigen::Matrix3d out;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out(r, c) = m(r, c);
  return out;
}
Vector3d ToEigen(const Vec3& v) { return {v.x, v.y, v.z}; }

// Nearest t > 0 of the line o + t d with a planar rectangle given by its
// centre, two in-plane unit axes and half extents.
double HitRectangle(const Vector3d& o, const Vector3d& d, const Vector3d& center, const Vector3d& axis_u,
                    const Vector3d& axis_v, double half_u, double half_v) {
  const Eigen::Hyperplane<double, 3> plane(axis_u.cross(axis_v).normalized(), center);
  const Eigen::ParametrizedLine<double, 3> line(o, d);
  const double t = line.intersectionParameter(plane);
  if (!(t > 0) || !std::isfinite(t)) return kInf;
  const Vector3d q = line.pointAt(t) - center;
  return (std::abs(q.dot(axis_u)) <= half_u && std::abs(q.dot(axis_v)) <= half_v) ? t : kInf;
}

// Both roots of |o + t d - c|^2 = r^2 (textbook formula, double precision).
std::pair<double, double> SphereRoots(const Vector3d& o, const Vector3d& d, const Vector3d& c, double r) {
  const Vector3d oc = o - c;
  const double a = d.squaredNorm(), b = 2 * oc.dot(d), cc = oc.squaredNorm() - r * r;
  const double disc = b * b - 4 * a * cc;
  if (disc < 0) return {kInf, kInf};
  return {(-b - std::sqrt(disc)) / (2 * a), (-b + std::sqrt(disc)) / (2 * a)};
}

// Independent nearest hit of one primitive (no height fields).
double ReferenceHit(const Primitive& p, const Vector3d& o, const Vector3d& d) {
  const Eigen::Matrix3d R = ToEigen(p.rotation);
  const Vector3d c = ToEigen(p.center);
  const Vector3d h = ToEigen(p.half_size);
  switch (p.shape) {
    case Shape::kQuad: return HitRectangle(o, d, c, R.col(0), R.col(1), h.x(), h.y());
    case Shape::kBox: {
      // Six faces; the enclosure sees the farthest face hit, a solid the nearest.
      double best = p.inside ? -kInf : kInf;
      for (int axis = 0; axis < 3; ++axis) {
        for (double side : {-1.0, 1.0}) {
          const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
          const double t = HitRectangle(o, d, c + side * h[axis] * R.col(axis), R.col(a1), R.col(a2), h[a1], h[a2]);
          if (!std::isfinite(t)) continue;
          best = p.inside ? std::max(best, t) : std::min(best, t);
        }
      }
      return std::isfinite(best) ? best : kInf;
    }
    case Shape::kSphere: {
      const auto [t0, t1] = SphereRoots(o, d, c, h.x());
      if (p.inside) return t1 > 0 ? t1 : kInf;
      return t0 > 0 ? t0 : kInf;
    }
    case Shape::kCylinder: {
      // Side: the quadratic of the distance to the axis, then the height check.
      const Vector3d ol = R.transpose() * (o - c), dl = R.transpose() * d;
      double best = kInf;
      const double a = dl.x() * dl.x() + dl.y() * dl.y();
      const double b = 2 * (ol.x() * dl.x() + ol.y() * dl.y());
      const double cc = ol.x() * ol.x() + ol.y() * ol.y() - h.x() * h.x();
      const double disc = b * b - 4 * a * cc;
      if (a > 0 && disc >= 0) {
        for (double t : {(-b - std::sqrt(disc)) / (2 * a), (-b + std::sqrt(disc)) / (2 * a)}) {
          if (t > 0 && std::abs(ol.z() + t * dl.z()) <= h.z()) best = std::min(best, t);
        }
      }
      for (double side : {-1.0, 1.0}) {
        const Eigen::Hyperplane<double, 3> cap(R.col(2), c + side * h.z() * R.col(2));
        const double t = Eigen::ParametrizedLine<double, 3>(o, d).intersectionParameter(cap);
        if (!(t > 0) || !std::isfinite(t)) continue;
        const Vector3d q = R.transpose() * (o + t * d - c);
        if (q.x() * q.x() + q.y() * q.y() <= h.x() * h.x()) best = std::min(best, t);
      }
      return best;
    }
    case Shape::kHeightField: break;
  }
  ADD_FAILURE() << "no reference for " << ShapeName(p.shape);
  return kInf;
}

struct ReferenceImage {
  std::vector<double> depth;  // 0 where no hit
  std::vector<int64_t> primitive;
};

ReferenceImage ReferenceCast(const Scene& scene, const PinholeCamera& cam, int64_t height, int64_t width) {
  ReferenceImage ref;
  const Eigen::Matrix3d R = ToEigen(cam.rotation);
  const Vector3d o = ToEigen(cam.Center());
  for (int64_t i = 0; i < height; ++i) {
    for (int64_t j = 0; j < width; ++j) {
      const Vector3d d = R.transpose() * Vector3d((j - cam.cx) / cam.fx, (i - cam.cy) / cam.fy, 1.0);
      double best = kInf;
      int64_t best_index = -1;
      for (size_t k = 0; k < scene.primitives.size(); ++k) {
        const double t = ReferenceHit(scene.primitives[k], o, d);
        if (t < best) {
          best = t;
          best_index = static_cast<int64_t>(k);
        }
      }
      // d has camera z = 1, so t is the depth.
      ref.depth.push_back(best_index >= 0 ? best : 0.0);
      ref.primitive.push_back(best_index);
    }
  }
  return ref;
}

Primitive MakePrimitive(Shape shape, const Vec3& center, const Vec3& half, const Mat3& rotation, int texture = 0) {
  Primitive p;
  p.shape = shape;
  p.center = center;
  p.half_size = half;
  p.rotation = rotation;
  p.texture = texture;
  return p;
}

// A sphere, a tilted quad, a rotated box, a thin rod, a cylinder, in front of
// a background box seen from inside.
Scene TestScene() {
  Scene scene;
  scene.textures.push_back(TextureSpec{});
  scene.primitives.push_back(MakePrimitive(Shape::kSphere, {0.4, -0.2, 5}, {1, 1, 1}, Mat3::Identity()));
  scene.primitives.push_back(
      MakePrimitive(Shape::kQuad, {-1.2, 0.5, 6}, {1.5, 1.0, 0}, AxisAngle({1, 0.3, 0.2}, 0.7)));
  scene.primitives.push_back(MakePrimitive(Shape::kBox, {1.5, 1.0, 7}, {0.8, 0.5, 0.6}, AxisAngle({0.2, 1, 0.1}, 0.5)));
  scene.primitives.push_back(MakePrimitive(Shape::kBox, {0, 0, 4}, {2.0, 0.03, 0.03}, AxisAngle({0, 0, 1}, 0.3)));
  scene.primitives.push_back(
      MakePrimitive(Shape::kCylinder, {-0.8, -1.0, 5.5}, {0.5, 0.5, 0.7}, AxisAngle({1, 0.5, 0}, 1.1)));
  Primitive room = MakePrimitive(Shape::kBox, {0, 0, 3}, {8, 6, 10}, AxisAngle({0, 0, 1}, 0.1));
  room.inside = true;
  scene.primitives.push_back(room);
  return scene;
}

PinholeCamera TestCamera(double cx, double cy) {
  PinholeCamera cam = PinholeCamera::LookAt({0.3, -0.4, -0.5}, {0.2, 0.1, 5}, {0, -1, 0});
  cam.fx = 70;
  cam.fy = 72;
  cam.cx = cx;
  cam.cy = cy;
  return cam;
}

TEST(RaycastTest, DoubleMatchesIndependentReferenceExactly) {
  const Scene scene = TestScene();
  const int64_t height = 48, width = 64;
  const PinholeCamera cam = TestCamera(31.5, 23.5);
  RaycastOptions options;
  options.dtype = torch::kDouble;
  const RayHits hits = CastImage(scene, cam, height, width, options);
  const ReferenceImage ref = ReferenceCast(scene, cam, height, width);
  const auto depth = hits.depth.contiguous();
  const auto prim = hits.primitive.contiguous();
  std::vector<int> seen(scene.primitives.size(), 0);
  for (int64_t k = 0; k < height * width; ++k) {
    ASSERT_EQ(prim.data_ptr<int64_t>()[k], ref.primitive[k]) << "pixel " << k;
    EXPECT_NEAR(depth.data_ptr<double>()[k], ref.depth[k], 1e-9 * ref.depth[k]) << "pixel " << k;
    if (ref.primitive[k] >= 0) ++seen[static_cast<size_t>(ref.primitive[k])];
  }
  // The scene is arranged so that every primitive is visible.
  for (size_t k = 0; k < seen.size(); ++k) EXPECT_GT(seen[k], 0) << "primitive " << k << " not visible";
  // Each ray's world direction, seen from the camera, has z = 1 and points
  // through its own pixel: centre + direction projects to (col, row).
  ASSERT_EQ(hits.direction.sizes(), (std::vector<int64_t>{height, width, 3}));
  for (const auto& [row, col] : {std::pair<int64_t, int64_t>{0, 0}, {17, 40}, {47, 63}}) {
    const Vec3 d{hits.direction[row][col][0].item<double>(), hits.direction[row][col][1].item<double>(),
                 hits.direction[row][col][2].item<double>()};
    const Vec3 in_camera = cam.ToCamera(cam.Center() + d);
    EXPECT_NEAR(in_camera.z, 1.0, 1e-12);
    EXPECT_NEAR(cam.fx * in_camera.x / in_camera.z + cam.cx, static_cast<double>(col), 1e-9);
    EXPECT_NEAR(cam.fy * in_camera.y / in_camera.z + cam.cy, static_cast<double>(row), 1e-9);
  }
}

TEST(RaycastTest, FloatDepthWithin1e5OfReference) {
  const Scene scene = TestScene();
  const int64_t height = 48, width = 64;
  const PinholeCamera cam = TestCamera(30.2, 24.9);
  const RayHits hits = CastImage(scene, cam, height, width);
  ASSERT_EQ(hits.depth.scalar_type(), torch::kFloat);
  const ReferenceImage ref = ReferenceCast(scene, cam, height, width);
  const auto depth = hits.depth.contiguous();
  const auto prim = hits.primitive.contiguous();
  int mismatched = 0;
  for (int64_t k = 0; k < height * width; ++k) {
    if (prim.data_ptr<int64_t>()[k] != ref.primitive[k]) {
      ++mismatched;  // only possible where a pixel centre grazes an edge
      continue;
    }
    EXPECT_NEAR(depth.data_ptr<float>()[k], ref.depth[k], 1e-5 * ref.depth[k]) << "pixel " << k;
  }
  EXPECT_LE(mismatched, 3);
}

TEST(RaycastTest, PixelConventionCentreOfPixelIJIsXEqualsJ) {
  // cx = cy = 0: the ray of pixel (row 0, col 0) is the optical axis, which
  // meets a fronto-parallel quad at depth 3; the ray of pixel (row i, col j)
  // meets it at x = 3 j / fx, y = 3 i / fy.
  Scene scene;
  scene.textures.push_back(TextureSpec{});
  scene.primitives.push_back(MakePrimitive(Shape::kQuad, {0, 0, 3}, {10, 10, 0}, Mat3::Identity()));
  scene.primitives[0].uv_unit = 1.0;
  PinholeCamera cam;
  cam.fx = 50;
  cam.fy = 40;
  RaycastOptions options;
  options.dtype = torch::kDouble;
  const RayHits hits = CastImage(scene, cam, 5, 7, options);
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < 7; ++j) {
      EXPECT_DOUBLE_EQ(hits.depth[i][j].item<double>(), 3.0);
      EXPECT_NEAR(hits.uv[i][j][0].item<double>(), 3.0 * j / 50, 1e-12);
      EXPECT_NEAR(hits.uv[i][j][1].item<double>(), 3.0 * i / 40, 1e-12);
      EXPECT_NEAR(hits.normal[i][j][2].item<double>(), -1.0, 1e-12);  // turned towards the camera
    }
  }
  // CastPixels at the same positions gives the same answers.
  const torch::Tensor xy = torch::tensor({6.0, 4.0, 0.0, 0.0}, torch::kDouble).view({2, 2});
  const RayHits some = CastPixels(scene, cam, xy, options);
  EXPECT_DOUBLE_EQ(some.uv[0][0].item<double>(), hits.uv[4][6][0].item<double>());
  EXPECT_DOUBLE_EQ(some.depth[1].item<double>(), 3.0);
}

TEST(RaycastTest, SphereNormalAndUvAreOnTheSurface) {
  Scene scene;
  scene.textures.push_back(TextureSpec{});
  scene.primitives.push_back(MakePrimitive(Shape::kSphere, {0.2, 0.1, 4}, {1, 1, 1}, Mat3::Identity()));
  PinholeCamera cam;
  cam.fx = cam.fy = 40;
  cam.cx = 15.5;
  cam.cy = 15.5;
  RaycastOptions options;
  options.dtype = torch::kDouble;
  const RayHits hits = CastImage(scene, cam, 32, 32, options);
  int checked = 0;
  for (int i = 0; i < 32; ++i) {
    for (int j = 0; j < 32; ++j) {
      const double z = hits.depth[i][j].item<double>();
      if (z == 0) continue;
      const Vector3d point((j - cam.cx) / cam.fx * z, (i - cam.cy) / cam.fy * z, z);
      const Vector3d expected_normal = (point - Vector3d(0.2, 0.1, 4)).normalized();
      for (int a = 0; a < 3; ++a) EXPECT_NEAR(hits.normal[i][j][a].item<double>(), expected_normal[a], 1e-9);
      const double latitude = std::asin(expected_normal.z());
      EXPECT_NEAR(hits.uv[i][j][1].item<double>(), latitude, 1e-9);  // radius 1, uv_unit 1
      ++checked;
    }
  }
  EXPECT_GT(checked, 300);
}

double Height(const Primitive& p, double x, double y) {
  double h = p.wave.amplitude * std::sin(p.wave.kx * x + p.wave.ky * y + p.wave.phase);
  for (const HeightBump& b : p.bumps) {
    h += b.amplitude * std::exp(-((x - b.x) * (x - b.x) + (y - b.y) * (y - b.y)) / (2 * b.sigma * b.sigma));
  }
  return h;
}

TEST(RaycastTest, HeightFieldHitIsTheFirstCrossingOfTheSurface) {
  Scene scene;
  scene.textures.push_back(TextureSpec{});
  Primitive field = MakePrimitive(Shape::kHeightField, {0, 0, 0}, {2, 1.5, 0}, AxisAngle({0, 0, 1}, 0.4));
  field.bumps = {{0.5, 0.2, 0.6, 0.4}, {-0.8, -0.3, 0.4, 0.3}, {0.9, -0.7, -0.3, 0.5}};
  field.wave = {0.05, 4.0, 3.0, 0.3};
  scene.primitives.push_back(field);
  PinholeCamera cam = PinholeCamera::LookAt({0.5, -4, 2.5}, {0, 0, 0}, {0, 0, 1});
  cam.fx = cam.fy = 60;
  cam.cx = 31.5;
  cam.cy = 23.5;
  // Enough bisections (in double) that the bracket is below 1e-12: the hit
  // must then lie on the surface to 1e-9.
  RaycastOptions options;
  options.dtype = torch::kDouble;
  options.bisection_steps = 40;
  const RayHits hits = CastImage(scene, cam, 48, 64, options);
  const Eigen::Matrix3d R = ToEigen(cam.rotation), Rp = ToEigen(field.rotation);
  const Vector3d o = ToEigen(cam.Center());
  int on_top = 0;
  for (int i = 0; i < 48; ++i) {
    for (int j = 0; j < 64; ++j) {
      const double t = hits.depth[i][j].item<double>();
      if (t == 0) continue;
      const Vector3d d = R.transpose() * Vector3d((j - cam.cx) / cam.fx, (i - cam.cy) / cam.fy, 1.0);
      const Vector3d q = Rp.transpose() * (o + t * d);  // field centre is the origin
      ASSERT_LE(std::abs(q.x()), 2 + 1e-9);
      ASSERT_LE(std::abs(q.y()), 1.5 + 1e-9);
      const bool top = std::abs(q.z() - Height(field, q.x(), q.y())) < 1e-9;
      if (!top) continue;  // a wall of the block
      ++on_top;
      // No earlier crossing: dense samples before t are all above the surface.
      for (int s = 1; s < 2000; ++s) {
        const double ts = t * s / 2000.0;
        const Vector3d qs = Rp.transpose() * (o + ts * d);
        if (std::abs(qs.x()) > 2 || std::abs(qs.y()) > 1.5) continue;
        ASSERT_GT(qs.z(), Height(field, qs.x(), qs.y())) << "earlier crossing at pixel " << i << "," << j;
      }
    }
  }
  EXPECT_GT(on_top, 500);
}

TEST(RaycastTest, ScaledSceneGivesScaledDepthAndSameUv) {
  const Scene scene = TestScene();
  PinholeCamera cam = TestCamera(31.5, 23.5);
  RaycastOptions options;
  options.dtype = torch::kDouble;
  const RayHits unit = CastImage(scene, cam, 48, 64, options);
  for (const double scale : {1e-3, 1e3}) {
    PinholeCamera scaled_cam = cam;
    scaled_cam.translation = scale * cam.translation;
    const RayHits scaled = CastImage(ScaleScene(scene, scale), scaled_cam, 48, 64, options);
    EXPECT_TRUE(torch::equal(unit.primitive, scaled.primitive));
    EXPECT_TRUE(torch::allclose(scaled.depth, unit.depth * scale, 1e-10, 0));
    EXPECT_TRUE(torch::allclose(scaled.uv, unit.uv, 0, 1e-8));
    EXPECT_TRUE(torch::allclose(scaled.normal, unit.normal, 0, 1e-8));
  }
}

// A sphere at infinity (a sky) is where the ray's direction alone says, in
// every camera however far apart: its UV and normal are those of the point
// radius x (unit direction) around its centre, computed here from the
// direction alone, and its depth reads 0. A finite object in front of it
// keeps its depth. The same sphere not at infinity is seen elsewhere (the
// check can fail).
TEST(RaycastTest, SphereAtInfinityDependsOnTheDirectionAlone) {
  constexpr double kRadius = 500, kUnit = 7;
  Scene scene;
  scene.textures.push_back(TextureSpec{});
  const Mat3 sky_rotation = AxisAngle({0.3, -0.5, 0.8}, 0.7);
  Primitive sky = MakePrimitive(Shape::kSphere, {30, -20, 10}, {kRadius, kRadius, kRadius}, sky_rotation);
  sky.inside = sky.at_infinity = true;
  sky.uv_unit = kUnit;
  scene.primitives.push_back(sky);
  scene.primitives.push_back(MakePrimitive(Shape::kSphere, {0.5, 0.2, 6}, {1, 1, 1}, Mat3::Identity()));
  Scene finite = scene;
  finite.primitives[0].at_infinity = false;

  PinholeCamera near_origin = PinholeCamera::LookAt({0, 0, 0}, {0, 0, 1}, {0, -1, 0});
  PinholeCamera far_away = PinholeCamera::LookAt({60, 35, -15}, {61, 35.2, -14}, {0, -1, 0});
  for (PinholeCamera* cam : {&near_origin, &far_away}) {
    cam->fx = cam->fy = 30;
    cam->cx = 23.5;
    cam->cy = 15.5;
  }
  RaycastOptions options;
  options.dtype = torch::kDouble;
  const Eigen::Matrix3d rp = ToEigen(sky_rotation);
  for (const PinholeCamera* cam : {&near_origin, &far_away}) {
    const RayHits hits = CastImage(scene, *cam, 32, 48, options);
    const RayHits moved = CastImage(finite, *cam, 32, 48, options);
    const Eigen::Matrix3d r = ToEigen(cam->rotation);
    int on_sky = 0, on_object = 0;
    double largest_shift = 0;
    for (int i = 0; i < 32; ++i) {
      for (int j = 0; j < 48; ++j) {
        const int64_t primitive = hits.primitive[i][j].item<int64_t>();
        if (primitive == 1) {
          EXPECT_GT(hits.depth[i][j].item<double>(), 4.0);
          ++on_object;
          continue;
        }
        ASSERT_EQ(primitive, 0);
        ++on_sky;
        EXPECT_EQ(hits.depth[i][j].item<double>(), 0.0);
        const Vector3d direction = (r.transpose() * Vector3d((j - cam->cx) / cam->fx, (i - cam->cy) / cam->fy, 1)).normalized();
        const Vector3d local = rp.transpose() * (kRadius * direction);
        const double u = std::atan2(local.y(), local.x()) * kRadius / kUnit;
        const double v = std::asin(local.z() / kRadius) * kRadius / kUnit;
        EXPECT_NEAR(hits.uv[i][j][0].item<double>(), u, 1e-9);
        EXPECT_NEAR(hits.uv[i][j][1].item<double>(), v, 1e-9);
        for (int a = 0; a < 3; ++a) EXPECT_NEAR(hits.normal[i][j][a].item<double>(), -direction[a], 1e-9);
        largest_shift = std::max(largest_shift, std::abs(moved.uv[i][j][0].item<double>() - u));
      }
    }
    EXPECT_GT(on_sky, 1000);
    if (cam == &near_origin) EXPECT_GT(on_object, 50);  // the object stands in front of it
    EXPECT_GT(largest_shift, 0.05);  // a finite sphere shows parallax
  }
}

TEST(RaycastTest, RejectsBadInput) {
  Scene scene = TestScene();
  const PinholeCamera cam = TestCamera(31.5, 23.5);
  EXPECT_THROW(CastImage(scene, cam, 0, 10), std::invalid_argument);
  EXPECT_THROW(CastPixels(scene, cam, torch::zeros({4, 3})), std::invalid_argument);
  PinholeCamera bad = cam;
  bad.fx = 0;
  EXPECT_THROW(CastImage(scene, bad, 8, 8), std::invalid_argument);
  scene.primitives[0].texture = 5;
  EXPECT_THROW(CastImage(scene, cam, 8, 8), std::invalid_argument);
  scene = TestScene();
  scene.primitives[1].half_size.x = -1;
  EXPECT_THROW(CastImage(scene, cam, 8, 8), std::invalid_argument);
  // Only a sphere enclosure can be at infinity.
  for (const bool inside : {false, true}) {
    for (const Shape shape : {Shape::kSphere, Shape::kBox}) {
      if (inside && shape == Shape::kSphere) continue;
      scene = TestScene();
      scene.primitives[0].shape = shape;
      scene.primitives[0].inside = inside;
      scene.primitives[0].at_infinity = true;
      EXPECT_THROW(CastImage(scene, cam, 8, 8), std::invalid_argument);
    }
  }
}

}  // namespace
}  // namespace dispmvs::synth
