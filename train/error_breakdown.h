#pragma once
// Where the depth error comes from, on the validation scenes: the first part
// of the precision diagnosis (dispmvs_train --evaluate W --breakdown).
//
//  * After every GRU iteration, coarse then fine: the fused inverse depth
//    that iteration gives, upsampled to full resolution as the output is,
//    scored like the output (depth within 1 / 2 / 5 %, AbsRel) and seen from
//    the sources (its matches within 1 / 2 source pixels of the true ones,
//    source_pixel_metrics.h). The last row is the output itself. Whether the
//    fine iterations still gain, and how far from sub-pixel matches the
//    last one is, says which stage holds the error.
//    With --eval_refinement ncc (TrainOptions::eval_refinement) one more
//    row, "refined": the output after the photometric refinement
//    (model/photometric_refinement.h), which the splits below then use.
//  * The output split by texture (the reference image's local gradient) and
//    by ground-truth depth, each in thirds per scene: whether the error sits
//    on weak texture (ambiguous matches) or on well-textured surfaces
//    (imprecise matches), near or far.
//  * The coarse matches (the segment volume's, as the validation table's
//    coarse top-1) split by the same texture and depth thirds, taken at each
//    coarse cell's pixel: how often the arg-max, or one of the 2 / 4
//    highest peaks, is within a 1/16 pixel of the true match. Whether wrong
//    coarse matches gather on weak texture, and how many a design that
//    keeps several candidates could recover there.
//  * Two oracles, scored the same way, without the network:
//    - "oracle matches": every source's ground-truth match (the source pixel
//      of the reference's true depth) triangulated and fused with equal
//      weights by the network's own geometry (model/geometry.h). It must
//      score 1 within 1 %: a check of the geometry end to end.
//    - "oracle 1/4 grid": the true inverse depth at the fine stage's cells
//      (full-resolution pixel (4i, 4j), where the network puts them),
//      upsampled bilinearly: what a perfect fine stage would give through a
//      smooth upsampler. How far it is from 1 is the resolution's share of
//      the error; the network's learned upsampler can do better at edges.
//
// The scenes run as in the validation table (same seeds, same
// initialisation), so the last iteration's numbers are that table's row of
// the same depth-range widening.

#include <string>
#include <vector>

#include "model/dispmvs_net.h"
#include "synth/generator.h"
#include "train/source_pixel_metrics.h"
#include "train/trainer.h"
#include "train/validation_metrics.h"

namespace dispmvs::train {

struct BreakdownRow {
  std::string label;                  // "coarse 1", "fine 4", "texture weak", "depth far", ...
  ValidationDepthMetrics depth;       // over the row's ground-truth pixels
  SourcePixelShares source_pixels;    // over the row's (pixel, seeing source) pairs
};

// Shares of the (coarse cell, source) pairs with a visible true match
// (model::MatchingLoss's counts).
struct CoarseMatchRow {
  std::string label;  // "all", "texture weak", ..., "depth far"
  double top1 = 0, top2_peaks = 0, top4_peaks = 0;
  int64_t pairs = 0;
};

struct ErrorBreakdown {
  std::vector<BreakdownRow> iterations;  // coarse 1..Tc, fine 1..Tf
  std::vector<BreakdownRow> texture;     // weak, medium, strong
  std::vector<BreakdownRow> depth;       // near, middle, far
  std::vector<CoarseMatchRow> coarse_matches;  // all, the texture thirds, the depth thirds
  std::vector<BreakdownRow> oracles;     // "oracle matches", "oracle 1/4 grid"
};

// `widening` as in EvaluateWeights (0: no hint). The network's iterations
// and precision are used as set. Throws std::invalid_argument as validation
// does (no hint for weights that need one).
ErrorBreakdown BreakDownErrors(model::DispMvsNet& net, const std::vector<synth::SynthSample>& scenes,
                               const TrainOptions& options, double widening);

// Loads the weights as EvaluateWeights does and breaks down their errors on
// the validation scenes of `options`.
ErrorBreakdown EvaluateErrorBreakdown(const std::string& weights_path, const TrainOptions& options,
                                      double widening);

// A table: one line per row, "label  <1%: ...  <2%: ...  <5%: ...  AbsRel: ...
// coverage: ...  | <1px: ...  <2px: ...", the three groups apart.
std::string FormatBreakdown(const ErrorBreakdown& breakdown);

}  // namespace dispmvs::train
