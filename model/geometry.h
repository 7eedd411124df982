#pragma once
// Epipolar geometry of DispMVS, in batched, differentiable LibTorch ops.
// Read this file against the paper (Sec. "Flow and Depth", "E-flow") and
// docs/method.md, sections 1-5 (conventions, epipolar line and segment,
// E-flow, triangulation), which derives every formula below.
//
// Conventions
//  * Pixel coordinates are in the pixel-index convention of the tensor the
//    network works on: the centre of pixel (row i, col j) is (x, y) = (j, i).
//    (COLMAP puts the top-left pixel centre at (0.5, 0.5); the conversion
//    happens once, where intrinsics enter the model.)
//  * K_ref, K_src: [B,3,3] intrinsics at the resolution of the current stage.
//  * R, T: [B,3,3], [B,3]: the rigid motion mapping reference-camera
//    coordinates to source-camera coordinates (X_s = R X_r + T).
//  * Depth is handled as inverse depth w = 1/d throughout; w = 0 is a point at
//    infinity and is representable.
//
// With a = K_s R K_r^-1 p~ and b = K_s T, the source pixel of reference pixel p
// at inverse depth w is  p_s(w) = (a_xy + w b_xy) / (a_z + w b_z).
// Every function returns finite values everywhere, and finite gradients with
// respect to inverse depth, source pixels, E-flows and logits; where the
// geometry is degenerate (zero baseline, epipole, behind a camera, non-finite
// input) the returned `valid` mask is false and the value is 0.
// "Degenerate" is decided relative to the magnitudes of the terms involved
// (tolerance sqrt(machine epsilon) of the dtype), so the masks do not depend
// on the unit of the scene: millimetres and kilometres give the same masks.
// float32 and float64 both work; tensors may live on any device (all inputs of
// one call on the same device, with the same dtype).

#include <utility>

#include <torch/torch.h>

namespace dispmvs::model {

// Per-pixel projection coefficients of one reference/source pair.
struct EpipolarPair {
  torch::Tensor a;  // [B,3,H,W]  K_s R K_r^-1 p~
  torch::Tensor b;  // [B,3,1,1]  K_s T
};

// Pixel-centre grid [1,2,H,W] holding (x, y) = (col, first_row + row): the
// rows first_row.. of a larger image (a band of it) with first_row > 0.
// Throws std::invalid_argument unless height, width > 0 and first_row >= 0.
torch::Tensor PixelGrid(int64_t height, int64_t width, const torch::TensorOptions& options,
                        int64_t first_row = 0);

// Batch sizes may be B or 1 (broadcast). Throws std::invalid_argument on bad
// shapes or mixed dtypes/devices. Cameras with non-finite entries or a
// singular K_ref give a = 0 (and b = 0 where K_src or T is the culprit): every
// function below reads that as degenerate.
// The pair of the reference's rows first_row .. first_row + height - 1
// (all of them with first_row = 0): a band of a larger image gets the same
// coefficients, to the bit, as those rows of the whole image.
EpipolarPair MakeEpipolarPair(const torch::Tensor& K_ref, const torch::Tensor& K_src,
                              const torch::Tensor& R, const torch::Tensor& T,
                              int64_t height, int64_t width, int64_t first_row = 0);

struct SourcePixels {
  torch::Tensor xy;     // [B,2,H,W]
  torch::Tensor valid;  // [B,1,H,W] bool: w finite and >= 0, point in front of the source camera
};
// Source pixel of every reference pixel at inverse depth w [B,1,H,W].
// w = 0 is valid: it projects to the vanishing point a_xy / a_z when that lies
// in front of the source camera. Also invalid: projections more than 2^24
// pixels away (no image is that large; keeps quotients away from overflow).
SourcePixels ProjectInverseDepth(const EpipolarPair& pair, const torch::Tensor& inv_depth);

struct EpipolarDirection {
  torch::Tensor dir;    // [B,2,H,W] unit vector along dp_s/dw (towards nearer points); 0 where invalid
  torch::Tensor valid;  // [B,1,H,W] bool: false at zero baseline and at the epipole
};
// Analytic, scale-free epipolar direction: dp_s/dw is proportional to
// (b_xy a_z - a_xy b_z), independent of w, so the line is straight and the
// direction does not depend on the unit of the scene.
EpipolarDirection ComputeEpipolarDirection(const EpipolarPair& pair);

// How far the source pixel moves per unit of inverse depth at inv_depth
// [B,1,H,W] (batch as the pair's): |dp_s/dw| = |b_xy a_z - a_xy b_z| /
// (a_z + w b_z)^2, in source pixels. 0 where the point is not in front of
// the source camera (a_z + w b_z <= 0) or the value is not finite. What
// the photometric refinement spaces its hypotheses by. [B,1,H,W].
torch::Tensor MatchShiftPerInverseDepth(const EpipolarPair& pair, const torch::Tensor& inv_depth);

// Per batch item, the smallest and the largest inverse depth of the
// `usable` pixels of w (both [B,1,H,W]), each [B,1,1,1] (+inf and 0 for an
// item without usable pixels): the range a map's candidates stay within
// (a plane extended far reaches inverse depths near 0, depths without
// bound, where no surface was seen).
std::pair<torch::Tensor, torch::Tensor> InverseDepthBounds(const torch::Tensor& w, const torch::Tensor& usable);

// How far inside the (height x width) image of its best-placed source the
// match of each reference pixel at inverse depth `w` [B,1,H,W] lies: the
// largest, over the `sources` sources of its batch item, of the match's
// distance to the nearest image border (min(x, W-1-x, y, H-1-y), pixels;
// negative outside), -inf where no source has the point in front of it or
// w <= 0 (no depth). `pair` holds the B * sources pairs, batch item major.
// "Some source sees the pixel, at least m pixels from its border" is
// DistanceInsideSources(...) >= m. [B,1,H,W]. Throws std::invalid_argument
// on mismatched shapes or sources < 1.
torch::Tensor DistanceInsideSources(const EpipolarPair& pair, const torch::Tensor& w, int64_t sources,
                                    int64_t height, int64_t width);

// The epipolar segment of every reference pixel in one source view: the
// source pixels that a POSITIVE depth can project to, clipped to the source
// image. It is defined by the cameras alone (no depth range):
//  * the valid inverse depths are w > 0 with a_z + w b_z > 0 (in front of the
//    source camera); over them the projection moves monotonically along the
//    line in `dir` (towards larger w, nearer points);
//  * its far end (w -> 0, depth -> infinity) is the vanishing point a_xy / a_z
//    when a_z > 0, and lies at infinity otherwise (ray parallel to the source
//    image plane, or a ray that only enters the source's view at a finite
//    depth);
//  * its near end (w -> infinity, depth -> 0+) is the epipole b_xy / b_z when
//    b_z > 0 (the reference camera's centre lies in front of the source
//    camera), at infinity otherwise;
//  * the result is that interval intersected with the source image's pixel
//    centres [0, width-1] x [0, height-1].
// Positions along the line are E-flows (geometry.h: src = base + e * dir),
// measured from `base`, the foot of the perpendicular from the source image
// centre onto the line (always finite, within half an image diagonal of the
// image when the line crosses it). Ends at infinity are represented by
// +-2^24 before clipping.
struct EpipolarSegment {
  torch::Tensor base_xy;  // [B,2,H,W] source pixels, on the epipolar line
  torch::Tensor dir;      // [B,2,H,W] unit, as ComputeEpipolarDirection
  torch::Tensor start;    // [B,1,H,W] E-flow of the far end (after clipping)
  torch::Tensor end;      // [B,1,H,W] E-flow of the near end, >= start where valid
  torch::Tensor valid;    // [B,1,H,W] bool: a non-degenerate line with a non-empty segment
};
// src_height, src_width: the source image size at the pair's resolution.
EpipolarSegment ComputeEpipolarSegment(const EpipolarPair& pair, int64_t src_height,
                                       int64_t src_width);

struct InverseDepth {
  torch::Tensor inv_depth;  // [B,1,H,W]; 0 where invalid
  torch::Tensor valid;      // [B,1,H,W] bool: w > 0 and finite, in front of both cameras
};
// Closed-form triangulation of the matched source pixel xy [B,2,H,W]:
//   w = (a_x - u a_z) / (u b_z - b_x)   or   w = (a_y - v a_z) / (v b_z - b_y),
// taking the equation with the larger denominator (the paper's Eq. 7
// selection by the larger flow component). Also invalid: a match at the
// vanishing point (w = 0), a pixel or match on the epipole, zero baseline,
// non-finite coordinates.
InverseDepth TriangulateInverseDepth(const EpipolarPair& pair, const torch::Tensor& src_xy);

// E-flow <-> source pixel, for a base point and direction held fixed within a stage:
// src = base + e * dir and e = dir . (src - base) (exact inverses for unit dir
// and src on the line). Non-finite inputs are read as 0.
torch::Tensor EflowToSourcePixel(const torch::Tensor& base_xy, const torch::Tensor& dir,
                                 const torch::Tensor& eflow /*[B,1,H,W]*/);
torch::Tensor SourcePixelToEflow(const torch::Tensor& base_xy, const torch::Tensor& dir,
                                 const torch::Tensor& src_xy);

// Softmax-weighted fusion over the source axis: inv_depths, logits, valid are
// [B,N,H,W] (valid is bool); invalid pairs, and pairs with a non-finite inverse
// depth or logit, get zero weight. Returns fused inverse depth
// [B,1,H,W], the weights [B,N,H,W], and a mask [B,1,H,W] of pixels with at
// least one valid pair (elsewhere weights and fused value are 0).
struct FusedInverseDepth {
  torch::Tensor inv_depth;
  torch::Tensor weights;
  torch::Tensor valid;
};
FusedInverseDepth FuseInverseDepths(const torch::Tensor& inv_depths, const torch::Tensor& logits,
                                    const torch::Tensor& valid);

// Uniform random inverse depth in [1/d_max, 1/d_min]; d_min, d_max are [B]
// tensors (per-sample range hint), 0 < d_min <= d_max, d_max may be +inf
// (otherwise std::invalid_argument). Shape [B,1,H,W], dtype and device of
// d_min. A defined generator makes it deterministic: the numbers are drawn on
// the generator's device, so a CPU generator gives the same values for CPU
// and CUDA results.
torch::Tensor RandomInverseDepth(const torch::Tensor& d_min, const torch::Tensor& d_max,
                                 int64_t height, int64_t width, torch::Generator generator = {});

// (w - 1/d_max) / (1/d_min - 1/d_max): 0 at d_max, 1 at d_min. Not clipped:
// values outside the hint stay valid. d_min, d_max are [B] tensors with
// 0 < d_min < d_max (d_max may be +inf), otherwise std::invalid_argument.
// The result has the dtype and device of the first argument.
torch::Tensor NormalizeInverseDepth(const torch::Tensor& inv_depth, const torch::Tensor& d_min,
                                    const torch::Tensor& d_max);
torch::Tensor DenormalizeInverseDepth(const torch::Tensor& normalized, const torch::Tensor& d_min,
                                      const torch::Tensor& d_max);

// Intrinsics of a stage at 1/factor resolution, in the pixel-index convention:
// c' = (c + 0.5) / factor - 0.5, f' = f / factor. K is [...,3,3]; factor > 0
// is the downsampling factor (4, 16).
torch::Tensor ScaleIntrinsics(const torch::Tensor& K, double factor);

// Intrinsics of a map whose cell j sits at full-resolution pixel stride * j:
// f' = f / stride, c' = c / stride. This is where a chain of stride-2
// convolutions with "same" padding (3x3 pad 1, 7x7 pad 3, 1x1) puts its
// cells: output j reads the input centred at 2j, so after k of them cell j
// is centred at 2^k j, not at the centre 2^k j + (2^k - 1) / 2 of its block
// that ScaleIntrinsics assumes (7.5 pixels off at 1/16). Model v2 samples its
// feature maps with these; the paper configuration keeps ScaleIntrinsics,
// which its weights were trained with.
torch::Tensor StridedIntrinsics(const torch::Tensor& K, double stride);

}  // namespace dispmvs::model
