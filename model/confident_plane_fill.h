#pragma once
// After the confidence model (confidence_model.h): pixels with little chance
// of being right take the plane of the nearest confident pixel
// (nearest_plane.h).
//
// Why: where the photometric refinement could not confirm a depth (weak
// texture, a source that sees another surface there, no window inside a
// source), the depth is the network's guess, or a match on the wrong
// surface, and the confidence model says so (it predicts the probability
// that a pixel is within 2 %, from the network's confidence, the NCC at the
// output depth and the texture). Most such pixels lie on a surface that
// continues from confident pixels nearby in photographs of buildings and
// rooms; the nearest confident pixel's plane is exact over a planar
// continuation. Not where surfaces are small and separate: off by default
// (ConfidentPlaneFillOptions; docs/refinement-measurements.md, "Filling from confident
// planes"). The confidence map itself is left as it was: a filled pixel
// keeps its low confidence, so that fusion and the geometric filter still
// treat it as a guess.
//
// depth [B,1,H,W] (0: none), confidence [B,1,H,W] in [0, 1]. Pixels without
// depth stay without. A filled pixel's inverse depth is kept within the
// inverse depths of the map's own pixels. Runs on any device (the nearest
// confident pixel is found on the CPU).

#include <torch/torch.h>

#include "model/photometric_refinement_options.h"

namespace dispmvs::model {

struct ConfidentPlaneFill {
  torch::Tensor depth;   // [B,1,H,W]
  torch::Tensor filled;  // [B,1,H,W] bool: where the depth was replaced
};

// Throws std::invalid_argument on mismatched shapes or bad options.
ConfidentPlaneFill FillFromConfidentPlanes(const torch::Tensor& depth, const torch::Tensor& confidence,
                                           const ConfidentPlaneFillOptions& options);

}  // namespace dispmvs::model
