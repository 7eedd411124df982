#pragma once
// The settings of the photometric refinement (photometric_refinement.h),
// apart from it so that code that keeps LibTorch out of its headers
// (dense/depth_estimator.h) can hold them.

#include <cstdint>
#include <string>

namespace dispmvs::model {

struct PhotometricRefinementOptions {
  int64_t window_radius = 3;  // NCC window (2r+1) x (2r+1) pixels
  // Shifted windows (shifted_windows.h), 0 = the centred window alone: every
  // surface is scored at a pixel by the best of five windows that contain
  // it, centred and shifted this many pixels left, right, up and down (in
  // the coarse pass too, in its own pixels). Where the centred window
  // straddles a depth edge or a patch the source sees differently, a
  // shifted one can still confirm the pixel's surface. 2 by default:
  // realval's MVS pairs within 2 % 0.626 against 0.612 without shifts, the 20
  // generated scenes 0.5410 against 0.5342 (shift 1: 0.621, 3: 0.621;
  // docs/refinement-measurements.md, "Shifted windows").
  int64_t window_shift = 2;
  // Hypotheses on each side of the start's depth. 2 since the sweep (below)
  // joined the coarse propagation in giving the search its reach (3 before,
  // 6 without propagation before that).
  int64_t steps = 2;
  double step_pixels = 1.0;   // their spacing in the source with most parallax, pixels
  double min_ncc = 0.2;       // the best score needed to replace the network's depth
  // The reference window's grey-value standard deviation needed (images in
  // [0, 1]). 0.005 (about 1.3 grey levels of an 8-bit image) since the
  // seventh revision, 0.01 before: fine real texture such as carpet varies
  // by less than 0.01 over 7x7 pixels and still correlates (realval's MVS
  // pairs within 2 % 0.581 against 0.577, mvs_001 0.621 against 0.560; the
  // 20 generated scenes 0.5077 against 0.5050; docs/refinement-measurements.md).
  double min_texture = 0.005;
  // Propagation (photometric_refinement.h), 0 rounds = off:
  // candidates are the planes of the pixels `propagation_distance`, half
  // that, ... (`propagation_levels` jumps) away in four directions, their
  // slopes fitted to the current map over (2 radius + 1)^2 windows.
  // 2 since the NCC pass's AVX2 build (surface_ncc_rows.h) made two rounds at
  // scale 2 cheaper than one was: realval's MVS pairs within 2 % 0.537
  // against 0.526 for one round (stage 28), 1.29-1.34x the network's time in
  // fp32 and 1.38-1.43x in bf16 (docs/refinement-measurements.md, "Propagation").
  int64_t propagation_rounds = 2;
  int64_t propagation_distance = 32;
  int64_t propagation_levels = 4;
  int64_t propagation_slope_radius = 8;
  // 1: propagation runs at full resolution, after the search. 2 or 4: it
  // runs first, on images averaged over scale x scale blocks (a search and
  // propagation at that resolution, distances and radii scaled with it, a
  // quarter or a sixteenth of the pixels); where its surface correlates
  // better at full resolution than the network's, the full-resolution search
  // starts from it. 2 by default: realval's 21 MVS pairs within 2 % 0.509
  // against 0.463 for the search alone, in about the search's old time
  // (docs/refinement-measurements.md, "Propagation").
  int64_t propagation_scale = 2;
  // With propagation_scale 2 or 4: rounds of propagation at full resolution
  // after the full-resolution search, with full_resolution_levels jumps from
  // propagation_distance / propagation_scale pixels (16 by default; 16 and
  // 8 with two levels) and slopes over (2 propagation_slope_radius + 1)^2
  // pixels. The coarse rounds find the surface; this round gives it planes
  // fitted at full resolution: realval's MVS pairs within 2 % 0.554 against
  // 0.537 without it, in 1.30-1.36x the network's time in fp32 and 1.38x in
  // bf16 (three levels: 0.556, but bf16 up to 1.50x; docs/refinement-measurements.md, "A
  // full-resolution round after the coarse ones"). One level since the
  // long-range planes come from four sides (trusted_plane_axis_anchors),
  // which pays for their four candidates: realval 0.603 against 0.604 with
  // two levels, the 20 generated scenes 0.5155 against 0.5152.
  int64_t full_resolution_rounds = 1;
  int64_t full_resolution_levels = 1;
  // The sweep (depth_sweep.h), 0 hypotheses = off: constant inverse depths
  // over the network's range, about sweep_step_pixels apart in the one
  // source chosen at most pixels, at most sweep_hypotheses of them, on the
  // grid where the search starts from the network's depth (the coarse one
  // with propagation_scale 2 or 4). Its smoothed winners are a second start
  // where they correlate better than the network's depth. With it the
  // search's steps fell from 3 to 2 (the time): realval's MVS pairs within
  // 2 % 0.577 against 0.554 before, the 20 generated scenes 0.5050 against
  // 0.5041, in 1.36-1.37x the network's time in fp32 and 1.44-1.47x in
  // bf16, against 1.30-1.36x and 1.38-1.40x (docs/refinement-measurements.md, "The sweep").
  int64_t sweep_hypotheses = 128;
  double sweep_step_pixels = 2.0;
  // Pixels no source sees at the refined depth (nearest_plane.h), 0 = off:
  // the plane of the nearest refined pixel that some source sees at least
  // kUnseenAnchorMargin pixels inside its image, its slopes fitted over the
  // (2 unseen_slope_radius + 1)^2 such pixels around it, extended over them
  // where its inverse depth is within kUnseenMaxChange of the network's
  // (photometric_refinement.h). realval's MVS pairs within 2 % 0.584
  // against 0.581 without, the mean relative error unchanged (docs/refinement-measurements.md,
  // "Fine texture, and pixels no source sees").
  int64_t unseen_slope_radius = 16;
  // Long-range planes (photometric_refinement.h), 0 = off: after the
  // full-resolution propagation every pixel tries the plane of the nearest
  // refined pixel whose NCC is at least this, kept where it correlates
  // better. realval's MVS pairs within 2 % 0.596 against 0.584 without,
  // the 20 generated scenes 0.5093 against 0.5079 (docs/refinement-measurements.md,
  // "Long-range planes").
  double trusted_plane_min_ncc = 0.9;
  // With long-range planes, how many more anchors each pixel tries: 0, the
  // nearest anchor alone; 2, also the nearest on its row to its left and to
  // its right; 4, and on its column above and below. Where the nearest
  // anchor lies on another surface, an anchor on another side of the wrong
  // block lies on the right one. realval's MVS pairs within 2 % 0.604
  // (4) against 0.601 (2) and 0.598 (0), with two full-resolution levels;
  // each costs one more candidate (docs/refinement-measurements.md, "Long-range planes from
  // four sides").
  int64_t trusted_plane_axis_anchors = 4;
  // Local planes (local_planes.h), radius 0 = off: last, every pixel's
  // inverse depth becomes the value at the pixel of the least-squares plane
  // through the pixels of the (2 local_plane_radius + 1)^2 window around it
  // that correlate at NCC >= kLocalPlaneMinNcc, where that value lies within
  // local_plane_max_change (relative) of the pixel's own. The search's
  // per-pixel maxima of a 7x7 window's NCC each carry their own error; the
  // plane through the neighbours averages them out, and the bound keeps it
  // from crossing a depth edge. realval's MVS pairs within
  // 2 % 0.612 against 0.603, their geometric maps 0.490 against 0.440
  // (radius 2, 0.03; docs/refinement-measurements.md, "Local planes").
  int64_t local_plane_radius = 2;
  double local_plane_max_change = 0.03;

  // Throws std::invalid_argument naming the field: radius in [1, 15], window
  // shift in [0, radius], steps
  // in [1, 64], step_pixels in (0, 8], min_ncc in [-1, 1], min_texture >= 0,
  // propagation rounds in [0, 16], distance in [1, 256], levels in [1, 16],
  // slope radius in [1, 64], scale 1, 2 or 4, full-resolution rounds in
  // [0, 16] and levels in [1, 16], sweep hypotheses in [0, 1024] and step
  // pixels in (0, 64], unseen slope radius in [0, 64], trusted plane NCC in
  // [0, 1], trusted plane axis anchors 0, 2 or 4, local plane radius in
  // [0, 16] and max change in (0, 1].
  void Check() const;
};

// The settings of the plane fill after the confidence model
// (confident_plane_fill.h), here for the same reason.
struct ConfidentPlaneFillOptions {
  // Pixels whose confidence (the probability that the depth is within 2 %)
  // is below `below` take the plane of the nearest pixel whose confidence
  // is at least `anchor`, its slopes fitted over the (2 slope_radius + 1)^2
  // such pixels around it; with max_change > 0 only where that plane's
  // inverse depth differs from theirs by at most max_change (relative).
  // below 0 (the default) = off: it is a prior of large planes, which wins
  // on realval's photographs of buildings and rooms (within 2 % 0.626
  // against 0.584 with below 0.5) and loses on the generated scenes of
  // separate objects (0.422 against 0.508; docs/refinement-measurements.md, "Filling from
  // confident planes").
  double below = 0.0;
  double anchor = 0.7;
  int64_t slope_radius = 16;
  double max_change = 0.0;  // 0: any change

  // Throws std::invalid_argument naming the field: below in [0, 1), anchor
  // in (below, 1], slope_radius in [1, 64], max_change >= 0.
  void Check() const;
};

// The refinement mode of a command line: true for "ncc", false for "none";
// throws std::invalid_argument "OPTION must be ncc or none, got 'VALUE'".
bool ParseRefinementMode(const std::string& value, const std::string& option);

}  // namespace dispmvs::model
