#pragma once
// The plane of the nearest trusted pixel, extended over pixels whose own
// depth cannot be trusted: where no source sees a pixel (the photometric
// refinement's last step, photometric_refinement.h) and where the
// confidence model gives a pixel little chance of being right
// (confident_plane_fill.h).
//
// Why: on a plane in the scene, inverse depth is affine in the pixel
// coordinates, w(x, y) = w0 + gx x + gy y, so a trusted pixel's inverse
// depth and the slopes (gx, gy) fitted around it (LeastSquaresSlopes,
// propagation_planes.h) give the exact depth of every pixel on the same
// plane, however far. Walls, floors and facades continue past where the
// sources see them and through where they correlate poorly (weak texture,
// occlusion in a source); the nearest trusted pixel lies most often on the
// same surface.
//
//  * NearestAnchor: for every pixel, the nearest pixel of a mask;
//    NearestAnchorsAlongAxes: the nearest on its row to either side and on
//    its column above and below (four more pixels, on four sides of it);
//  * ExtendNearestPlane: that pixel's plane extended to the pixel;
//    ExtendNearestPlaneWithin: the same, kept within bounds;
//  * ExtendTrustedPlanes: both, with the slopes fitted over trusted pixels,
//    the result kept within bounds (InverseDepthBounds, geometry.h) and,
//    optionally, near each pixel's own depth.

#include <array>
#include <cstdint>

#include <torch/torch.h>

namespace dispmvs::model {

// For every pixel, the flat index (row * W + column) of the nearest pixel of
// `anchor` ([B,1,H,W] bool) in its own image, by breadth-first steps to the
// eight neighbours (distance in the chessboard metric, ties to the pixel
// reached first); -1 in an image without anchors. [B,1,H,W] long, on
// anchor's device (computed on the CPU). Throws std::invalid_argument unless
// anchor is [B,1,H,W] bool.
torch::Tensor NearestAnchor(const torch::Tensor& anchor);

// For every pixel, the nearest pixel of `anchor` ([B,1,H,W] bool) on its own
// row at or left of it, at or right of it, on its own column at or above it,
// at or below it (in that order), as flat indices (row * W + column); -1
// where there is none. Where the nearest anchor of all (NearestAnchor) lies
// on one surface, these may lie on others: a wrong block is surrounded by
// the surfaces around it. [B,1,H,W] long each, on anchor's device (computed
// on the CPU). Throws std::invalid_argument unless anchor is [B,1,H,W] bool.
std::array<torch::Tensor, 4> NearestAnchorsAlongAxes(const torch::Tensor& anchor);

// The plane of pixel q = nearest(p) extended to p: w(q) + gx(q) (x_p - x_q)
// + gy(q) (y_p - y_q); 0 where nearest is -1. w, gx, gy [B,1,H,W] float,
// nearest [B,1,H,W] long (NearestAnchor's). Throws std::invalid_argument on
// mismatched shapes.
torch::Tensor ExtendNearestPlane(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                                 const torch::Tensor& nearest);

// The same by LibTorch operations on any device (ExtendNearestPlane is one
// loop on CPU float maps; the same arithmetic in float).
torch::Tensor ExtendNearestPlaneByOps(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                                      const torch::Tensor& nearest);

// ExtendNearestPlane kept within [low, high] ([B,1,1,1]); 0 where nearest is
// -1 and where the plane is not positive (it passes behind the camera).
torch::Tensor ExtendNearestPlaneWithin(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                                       const torch::Tensor& nearest, const torch::Tensor& low,
                                       const torch::Tensor& high);

// At every pixel, the plane of the nearest `trusted` pixel of w (its slopes
// fitted over the (2 slope_radius + 1)^2 trusted pixels around it,
// LeastSquaresSlopes), kept within [low, high] ([B,1,1,1]); 0 where the
// plane is not positive (it passes behind the camera), in an image without
// trusted pixels, and, with max_change > 0, where the pixel has a depth
// (w > 0) and the plane's inverse depth differs from it by more than
// max_change (relative). w [B,1,H,W] float, trusted [B,1,H,W] bool.
torch::Tensor ExtendTrustedPlanes(const torch::Tensor& w, const torch::Tensor& trusted, int64_t slope_radius,
                                  const torch::Tensor& low, const torch::Tensor& high, double max_change);

}  // namespace dispmvs::model
