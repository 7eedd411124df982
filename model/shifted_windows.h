#pragma once
// Shifted windows (photometric_refinement.h, options.window_shift): a
// pixel's score for a surface is the best of the windows around it that
// contain it, not only the one centred on it.
//
// Why: the refinement scores a surface at a pixel by the NCC of the
// (2r+1)^2 window centred there (surface_ncc.h). Where that window
// straddles a depth edge, or takes in a patch the source renders
// differently, it correlates poorly at the pixel's true depth, and a wrong
// surface can win. A window shifted by a few pixels still contains the
// pixel and may lie on its own surface alone. Scoring every hypothesis by
// the best of five windows (centred, and shifted left, right, up, down)
// lets the right surface win there; realval's 21 MVS pairs within 2 %
// 0.626 against 0.612 (docs/refinement-measurements.md, "Shifted windows").

#include <cstdint>

#include <torch/torch.h>

namespace dispmvs::model {

// At every pixel p of `score` ([B,1,H,W] float), the largest of score at p
// and at p + (shift, 0), p - (shift, 0), p + (0, shift), p - (0, shift),
// of those inside the image; score itself (not a copy) at shift 0. The
// value at p + o is the score of the window centred there, which contains p
// while shift is at most the window's radius. One loop on CPU float
// tensors, LibTorch operations elsewhere. Throws std::invalid_argument unless score
// is [B,1,H,W] floating point and shift >= 0.
torch::Tensor BestOfShiftedWindows(const torch::Tensor& score, int64_t shift);

// The same by LibTorch operations on any device (the same values).
torch::Tensor BestOfShiftedWindowsByOps(const torch::Tensor& score, int64_t shift);

}  // namespace dispmvs::model
