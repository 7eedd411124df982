#include "synth/raycast.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <vector>

namespace dispmvs::synth {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Rays expressed in one primitive's local frame: the shared origin (the
// camera centre, kept in double) and per-ray directions [...,3].
struct LocalRays {
  Vec3 origin;
  torch::Tensor dir;
};

// Nearest hit of rays with one primitive: t = +inf where missed. `face`
// (int64) says which part of the primitive was hit, so that UV and normal
// can be computed afterwards for the winning primitive only:
//   box / height-field wall: axis * 2 + (1 if on the +half_size side)
//   cylinder: 0 side, 1 top cap, 2 bottom cap; height field: 0 top surface,
//   1 + box code for its walls; quad, sphere: 0.
struct Hit {
  torch::Tensor t;
  torch::Tensor face;
};

torch::Tensor C(const torch::Tensor& v, int64_t i) { return v.select(-1, i); }

torch::Tensor MaskedT(const torch::Tensor& hit, const torch::Tensor& t) {
  return torch::where(hit, t, torch::full_like(t, kInf));
}

torch::Tensor ToTensor(const Mat3& m, const torch::TensorOptions& options) {
  return torch::tensor(std::vector<double>(m.m.begin(), m.m.end()), torch::kDouble)
      .reshape({3, 3})
      .to(options);
}

// Ray / axis-aligned box [lo, hi] (slab method). Non-finite values (rays
// parallel to a face, starting on it) compare false and so count as misses.
struct Slabs {
  torch::Tensor t_near, t_far;        // entry and exit parameters
  torch::Tensor near_face, far_face;  // box face codes of entry and exit
};

Slabs IntersectSlabs(const Vec3& o, const torch::Tensor& dir, const Vec3& lo, const Vec3& hi) {
  std::vector<torch::Tensor> t_lo, t_hi;
  for (int i = 0; i < 3; ++i) {
    const torch::Tensor inv = torch::reciprocal(C(dir, i));
    const torch::Tensor a = (lo[i] - o[i]) * inv;
    const torch::Tensor b = (hi[i] - o[i]) * inv;
    t_lo.push_back(torch::minimum(a, b));
    t_hi.push_back(torch::maximum(a, b));
  }
  auto [t_near, axis_near] = torch::stack(t_lo, -1).max(-1);
  auto [t_far, axis_far] = torch::stack(t_hi, -1).min(-1);
  const torch::Tensor d_near = dir.gather(-1, axis_near.unsqueeze(-1)).squeeze(-1);
  const torch::Tensor d_far = dir.gather(-1, axis_far.unsqueeze(-1)).squeeze(-1);
  // A ray moving towards -axis enters through the + side and leaves through the - side.
  return {t_near, t_far, axis_near * 2 + (d_near < 0).to(torch::kLong),
          axis_far * 2 + (d_far > 0).to(torch::kLong)};
}

Hit IntersectQuad(const Primitive& p, const LocalRays& r) {
  const torch::Tensor t = -r.origin.z / C(r.dir, 2);
  const torch::Tensor x = r.origin.x + t * C(r.dir, 0);
  const torch::Tensor y = r.origin.y + t * C(r.dir, 1);
  const torch::Tensor hit = (t > 0) & (torch::abs(x) <= p.half_size.x) & (torch::abs(y) <= p.half_size.y);
  return {MaskedT(hit, t), torch::zeros_like(t, torch::kLong)};
}

Hit IntersectBox(const Primitive& p, const LocalRays& r) {
  const Slabs s = IntersectSlabs(r.origin, r.dir, -1.0 * p.half_size, p.half_size);
  if (p.inside) {
    const torch::Tensor hit = (s.t_near <= s.t_far) & (s.t_far > 0);
    return {MaskedT(hit, s.t_far), s.far_face};
  }
  const torch::Tensor hit = (s.t_near <= s.t_far) & (s.t_near > 0);
  return {MaskedT(hit, s.t_near), s.near_face};
}

Hit IntersectSphere(const Primitive& p, const LocalRays& r) {
  // Closest approach of the ray to the centre, then the half chord: stable
  // even when the sphere is far away compared to its radius.
  const Vec3& o = r.origin;
  const torch::Tensor dx = C(r.dir, 0), dy = C(r.dir, 1), dz = C(r.dir, 2);
  const torch::Tensor dd = dx * dx + dy * dy + dz * dz;
  const torch::Tensor tc = -(o.x * dx + o.y * dy + o.z * dz) / dd;
  const torch::Tensor qx = o.x + tc * dx, qy = o.y + tc * dy, qz = o.z + tc * dz;
  const double radius = p.half_size.x;
  const torch::Tensor disc = radius * radius - (qx * qx + qy * qy + qz * qz);
  const torch::Tensor half = torch::sqrt(torch::clamp_min(disc, 0) / dd);
  const torch::Tensor t = p.inside ? tc + half : tc - half;
  return {MaskedT((disc >= 0) & (t > 0), t), torch::zeros_like(t, torch::kLong)};
}

Hit IntersectCylinder(const Primitive& p, const LocalRays& r) {
  const Vec3& o = r.origin;
  const double radius = p.half_size.x, half_height = p.half_size.z;
  const torch::Tensor dx = C(r.dir, 0), dy = C(r.dir, 1), dz = C(r.dir, 2);
  // Side: the circle in the xy projection, in closest-approach form.
  const torch::Tensor dd = dx * dx + dy * dy;
  const torch::Tensor tc = -(o.x * dx + o.y * dy) / dd;
  const torch::Tensor qx = o.x + tc * dx, qy = o.y + tc * dy;
  const torch::Tensor disc = radius * radius - (qx * qx + qy * qy);
  const torch::Tensor t_side = tc - torch::sqrt(torch::clamp_min(disc, 0) / dd);
  const torch::Tensor side_hit =
      (disc >= 0) & (t_side > 0) & (torch::abs(o.z + t_side * dz) <= half_height);
  std::vector<torch::Tensor> candidates{MaskedT(side_hit, t_side)};
  for (const double cap_z : {half_height, -half_height}) {
    const torch::Tensor t = (cap_z - o.z) / dz;
    const torch::Tensor x = o.x + t * dx, y = o.y + t * dy;
    candidates.push_back(MaskedT((t > 0) & (x * x + y * y <= radius * radius), t));
  }
  auto [t, face] = torch::stack(candidates, -1).min(-1);
  return {t, face};
}

torch::Tensor Height(const Primitive& p, const torch::Tensor& x, const torch::Tensor& y) {
  torch::Tensor h = p.wave.amplitude * torch::sin(x * p.wave.kx + y * p.wave.ky + p.wave.phase);
  for (const HeightBump& b : p.bumps) {
    h = h + b.amplitude * torch::exp(((x - b.x).square() + (y - b.y).square()) * (-0.5 / (b.sigma * b.sigma)));
  }
  return h;
}

// (dh/dx, dh/dy) of Height().
std::pair<torch::Tensor, torch::Tensor> HeightGradient(const Primitive& p, const torch::Tensor& x,
                                                       const torch::Tensor& y) {
  const torch::Tensor wave = p.wave.amplitude * torch::cos(x * p.wave.kx + y * p.wave.ky + p.wave.phase);
  torch::Tensor gx = wave * p.wave.kx, gy = wave * p.wave.ky;
  for (const HeightBump& b : p.bumps) {
    const double inv_var = 1.0 / (b.sigma * b.sigma);
    const torch::Tensor g =
        b.amplitude * torch::exp(((x - b.x).square() + (y - b.y).square()) * (-0.5 * inv_var)) * (-inv_var);
    gx = gx + g * (x - b.x);
    gy = gy + g * (y - b.y);
  }
  return {gx, gy};
}

// `nearest`: the nearest hit so far of each ray; rays that enter the block
// beyond it cannot be changed by this primitive and are not marched.
Hit IntersectHeightField(const Primitive& p, const LocalRays& r, const torch::Tensor& nearest,
                         const RaycastOptions& options) {
  const Vec3& o = r.origin;
  const Vec3 lo{-p.half_size.x, -p.half_size.y, p.HeightFieldBottom()};
  const Vec3 hi{p.half_size.x, p.half_size.y, p.HeightFieldTop()};
  const Slabs s = IntersectSlabs(o, r.dir, lo, hi);
  const auto shape = r.dir.sizes().slice(0, r.dir.dim() - 1).vec();
  torch::Tensor t_out = torch::full({s.t_near.numel()}, kInf, r.dir.options());
  torch::Tensor face_out = torch::zeros({s.t_near.numel()}, r.dir.options().dtype(torch::kLong));

  // March only the rays that cross the block.
  const torch::Tensor crosses = ((s.t_near <= s.t_far) & (s.t_far > 0) & (s.t_near < nearest)).reshape({-1});
  const torch::Tensor index = torch::nonzero(crosses).squeeze(1);
  if (index.numel() > 0) {
    const torch::Tensor dir = r.dir.reshape({-1, 3}).index_select(0, index);
    const torch::Tensor t_near = s.t_near.reshape({-1}).index_select(0, index);
    const torch::Tensor t_far = s.t_far.reshape({-1}).index_select(0, index);
    const torch::Tensor near_face = s.near_face.reshape({-1}).index_select(0, index);
    // Signed height of the ray above the surface at parameter t ([n] or [n,k]).
    auto above = [&](const torch::Tensor& t) {
      const bool grid = t.dim() == 2;
      const torch::Tensor dx = grid ? C(dir, 0).unsqueeze(1) : C(dir, 0);
      const torch::Tensor dy = grid ? C(dir, 1).unsqueeze(1) : C(dir, 1);
      const torch::Tensor dz = grid ? C(dir, 2).unsqueeze(1) : C(dir, 2);
      return (o.z + t * dz) - Height(p, o.x + t * dx, o.y + t * dy);
    };
    const torch::Tensor t_start = torch::clamp_min(t_near, 0);
    const torch::Tensor start_above = above(t_start) > 0;
    // Entering the block below the surface means hitting its wall (or
    // bottom); starting below it means the camera is inside the solid.
    const torch::Tensor wall = (t_near > 0) & ~start_above;

    const int64_t steps = options.march_steps;
    const torch::Tensor fractions =
        torch::arange(1, steps + 1, dir.options()).div(static_cast<double>(steps)).unsqueeze(0);
    const torch::Tensor ts = t_start.unsqueeze(1) + (t_far - t_start).unsqueeze(1) * fractions;  // [n,steps]
    const torch::Tensor below = above(ts) <= 0;
    // First step at or below the surface (steps where there is none).
    const torch::Tensor step_index = torch::arange(steps, below.options().dtype(torch::kLong)).unsqueeze(0);
    const torch::Tensor first = std::get<0>(torch::where(below, step_index, steps).min(1));
    const torch::Tensor crossed = first < steps;
    const torch::Tensor k = torch::clamp_max(first, steps - 1).unsqueeze(1);
    torch::Tensor hi_t = ts.gather(1, k).squeeze(1);
    torch::Tensor lo_t = torch::where(k.squeeze(1) > 0, ts.gather(1, torch::clamp_min(k - 1, 0)).squeeze(1), t_start);
    // Bisection keeps f(lo) > 0 >= f(hi); a final secant (regula falsi)
    // step inside the small bracket removes most of the remaining error.
    torch::Tensor lo_f = above(lo_t), hi_f = above(hi_t);
    for (int i = 0; i < options.bisection_steps; ++i) {
      const torch::Tensor mid = 0.5 * (lo_t + hi_t);
      const torch::Tensor mid_f = above(mid);
      const torch::Tensor mid_below = mid_f <= 0;
      hi_t = torch::where(mid_below, mid, hi_t);
      hi_f = torch::where(mid_below, mid_f, hi_f);
      lo_t = torch::where(mid_below, lo_t, mid);
      lo_f = torch::where(mid_below, lo_f, mid_f);
    }
    const torch::Tensor denominator = lo_f - hi_f;
    const torch::Tensor secant = lo_t + (hi_t - lo_t) * torch::clamp(lo_f / denominator, 0, 1);
    const torch::Tensor root = torch::where(denominator > 0, secant, 0.5 * (lo_t + hi_t));
    const torch::Tensor surface = crossed & start_above;
    const torch::Tensor t = torch::where(wall, t_near, MaskedT(surface, root));
    t_out.index_copy_(0, index, t);
    face_out.index_copy_(0, index, torch::where(wall, near_face + 1, torch::zeros_like(near_face)));
  }
  return {t_out.reshape(shape), face_out.reshape(shape)};
}

Hit Intersect(const Primitive& p, const LocalRays& r, const torch::Tensor& nearest, const RaycastOptions& options) {
  switch (p.shape) {
    case Shape::kQuad: return IntersectQuad(p, r);
    case Shape::kBox: return IntersectBox(p, r);
    case Shape::kSphere: return IntersectSphere(p, r);
    case Shape::kCylinder: return IntersectCylinder(p, r);
    case Shape::kHeightField: return IntersectHeightField(p, r, nearest, options);
  }
  throw std::logic_error("Intersect: unknown shape");
}

// UV and local normal on a box face (codes as in Hit). Each face gets its own
// UV offset so opposite faces do not look alike.
std::pair<torch::Tensor, torch::Tensor> BoxFaceSurface(const torch::Tensor& q, const torch::Tensor& face,
                                                       double uv_unit) {
  const torch::Tensor axis = torch::div(face, 2, "floor");
  const torch::Tensor sign = (torch::remainder(face, 2) * 2 - 1).to(q.scalar_type());
  const torch::Tensor normal = torch::one_hot(axis, 3).to(q.scalar_type()) * sign.unsqueeze(1);
  const torch::Tensor u = q.gather(1, torch::remainder(axis + 1, 3).unsqueeze(1)).squeeze(1);
  const torch::Tensor v = q.gather(1, torch::remainder(axis + 2, 3).unsqueeze(1)).squeeze(1);
  const torch::Tensor offset = face.to(q.scalar_type()) * 3.7;
  return {torch::stack({u / uv_unit + offset, v / uv_unit + offset}, 1), normal};
}

// UV [n,2] and local unit normal [n,3] at local hit points q [n,3].
std::pair<torch::Tensor, torch::Tensor> SurfaceAt(const Primitive& p, const torch::Tensor& q,
                                                  const torch::Tensor& face) {
  const torch::Tensor x = C(q, 0), y = C(q, 1), z = C(q, 2);
  const double unit = p.uv_unit;
  switch (p.shape) {
    case Shape::kQuad:
      return {torch::stack({x / unit, y / unit}, 1),
              torch::zeros_like(q).index_fill_(1, torch::tensor({2}, face.options()), 1.0)};
    case Shape::kBox:
      return BoxFaceSurface(q, face, unit);
    case Shape::kSphere: {
      const double radius = p.half_size.x;
      const torch::Tensor latitude = torch::asin(torch::clamp(z / radius, -1, 1));
      return {torch::stack({torch::atan2(y, x) * (radius / unit), latitude * (radius / unit)}, 1),
              q / radius};
    }
    case Shape::kCylinder: {
      const double radius = p.half_size.x;
      const torch::Tensor side_uv = torch::stack({torch::atan2(y, x) * (radius / unit), z / unit}, 1);
      const torch::Tensor cap_uv = torch::stack({x / unit + 5.0, y / unit + 5.0}, 1);
      const torch::Tensor side_normal = torch::stack({x / radius, y / radius, torch::zeros_like(z)}, 1);
      const torch::Tensor cap_sign = torch::where(face == 1, 1.0, -1.0).to(q.scalar_type());
      const torch::Tensor cap_normal =
          torch::stack({torch::zeros_like(z), torch::zeros_like(z), cap_sign}, 1);
      const torch::Tensor is_side = (face == 0).unsqueeze(1);
      return {torch::where(is_side, side_uv, cap_uv), torch::where(is_side, side_normal, cap_normal)};
    }
    case Shape::kHeightField: {
      auto [gx, gy] = HeightGradient(p, x, y);
      torch::Tensor top_normal = torch::stack({-gx, -gy, torch::ones_like(gx)}, 1);
      top_normal = top_normal / top_normal.norm(2, 1, true);
      const torch::Tensor top_uv = torch::stack({x / unit, y / unit}, 1);
      auto [wall_uv, wall_normal] = BoxFaceSurface(q, torch::clamp_min(face - 1, 0), unit);
      const torch::Tensor is_top = (face == 0).unsqueeze(1);
      return {torch::where(is_top, top_uv, wall_uv), torch::where(is_top, top_normal, wall_normal)};
    }
  }
  throw std::logic_error("SurfaceAt: unknown shape");
}

// Pixel rectangle (inclusive rows r0..r1, cols c0..c1) that contains every
// pixel centre whose ray can hit `p`, or nullopt when none can. When the
// primitive's bounding box is entirely in front of the camera its image is
// inside the hull of the 8 projected corners; otherwise the whole image.
struct PixelRect {
  int64_t r0, r1, c0, c1;
};
std::optional<PixelRect> ImageRect(const Primitive& p, const PinholeCamera& camera, int64_t height,
                                   int64_t width) {
  const PixelRect full{0, height - 1, 0, width - 1};
  if (p.inside) return full;
  double x_min = kInf, x_max = -kInf, y_min = kInf, y_max = -kInf;
  for (const Vec3& corner : p.BoundingCorners()) {
    const Vec3 c = camera.ToCamera(corner);
    if (!(c.z > 0)) {
      // Partly behind the camera: the rectangle is unbounded unless the whole
      // box is behind it.
      bool all_behind = true;
      for (const Vec3& other : p.BoundingCorners()) all_behind &= !(camera.ToCamera(other).z > 0);
      return all_behind ? std::nullopt : std::optional<PixelRect>(full);
    }
    const double x = camera.fx * c.x / c.z + camera.cx, y = camera.fy * c.y / c.z + camera.cy;
    x_min = std::min(x_min, x);
    x_max = std::max(x_max, x);
    y_min = std::min(y_min, y);
    y_max = std::max(y_max, y);
  }
  // One pixel of margin absorbs rounding in the float ray directions.
  const double r0 = std::max(std::floor(y_min) - 1, 0.0), r1 = std::min(std::ceil(y_max) + 1, double(height - 1));
  const double c0 = std::max(std::floor(x_min) - 1, 0.0), c1 = std::min(std::ceil(x_max) + 1, double(width - 1));
  if (r0 > r1 || c0 > c1) return std::nullopt;
  return PixelRect{int64_t(r0), int64_t(r1), int64_t(c0), int64_t(c1)};
}

// Camera-frame ray directions (z = 1) [...,2] pixel positions -> [...,3].
torch::Tensor CameraDirections(const PinholeCamera& camera, const torch::Tensor& x, const torch::Tensor& y) {
  const torch::Tensor dx = (x - camera.cx) / camera.fx;
  const torch::Tensor dy = (y - camera.cy) / camera.fy;
  return torch::stack({dx, dy, torch::ones_like(dx)}, -1);
}

// Where `p` stands for `camera`: a primitive at infinity (a sky) is centred
// on the camera, so that where a ray meets it depends on the ray's direction
// alone (Primitive::at_infinity).
Vec3 CentreSeenFrom(const Primitive& p, const PinholeCamera& camera) {
  return p.at_infinity ? camera.Center() : p.center;
}

// Nearest primitive of every ray: updates t / primitive / face (views of the
// caller's buffers, same leading shape as dir_cam) in place.
void NearestOfPrimitive(const Scene& scene, int64_t index, const PinholeCamera& camera,
                        const torch::Tensor& dir_cam, torch::Tensor t, torch::Tensor primitive,
                        torch::Tensor face, const RaycastOptions& options) {
  const Primitive& p = scene.primitives[static_cast<size_t>(index)];
  LocalRays rays;
  rays.origin = Transposed(p.rotation) * (camera.Center() - CentreSeenFrom(p, camera));
  // d_local = Rp^T R^T d_cam, i.e. as a row vector d_cam (R Rp).
  rays.dir = torch::matmul(dir_cam, ToTensor(camera.rotation * p.rotation, dir_cam.options()));
  const Hit hit = Intersect(p, rays, t, options);
  const torch::Tensor closer = hit.t < t;
  t.copy_(torch::where(closer, hit.t, t));
  primitive.masked_fill_(closer, index);
  face.copy_(torch::where(closer, hit.face, face));
}

// UV and normal for the winning primitive of every ray; flat [N] inputs.
RayHits Finish(const Scene& scene, const PinholeCamera& camera, const torch::Tensor& dir_cam,
               const torch::Tensor& t, const torch::Tensor& primitive, const torch::Tensor& face) {
  const int64_t n = t.size(0);
  RayHits hits;
  hits.primitive = primitive;
  hits.depth = torch::where(primitive >= 0, t, torch::zeros_like(t));
  hits.uv = torch::zeros({n, 2}, t.options());
  hits.normal = torch::zeros({n, 3}, t.options());
  const torch::Tensor dir_world = torch::matmul(dir_cam, ToTensor(camera.rotation, t.options()));
  hits.direction = dir_world;
  for (size_t i = 0; i < scene.primitives.size(); ++i) {
    const torch::Tensor index = torch::nonzero(primitive == static_cast<int64_t>(i)).squeeze(1);
    if (index.numel() == 0) continue;
    const Primitive& p = scene.primitives[i];
    const Vec3 origin = Transposed(p.rotation) * (camera.Center() - CentreSeenFrom(p, camera));
    const torch::Tensor dir_local =
        torch::matmul(dir_cam.index_select(0, index), ToTensor(camera.rotation * p.rotation, t.options()));
    const torch::Tensor q = torch::tensor({origin.x, origin.y, origin.z}, torch::kDouble).to(t.options()) +
                            t.index_select(0, index).unsqueeze(1) * dir_local;
    auto [uv, normal_local] = SurfaceAt(p, q, face.index_select(0, index));
    // n_world = Rp n_local, i.e. as a row vector n_local Rp^T; then face the camera.
    torch::Tensor normal = torch::matmul(normal_local, ToTensor(p.rotation, t.options()).t());
    const torch::Tensor away = (normal * dir_world.index_select(0, index)).sum(1, true) > 0;
    normal = torch::where(away, -normal, normal);
    hits.uv.index_copy_(0, index, uv);
    hits.normal.index_copy_(0, index, normal);
    if (p.at_infinity) hits.depth.index_fill_(0, index, 0.0);  // a sky has no depth
  }
  return hits;
}

// Height fields last: by then most occluded rays already have a nearer hit
// and skip the (expensive) march. The nearest hit does not depend on order.
std::vector<size_t> CastingOrder(const Scene& scene) {
  std::vector<size_t> order;
  for (int pass = 0; pass < 2; ++pass) {
    for (size_t i = 0; i < scene.primitives.size(); ++i) {
      if ((scene.primitives[i].shape == Shape::kHeightField) == (pass == 1)) order.push_back(i);
    }
  }
  return order;
}

void CheckInputs(const Scene& scene, const PinholeCamera& camera, const RaycastOptions& options) {
  scene.Check();
  if (!(camera.fx > 0 && camera.fy > 0) || !std::isfinite(camera.cx) || !std::isfinite(camera.cy)) {
    throw std::invalid_argument("raycast: camera focal lengths must be positive and the principal point finite");
  }
  if (options.dtype != torch::kFloat && options.dtype != torch::kDouble) {
    throw std::invalid_argument("raycast: dtype must be float32 or float64");
  }
  // The march holds (rays crossing a height field) x march_steps values.
  if (options.march_steps < 1 || options.march_steps > 256 || options.bisection_steps < 0 ||
      options.bisection_steps > 64) {
    throw std::invalid_argument("raycast: march_steps must be in [1, 256], bisection_steps in [0, 64]");
  }
}

RayHits Reshape(RayHits hits, const std::vector<int64_t>& shape) {
  std::vector<int64_t> uv_shape = shape, vector_shape = shape;
  uv_shape.push_back(2);
  vector_shape.push_back(3);
  return {hits.depth.reshape(shape), hits.primitive.reshape(shape), hits.uv.reshape(uv_shape),
          hits.normal.reshape(vector_shape), hits.direction.reshape(vector_shape)};
}

}  // namespace

RayHits CastImage(const Scene& scene, const PinholeCamera& camera, int64_t height, int64_t width,
                  const RaycastOptions& options) {
  CheckInputs(scene, camera, options);
  if (height < 1 || width < 1 || height > 16384 || width > 16384) {
    throw std::invalid_argument("CastImage: image size must be in [1, 16384]");
  }
  const auto real = torch::TensorOptions().dtype(options.dtype).device(options.device);
  const torch::Tensor x = torch::arange(width, real).unsqueeze(0).expand({height, width});
  const torch::Tensor y = torch::arange(height, real).unsqueeze(1).expand({height, width});
  const torch::Tensor dir_cam = CameraDirections(camera, x, y);  // [H,W,3]
  torch::Tensor t = torch::full({height, width}, kInf, real);
  torch::Tensor primitive = torch::full({height, width}, -1, real.dtype(torch::kLong));
  torch::Tensor face = torch::zeros({height, width}, real.dtype(torch::kLong));
  for (const size_t i : CastingOrder(scene)) {
    const auto rect = ImageRect(scene.primitives[i], camera, height, width);
    if (!rect) continue;
    auto region = [&](const torch::Tensor& full) {
      return full.narrow(0, rect->r0, rect->r1 - rect->r0 + 1).narrow(1, rect->c0, rect->c1 - rect->c0 + 1);
    };
    NearestOfPrimitive(scene, static_cast<int64_t>(i), camera, region(dir_cam), region(t), region(primitive),
                       region(face), options);
  }
  const RayHits flat = Finish(scene, camera, dir_cam.reshape({-1, 3}), t.reshape({-1}), primitive.reshape({-1}),
                              face.reshape({-1}));
  return Reshape(flat, {height, width});
}

RayHits CastPixels(const Scene& scene, const PinholeCamera& camera, const torch::Tensor& xy,
                   const RaycastOptions& options) {
  CheckInputs(scene, camera, options);
  if (xy.dim() != 2 || xy.size(1) != 2) throw std::invalid_argument("CastPixels: xy must be [N,2]");
  const auto real = torch::TensorOptions().dtype(options.dtype).device(options.device);
  const torch::Tensor pixels = xy.to(real);
  const int64_t n = pixels.size(0);
  const torch::Tensor dir_cam = CameraDirections(camera, C(pixels, 0), C(pixels, 1));  // [N,3]
  torch::Tensor t = torch::full({n}, kInf, real);
  torch::Tensor primitive = torch::full({n}, -1, real.dtype(torch::kLong));
  torch::Tensor face = torch::zeros({n}, real.dtype(torch::kLong));
  for (const size_t i : CastingOrder(scene)) {
    NearestOfPrimitive(scene, static_cast<int64_t>(i), camera, dir_cam, t, primitive, face, options);
  }
  return Finish(scene, camera, dir_cam, t, primitive, face);
}

}  // namespace dispmvs::synth
