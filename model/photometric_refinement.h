#pragma once
// Photometric refinement of a depth map: a short search along each source's
// epipolar line around the network's depth, scored by normalised
// cross-correlation (NCC) of image windows at full resolution.
//
// Why: the network's fine stage works on a 1/4 grid with a learned matching
// cost, and its matches are often a full-resolution pixel or more off even
// where the depth is roughly right (docs/training.md, "Oracles"): a 2-10 %
// error across textured planes. NCC of the images themselves is exact to a
// fraction of a pixel there, and invariant to gain and offset (exposure), but
// it cannot find the right match on its own over a whole epipolar line in
// weak or repeated texture. So the network gives the start and the search
// stays within a few pixels of it: the network decides which surface, the
// images decide exactly where.
//
// For every reference pixel p with network inverse depth w0 (geometry.h's
// conventions):
//  * the step dw is chosen so that one step moves p's match by `step_pixels`
//    in the source where it moves most (the largest |dp_s/dw| at w0);
//  * hypotheses w_k = w0 + k dw, k = -steps..steps (w_k > 0);
//  * each source image is sampled (bilinearly) where every pixel q projects
//    at its own w0(q) + k dw(q): the window around p follows the network's
//    surface shape, not a fronto-parallel plane;
//  * score(k) = NCC of the (2r+1)^2 windows of the reference and the sampled
//    source (grey values), averaged over the better half of the sources,
//    chosen per pixel once, by their NCC at the network's depth (occlusion:
//    the worse half is left out); a chosen source whose match comes within
//    r pixels of its border at step k scores -1 there;
//  * the best k, refined by a parabola through its neighbours' scores.
// Every score here and below is, with options.window_shift > 0 (2 by
// default, shifted_windows.h), the best of five windows that contain the
// pixel: the centred one and those shifted window_shift pixels left, right,
// up and down; where the centred window straddles a depth edge, a shifted
// one can lie on the pixel's own surface.
// The refined depth replaces the network's only where the search has a clear
// answer: the best score is at least `min_ncc`, it lies strictly inside the
// searched interval (a best score at the border means the truth may be
// outside), and the reference window has texture (standard deviation of
// grey values at least `min_texture`). Elsewhere the network's depth stays.
//
// Propagation (options.propagation_rounds > 0; two rounds by default): every
// pixel tries the planes of the pixels propagation_distance,
// half that, ... (propagation_levels jumps) away in four directions: the
// neighbour's inverse depth extended by the slopes of the least-squares
// plane through the current map around it (inverse depth is affine in the
// pixel coordinates on a plane). A candidate replaces the current depth
// where it scores better (the same NCC on the same sources), at least
// min_ncc, on a textured window and within the inverse depths the network
// gave the view. The right surface then spreads over blocks where the
// network's match was beyond the search's reach, as in PatchMatch; each
// candidate is a whole shifted map, one warp and window pass like one
// hypothesis of the search.
//
// Where propagation runs (options.propagation_scale): at 1, at full
// resolution after the search, as above. At 2 (the default) or 4, first, on
// the images averaged over 2x2 or 4x4 blocks with the network's inverse
// depth averaged the same way: a search and propagation at that resolution
// (steps of one coarse pixel, distances and slope radius divided by the
// scale), whose surface, upsampled bilinearly, replaces the network's as the
// start of the full-resolution search wherever it correlates better at full
// resolution on the same sources. The coarse passes reach further (a coarse
// pixel is 2 or 4 pixels) at a quarter or a sixteenth of the cost, and the
// full-resolution search needs fewer steps (2 by default) after them. Then
// options.full_resolution_rounds rounds (1 by default) propagate at full
// resolution, with jumps of propagation_distance / scale pixels and
// full_resolution_levels levels (16 by default): the coarse rounds find the
// surface, this round gives it planes fitted at full resolution, which the
// search's parabola between whole steps does not reach. Too small an image
// for the coarse window (fewer than 2r + 2 coarse pixels a side)
// propagates at full resolution instead (propagation_rounds rounds).
//
// The sweep (options.sweep_hypotheses > 0; 128 by default, depth_sweep.h):
// before the search, where the search starts from the network's depth (on
// the coarse grid with propagation_scale 2 or 4, else at full resolution),
// constant inverse depths over the network's range are tried at every pixel
// in the one source chosen at most pixels; the smoothed winner replaces the
// network's depth as the start wherever it correlates better (on the chosen
// sources, at least min_ncc, textured windows). It reaches surfaces the
// network missed entirely, which neither the search nor propagation can.
//
// Long-range planes (options.trusted_plane_min_ncc > 0; 0.9 by default,
// nearest_plane.h): after the full-resolution propagation, every pixel tries
// the planes of the nearest refined pixels ("anchors") that correlate at
// least that well: the nearest of all and, with
// options.trusted_plane_axis_anchors (4 by default), the nearest on its row
// to either side and on its column above and below. Each is the
// least-squares plane through the anchors of the (2
// kTrustedPlaneSlopeRadius + 1)^2 window around the anchor (its value
// there, not the anchor's own depth, and its slopes), kept as
// propagation's candidates are (where it scores better, on a textured
// window, within the network's inverse depths) and where it takes the
// pixel at most kTrustedPlaneMaxDepthRatio times further. Propagation's
// candidates come from a few dozen pixels away, from whatever depth lies
// there; these from the nearest surfaces the images confirm, on every side
// of wrong blocks of any size.
//
// Local planes (options.local_plane_radius > 0; 2 by default,
// local_planes.h): then, in the coarse pass as in the full-resolution one,
// every pixel takes the value at the pixel of the least-squares plane
// through the pixels of the (2 radius + 1)^2 window around it whose NCC at
// their depth is at least kLocalPlaneMinNcc, where that value lies within
// options.local_plane_max_change (3 % by default) of its own inverse depth.
// The search's and propagation's per-pixel NCC maxima each carry their own
// error; the plane through the neighbours averages them out, and the bound
// keeps it off depth edges.
//
// Pixels no source sees (options.unseen_slope_radius > 0; 16 by default,
// nearest_plane.h): last, at full resolution, where the refined depth's
// match lies outside every source's image, the plane of the nearest refined
// pixel that a source sees (at least kUnseenAnchorMargin pixels inside its
// image) is extended over the pixel, where it lies within kUnseenMaxChange
// of the pixel's own depth (the network's: nothing scores an unseen pixel):
// exact where a plane continues past the sources' view, as walls and floors
// do; nothing can be matched there.
//
// Runs without autograd on any device; images [B,V,3,H,W] as in
// DispMvsInput (view 0 the reference), intrinsics in the pixel-index
// convention at the images' resolution.

#include <torch/torch.h>

#include "model/dispmvs_net.h"
#include "model/photometric_refinement_options.h"

namespace dispmvs::model {

struct PhotometricRefinement {
  torch::Tensor depth;    // [B,1,H,W], 0 where invalid
  torch::Tensor valid;    // [B,1,H,W] bool: the input's valid mask (refinement adds none)
  // [B,1,H,W] bool: where the search, propagation, the local planes or the
  // unseen pixels' extension replaced the depth
  torch::Tensor refined;
  torch::Tensor score;    // [B,1,H,W] the best NCC found, -1 where none was computed
  // [B,1,H,W] the NCC at the output depth: the accepted score where the
  // search or propagation replaced the depth, the network depth's own score
  // elsewhere (where local planes then moved it, by at most
  // local_plane_max_change, the score before the move); -1 where none was
  // computed. With `texture`, what the
  // confidence model (model/confidence_model.h) reads.
  torch::Tensor output_score;
  torch::Tensor texture;  // [B,1,H,W] standard deviation of the reference window's grey values
  // [B,1,H,W] the share of windows within kSignalRadius pixels whose grey
  // values vary at all (texture >= kSignalFloor): 0 where nothing near a
  // pixel holds any image signal, only flat, clipped or empty image (an
  // all-black view, a saturated sky).
  torch::Tensor signal_support;
};

// What "varies at all" means for signal_support: half a grey level of an
// 8-bit image. Sensor noise alone lifts every window of a photograph or a
// generated view above it; only exactly flat image stays below.
inline constexpr double kSignalFloor = 0.002;
// How far inside a source's image (pixels) a match must lie for its pixel to
// lend its plane to the pixels no source sees: the refinement scores no
// window that leaves the image (radius 3 by default), so the last pixels
// before the border keep the network's depth (8 against 3 and 16 on
// realval's MVS pairs, in a scratch program on the maps: 0.5898 against
// 0.5890 and 0.5892 within 2 %, in that program's count).
inline constexpr double kUnseenAnchorMargin = 8.0;
// The extended plane replaces an unseen pixel's depth only where its inverse
// depth differs from the network's by at most this (relative): it snaps a
// roughly right guess onto the plane. Without the bound, planes extended
// over wide unseen bands (a side wall seen at a grazing angle) reached
// depths far from any surface: realval's MVS pairs' mean relative error
// rose from 0.35 to 0.48 for 0.004 more pixels within 2 %.
inline constexpr double kUnseenMaxChange = 0.3;
// A long-range plane (options.trusted_plane_min_ncc) is fitted over the
// (2 r + 1)^2 trusted pixels around its anchor, r this: as
// wide as the unseen pixels' planes' default, so that a plane is fitted
// over more than the texture of one window.
inline constexpr int64_t kTrustedPlaneSlopeRadius = 16;
// A long-range plane takes a pixel at most this many times further than
// its depth was (it may bring it nearer without bound). Without the bound the
// 20 generated scenes' mean relative error rose from 0.361 to 0.403, for
// 0.001 more pixels within 2 %; with it, 0.358 (docs/refinement-measurements.md, "Long-range
// planes").
inline constexpr double kTrustedPlaneMaxDepthRatio = 2.0;
// The radius of PhotometricRefinement::signal_support, full-resolution pixels.
inline constexpr int64_t kSignalRadius = 32;
// Local planes (options.local_plane_radius): the pixels whose NCC at their
// depth is at least this carry the planes. realval's MVS pairs within 2 %
// 0.6110 against 0.6100 at 0.2 and 0.6098 at 0.8 (radius 2, change 0.02).
inline constexpr double kLocalPlaneMinNcc = 0.5;

// depth, valid: [B,1,H,W] (the network's DispMvsOutput::depth and valid).
// Throws std::invalid_argument on mismatched shapes or V < 2.
PhotometricRefinement RefineDepthPhotometrically(const torch::Tensor& images,
                                                 const torch::Tensor& intrinsics,
                                                 const torch::Tensor& extrinsics,
                                                 const torch::Tensor& depth,
                                                 const torch::Tensor& valid,
                                                 const PhotometricRefinementOptions& options);

// The network's output refined on its own input.
PhotometricRefinement RefineDepthPhotometrically(const DispMvsInput& input,
                                                 const DispMvsOutput& output,
                                                 const PhotometricRefinementOptions& options);

}  // namespace dispmvs::model
