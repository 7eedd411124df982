// Tests of model v2's epipolar segment, segment correlation volume and
// matching loss.
//
// The segment is checked against an independent double-precision computation
// with Eigen: explicit 3-D points X = d K_ref^-1 p~ at depths from 1e-9 to
// 1e12 (times the scene scale), moved into the source camera and projected.
// It never uses the a / b coefficients of geometry.h.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "model/geometry.h"
#include "model/matching_loss.h"
#include "model/segment_correlation.h"

namespace dispmvs::model {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector2d;
using Eigen::Vector3d;
using RowMatrix3d = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

torch::Tensor MatrixTensor(const Matrix3d& m) {
  RowMatrix3d row_major = m;
  return torch::from_blob(row_major.data(), {1, 3, 3}, torch::kFloat64).clone();
}
torch::Tensor VectorTensor(const Vector3d& v) {
  Vector3d copy = v;
  return torch::from_blob(copy.data(), {1, 3}, torch::kFloat64).clone();
}

Matrix3d Rotation(double yaw, double pitch, double roll) {
  return (Eigen::AngleAxisd(yaw, Vector3d::UnitY()) * Eigen::AngleAxisd(pitch, Vector3d::UnitX()) *
          Eigen::AngleAxisd(roll, Vector3d::UnitZ()))
      .toRotationMatrix();
}

struct Rig {
  std::string name;
  Matrix3d K_ref, K_src, R;  // R, T: reference -> source camera coordinates
  Vector3d T;
  int width = 40, height = 30;  // both images
};

Matrix3d Intrinsics(double f, int width, int height) {
  Matrix3d K;
  K << f, 0, 0.5 * (width - 1), 0, f, 0.5 * (height - 1), 0, 0, 1;
  return K;
}

// Source camera with centre C (in reference coordinates) and orientation
// R_wc (columns: its axes in reference coordinates).
Rig MakeRig(const std::string& name, const Vector3d& centre, const Matrix3d& axes, double scale) {
  Rig rig;
  rig.name = name;
  rig.K_ref = Intrinsics(30, rig.width, rig.height);
  rig.K_src = Intrinsics(34, rig.width, rig.height);
  rig.R = axes.transpose();
  rig.T = -rig.R * (centre * scale);
  return rig;
}

std::vector<Rig> Rigs() {
  const double kPi = 3.14159265358979323846;
  std::vector<Rig> rigs;
  // Sideways baseline, converging a little: the usual stereo case.
  rigs.push_back(MakeRig("side", Vector3d(1, 0.1, 0.05), Rotation(-0.15, 0.02, 0.01), 1.0));
  // The same in kilometres: the segment must not depend on the unit.
  rigs.push_back(MakeRig("side_km", Vector3d(1, 0.1, 0.05), Rotation(-0.15, 0.02, 0.01), 1e3));
  // Forward motion: the reference centre is behind the source (b_z < 0), so
  // the near ends run off the image; the far ends are the vanishing points.
  rigs.push_back(MakeRig("forward", Vector3d(0.05, 0.02, 1.0), Rotation(0.02, 0.01, 0), 1.0));
  // Backward motion: the reference centre is in front of the source
  // (b_z > 0), so the near ends converge on the epipole inside the image.
  rigs.push_back(MakeRig("backward", Vector3d(0.03, -0.02, -1.0), Rotation(0.01, 0.0, 0.02), 1.0));
  // Source turned 90 degrees: many rays are parallel to its image plane or
  // enter its view only from a finite depth on (a_z <= 0).
  rigs.push_back(MakeRig("turned", Vector3d(1.5, 0, 2.0), Rotation(-kPi / 2, 0, 0), 1.0));
  // Facing the reference: the source sees the reference centre (b_z > 0)
  // and the far points behind itself (a_z < 0).
  rigs.push_back(MakeRig("facing", Vector3d(0.3, 0.1, 4.0), Rotation(kPi - 0.1, 0.05, 0), 1.0));
  return rigs;
}

struct SegmentInDouble {
  torch::Tensor base, dir, start, end, valid;  // CPU double, [1,*,H,W]
};

SegmentInDouble Compute(const Rig& rig, torch::ScalarType dtype) {
  const EpipolarPair pair =
      MakeEpipolarPair(MatrixTensor(rig.K_ref).to(dtype), MatrixTensor(rig.K_src).to(dtype),
                       MatrixTensor(rig.R).to(dtype), VectorTensor(rig.T).to(dtype), rig.height,
                       rig.width);
  const EpipolarSegment s = ComputeEpipolarSegment(pair, rig.height, rig.width);
  const auto d = [](const torch::Tensor& t) { return t.to(torch::kFloat64).contiguous(); };
  return {d(s.base_xy), d(s.dir), d(s.start), d(s.end), s.valid.contiguous()};
}

// The segment against explicit projections of points along each ray.
void CheckAgainstProjections(const Rig& rig, torch::ScalarType dtype, double tol_px) {
  SCOPED_TRACE(rig.name + (dtype == torch::kFloat32 ? " float32" : " float64"));
  const SegmentInDouble seg = Compute(rig, dtype);
  const Vector3d epipole_h = rig.K_src * rig.T;  // image of the reference centre
  const double scale = rig.T.norm();
  int checked = 0, valid_pixels = 0, border_ends = 0, limit_ends = 0;
  double worst = 0;
  for (int y = 0; y < rig.height; ++y) {
    for (int x = 0; x < rig.width; ++x) {
      const Vector3d ray = rig.K_ref.inverse() * Vector3d(x, y, 1);
      const bool valid = seg.valid[0][0][y][x].item<bool>();
      const Vector2d base(seg.base[0][0][y][x].item<double>(), seg.base[0][1][y][x].item<double>());
      const Vector2d dir(seg.dir[0][0][y][x].item<double>(), seg.dir[0][1][y][x].item<double>());
      const double start = seg.start[0][0][y][x].item<double>();
      const double end = seg.end[0][0][y][x].item<double>();
      // Every positive depth that projects well inside the image must lie on
      // the segment; if the segment is empty, none may.
      int inside_samples = 0;
      for (double log_d = -9; log_d <= 12; log_d += 0.01) {
        const Vector3d X = rig.R * (std::pow(10.0, log_d) * scale * ray) + rig.T;
        if (X.z() <= 0) continue;
        const Vector3d h = rig.K_src * X;
        const Vector2d p(h.x() / h.z(), h.y() / h.z());
        const double margin = 2 * tol_px;
        if (p.x() < margin || p.y() < margin || p.x() > rig.width - 1 - margin ||
            p.y() > rig.height - 1 - margin) {
          continue;
        }
        ++inside_samples;
        ASSERT_TRUE(valid) << "pixel " << x << "," << y << ": depth 1e" << log_d
                           << " projects inside the image at " << p.transpose()
                           << " but the segment is empty";
        const double e = dir.dot(p - base);
        const double off_line = std::abs(Vector2d(-dir.y(), dir.x()).dot(p - base));
        worst = std::max(worst, off_line);
        EXPECT_LE(off_line, tol_px) << "pixel " << x << "," << y;
        EXPECT_GE(e, start - tol_px) << "pixel " << x << "," << y << " depth 1e" << log_d;
        EXPECT_LE(e, end + tol_px) << "pixel " << x << "," << y << " depth 1e" << log_d;
      }
      if (!valid) continue;
      ++valid_pixels;
      ASSERT_LE(start, end + 1e-12);
      // Each end is on the image border, or is the limit of the curve: the
      // vanishing point (far end) or the epipole (near end).
      const Vector3d vp_h = rig.K_src * rig.R * ray;
      const auto on_border = [&](const Vector2d& p) {
        return std::abs(p.x()) <= tol_px || std::abs(p.y()) <= tol_px ||
               std::abs(p.x() - (rig.width - 1)) <= tol_px ||
               std::abs(p.y() - (rig.height - 1)) <= tol_px;
      };
      const Vector2d p_start = base + start * dir, p_end = base + end * dir;
      for (const Vector2d& p : {p_start, p_end}) {
        EXPECT_GE(p.x(), -tol_px);
        EXPECT_GE(p.y(), -tol_px);
        EXPECT_LE(p.x(), rig.width - 1 + tol_px);
        EXPECT_LE(p.y(), rig.height - 1 + tol_px);
      }
      if (on_border(p_start)) {
        ++border_ends;
      } else {
        ASSERT_GT(vp_h.z(), 0) << "far end inside the image must be the vanishing point";
        EXPECT_NEAR((p_start - vp_h.head<2>() / vp_h.z()).norm(), 0, tol_px);
        ++limit_ends;
      }
      if (on_border(p_end)) {
        ++border_ends;
      } else {
        ASSERT_GT(epipole_h.z(), 0) << "near end inside the image must be the epipole";
        EXPECT_NEAR((p_end - epipole_h.head<2>() / epipole_h.z()).norm(), 0, tol_px);
        ++limit_ends;
      }
      if (inside_samples > 0) ++checked;
    }
  }
  std::printf("[segment %s %s] %d valid pixels, %d checked against projections, ends: %d on the "
              "border, %d at a limit point; worst distance from the line %.2e px\n",
              rig.name.c_str(), dtype == torch::kFloat32 ? "f32" : "f64", valid_pixels, checked,
              border_ends, limit_ends, worst);
  EXPECT_GT(checked, 0);
}

TEST(EpipolarSegment, MatchesExplicitProjections) {
  for (const Rig& rig : Rigs()) {
    CheckAgainstProjections(rig, torch::kFloat64, 1e-6);
    CheckAgainstProjections(rig, torch::kFloat32, 2e-3);
  }
}

TEST(EpipolarSegment, LimitPointsAreReachedWhereTheyLieInside) {
  // Backward motion: the reference centre is in front of the source, its
  // image (the epipole) is inside the source image, and the near ends of the
  // segments (depth -> 0+) converge on it.
  const Rig backward = Rigs()[3];
  const SegmentInDouble seg = Compute(backward, torch::kFloat64);
  const Vector3d e = backward.K_src * backward.T;
  ASSERT_GT(e.z(), 0);
  const Vector2d epipole = e.head<2>() / e.z();
  ASSERT_TRUE(epipole.x() > 0 && epipole.x() < backward.width - 1);
  const int x = 3, y = 4;  // a pixel far from the epipole
  ASSERT_TRUE(seg.valid[0][0][y][x].item<bool>());
  const Vector2d base(seg.base[0][0][y][x].item<double>(), seg.base[0][1][y][x].item<double>());
  const Vector2d dir(seg.dir[0][0][y][x].item<double>(), seg.dir[0][1][y][x].item<double>());
  EXPECT_NEAR((base + seg.end[0][0][y][x].item<double>() * dir - epipole).norm(), 0, 1e-9);
  // And the segment is invariant to the scene unit (side vs side_km).
  const SegmentInDouble m = Compute(Rigs()[0], torch::kFloat64);
  const SegmentInDouble km = Compute(Rigs()[1], torch::kFloat64);
  EXPECT_TRUE(torch::equal(m.valid, km.valid));
  EXPECT_LT((m.start - km.start).abs().max().item<double>(), 1e-8);
  EXPECT_LT((m.end - km.end).abs().max().item<double>(), 1e-8);
}

TEST(EpipolarSegment, ZeroBaselineIsInvalid) {
  Rig rig = Rigs()[0];
  rig.T.setZero();
  const SegmentInDouble seg = Compute(rig, torch::kFloat64);
  EXPECT_FALSE(seg.valid.any().item<bool>());
  EXPECT_TRUE(torch::isfinite(seg.start).all().item<bool>());
}

// ------------------------------------------------------------ the volume

// A segment along image rows: base (0, y), dir (1, 0), from start to end.
EpipolarSegment RowSegment(int64_t h, int64_t w, double start, double end) {
  EpipolarSegment s;
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  const torch::Tensor rows = torch::arange(h, opts).view({1, 1, h, 1}).expand({1, 1, h, w});
  s.base_xy = torch::cat({torch::zeros({1, 1, h, w}, opts), rows}, 1);
  s.dir = torch::cat({torch::ones({1, 1, h, w}, opts), torch::zeros({1, 1, h, w}, opts)}, 1);
  s.start = torch::full({1, 1, h, w}, start, opts);
  s.end = torch::full({1, 1, h, w}, end, opts);
  s.valid = torch::ones({1, 1, h, w}, torch::kBool);
  return s;
}

TEST(SegmentCorrelation, VolumeIsTheDotProductAlongTheSegment) {
  torch::manual_seed(3);
  const int64_t c = 8, h = 3, w = 4, src_w = 12;
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  const torch::Tensor ref = torch::randn({1, c, h, w}, opts);
  const torch::Tensor src = torch::randn({1, c, h, src_w}, opts);
  const EpipolarSegment seg = RowSegment(h, w, 1.5, 7.25);  // 7 samples: 1.5 .. 7.5 > 7.25
  const SegmentCorrelation volume(ref, src, seg, /*levels=*/2, /*samples=*/3);
  ASSERT_EQ(volume.length(), 7);  // ceil(5.75) + 1
  for (int64_t y = 0; y < h; ++y) {
    for (int64_t x = 0; x < w; ++x) {
      for (int64_t k = 0; k < 7; ++k) {
        const double e = 1.5 + static_cast<double>(k);
        double expected = 0;
        if (e <= 7.25) {
          // Bilinear between columns floor(e) and floor(e) + 1 of row y.
          const int64_t x0 = static_cast<int64_t>(std::floor(e));
          const double f = e - static_cast<double>(x0);
          const torch::Tensor feature = src[0].select(1, y).select(1, x0) * (1 - f) +
                                        src[0].select(1, y).select(1, x0 + 1) * f;
          expected = (feature * ref[0].select(1, y).select(1, x)).sum().item<double>() / c;
        }
        EXPECT_NEAR(volume.volume()[0][k][y][x].item<double>(), expected, 1e-12)
            << "k=" << k << " y=" << y << " x=" << x;
        EXPECT_EQ(volume.inside()[0][k][y][x].item<bool>(), e <= 7.25);
      }
    }
  }
}

// Random segments on a [b, h, w] grid for a 20x26 source: some invalid,
// some leaving the map.
EpipolarSegment RandomSegments(int64_t b, int64_t h, int64_t w) {
  EpipolarSegment seg;
  seg.base_xy = torch::rand({b, 2, h, w}) * 30.0 - 2.0;
  const torch::Tensor angle = torch::rand({b, 1, h, w}) * 6.283;
  seg.dir = torch::cat({torch::cos(angle), torch::sin(angle)}, 1);
  seg.start = torch::rand({b, 1, h, w}) * -20.0;
  seg.end = seg.start + torch::rand({b, 1, h, w}) * 30.0;
  seg.valid = torch::rand({b, 1, h, w}) > 0.1;
  return seg;
}

// Inference on the CPU builds the volume with the fused lookup of
// correlation_cpu.h, against the ATen ops: on float features, the same
// volume to float rounding, and the same best matches.
TEST(SegmentCorrelation, FusedInferenceVolumeEqualsAtenVolume) {
  torch::manual_seed(21);
  const int64_t b = 3, c = 64, h = 12, w = 16, src_h = 20, src_w = 26;
  const torch::Tensor ref = torch::randn({b, c, h, w});
  const torch::Tensor src = torch::randn({b, c, src_h, src_w});
  const EpipolarSegment seg = RandomSegments(b, h, w);
  const SegmentCorrelation aten(ref, src, seg, /*levels=*/3, /*samples=*/9,
                                CorrelationImpl::kAtenOps);
  torch::NoGradGuard no_grad;
  const SegmentCorrelation fused(ref, src, seg, /*levels=*/3, /*samples=*/9);
  ASSERT_EQ(fused.length(), aten.length());
  EXPECT_TRUE(torch::equal(fused.inside(), aten.inside()));
  EXPECT_LT((fused.volume() - aten.volume()).abs().max().item<float>(), 1e-5f);
  EXPECT_GT(aten.volume().abs().mean().item<float>(), 0.01f);  // not a comparison of zeros
  const torch::Tensor match_xy = seg.base_xy + seg.dir * (seg.start + 3.3);
  EXPECT_LT((fused.Lookup(match_xy).cost - aten.Lookup(match_xy).cost).abs().max().item<float>(),
            1e-5f);
  EXPECT_LT((fused.BestMatch().eflow - aten.BestMatch().eflow).abs().max().item<float>(), 1e-3f);
}

// Training builds the volume with the fused pass as an autograd node: the
// same volume as the ATen ops, and the same gradients w.r.t. both feature
// maps (the gradient weights every sample differently).
TEST(SegmentCorrelation, FusedTrainingVolumeGradientsEqualAtenVolume) {
  torch::manual_seed(22);
  const int64_t b = 3, c = 64, h = 12, w = 16, src_h = 20, src_w = 26;
  const torch::Tensor ref_values = torch::randn({b, c, h, w});
  const torch::Tensor src_values = torch::randn({b, c, src_h, src_w});
  const EpipolarSegment seg = RandomSegments(b, h, w);
  struct Result {
    torch::Tensor volume, ref_grad, src_grad;
  };
  torch::Tensor weights;
  const auto run = [&](CorrelationImpl impl) {
    torch::Tensor ref = ref_values.clone().requires_grad_(true);
    torch::Tensor src = src_values.clone().requires_grad_(true);
    const SegmentCorrelation volume(ref, src, seg, /*levels=*/3, /*samples=*/9, impl);
    if (!weights.defined()) weights = torch::randn(volume.volume().sizes());
    (volume.volume() * weights).sum().backward();
    return Result{volume.volume().detach(), ref.grad(), src.grad()};
  };
  const Result aten = run(CorrelationImpl::kAtenOps);
  const Result fused = run(CorrelationImpl::kAuto);
  ASSERT_EQ(fused.volume.sizes(), aten.volume.sizes());
  EXPECT_LT((fused.volume - aten.volume).abs().max().item<float>(), 1e-5f);
  const auto relative = [](const torch::Tensor& a, const torch::Tensor& b) {
    return ((a - b).abs().max() / b.abs().max()).item<float>();
  };
  EXPECT_GT(aten.src_grad.abs().max().item<float>(), 0.01f);  // not a comparison of zeros
  EXPECT_LT(relative(fused.ref_grad, aten.ref_grad), 1e-5f);
  EXPECT_LT(relative(fused.src_grad, aten.src_grad), 1e-5f);
}

TEST(SegmentCorrelation, LookupInterpolatesAlongTheSegment) {
  torch::manual_seed(4);
  const int64_t c = 4, h = 2, w = 2;
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  const EpipolarSegment seg = RowSegment(h, w, 0.0, 9.0);
  const SegmentCorrelation volume(torch::randn({1, c, h, w}, opts), torch::randn({1, c, h, 10}, opts),
                                  seg, /*levels=*/2, /*samples=*/3);
  const torch::Tensor vol = volume.volume();
  // A match at E-flow 4.3 on row y: level 0 reads u = 3.3, 4.3, 5.3.
  const double e = 4.3;
  const torch::Tensor match = torch::cat(
      {torch::full({1, 1, h, w}, e, opts), seg.base_xy.narrow(1, 1, 1)}, 1);
  const CorrelationSamples out = volume.Lookup(match);
  ASSERT_EQ(out.cost.size(1), 6);
  const auto lerp = [&](const torch::Tensor& v, double u, int64_t y, int64_t x) {
    const int64_t i = static_cast<int64_t>(std::floor(u));
    const double f = u - static_cast<double>(i);
    const auto at = [&](int64_t k) { return (k >= 0 && k < v.size(1)) ? v[0][k][y][x].item<double>() : 0.0; };
    return at(i) * (1 - f) + at(i + 1) * f;
  };
  // Level 1: pairs averaged, index (u + 0.5) / 2 - 0.5.
  const torch::Tensor level1 = (vol.narrow(1, 0, 10).view({1, 5, 2, h, w}).mean(2));
  for (int64_t y = 0; y < h; ++y) {
    for (int64_t x = 0; x < w; ++x) {
      for (int64_t k = 0; k < 3; ++k) {
        EXPECT_NEAR(out.cost[0][k][y][x].item<double>(), lerp(vol, e - 1 + k, y, x), 1e-12);
        const double u1 = (e + 0.5) / 2 - 0.5 + (k - 1);
        EXPECT_NEAR(out.cost[0][3 + k][y][x].item<double>(), lerp(level1, u1, y, x), 1e-12);
      }
    }
  }
}

TEST(SegmentCorrelation, BestMatchFindsAPlantedMatchToSubPixel) {
  // Source features: a smooth bump along the row, peaking at column 6.3;
  // the reference feature is the bump's direction, so the volume peaks there.
  const int64_t c = 2, h = 1, w = 1, src_w = 16;
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  const torch::Tensor cols = torch::arange(src_w, opts);
  const torch::Tensor bump = torch::exp(-0.5 * (cols - 6.3).pow(2) / (1.2 * 1.2)) * 4.0;
  const torch::Tensor src = torch::stack({bump, torch::zeros_like(bump)}).view({1, c, 1, src_w});
  const torch::Tensor ref = torch::tensor({1.0, 0.0}, opts).view({1, c, 1, 1});
  const SegmentCorrelation volume(ref, src, RowSegment(h, w, 0.0, 15.0), 1, 1);
  const SegmentMatch best = volume.BestMatch();
  ASSERT_TRUE(best.valid.item<bool>());
  EXPECT_NEAR(best.eflow.item<double>(), 6.3, 0.15);
  EXPECT_GT(best.confidence.item<double>(), 0.5);
}

// ------------------------------------------------------------ matching loss

TEST(MatchingLoss, CrossEntropyOfAPeakedDistributionAtTheTruth) {
  // One pixel, 5 samples at E-flows 10..14, truth at 12.25: target 0.75 on
  // sample 2 and 0.25 on sample 3.
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  StageMatching m;
  m.stride = 4;
  m.sample_eflow = (torch::arange(5, opts) + 10).view({1, 5, 1, 1});
  m.inside = torch::ones({1, 5, 1, 1}, torch::kBool);
  m.base_xy = torch::zeros({1, 2, 1, 1}, opts);
  m.dir = torch::tensor({1.0, 0.0}, opts).view({1, 2, 1, 1});
  GroundTruthMatches truth;
  truth.xy = torch::tensor({12.25, 0.0}, opts).view({1, 2, 1, 1});
  truth.valid = torch::ones({1, 1, 1, 1}, torch::kBool);

  m.logits = torch::tensor({0.0, 1.0, 3.0, 2.0, 0.5}, opts).view({1, 5, 1, 1});
  const torch::Tensor log_p = torch::log_softmax(m.logits, 1);
  const double expected = -(0.75 * log_p[0][2][0][0].item<double>() + 0.25 * log_p[0][3][0][0].item<double>());
  const MatchingLossResult r = MatchingLoss(m, truth);
  EXPECT_NEAR(r.loss.item<double>(), expected, 1e-12);
  EXPECT_EQ(r.count, 1);
  EXPECT_EQ(r.top1, 1);  // arg-max at 12, truth at 12.25

  // Arg-max two samples away: not a top-1 hit.
  m.logits = torch::tensor({5.0, 1.0, 0.0, 0.0, 0.0}, opts).view({1, 5, 1, 1});
  EXPECT_EQ(MatchingLoss(m, truth).top1, 0);
  // ... but the second-highest peak is at the truth (sample 3, E-flow 13):
  // a top-2 and top-4 hit. A sample higher than its neighbours but outside
  // the image is no peak.
  m.logits = torch::tensor({5.0, 1.0, 0.0, 2.0, 0.0}, opts).view({1, 5, 1, 1});
  MatchingLossResult peaks = MatchingLoss(m, truth);
  EXPECT_EQ(peaks.top1, 0);
  EXPECT_EQ(peaks.top2_peaks, 1);
  EXPECT_EQ(peaks.top4_peaks, 1);
  m.inside = torch::tensor({true, true, true, false, true}).view({1, 5, 1, 1});
  peaks = MatchingLoss(m, truth);
  EXPECT_EQ(peaks.top2_peaks, 0);
  m.inside = torch::ones({1, 5, 1, 1}, torch::kBool);
  // The third-highest peak at the truth: only a top-4 hit (sample 3, on a
  // slope, is no peak).
  m.logits = torch::tensor({5.0, 1.0, 3.0, 2.0, 4.0}, opts).view({1, 5, 1, 1});
  m.sample_eflow = torch::tensor({10.0, 11.0, 12.5, 15.0, 18.0}, opts).view({1, 5, 1, 1});
  peaks = MatchingLoss(m, truth);
  EXPECT_EQ(peaks.top1, 0);
  EXPECT_EQ(peaks.top2_peaks, 0);
  EXPECT_EQ(peaks.top4_peaks, 1);
  m.sample_eflow = (torch::arange(5, opts) + 10).view({1, 5, 1, 1});
  // Truth outside the sampled interval or masked: not counted, loss 0.
  truth.xy = torch::tensor({20.0, 0.0}, opts).view({1, 2, 1, 1});
  EXPECT_EQ(MatchingLoss(m, truth).count, 0);
  EXPECT_EQ(MatchingLoss(m, truth).loss.item<double>(), 0.0);
}

TEST(SourceFlowLoss, DistancesToTheTruthWithRaftsWeightsAndACap) {
  // Two pairs on a 1x2 grid, truth at (3, 4) and (10, 10); the second pair
  // is not counted. Iteration 0 is 5 px off on the first pair, iteration 1
  // 0.2 px off; gamma 0.5.
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  GroundTruthMatches truth;
  truth.xy = torch::tensor({3.0, 10.0, 4.0, 10.0}, opts).view({1, 2, 1, 2});
  truth.valid = torch::tensor({true, false}).view({1, 1, 1, 2});
  const torch::Tensor first = torch::tensor({0.0, 99.0, 0.0, 99.0}, opts).view({1, 2, 1, 2});
  torch::Tensor second = torch::tensor({3.2, 99.0, 4.0, 99.0}, opts).view({1, 2, 1, 2});
  second.requires_grad_(true);
  const SourceFlowLossResult r = SourceFlowLoss({first, second}, truth, 0.5);
  EXPECT_NEAR(r.loss.item<double>(), 0.5 * 5.0 + 0.2, 1e-6);
  EXPECT_EQ(r.count, 1);
  EXPECT_EQ(r.last_within_quarter, 1);
  r.loss.backward();
  // d|xy - t| / dxy = the unit vector from the truth; nothing for the
  // uncounted pair.
  EXPECT_NEAR(second.grad()[0][0][0][0].item<double>(), 1.0, 1e-6);
  EXPECT_NEAR(second.grad()[0][1][0][0].item<double>(), 0.0, 1e-6);
  EXPECT_EQ(second.grad()[0][0][0][1].item<double>(), 0.0);
  // A match farther than the cap adds the cap, without gradient.
  torch::Tensor far = torch::tensor({3.0 + 2 * kFlowLossCap, 0.0, 4.0, 0.0}, opts).view({1, 2, 1, 2});
  far.requires_grad_(true);
  const SourceFlowLossResult capped = SourceFlowLoss({far}, truth);
  EXPECT_NEAR(capped.loss.item<double>(), kFlowLossCap, 1e-9);
  EXPECT_EQ(capped.last_within_quarter, 0);
  capped.loss.backward();
  EXPECT_EQ(far.grad().abs().sum().item<double>(), 0.0);
  // Bad input.
  EXPECT_THROW(SourceFlowLoss({}, truth), std::invalid_argument);
  EXPECT_THROW(SourceFlowLoss({torch::zeros({1, 2, 2, 2}, opts)}, truth), std::invalid_argument);
  EXPECT_THROW(SourceFlowLoss({first}, truth, 0.0), std::invalid_argument);
}

TEST(MatchingLoss, GroundTruthMatchesAreTheProjectionsAndOcclusionIsMasked) {
  // Two views looking down +z, the source shifted by 0.2 along x; a fronto-
  // parallel plane at depth 2 in the reference. The source's own depth map
  // is the same plane except a nearer occluder on its left half.
  const int64_t H = 32, W = 32, stride = 4;
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  const double f = 20, cx = 15.5, cy = 15.5;
  const torch::Tensor K = torch::tensor({f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0}, opts).view({1, 1, 3, 3}).expand({1, 2, 3, 3}).clone();
  torch::Tensor E = torch::eye(4, opts).view({1, 1, 4, 4}).repeat({1, 2, 1, 1});
  E[0][1][0][3] = -0.2;  // source centre at x = +0.2
  torch::Tensor depths = torch::full({1, 2, 1, H, W}, 2.0, opts);
  depths[0][1].narrow(2, 0, W / 2).fill_(1.0);  // occluder in the source's left half
  const GroundTruthMatches gt = ComputeGroundTruthMatches(depths, K, E, stride, H / stride, W / stride);
  // Reference stage cell (i, j) = full pixel (4i, 4j); it moves by -f * 0.2 / 2 = -2 px in x.
  for (int64_t i = 0; i < H / stride; ++i) {
    for (int64_t j = 0; j < W / stride; ++j) {
      const double src_x = 4.0 * j - 2.0, src_y = 4.0 * i;
      const bool inside = src_x >= 0;
      const bool occluded = src_x < W / 2.0;  // the occluder's half (with a margin of one pixel)
      if (src_x < 0) continue;
      if (std::abs(src_x - (W / 2.0 - 0.5)) < 1.5) continue;  // the occluder's edge
      EXPECT_EQ(gt.valid[0][0][i][j].item<bool>(), inside && !occluded) << i << "," << j;
      if (gt.valid[0][0][i][j].item<bool>()) {
        EXPECT_NEAR(gt.xy[0][0][i][j].item<double>(), src_x / stride, 1e-12);
        EXPECT_NEAR(gt.xy[0][1][i][j].item<double>(), src_y / stride, 1e-12);
      }
    }
  }
}

TEST(StridedIntrinsics, StridedConvolutionsPutCellsThere) {
  // The encoder's down-sampling chain (7x7/2 pad 3, then three 3x3/2 pad 1)
  // with centre-tap kernels is a pure subsampling: cell j reads input
  // pixel 16 j. StridedIntrinsics says the same; ScaleIntrinsics would put
  // it at 16 j + 7.5.
  namespace F = torch::nn::functional;
  const int64_t size = 64;
  const torch::Tensor image = torch::arange(size * size, torch::kFloat64).view({1, 1, size, size});
  torch::Tensor x = image;
  torch::Tensor k7 = torch::zeros({1, 1, 7, 7}, torch::kFloat64);
  k7[0][0][3][3] = 1;
  x = F::conv2d(x, k7, F::Conv2dFuncOptions().stride(2).padding(3));
  torch::Tensor k3 = torch::zeros({1, 1, 3, 3}, torch::kFloat64);
  k3[0][0][1][1] = 1;
  for (int i = 0; i < 3; ++i) x = F::conv2d(x, k3, F::Conv2dFuncOptions().stride(2).padding(1));
  ASSERT_EQ(x.size(2), size / 16);
  const torch::Tensor K = torch::tensor({10.0, 0.0, 20.0, 0.0, 10.0, 30.0, 0.0, 0.0, 1.0}, torch::kFloat64).view({3, 3});
  const torch::Tensor Ks = StridedIntrinsics(K, 16);
  // A point that projects to full-resolution pixel (u, v) projects to
  // (u / 16, v / 16) on the strided grid: cell (i, j) <-> pixel (16 i, 16 j).
  EXPECT_NEAR(Ks[0][2].item<double>(), 20.0 / 16, 1e-15);
  EXPECT_NEAR(Ks[0][0].item<double>(), 10.0 / 16, 1e-15);
  for (int64_t i = 0; i < x.size(2); ++i) {
    for (int64_t j = 0; j < x.size(3); ++j) {
      EXPECT_EQ(x[0][0][i][j].item<double>(), image[0][0][16 * i][16 * j].item<double>());
    }
  }
}

}  // namespace
}  // namespace dispmvs::model
