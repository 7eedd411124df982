#pragma once
// The photometric refinement's last step (photometric_refinement.h,
// options.local_plane_radius): every pixel's inverse depth is replaced by the
// value at that pixel of the least-squares plane through the well-correlated
// pixels around it, where that value lies near its own.
//
// Why: the search takes each pixel's own maximum of a 7x7 window's NCC, and
// propagation keeps a candidate wherever it scores higher; nothing makes
// neighbours on one surface agree, and each maximum carries its own error
// (on a textured plane the search alone leaves a median error of 0.35 %
// that varies along the plane). On a plane in the scene inverse depth is
// affine in the pixel coordinates, so the plane through the neighbours'
// depths averages those errors out (0.19 %). The bound on the change keeps
// the fit from pulling a pixel across a depth edge: there the plane through
// the window mixes two surfaces and lies far from both.

#include <cstdint>

#include <torch/torch.h>

namespace dispmvs::model {

struct LocalPlaneSnap {
  torch::Tensor w;        // [B,1,H,W] the inverse depths after the step
  torch::Tensor snapped;  // [B,1,H,W] bool: where the plane's value was taken
};

// For every pixel where `apply`: the value v at the pixel of the
// least-squares plane through the inverse depths `w` of the `support`
// pixels of the (2 radius + 1)^2 window around it (LeastSquaresPlanes,
// propagation_planes.h), taken where v > 0 and |v - w| <= max_change * w;
// elsewhere w stays. w [B,1,H,W] float, support and apply [B,1,H,W] bool.
// Throws std::invalid_argument on mismatched shapes, radius < 1 or
// max_change outside (0, 1].
LocalPlaneSnap SnapToLocalPlanes(const torch::Tensor& w, const torch::Tensor& support, const torch::Tensor& apply,
                                 int64_t radius, double max_change);

}  // namespace dispmvs::model
