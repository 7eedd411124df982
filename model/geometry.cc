// Epipolar geometry of DispMVS. See geometry.h for the conventions and
// docs/method.md (sections 2-5, "The epipolar line of a reference pixel" to
// "Triangulation") for the derivations.
//
// Two rules hold in every function below:
//  * Degenerate geometry is detected with thresholds RELATIVE to the
//    magnitudes of the terms that cancel (see IsClearlyPositive). Scaling the
//    scene by s multiplies b = K_s T by s and divides w by s, so the products
//    w b, the ratios between b components, and a are unit-free; every test
//    below compares quantities of the same unit and gives the same mask for a
//    scene in millimetres and in kilometres.
//  * Nothing non-finite is ever created, not even in a masked-out branch:
//    inputs are cleaned (non-finite -> 0) on entry, and denominators are
//    replaced by 1 with torch::where BEFORE dividing. torch::where only masks
//    the forward value; its backward still runs the masked branch with a zero
//    incoming gradient, and 0 * inf = NaN would leak into the gradients.

#include "model/geometry.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace dispmvs::model {
namespace {

// Relative tolerance of the degeneracy tests: sqrt(machine epsilon).
// A quantity obtained by cancellation (e.g. the epipolar gradient
// b_xy a_z - a_xy b_z near the epipole) carries an absolute rounding error of
// a few eps * (magnitude of the terms). Once it falls below sqrt(eps) times
// those terms its relative error exceeds ~sqrt(eps) (3e-4 in float32), so a
// direction or depth computed from it is no longer trustworthy.
double RelativeTolerance(torch::ScalarType dtype) {
  switch (dtype) {
    case torch::kFloat64:
      return std::sqrt(std::numeric_limits<double>::epsilon());
    case torch::kFloat32:
      return std::sqrt(static_cast<double>(std::numeric_limits<float>::epsilon()));
    case torch::kFloat16:
      return std::sqrt(9.765625e-4);  // 2^-10
    case torch::kBFloat16:
      return std::sqrt(7.8125e-3);  // 2^-7
    default:
      throw std::invalid_argument("dispmvs geometry: tensors must have a floating-point dtype");
  }
}

// No image is 2^24 pixels wide, and float32 cannot even address single pixels
// beyond that: a projection further out is treated as unusable. The bound
// also keeps quotients (and their gradients) far from overflow when a ray is
// almost parallel to the source image plane.
constexpr double kMaxPixelCoordinate = 16777216.0;  // 2^24

void CheckFloating(const torch::Tensor& t, const char* name) {
  if (!t.defined()) {
    throw std::invalid_argument(std::string("dispmvs geometry: ") + name + " is undefined");
  }
  if (!t.is_floating_point()) {
    throw std::invalid_argument(std::string("dispmvs geometry: ") + name +
                                " must have a floating-point dtype");
  }
}

// [B,C,H,W] with the given channel count (C < 0: any).
void CheckImage(const torch::Tensor& t, int64_t channels, const char* name) {
  CheckFloating(t, name);
  if (t.dim() != 4 || (channels >= 0 && t.size(1) != channels)) {
    throw std::invalid_argument(
        std::string("dispmvs geometry: ") + name + " must be [B," +
        (channels >= 0 ? std::to_string(channels) : std::string("N")) + ",H,W], got " +
        std::to_string(t.dim()) + " dimensions" +
        (t.dim() >= 2 ? ", " + std::to_string(t.size(1)) + " channels" : std::string()));
  }
}

// [B,rows,cols]; returns B.
int64_t CheckBatchedMatrix(const torch::Tensor& t, int64_t rows, int64_t cols, const char* name) {
  CheckFloating(t, name);
  const bool ok = (cols > 0) ? (t.dim() == 3 && t.size(1) == rows && t.size(2) == cols)
                             : (t.dim() == 2 && t.size(1) == rows);
  if (!ok) {
    throw std::invalid_argument(std::string("dispmvs geometry: ") + name + " must be [B," +
                                std::to_string(rows) +
                                (cols > 0 ? "," + std::to_string(cols) : std::string()) + "]");
  }
  return t.size(0);
}

void CheckSameKind(const torch::Tensor& t, const torch::Tensor& reference, const char* name) {
  if (t.scalar_type() != reference.scalar_type() || t.device() != reference.device()) {
    throw std::invalid_argument(std::string("dispmvs geometry: ") + name +
                                " must have the same dtype and device as the other inputs");
  }
}

void CheckPair(const EpipolarPair& pair) {
  CheckImage(pair.a, 3, "EpipolarPair::a");
  CheckImage(pair.b, 3, "EpipolarPair::b");
  CheckSameKind(pair.b, pair.a, "EpipolarPair::b");
}

torch::Tensor ZeroNonFinite(const torch::Tensor& t) {
  return torch::where(torch::isfinite(t), t, torch::zeros_like(t));
}

// value > tol * scale, where `scale` is the sum of the magnitudes of the terms
// that make up `value`: positive beyond rounding noise, unit-free.
torch::Tensor IsClearlyPositive(const torch::Tensor& value, const torch::Tensor& scale,
                                double tol) {
  return value > scale * tol;
}
torch::Tensor IsClearlyNonZero(const torch::Tensor& value, const torch::Tensor& scale, double tol) {
  return value.abs() > scale * tol;
}

torch::Tensor Channel(const torch::Tensor& t, int64_t c) { return t.slice(1, c, c + 1); }

// One-element-per-batch parameter [B] viewed as [B,1,1,1] for broadcasting.
torch::Tensor AsImageScalar(const torch::Tensor& t) { return t.reshape({-1, 1, 1, 1}); }

// Pair coefficients with non-finite entries replaced by zero; a zeroed pixel
// has a = 0, which every consumer below reads as degenerate.
struct CleanPair {
  torch::Tensor a_x, a_y, a_z, b_x, b_y, b_z;
  explicit CleanPair(const EpipolarPair& pair) {
    CheckPair(pair);
    const torch::Tensor a = ZeroNonFinite(pair.a);
    const torch::Tensor b = ZeroNonFinite(pair.b);
    a_x = Channel(a, 0);
    a_y = Channel(a, 1);
    a_z = Channel(a, 2);
    b_x = Channel(b, 0);
    b_y = Channel(b, 1);
    b_z = Channel(b, 2);
  }
};

// The epipolar gradient g = b_xy a_z - a_xy b_z: dp_s/dw = g / (a_z + w b_z)^2,
// so g points along the epipolar line towards larger w (nearer points).
// It vanishes with the baseline (b = 0) and at the epipole (a parallel to b).
struct EpipolarGradient {
  torch::Tensor g_x, g_y;
  torch::Tensor valid;  // [B,1,H,W]
};
EpipolarGradient ComputeEpipolarGradient(const CleanPair& p, double tol) {
  EpipolarGradient out;
  out.g_x = p.b_x * p.a_z - p.a_x * p.b_z;
  out.g_y = p.b_y * p.a_z - p.a_y * p.b_z;
  const torch::Tensor terms =
      (p.b_x.abs() + p.b_y.abs()) * p.a_z.abs() + (p.a_x.abs() + p.a_y.abs()) * p.b_z.abs();
  out.valid = IsClearlyPositive(out.g_x.abs() + out.g_y.abs(), terms, tol);
  return out;
}

}  // namespace

torch::Tensor PixelGrid(int64_t height, int64_t width, const torch::TensorOptions& options,
                        int64_t first_row) {
  if (height <= 0 || width <= 0 || first_row < 0) {
    throw std::invalid_argument(
        "dispmvs geometry: PixelGrid needs a positive height and width and a first row >= 0");
  }
  const torch::Tensor rows = torch::arange(first_row, first_row + height, options);
  const torch::Tensor cols = torch::arange(width, options);
  const auto yx = torch::meshgrid({rows, cols}, "ij");
  return torch::stack({yx[1], yx[0]}, 0).unsqueeze(0);  // (x, y) = (col, row)
}

EpipolarPair MakeEpipolarPair(const torch::Tensor& K_ref, const torch::Tensor& K_src,
                              const torch::Tensor& R, const torch::Tensor& T, int64_t height,
                              int64_t width, int64_t first_row) {
  const int64_t batch_sizes[] = {
      CheckBatchedMatrix(K_ref, 3, 3, "K_ref"), CheckBatchedMatrix(K_src, 3, 3, "K_src"),
      CheckBatchedMatrix(R, 3, 3, "R"), CheckBatchedMatrix(T, 3, 0, "T")};
  CheckSameKind(K_src, K_ref, "K_src");
  CheckSameKind(R, K_ref, "R");
  CheckSameKind(T, K_ref, "T");
  int64_t batch = 1;
  for (int64_t b : batch_sizes) batch = std::max(batch, b);
  for (int64_t b : batch_sizes) {
    if (b != 1 && b != batch) {
      throw std::invalid_argument(
          "dispmvs geometry: K_ref, K_src, R, T batch sizes must be equal (or 1)");
    }
  }

  // linalg_inv_ex does not throw: a singular K_ref is reported in `info` and
  // turned into degenerate (zero) coefficients below. It runs on the CPU
  // whatever the device (9 numbers per camera; on the CPU nothing changes):
  // on CUDA it would need LibTorch's CUDA linear-algebra backend (cuSOLVER /
  // MAGMA, which some builds load lazily from libtorch_cuda_linalg.so) for
  // nothing else in the network, and the CPU inverse keeps K^-1 identical on
  // every device. One small copy each way per call.
  const auto [K_ref_inv_cpu, info_cpu] = torch::linalg_inv_ex(K_ref.cpu());
  const torch::Tensor K_ref_inv = K_ref_inv_cpu.to(K_ref.device());
  const torch::Tensor info = info_cpu.to(K_ref.device());
  const torch::Tensor M = K_src.matmul(R).matmul(K_ref_inv).expand({batch, 3, 3});

  const torch::Tensor grid = PixelGrid(height, width, K_ref.options(), first_row).reshape({2, -1});
  const torch::Tensor homogeneous = torch::cat({grid, torch::ones_like(grid.slice(0, 0, 1))}, 0);
  torch::Tensor a = M.matmul(homogeneous).reshape({batch, 3, height, width});
  torch::Tensor b = K_src.matmul(T.unsqueeze(-1)).expand({batch, 3, 1}).reshape({batch, 3, 1, 1});

  // Non-finite cameras are checked on the inputs, not only on a and b: an
  // infinite focal length, say, inverts to a finite but meaningless matrix.
  auto all_finite = [](const torch::Tensor& t) {
    return torch::isfinite(t).flatten(1).all(1).reshape({-1, 1, 1, 1});
  };
  const torch::Tensor b_ok =
      torch::isfinite(b).all(1, /*keepdim=*/true) & all_finite(K_src) & all_finite(T);
  const torch::Tensor cameras_ok =
      all_finite(K_ref) & all_finite(R) & (info == 0).reshape({-1, 1, 1, 1});
  const torch::Tensor a_ok = torch::isfinite(a).all(1, /*keepdim=*/true) & b_ok & cameras_ok;
  a = torch::where(a_ok, a, torch::zeros_like(a));
  b = torch::where(b_ok, b, torch::zeros_like(b));
  return {a, b};
}

SourcePixels ProjectInverseDepth(const EpipolarPair& pair, const torch::Tensor& inv_depth) {
  const CleanPair p(pair);
  CheckImage(inv_depth, 1, "inv_depth");
  CheckSameKind(inv_depth, pair.a, "inv_depth");
  const double tol = RelativeTolerance(inv_depth.scalar_type());

  const torch::Tensor w_ok = torch::isfinite(inv_depth) & (inv_depth >= 0);
  const torch::Tensor w = torch::where(w_ok, inv_depth, torch::zeros_like(inv_depth));

  // Homogeneous source pixel; its z is z_src / z_ref, positive in front of the
  // source camera.
  const torch::Tensor num_x = p.a_x + w * p.b_x;
  const torch::Tensor num_y = p.a_y + w * p.b_y;
  const torch::Tensor den = p.a_z + w * p.b_z;
  const torch::Tensor in_front = IsClearlyPositive(den, p.a_z.abs() + (w * p.b_z).abs(), tol);
  const torch::Tensor representable =
      torch::max(num_x.abs(), num_y.abs()) < den.abs() * kMaxPixelCoordinate;
  const torch::Tensor valid = w_ok & in_front & representable;

  const torch::Tensor safe_den = torch::where(valid, den, torch::ones_like(den));
  const torch::Tensor xy = torch::cat({num_x, num_y}, 1) / safe_den;
  return {torch::where(valid, xy, torch::zeros_like(xy)), valid};
}

torch::Tensor MatchShiftPerInverseDepth(const EpipolarPair& pair, const torch::Tensor& inv_depth) {
  const torch::Tensor a_z = pair.a.narrow(1, 2, 1), b_z = pair.b.narrow(1, 2, 1);
  const torch::Tensor along_x = pair.b.narrow(1, 0, 1) * a_z - pair.a.narrow(1, 0, 1) * b_z;
  const torch::Tensor along_y = pair.b.narrow(1, 1, 1) * a_z - pair.a.narrow(1, 1, 1) * b_z;
  const torch::Tensor denominator = a_z + inv_depth * b_z;
  // (Written out: LibTorch's norm over the channel dimension took ten times longer.)
  const torch::Tensor shift = torch::sqrt(along_x * along_x + along_y * along_y) / (denominator * denominator);
  return torch::where((denominator > 0) & torch::isfinite(shift), shift, torch::zeros_like(shift));
}

std::pair<torch::Tensor, torch::Tensor> InverseDepthBounds(const torch::Tensor& w, const torch::Tensor& usable) {
  const torch::Tensor low =
      torch::where(usable, w, torch::full_like(w, std::numeric_limits<float>::infinity())).amin({1, 2, 3}, true);
  const torch::Tensor high = torch::where(usable, w, torch::zeros_like(w)).amax({1, 2, 3}, true);
  return {low, high};
}

torch::Tensor DistanceInsideSources(const EpipolarPair& pair, const torch::Tensor& w, int64_t sources,
                                    int64_t height, int64_t width) {
  if (sources < 1) throw std::invalid_argument("DistanceInsideSources: sources must be >= 1");
  if (!w.defined() || w.dim() != 4 || w.size(1) != 1 || w.size(2) != height || w.size(3) != width) {
    throw std::invalid_argument("DistanceInsideSources: w must be [B,1,height,width]");
  }
  const int64_t b = w.size(0);
  if (!pair.a.defined() || pair.a.size(0) != b * sources || pair.a.size(2) != height || pair.a.size(3) != width) {
    throw std::invalid_argument("DistanceInsideSources: the pair must hold B * sources pairs of w's size");
  }
  // The projection written out (K_s (R K_r^-1 p / w + T) ~ a + w b). On CPU
  // float maps with one b per pair (as MakeEpipolarPair gives) one loop over
  // the pixels, every source at once: 1.5 ms for four sources at 640x480
  // where the operations below, a dozen full-size passes, took 26-29 ms
  // (and ProjectInverseDepth's checks 60 ms). A match that is not finite
  // compares false and counts as outside, as its invalid matches would.
  if (w.device().is_cpu() && w.scalar_type() == torch::kFloat32 && pair.a.scalar_type() == torch::kFloat32 &&
      pair.a.size(1) == 3 && pair.b.scalar_type() == torch::kFloat32 && pair.b.dim() == 4 &&
      pair.b.size(0) == b * sources && pair.b.size(1) == 3 && pair.b.size(2) == 1 && pair.b.size(3) == 1) {
    const torch::Tensor wc = w.contiguous(), ac = pair.a.contiguous(), bc = pair.b.contiguous();
    torch::Tensor best = torch::empty_like(wc);
    const float* w_p = wc.data_ptr<float>();
    const float* a_p = ac.data_ptr<float>();
    const float* b_p = bc.data_ptr<float>();
    float* out = best.data_ptr<float>();
    const int64_t plane = height * width;
    const float right = static_cast<float>(width - 1), bottom = static_cast<float>(height - 1);
    const float outside = -std::numeric_limits<float>::infinity();
    at::parallel_for(0, b * height, 16, [&](int64_t row_begin, int64_t row_end) {
      for (int64_t row = row_begin; row < row_end; ++row) {
        const int64_t item = row / height, first = (row % height) * width;
        const float* w_row = w_p + item * plane + first;
        float* out_row = out + item * plane + first;
        for (int64_t x = 0; x < width; ++x) out_row[x] = outside;
        for (int64_t s = 0; s < sources; ++s) {
          const int64_t pair_index = item * sources + s;
          const float* a0 = a_p + pair_index * 3 * plane + first;
          const float* a1 = a0 + plane;
          const float* a2 = a1 + plane;
          const float bx = b_p[pair_index * 3], by = b_p[pair_index * 3 + 1], bz = b_p[pair_index * 3 + 2];
          for (int64_t x = 0; x < width; ++x) {
            const float wx = w_row[x];
            const float px = a0[x] + wx * bx, py = a1[x] + wx * by, pz = a2[x] + wx * bz;
            const float u = px / pz, v = py / pz;
            const float inside = std::min(std::min(u, right - u), std::min(v, bottom - v));
            // NaN compares false: outside.
            if (pz > 0 && std::isfinite(inside) && inside > out_row[x]) out_row[x] = inside;
          }
        }
        for (int64_t x = 0; x < width; ++x) {
          if (!(w_row[x] > 0)) out_row[x] = outside;
        }
      }
    });
    return best;
  }
  const double none = -std::numeric_limits<double>::infinity();
  const torch::Tensor p = torch::addcmul(pair.a, w.repeat_interleave(sources, 0), pair.b);
  const torch::Tensor z = p.narrow(1, 2, 1);
  const torch::Tensor x = p.narrow(1, 0, 1) / z, y = p.narrow(1, 1, 1) / z;
  const torch::Tensor inside = torch::minimum(torch::minimum(x, (width - 1) - x), torch::minimum(y, (height - 1) - y));
  const torch::Tensor in_front = (z > 0) & torch::isfinite(inside);
  const torch::Tensor distance = torch::where(in_front, inside, torch::full_like(inside, none));
  const torch::Tensor best = distance.view({b, sources, height, width}).amax(1, /*keepdim=*/true);
  return torch::where(w > 0, best, torch::full_like(best, none));
}

EpipolarDirection ComputeEpipolarDirection(const EpipolarPair& pair) {
  const CleanPair p(pair);
  const EpipolarGradient g = ComputeEpipolarGradient(p, RelativeTolerance(pair.a.scalar_type()));

  // Normalise in two steps, first by the larger component, so that squaring
  // cannot overflow or underflow whatever the scene unit. The first step is
  // detached: g / |g| does not depend on it, and it keeps max() out of the graph.
  const torch::Tensor largest = torch::max(g.g_x.abs(), g.g_y.abs()).detach();
  const torch::Tensor safe_largest = torch::where(g.valid, largest, torch::ones_like(largest));
  const torch::Tensor ux = torch::where(g.valid, g.g_x / safe_largest, torch::ones_like(largest));
  const torch::Tensor uy = torch::where(g.valid, g.g_y / safe_largest, torch::zeros_like(largest));
  const torch::Tensor norm = torch::sqrt(ux * ux + uy * uy);  // >= 1: the larger component is +-1
  const torch::Tensor dir = torch::cat({ux, uy}, 1) / norm;
  return {torch::where(g.valid, dir, torch::zeros_like(dir)), g.valid};
}

EpipolarSegment ComputeEpipolarSegment(const EpipolarPair& pair, int64_t src_height,
                                       int64_t src_width) {
  if (src_height <= 0 || src_width <= 0) {
    throw std::invalid_argument("dispmvs geometry: ComputeEpipolarSegment needs a positive size");
  }
  const CleanPair p(pair);
  const double tol = RelativeTolerance(pair.a.scalar_type());
  const EpipolarDirection direction = ComputeEpipolarDirection(pair);
  const torch::Tensor dx = Channel(direction.dir, 0);
  const torch::Tensor dy = Channel(direction.dir, 1);

  // The line through the homogeneous points a and b is l = a x b; its normal
  // (l_x, l_y) is perpendicular to dir, so with the unit normal n = (-dy, dx)
  // the line is n . x = c, c = l_z / |(l_x, l_y)|, and the foot of the
  // perpendicular from the image centre q is q - (n . q - c) n. Computing c as
  // the signed distance of a point of the line avoids forming l: for the
  // vanishing point or the epipole, whichever is better conditioned. Both
  // are ratios of homogeneous coordinates; use the one with the larger
  // relative z (the other may be at infinity).
  const torch::Tensor a_norm = p.a_x.abs() + p.a_y.abs() + p.a_z.abs();
  const torch::Tensor b_norm = p.b_x.abs() + p.b_y.abs() + p.b_z.abs();
  const torch::Tensor a_rel = p.a_z.abs() / torch::where(a_norm > 0, a_norm, torch::ones_like(a_norm));
  const torch::Tensor b_rel = p.b_z.abs() / torch::where(b_norm > 0, b_norm, torch::ones_like(b_norm));
  const torch::Tensor use_a = a_rel >= b_rel;
  // n . (h_xy / h_z) = (n_x h_x + n_y h_y) / h_z for the chosen point h.
  const torch::Tensor nx = -dy, ny = dx;
  const torch::Tensor h_x = torch::where(use_a, p.a_x, p.b_x);
  const torch::Tensor h_y = torch::where(use_a, p.a_y, p.b_y);
  const torch::Tensor h_z = torch::where(use_a, p.a_z, p.b_z);
  const torch::Tensor h_ok = IsClearlyNonZero(h_z, h_x.abs() + h_y.abs() + h_z.abs(), tol);
  const torch::Tensor safe_h_z = torch::where(h_ok, h_z, torch::ones_like(h_z));
  const torch::Tensor c = (nx * h_x + ny * h_y) / safe_h_z;
  const double qx = 0.5 * static_cast<double>(src_width - 1);
  const double qy = 0.5 * static_cast<double>(src_height - 1);
  const torch::Tensor offset = nx * qx + ny * qy - c;
  const torch::Tensor base_x = qx - offset * nx;
  const torch::Tensor base_y = qy - offset * ny;

  // E-flow of the homogeneous point h relative to base, where h_z is clearly
  // positive (else unused).
  const auto eflow_of = [&](const torch::Tensor& x, const torch::Tensor& y, const torch::Tensor& z,
                            const torch::Tensor& positive) {
    const torch::Tensor safe_z = torch::where(positive, z, torch::ones_like(z));
    const torch::Tensor e = dx * (x / safe_z - base_x) + dy * (y / safe_z - base_y);
    return e.clamp(-kMaxPixelCoordinate, kMaxPixelCoordinate);
  };
  const torch::Tensor a_front = IsClearlyPositive(p.a_z, a_norm, tol);
  const torch::Tensor b_front = IsClearlyPositive(p.b_z, b_norm, tol);
  const torch::Tensor far_end =
      torch::where(a_front, eflow_of(p.a_x, p.a_y, p.a_z, a_front),
                   torch::full_like(p.a_z, -kMaxPixelCoordinate));
  const torch::Tensor near_end =
      torch::where(b_front, eflow_of(p.b_x, p.b_y, p.b_z, b_front),
                   torch::full_like(p.a_z, kMaxPixelCoordinate));

  // Clip to the image: the slab [0, size - 1] along each axis, in E-flow.
  // An axis the line does not move along either contains the whole line or
  // none of it.
  const auto slab = [&](const torch::Tensor& base, const torch::Tensor& d, double size) {
    const torch::Tensor moves = d.abs() > tol;
    const torch::Tensor safe_d = torch::where(moves, d, torch::ones_like(d));
    const torch::Tensor t0 = (0.0 - base) / safe_d;
    const torch::Tensor t1 = (size - 1.0 - base) / safe_d;
    const torch::Tensor inside = (base >= 0.0) & (base <= size - 1.0);
    const torch::Tensor big = torch::full_like(base, kMaxPixelCoordinate);
    const torch::Tensor lo = torch::where(moves, torch::min(t0, t1), torch::where(inside, -big, big));
    const torch::Tensor hi = torch::where(moves, torch::max(t0, t1), torch::where(inside, big, -big));
    return std::make_pair(lo, hi);
  };
  const auto [x_lo, x_hi] = slab(base_x, dx, static_cast<double>(src_width));
  const auto [y_lo, y_hi] = slab(base_y, dy, static_cast<double>(src_height));
  const torch::Tensor start = torch::max(torch::max(far_end, x_lo), y_lo);
  const torch::Tensor end = torch::min(torch::min(near_end, x_hi), y_hi);
  const torch::Tensor valid =
      direction.valid & h_ok & (a_front | b_front) & (start <= end);

  EpipolarSegment out;
  out.base_xy = torch::where(valid, torch::cat({base_x, base_y}, 1), torch::zeros_like(direction.dir));
  out.dir = torch::where(valid, direction.dir, torch::zeros_like(direction.dir));
  out.start = torch::where(valid, start, torch::zeros_like(start));
  out.end = torch::where(valid, end, torch::zeros_like(end));
  out.valid = valid;
  return out;
}

InverseDepth TriangulateInverseDepth(const EpipolarPair& pair, const torch::Tensor& src_xy) {
  const CleanPair p(pair);
  CheckImage(src_xy, 2, "src_xy");
  CheckSameKind(src_xy, pair.a, "src_xy");
  const double tol = RelativeTolerance(src_xy.scalar_type());

  const torch::Tensor xy_ok = torch::isfinite(src_xy).all(1, /*keepdim=*/true);
  const torch::Tensor xy = ZeroNonFinite(src_xy);
  const torch::Tensor u = Channel(xy, 0);
  const torch::Tensor v = Channel(xy, 1);

  // u (a_z + w b_z) = a_x + w b_x  =>  w = (a_x - u a_z) / (u b_z - b_x); same for v.
  const torch::Tensor num_x = p.a_x - u * p.a_z;
  const torch::Tensor den_x = u * p.b_z - p.b_x;
  const torch::Tensor num_y = p.a_y - v * p.a_z;
  const torch::Tensor den_y = v * p.b_z - p.b_y;

  // Which equation: at the true match, u b_z - b_x = -g_x / (a_z + w b_z) and
  // v b_z - b_y = -g_y / (a_z + w b_z) with the epipolar gradient g (see
  // ComputeEpipolarGradient), so the denominators are the epipolar direction
  // scaled by one common factor. The larger |denominator| is therefore the
  // larger flow component (the paper's Eq. 7), and the better conditioned one.
  const torch::Tensor use_x = den_x.abs() >= den_y.abs();
  const torch::Tensor num = torch::where(use_x, num_x, num_y);
  const torch::Tensor den = torch::where(use_x, den_x, den_y);
  const torch::Tensor num_terms =
      torch::where(use_x, p.a_x.abs() + (u * p.a_z).abs(), p.a_y.abs() + (v * p.a_z).abs());
  const torch::Tensor den_terms =
      torch::where(use_x, (u * p.b_z).abs() + p.b_x.abs(), (v * p.b_z).abs() + p.b_y.abs());

  // den ~ 0: zero baseline, or the match sits on the epipole. num ~ 0: the match
  // is the vanishing point, w = 0 (infinitely far, depth undefined).
  // num / den < 0: the point is behind the reference camera.
  const torch::Tensor solvable = xy_ok & ComputeEpipolarGradient(p, tol).valid &
                                 IsClearlyNonZero(den, den_terms, tol) &
                                 IsClearlyNonZero(num, num_terms, tol) & ((num > 0) == (den > 0));
  const torch::Tensor safe_den = torch::where(solvable, den, torch::ones_like(den));
  const torch::Tensor w_raw = num / safe_den;
  const torch::Tensor w_finite = solvable & torch::isfinite(w_raw);
  const torch::Tensor w = torch::where(w_finite, w_raw, torch::zeros_like(w_raw));

  // Also in front of the source camera (the match could be the mirror image of
  // a point behind it).
  const torch::Tensor in_front =
      IsClearlyPositive(p.a_z + w * p.b_z, p.a_z.abs() + (w * p.b_z).abs(), tol);
  const torch::Tensor valid = w_finite & in_front;
  return {torch::where(valid, w, torch::zeros_like(w)), valid};
}

torch::Tensor EflowToSourcePixel(const torch::Tensor& base_xy, const torch::Tensor& dir,
                                 const torch::Tensor& eflow) {
  CheckImage(base_xy, 2, "base_xy");
  CheckImage(dir, 2, "dir");
  CheckImage(eflow, 1, "eflow");
  return ZeroNonFinite(base_xy) + ZeroNonFinite(eflow) * ZeroNonFinite(dir);
}

torch::Tensor SourcePixelToEflow(const torch::Tensor& base_xy, const torch::Tensor& dir,
                                 const torch::Tensor& src_xy) {
  CheckImage(base_xy, 2, "base_xy");
  CheckImage(dir, 2, "dir");
  CheckImage(src_xy, 2, "src_xy");
  // Projection onto the (unit) direction: exact inverse of EflowToSourcePixel
  // for pixels on the line; off the line it keeps the along-line component.
  return (ZeroNonFinite(dir) * (ZeroNonFinite(src_xy) - ZeroNonFinite(base_xy)))
      .sum(1, /*keepdim=*/true);
}

FusedInverseDepth FuseInverseDepths(const torch::Tensor& inv_depths, const torch::Tensor& logits,
                                    const torch::Tensor& valid) {
  CheckImage(inv_depths, -1, "inv_depths");
  CheckImage(logits, -1, "logits");
  if (!valid.defined() || valid.scalar_type() != torch::kBool) {
    throw std::invalid_argument("dispmvs geometry: FuseInverseDepths needs a bool valid mask");
  }
  if (logits.sizes() != inv_depths.sizes() || valid.sizes() != inv_depths.sizes()) {
    throw std::invalid_argument(
        "dispmvs geometry: inv_depths, logits and valid must all be [B,N,H,W]");
  }
  CheckSameKind(logits, inv_depths, "logits");

  const torch::Tensor usable = valid & torch::isfinite(inv_depths) & torch::isfinite(logits);
  const torch::Tensor any_usable = usable.any(1, /*keepdim=*/true);

  // Softmax restricted to usable pairs. The shift by the largest usable logit
  // is detached (softmax does not depend on it) and is 0 where none is usable;
  // unusable entries enter exp() as 0, never as a huge difference that would
  // overflow in the (masked) backward pass.
  const torch::Tensor shift_raw =
      torch::where(usable, logits.detach(), -std::numeric_limits<double>::infinity())
          .amax(1, /*keepdim=*/true);
  const torch::Tensor shift =
      torch::where(any_usable, shift_raw, torch::zeros_like(shift_raw)).detach();
  const torch::Tensor exponent = torch::where(usable, logits - shift, torch::zeros_like(logits));
  const torch::Tensor unnormalised =
      torch::where(usable, torch::exp(exponent), torch::zeros_like(logits));
  const torch::Tensor total = unnormalised.sum(1, /*keepdim=*/true);  // >= 1 where any usable
  const torch::Tensor safe_total = torch::where(any_usable, total, torch::ones_like(total));
  const torch::Tensor weights = unnormalised / safe_total;

  const torch::Tensor depths = torch::where(usable, inv_depths, torch::zeros_like(inv_depths));
  const torch::Tensor fused = (weights * depths).sum(1, /*keepdim=*/true);
  return {fused, weights, any_usable};
}

namespace {

// Checks a per-sample depth range: [B] tensors with 0 < d_min <= d_max
// (d_max may be +inf: no far limit). Synchronises with the device once.
void CheckDepthRange(const torch::Tensor& d_min, const torch::Tensor& d_max, bool strict) {
  CheckFloating(d_min, "d_min");
  CheckFloating(d_max, "d_max");
  CheckSameKind(d_max, d_min, "d_max");
  if (d_min.dim() != 1 || d_max.sizes() != d_min.sizes()) {
    throw std::invalid_argument("dispmvs geometry: d_min and d_max must both be [B]");
  }
  const torch::Tensor ordered = strict ? (d_max > d_min) : (d_max >= d_min);
  const bool ok = (torch::isfinite(d_min) & (d_min > 0) & ordered).all().item<bool>();
  if (!ok) {
    throw std::invalid_argument(
        std::string("dispmvs geometry: depth range must satisfy 0 < d_min ") +
        (strict ? "< " : "<= ") + "d_max, d_min finite");
  }
}

}  // namespace

torch::Tensor RandomInverseDepth(const torch::Tensor& d_min, const torch::Tensor& d_max,
                                 int64_t height, int64_t width, torch::Generator generator) {
  CheckDepthRange(d_min, d_max, /*strict=*/false);
  if (height <= 0 || width <= 0) {
    throw std::invalid_argument("dispmvs geometry: RandomInverseDepth needs a positive size");
  }
  const std::vector<int64_t> shape = {d_min.size(0), 1, height, width};
  torch::Tensor unit;
  if (generator.defined()) {
    // Draw on the generator's device so a given seed gives the same numbers
    // wherever the result lives.
    unit = torch::rand(shape, generator, d_min.options().device(generator.device()))
               .to(d_min.device());
  } else {
    unit = torch::rand(shape, d_min.options());
  }
  const torch::Tensor w_far = AsImageScalar(d_max.reciprocal());
  const torch::Tensor w_near = AsImageScalar(d_min.reciprocal());
  return w_far + unit * (w_near - w_far);
}

torch::Tensor NormalizeInverseDepth(const torch::Tensor& inv_depth, const torch::Tensor& d_min,
                                    const torch::Tensor& d_max) {
  CheckImage(inv_depth, -1, "inv_depth");
  CheckDepthRange(d_min, d_max, /*strict=*/true);
  // The range is a hint; the result keeps inv_depth's dtype and device.
  const torch::Tensor w_far = AsImageScalar(d_max.reciprocal()).to(inv_depth.options());
  const torch::Tensor w_near = AsImageScalar(d_min.reciprocal()).to(inv_depth.options());
  return (inv_depth - w_far) / (w_near - w_far);
}

torch::Tensor DenormalizeInverseDepth(const torch::Tensor& normalized, const torch::Tensor& d_min,
                                      const torch::Tensor& d_max) {
  CheckImage(normalized, -1, "normalized");
  CheckDepthRange(d_min, d_max, /*strict=*/true);
  const torch::Tensor w_far = AsImageScalar(d_max.reciprocal()).to(normalized.options());
  const torch::Tensor w_near = AsImageScalar(d_min.reciprocal()).to(normalized.options());
  return w_far + normalized * (w_near - w_far);
}

namespace {

// The image-side map x' = s x + shift applied to K: S K with
// S = [s 0 shift; 0 s shift; 0 0 1]. `who` names the caller in errors.
torch::Tensor ResampleIntrinsics(const torch::Tensor& K, double factor, bool block_centres,
                                 const char* who) {
  CheckFloating(K, "K");
  if (K.dim() < 2 || K.size(-1) != 3 || K.size(-2) != 3) {
    throw std::invalid_argument(std::string("dispmvs geometry: ") + who + " needs [...,3,3] matrices");
  }
  if (!std::isfinite(factor) || factor <= 0) {
    throw std::invalid_argument(std::string("dispmvs geometry: ") + who +
                                " factor must be finite and > 0");
  }
  const double s = 1.0 / factor;
  const double shift = block_centres ? 0.5 * s - 0.5 : 0.0;
  const torch::Tensor S = torch::tensor({s, 0.0, shift, 0.0, s, shift, 0.0, 0.0, 1.0},
                                        torch::TensorOptions().dtype(torch::kFloat64))
                              .reshape({3, 3})
                              .to(K.options());
  return S.matmul(K);
}

}  // namespace

torch::Tensor ScaleIntrinsics(const torch::Tensor& K, double factor) {
  // The pixel-index map x' = (x + 0.5) / factor - 0.5: f' = f / factor,
  // c' = (c + 0.5) / factor - 0.5 (cells at the centres of their blocks).
  return ResampleIntrinsics(K, factor, /*block_centres=*/true, "ScaleIntrinsics");
}

torch::Tensor StridedIntrinsics(const torch::Tensor& K, double stride) {
  // x' = x / stride (cell j at pixel stride * j).
  return ResampleIntrinsics(K, stride, /*block_centres=*/false, "StridedIntrinsics");
}

}  // namespace dispmvs::model
