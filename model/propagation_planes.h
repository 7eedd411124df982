#pragma once
// The candidates of the photometric refinement's propagation
// (photometric_refinement.h): the plane of every pixel of the current
// inverse-depth map, and that plane extended from a pixel (dx, dy) away to
// every pixel.
//
// On a plane in the scene, inverse depth is affine in the pixel coordinates,
// w(x, y) = w0 + gx x + gy y, so a pixel's plane is its inverse depth and
// the slopes (gx, gy) of the least-squares plane through the usable inverse
// depths of the (2r+1) x (2r+1) window around it.
//
// Every level of propagation fits the slopes once and builds four shifted
// candidates; at full resolution that was some forty full-size LibTorch
// operations on nine channels per level. On CPU float tensors both run as
// loops here: the fit keeps per-column sums of five quantities as the
// window moves down the rows and slides nine sums along each row (in
// double: no cancellation in the centred moments), bands of rows in
// parallel; the candidate is one pass. Other devices and types run the
// operations (the same arithmetic in float; propagation_planes_test.cc
// checks both against a direct fit).

#include <cstdint>
#include <utility>

#include <torch/torch.h>

namespace dispmvs::model {

// The slopes (gx, gy), each [B,1,H,W], of the least-squares plane through
// the inverse depths `w` [B,1,H,W] of the `usable` ([B,1,H,W] bool) pixels of
// the (2 radius + 1)^2 window around every pixel (clipped at the border).
// 0 where a quarter or less of the window's pixels inside the image are
// usable, or where they lie too near a line (the determinant of their
// coordinates' covariance at most 1e-3 pixels^4). Throws
// std::invalid_argument on mismatched shapes or radius < 1.
std::pair<torch::Tensor, torch::Tensor> LeastSquaresSlopes(const torch::Tensor& w, const torch::Tensor& usable,
                                                           int64_t radius);

// The same by LibTorch operations on any device (float arithmetic: the
// centred moments lose a few digits to cancellation far from the centre).
std::pair<torch::Tensor, torch::Tensor> LeastSquaresSlopesByOps(const torch::Tensor& w,
                                                                const torch::Tensor& usable, int64_t radius);

// A least-squares plane of every window: its inverse depth at the window's
// own pixel and its slopes, each [B,1,H,W].
struct LeastSquaresPlane {
  torch::Tensor value, gx, gy;
};

// LeastSquaresSlopes' fit with the plane's value at each window's pixel
// (the fit's intercept there), 0 where the fit declines (where the slopes
// are 0 for that reason). A pixel's own inverse depth may lie off the plane
// of its neighbours (noise, or the pixel is on another surface); the value
// is what its neighbours say. Same inputs and errors as LeastSquaresSlopes.
LeastSquaresPlane LeastSquaresPlanes(const torch::Tensor& w, const torch::Tensor& usable, int64_t radius);

// The same by LibTorch operations on any device (float arithmetic).
LeastSquaresPlane LeastSquaresPlanesByOps(const torch::Tensor& w, const torch::Tensor& usable, int64_t radius);

// The plane of the pixel (dx, dy) away, extended to every pixel p:
// w(p + o) - dx gx(p + o) - dy gy(p + o) with o = (dx, dy); 0 where p + o is
// outside the image, has no inverse depth (w <= 0) or the plane is not
// positive there. w, gx, gy: [B,1,H,W]. Throws std::invalid_argument on
// mismatched shapes.
torch::Tensor PlaneFromNeighbour(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                                 int64_t dx, int64_t dy);

// The same by LibTorch operations on any device (bit for bit the same).
torch::Tensor PlaneFromNeighbourByOps(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                                      int64_t dx, int64_t dy);

}  // namespace dispmvs::model
