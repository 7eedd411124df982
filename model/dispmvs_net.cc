#include "model/dispmvs_net.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "model/convex_upsample.h"
#include "model/correlation.h"
#include "model/geometry.h"
#include "model/segment_correlation.h"
#include "model/stage_timer.h"

namespace dispmvs::model {
namespace {

namespace F = torch::nn::functional;

// A map and the mask of where it holds a value.
struct MaskedMap {
  torch::Tensor value;  // [B,C,H,W], 0 where invalid
  torch::Tensor valid;  // [B,1,H,W] bool
};

// Upsamples a masked map with a linear upsampling operator `up` (convex or
// bilinear) so that invalid pixels do not leak into valid ones: the result is
// up(value * valid) / up(valid), valid where more than half of the
// interpolation weight came from valid pixels. Without the renormalisation an
// invalid neighbour (value 0, i.e. a point at infinity) would drag the
// inverse depth of its valid neighbours towards 0.
template <typename Up>
MaskedMap UpsampleMasked(const MaskedMap& in, Up up) {
  const torch::Tensor valid_f = in.valid.to(in.value.scalar_type());
  const torch::Tensor numerator = up(in.value * valid_f);
  const torch::Tensor weight = up(valid_f);
  MaskedMap out;
  out.valid = weight > 0.5;
  out.value = torch::where(out.valid, numerator / weight.clamp_min(0.5),
                           torch::zeros_like(numerator));
  return out;
}

MaskedMap ConvexUp(const MaskedMap& in, const torch::Tensor& mask_logits, int64_t factor) {
  return UpsampleMasked(in, [&](const torch::Tensor& x) {
    return ConvexUpsample(x, mask_logits, factor);
  });
}

// Bilinear x factor; align_corners=false is exactly the pixel-index
// convention under integer scaling (fine pixel centre (c + 0.5) * f - 0.5).
MaskedMap BilinearUp(const MaskedMap& in, int64_t factor) {
  return UpsampleMasked(in, [&](const torch::Tensor& x) {
    return F::interpolate(x, F::InterpolateFuncOptions()
                                 .size(std::vector<int64_t>{x.size(2) * factor,
                                                            x.size(3) * factor})
                                 .mode(torch::kBilinear)
                                 .align_corners(false));
  });
}

// Bilinear x factor for maps whose cell j sits at output pixel factor * j
// (model v2's strided cells, StridedIntrinsics): output pixel p reads input
// coordinate p / factor; past the last cell the border value is kept.
MaskedMap StridedBilinearUp(const MaskedMap& in, int64_t factor) {
  return UpsampleMasked(in, [&](const torch::Tensor& x) {
    const int64_t h = x.size(2), w = x.size(3);
    const auto coordinates = [&](int64_t size) {
      // Output p -> input p / factor -> grid_sample's (2 u + 1) / size - 1.
      const torch::Tensor u = torch::arange(size * factor, x.options()) / static_cast<double>(factor);
      return (2.0 * u + 1.0) / static_cast<double>(size) - 1.0;
    };
    const auto yx = torch::meshgrid({coordinates(h), coordinates(w)}, "ij");
    const torch::Tensor grid =
        torch::stack({yx[1], yx[0]}, -1).unsqueeze(0).expand({x.size(0), h * factor, w * factor, 2});
    return F::grid_sample(x, grid,
                          F::GridSampleFuncOptions()
                              .mode(torch::kBilinear)
                              .padding_mode(torch::kBorder)
                              .align_corners(false));
  });
}

torch::Tensor Crop(const torch::Tensor& x, int64_t height, int64_t width) {
  return x.narrow(2, 0, height).narrow(3, 0, width);
}

// images [B,V,3,H,W] -> [B*V,3,H',W'] padded bottom/right to multiples of
// `multiple` by replicating the border (pixel-index intrinsics stay valid).
torch::Tensor PadViews(const torch::Tensor& images, int64_t multiple) {
  const int64_t b = images.size(0), v = images.size(1), height = images.size(3), width = images.size(4);
  const int64_t padded_h = (height + multiple - 1) / multiple * multiple;
  const int64_t padded_w = (width + multiple - 1) / multiple * multiple;
  torch::Tensor flat = images.reshape({b * v, 3, height, width});
  if (padded_h == height && padded_w == width) return flat;
  return F::pad(flat, F::PadFuncOptions({0, padded_w - width, 0, padded_h - height})
                          .mode(torch::kReplicate));
}

// [B, ...] -> [B*N, ...], each batch entry repeated for its N sources
// (index b*N + i), matching the layout of the batched source views.
torch::Tensor RepeatPerSource(const torch::Tensor& x, int64_t sources) {
  std::vector<int64_t> expanded{x.size(0), sources};
  std::vector<int64_t> flat{x.size(0) * sources};
  for (int64_t d = 1; d < x.dim(); ++d) {
    expanded.push_back(x.size(d));
    flat.push_back(x.size(d));
  }
  return x.unsqueeze(1).expand(expanded).reshape(flat);
}

void CheckInput(const DispMvsInput& in, bool needs_depth_range) {
  const auto fail = [](const std::string& what) {
    throw std::invalid_argument("DispMvsNet: " + what);
  };
  const torch::Tensor& img = in.images;
  if (!img.defined() || img.dim() != 5 || img.size(0) < 1 || img.size(2) != 3 ||
      img.size(3) < 1 || img.size(4) < 1 || !img.is_floating_point()) {
    fail("images must be a floating-point [B,V,3,H,W] tensor, got " +
         (img.defined() ? c10::str(img.sizes()) : std::string("undefined")));
  }
  const int64_t batch = img.size(0);
  const int64_t views = img.size(1);
  if (views < 2) fail("need a reference and at least one source view, got V = " +
                      std::to_string(views));
  const auto check = [&](const torch::Tensor& t, const char* name,
                         std::vector<int64_t> expected) {
    if (!t.defined() || t.sizes() != torch::IntArrayRef(expected)) {
      fail(std::string(name) + " must be " + c10::str(torch::IntArrayRef(expected)) + ", got " +
           (t.defined() ? c10::str(t.sizes()) : std::string("undefined")));
    }
    if (!torch::isfinite(t).all().item<bool>()) fail(std::string(name) + " has non-finite values");
  };
  check(in.intrinsics, "intrinsics", {batch, views, 3, 3});
  check(in.extrinsics, "extrinsics", {batch, views, 4, 4});
  if (!needs_depth_range && !in.depth_min.defined() && !in.depth_max.defined()) return;
  check(in.depth_min, "depth_min", {batch});
  check(in.depth_max, "depth_max", {batch});
  if (!(in.depth_min > 0).all().item<bool>() ||
      !(in.depth_max > in.depth_min).all().item<bool>()) {
    fail("the depth range must satisfy 0 < depth_min < depth_max");
  }
}

}  // namespace

RelativePoses ReferenceToSourcePoses(const torch::Tensor& extrinsics) {
  if (!extrinsics.defined() || extrinsics.dim() != 4 || extrinsics.size(1) < 2 ||
      extrinsics.size(2) != 4 || extrinsics.size(3) != 4) {
    throw std::invalid_argument(
        "ReferenceToSourcePoses: extrinsics must be [B,V,4,4], V >= 2, got " +
        (extrinsics.defined() ? c10::str(extrinsics.sizes()) : std::string("undefined")));
  }
  const int64_t n = extrinsics.size(1) - 1;
  // X_s = R_s X_w + T_s and X_w = R_r^T (X_r - T_r).
  const torch::Tensor R_all = extrinsics.narrow(2, 0, 3).narrow(3, 0, 3);  // [B,V,3,3]
  const torch::Tensor T_all = extrinsics.narrow(2, 0, 3).select(3, 3);     // [B,V,3]
  const torch::Tensor R_ref = R_all.select(1, 0).unsqueeze(1);              // [B,1,3,3]
  const torch::Tensor T_ref = T_all.select(1, 0).unsqueeze(1);              // [B,1,3]
  RelativePoses poses;
  poses.R = torch::matmul(R_all.narrow(1, 1, n), R_ref.transpose(2, 3));
  poses.T = T_all.narrow(1, 1, n) - torch::matmul(poses.R, T_ref.unsqueeze(-1)).squeeze(-1);
  return poses;
}

namespace {

// Model v2's range-free start: every source's best match along its segment,
// triangulated, fused with log(confidence) as the fusion logit. Pixels where
// no source gives a valid depth start at the median of the valid ones of
// their sample (the whole problem's typical depth; the GRU moves them), or
// at `fallback` [B] when a sample has none at all.
torch::Tensor MatchStart(const EpipolarPair& pair, const SegmentCorrelation& volume, int64_t b,
                         int64_t n, const torch::Tensor& fallback) {
  const EpipolarSegment& segment = volume.segment();
  const SegmentMatch match = volume.BestMatch();
  const int64_t h = match.eflow.size(2), w = match.eflow.size(3);
  const torch::Tensor src_xy = EflowToSourcePixel(segment.base_xy, segment.dir, match.eflow);
  const InverseDepth triangulated = TriangulateInverseDepth(pair, src_xy);
  const torch::Tensor ok = triangulated.valid & match.valid;
  const torch::Tensor logits = torch::log(match.confidence.clamp_min(1e-6));
  const FusedInverseDepth fused = FuseInverseDepths(triangulated.inv_depth.view({b, n, h, w}),
                                                    logits.view({b, n, h, w}), ok.view({b, n, h, w}));
  std::vector<torch::Tensor> typical;
  for (int64_t i = 0; i < b; ++i) {
    const torch::Tensor values = fused.inv_depth[i].masked_select(fused.valid[i]);
    if (values.numel() > 0) {
      typical.push_back(values.median().reshape({1}));
    } else {
      typical.push_back(fallback.defined() ? fallback.narrow(0, i, 1).to(values.options())
                                           : torch::ones({1}, values.options()));
    }
  }
  const torch::Tensor typical_w = torch::cat(typical).view({b, 1, 1, 1});
  return torch::where(fused.valid, fused.inv_depth, typical_w.expand_as(fused.inv_depth)).detach();
}

// What one stage (coarse or fine) runs on.
struct StageInput {
  int64_t batch = 0;
  int64_t sources = 0;
  int64_t stride = 0;          // stage resolution = full / stride
  torch::Tensor ref_features;  // [B,C,h,w]
  torch::Tensor src_features;  // [B*N,C,h,w]
  torch::Tensor context;       // [B,hidden+input,h,w], raw encoder output
  int64_t hidden_channels = 0;
  int64_t levels = 0;
  int64_t samples = 0;
  int64_t iterations = 0;
  // Per (reference, source) pair, [B*N,...], full-resolution intrinsics.
  torch::Tensor K_ref, K_src, R, T;
  // [B,1,h,w], detached, valid everywhere; undefined: start from the best
  // matches along the segments (needs use_segment_volume).
  torch::Tensor init_inv_depth;
  // Model v2: the coarse correlation is the segment volume.
  bool use_segment_volume = false;
  // Feature cells at stride * j (StridedIntrinsics), else at the block
  // centres (ScaleIntrinsics, the paper configuration's convention).
  bool strided_cells = false;
  bool keep_every_iteration = false;
  bool keep_matching = false;  // fill StageResult::matching
  // Fallback start where no source matched, per sample [B] (undefined: 1).
  torch::Tensor hint_inv_depth;
  // The stage's maps are the rows first_row.. of the image's stage grid (a
  // band of the fine stage); 0: all of it.
  int64_t first_row = 0;
  // The sources' correlation pyramid, made once for all bands of a stage
  // (it depends on the sources alone); null: SetUpStage makes it.
  std::shared_ptr<const EpipolarCorrelation> correlation;
};

struct StageResult {
  struct Iteration {
    MaskedMap inv_depth;        // fused, [B,1,h,w]
    torch::Tensor mask_logits;  // [B,9f^2,h,w]; undefined when not kept
  };
  std::vector<Iteration> iterations;
  torch::Tensor state;       // [B,1,h,w] inverse depth carried to the next stage
  torch::Tensor agreement;   // [B,1,h,w] confidence of the last iteration
  std::optional<StageMatching> matching;
  // With keep_matching, in a local (window) stage: every iteration's matched
  // source pixels [B*N,2,h,w], for the flow loss.
  std::vector<torch::Tensor> source_xy;
};

// What stays fixed over a stage's iterations: the epipolar geometry of every
// (reference, source) pair and the correlation, one of two kinds.
struct StageSetup {
  EpipolarPair pair;
  EpipolarDirection direction;
  torch::Tensor ref_features;  // [B*N,C,h,w]: the reference's, once per source
  // Either the segment volume (v2 coarse) or the 2-D sampler (paper, fine).
  std::optional<SegmentCorrelation> volume;
  std::shared_ptr<const EpipolarCorrelation> correlation;
};

// Features of all views [B*V,C,h,w] -> the reference's [B,C,h,w] and the
// sources' [B*N,C,h,w] (index b*N + i, the layout of the pair tensors).
void SplitViews(const torch::Tensor& features, int64_t b, int64_t v, torch::Tensor& ref,
                torch::Tensor& src) {
  const int64_t c = features.size(1), h = features.size(2), w = features.size(3);
  const torch::Tensor views = features.view({b, v, c, h, w});
  ref = views.select(1, 0);
  src = views.narrow(1, 1, v - 1).reshape({b * (v - 1), c, h, w});
}

// The segment volume's matching distribution, for the matching loss.
StageMatching SegmentMatching(int64_t stride, const SegmentCorrelation& volume) {
  return StageMatching{stride,          volume.Logits(),          volume.SampleEflows(),
                       volume.inside(), volume.segment().base_xy, volume.segment().dir};
}

// The first lookup window of a local stage (level 0, one stage pixel apart)
// as a matching distribution, for the matching loss.
StageMatching WindowMatching(const StageInput& in, const StageSetup& setup,
                             const CorrelationSamples& cost, const torch::Tensor& base_xy,
                             const torch::Tensor& eflow) {
  const torch::Tensor level0 = cost.cost.narrow(1, 0, in.samples);
  const torch::Tensor inside = cost.inside.narrow(1, 0, in.samples) & setup.direction.valid;
  const double logit_scale = std::sqrt(static_cast<double>(in.src_features.size(1)));
  const torch::Tensor offsets =
      (torch::arange(in.samples, eflow.options()) - 0.5 * static_cast<double>(in.samples - 1))
          .view({1, in.samples, 1, 1});
  return StageMatching{in.stride,
                       torch::where(inside, level0 * logit_scale,
                                    torch::full_like(level0, kOutsideLogit)),
                       eflow + offsets, inside, base_xy, setup.direction.dir};
}

// The stage's epipolar geometry at its resolution, then its correlation:
// model v2's volume along the whole segments, or the pyramid that the
// iterations sample around their current match.
StageSetup SetUpStage(const StageInput& in, StageTimer* timer) {
  const int64_t h = in.ref_features.size(2), w = in.ref_features.size(3);
  const double scale = static_cast<double>(in.stride);
  const auto stage_intrinsics = [&](const torch::Tensor& K) {
    return in.strided_cells ? StridedIntrinsics(K, scale) : ScaleIntrinsics(K, scale);
  };
  StageSetup setup;
  std::optional<EpipolarSegment> segment;
  {
    const StageTimer::Section geometry(timer, NetStage::kGeometry);
    setup.pair = MakeEpipolarPair(stage_intrinsics(in.K_ref), stage_intrinsics(in.K_src), in.R,
                                  in.T, h, w, in.first_row);
    setup.direction = ComputeEpipolarDirection(setup.pair);
    if (in.use_segment_volume) {
      segment = ComputeEpipolarSegment(setup.pair, in.src_features.size(2), in.src_features.size(3));
    }
  }
  setup.ref_features = RepeatPerSource(in.ref_features, in.sources);
  {
    const StageTimer::Section correlation(timer, NetStage::kCorrelation);
    if (segment) {
      setup.volume.emplace(setup.ref_features, in.src_features, *segment, in.levels, in.samples);
    } else if (in.correlation) {
      setup.correlation = in.correlation;
    } else {
      setup.correlation = std::make_shared<const EpipolarCorrelation>(in.src_features, in.levels, in.samples);
    }
  }
  return setup;
}

// The inverse depth [B,1,h,w] the stage starts from, detached: the given one,
// else model v2's match start.
torch::Tensor StartInverseDepth(const StageInput& in, const StageSetup& setup, StageTimer* timer) {
  if (in.init_inv_depth.defined()) return in.init_inv_depth;
  if (!setup.volume) throw std::logic_error("DispMvsNet: a match start needs the segment volume");
  const StageTimer::Section geometry(timer, NetStage::kGeometry);
  return MatchStart(setup.pair, *setup.volume, in.batch, in.sources, in.hint_inv_depth);
}

// Every source's E-flow of the fused inverse depth `state`: resetting it from
// the fused depth each iteration keeps the views consistent (the first
// iteration gives exactly 0).
torch::Tensor EflowOf(const StageInput& in, const StageSetup& setup, const torch::Tensor& base_xy,
                      const torch::Tensor& state, StageTimer* timer) {
  const StageTimer::Section geometry(timer, NetStage::kGeometry);
  return SourcePixelToEflow(base_xy, setup.direction.dir,
                            ProjectInverseDepth(setup.pair, RepeatPerSource(state, in.sources)).xy);
}

CorrelationSamples LookUpCost(const StageSetup& setup, const torch::Tensor& base_xy,
                              const torch::Tensor& eflow, StageTimer* timer) {
  const StageTimer::Section correlation(timer, NetStage::kCorrelation);
  const torch::Tensor& dir = setup.direction.dir;
  return setup.volume ? setup.volume->Lookup(EflowToSourcePixel(base_xy, dir, eflow))
                      : setup.correlation->Lookup(setup.ref_features, base_xy, dir, eflow);
}

// Every source's match moved by the GRU's step, triangulated, and fused over
// the sources.
struct Triangulation {
  torch::Tensor src_xy;     // [B*N,2,h,w] the matched source pixels (stage pixels)
  InverseDepth per_source;  // [B*N,1,h,w]
  FusedInverseDepth fused;  // [B,1,h,w]
};
Triangulation TriangulateAndFuse(const StageInput& in, const StageSetup& setup,
                                 const torch::Tensor& base_xy, const torch::Tensor& eflow,
                                 const UpdateBlockOutput& update, StageTimer* timer) {
  const int64_t b = in.batch, n = in.sources;
  const int64_t h = base_xy.size(2), w = base_xy.size(3);
  const StageTimer::Section geometry(timer, NetStage::kGeometry);
  const torch::Tensor src_xy =
      EflowToSourcePixel(base_xy, setup.direction.dir, eflow + update.delta_eflow);
  Triangulation out;
  out.src_xy = src_xy;
  out.per_source = TriangulateInverseDepth(setup.pair, src_xy);
  const torch::Tensor pair_valid = out.per_source.valid & setup.direction.valid;
  out.fused = FuseInverseDepths(out.per_source.inv_depth.view({b, n, h, w}),
                                update.weight_logit.view({b, n, h, w}), pair_valid.view({b, n, h, w}));
  return out;
}

// The confidence output: the fusion weight of the sources that agree with
// the fused inverse depth `fused_w` [B,1,h,w]. A diagnostic, not trained: no
// gradient.
torch::Tensor SourceAgreement(const Triangulation& t, const torch::Tensor& fused_w) {
  const torch::Tensor per_source = t.per_source.inv_depth.view(t.fused.weights.sizes());
  const torch::Tensor agrees =
      (per_source - fused_w).abs() <= DispMvsNetImpl::kAgreementTolerance * fused_w.abs();
  return (t.fused.weights.detach() * agrees.to(t.fused.weights.scalar_type()))
      .sum(1, /*keepdim=*/true);
}

// The matching encoder on padded images [B',3,H',W'], one image at a time:
// in inference the encoder's full-resolution intermediate maps would
// otherwise grow with the number of views, and per-image encoding is what
// DispMvsNetImpl::EncodeMatching caches (instance norm is per image, so the
// features are those of a batched pass, up to the last bits).
FeaturePyramid EncodeOneByOne(MatchingEncoder& encoder, const torch::Tensor& padded) {
  std::vector<torch::Tensor> coarse, fine;
  for (int64_t i = 0; i < padded.size(0); ++i) {
    const FeaturePyramid one = encoder->forward(padded.narrow(0, i, 1));
    coarse.push_back(one.coarse);
    fine.push_back(one.fine);
  }
  return {torch::cat(coarse, 0), torch::cat(fine, 0)};
}

// `padded` [B',3,H',W']: padded images of the batch's references at least
// (for the size, device and type); `views` = B*V.
void CheckMatchingFeatures(const FeaturePyramid& features, int64_t views, const torch::Tensor& padded,
                           const ModelConfig& config) {
  const int64_t height = padded.size(2), width = padded.size(3);
  auto check = [&](const torch::Tensor& t, int64_t channels, int64_t stride, const char* name) {
    if (!t.defined() || t.dim() != 4 || t.size(0) != views || t.size(1) != channels ||
        t.size(2) != height / stride || t.size(3) != width / stride ||
        t.device() != padded.device() || t.scalar_type() != padded.scalar_type()) {
      throw std::invalid_argument(
          std::string("DispMvsNet: matching_features.") + name + " must be [" +
          std::to_string(views) + "," + std::to_string(channels) + "," +
          std::to_string(height / stride) + "," + std::to_string(width / stride) +
          "] on the images' device and type, got " +
          (t.defined() ? c10::str(t.sizes()) : std::string("undefined")));
    }
  };
  check(features.coarse, config.match_coarse_channels, DispMvsNetImpl::kCoarseStride, "coarse");
  check(features.fine, config.match_fine_channels, DispMvsNetImpl::kFineStride, "fine");
}

// One stage: `in.iterations` GRU updates of every source's E-flow, each
// followed by triangulation and fusion (the header's outline).
StageResult RunStage(const StageInput& in, UpdateBlock& block, StageTimer* timer) {
  const int64_t b = in.batch, n = in.sources, hid = in.hidden_channels;
  const int64_t h = in.ref_features.size(2), w = in.ref_features.size(3);
  if (in.context.size(1) <= hid) {
    throw std::runtime_error("DispMvsNet: context encoder returned too few channels");
  }
  const StageSetup setup = SetUpStage(in, timer);

  // Context: the initial hidden state (tanh), one copy per source pair, and
  // the GRU's input (relu), whose share of the gates is the same for every
  // source and iteration: computed once per reference here.
  torch::Tensor hidden = RepeatPerSource(torch::tanh(in.context.narrow(1, 0, hid)), n);
  torch::Tensor context_terms;
  {
    const StageTimer::Section gru(timer, NetStage::kUpdate);
    context_terms =
        block->ContextTerms(torch::relu(in.context.narrow(1, hid, in.context.size(1) - hid)));
  }

  torch::Tensor state = StartInverseDepth(in, setup, timer);  // [B,1,h,w], detached
  StageResult result;
  if (in.keep_matching && setup.volume) result.matching = SegmentMatching(in.stride, *setup.volume);
  // Base point and direction are fixed for the whole stage; the E-flow is the
  // offset from the base (docs/method.md, section 4 "E-flow").
  torch::Tensor base_xy;
  {
    const StageTimer::Section geometry(timer, NetStage::kGeometry);
    base_xy = ProjectInverseDepth(setup.pair, RepeatPerSource(state, n)).xy;
  }

  for (int64_t t = 0; t < in.iterations; ++t) {
    const bool last = t + 1 == in.iterations;
    const torch::Tensor eflow = EflowOf(in, setup, base_xy, state, timer);
    const CorrelationSamples cost = LookUpCost(setup, base_xy, eflow, timer);
    if (in.keep_matching && !setup.volume && t == 0) {
      result.matching = WindowMatching(in, setup, cost, base_xy, eflow);
    }
    UpdateBlockOutput update;
    {
      const StageTimer::Section gru(timer, NetStage::kUpdate);
      // Inference on the CPU runs the block on a few (reference, source)
      // pairs at a time: its intermediate maps would otherwise make up most
      // of the peak memory at large sizes. Training keeps one call (autograd
      // holds the intermediates anyway), and so does a GPU, which has the
      // memory and wants the larger kernels.
      update = torch::GradMode::is_enabled() || hidden.is_cuda()
                   ? block->forward(hidden, context_terms, cost.cost, eflow)
                   : UpdateInChunks(block, hidden, context_terms, cost.cost, eflow,
                                    kInferenceUpdatePixelsPerCall);
    }
    hidden = update.hidden;
    const Triangulation triangulation = TriangulateAndFuse(in, setup, base_xy, eflow, update, timer);
    const FusedInverseDepth& fused = triangulation.fused;
    if (in.keep_matching && !setup.volume) result.source_xy.push_back(triangulation.src_xy);

    StageResult::Iteration it;
    it.inv_depth.valid = fused.valid;
    it.inv_depth.value =
        torch::where(fused.valid, fused.inv_depth, torch::zeros_like(fused.inv_depth));
    if (in.keep_every_iteration || last) {
      // One mask per reference pixel, from the hidden state averaged over
      // the sources.
      const StageTimer::Section mask_head(timer, NetStage::kUpdate);
      it.mask_logits = block->MaskLogits(hidden.view({b, n, hid, h, w}).mean(1));
    }
    if (last) result.agreement = SourceAgreement(triangulation, it.inv_depth.value);
    result.iterations.push_back(it);
    // Invalid pixels keep their previous inverse depth; detach as the
    // release does, so each iteration learns its own step.
    state = torch::where(fused.valid, fused.inv_depth, state).detach();
  }
  result.state = state;
  return result;
}

// What both stages share: the batch layout, the cameras of every
// (reference, source) pair flattened to [B*N,...], and the flags.
StageInput SharedStageInput(const DispMvsInput& input, bool v2, bool training, StageTimer* timer) {
  const torch::TensorOptions opts = input.images.options();
  const int64_t b = input.images.size(0), n = input.images.size(1) - 1;
  const torch::Tensor K = input.intrinsics.to(opts);
  RelativePoses poses;
  {
    const StageTimer::Section geometry(timer, NetStage::kGeometry);
    poses = ReferenceToSourcePoses(input.extrinsics.to(opts));
  }
  StageInput stage;
  stage.batch = b;
  stage.sources = n;
  stage.K_ref = RepeatPerSource(K.select(1, 0), n);
  stage.K_src = K.narrow(1, 1, n).reshape({b * n, 3, 3});
  stage.R = poses.R.reshape({b * n, 3, 3});
  stage.T = poses.T.reshape({b * n, 3});
  stage.keep_every_iteration = training;
  stage.strided_cells = v2;
  stage.keep_matching = v2 && training;
  if (input.depth_min.defined()) {
    // The geometric mean of the hint's ends: used only where no source
    // matched anywhere in a sample.
    stage.hint_inv_depth = (input.depth_min.to(opts) * input.depth_max.to(opts)).rsqrt();
  }
  return stage;
}

// What sets a stage apart: its resolution and its sizes in the ModelConfig.
struct StageSizes {
  int64_t stride = 0;
  int64_t hidden_channels = 0;
  int64_t levels = 0;
  int64_t samples = 0;
  int64_t iterations = 0;
};

// The shared input completed for one stage: the stage's features of all
// views [B*V,C,h,w] and the reference's raw context.
StageInput ForStage(const StageInput& shared, const StageSizes& sizes, const torch::Tensor& features,
                    const torch::Tensor& context) {
  StageInput stage = shared;
  stage.stride = sizes.stride;
  stage.hidden_channels = sizes.hidden_channels;
  stage.levels = sizes.levels;
  stage.samples = sizes.samples;
  stage.iterations = sizes.iterations;
  SplitViews(features, shared.batch, shared.sources + 1, stage.ref_features, stage.src_features);
  stage.context = context;
  return stage;
}

// The last fine iteration's maps at full resolution (not cropped): the
// fused inverse depth (0 where invalid), its validity, the depth and the
// confidence, all [B,1,4h,4w].
struct FinalMaps {
  torch::Tensor inv_depth, valid, depth, confidence;
};
FinalMaps UpsampleFinal(const MaskedMap& last, const torch::Tensor& mask_logits,
                        const torch::Tensor& agreement) {
  constexpr int64_t f = DispMvsNetImpl::kUpsampleFactor;
  const MaskedMap final_map = ConvexUp(last, mask_logits, f);
  FinalMaps out;
  out.valid = final_map.valid;
  out.inv_depth = torch::where(out.valid, final_map.value, torch::zeros({}, final_map.value.options()));
  out.depth = torch::where(out.valid, 1.0 / torch::where(out.valid, out.inv_depth, torch::ones_like(out.inv_depth)),
                           torch::zeros_like(out.inv_depth));
  const MaskedMap confidence = ConvexUp(
      MaskedMap{torch::where(last.valid, agreement, torch::zeros_like(agreement)), last.valid}, mask_logits, f);
  out.confidence = torch::where(out.valid, confidence.value.clamp(0.0, 1.0), torch::zeros_like(out.inv_depth));
  return out;
}

// The outputs at full resolution (cropped back to height x width) from both
// stages' iterations: every iteration in training mode (for SequenceLoss),
// else the last one only.
DispMvsOutput FullResolutionOutputs(const StageResult& coarse, const StageResult& fine, bool v2,
                                    bool every_iteration, int64_t height, int64_t width,
                                    const torch::TensorOptions& opts) {
  constexpr int64_t f = DispMvsNetImpl::kUpsampleFactor;
  const auto finish = [&](const MaskedMap& full) {
    return torch::where(Crop(full.valid, height, width), Crop(full.value, height, width),
                        torch::zeros({}, opts));
  };
  DispMvsOutput out;
  if (coarse.matching) out.matching.push_back(*coarse.matching);
  if (fine.matching) out.matching.push_back(*fine.matching);
  out.fine_source_xy = fine.source_xy;
  if (every_iteration) {
    // Coarse maps are two upsamplings away from full resolution: convex to
    // 1/4, then bilinear (on model v2's strided cells, or block centres).
    for (const auto& it : coarse.iterations) {
      const MaskedMap quarter = ConvexUp(it.inv_depth, it.mask_logits, f);
      out.inv_depths.push_back(finish(v2 ? StridedBilinearUp(quarter, f) : BilinearUp(quarter, f)));
    }
    for (size_t i = 0; i + 1 < fine.iterations.size(); ++i) {
      const auto& it = fine.iterations[i];
      out.inv_depths.push_back(finish(ConvexUp(it.inv_depth, it.mask_logits, f)));
    }
  }
  const auto& last = fine.iterations.back();
  const FinalMaps final_maps = UpsampleFinal(last.inv_depth, last.mask_logits, fine.agreement);
  out.valid = Crop(final_maps.valid, height, width);
  out.inv_depths.push_back(Crop(final_maps.inv_depth, height, width));
  out.depth = Crop(final_maps.depth, height, width);
  out.confidence = Crop(final_maps.confidence, height, width);
  return out;
}

// Fine-stage cells on either side of a band that its inner rows depend on,
// for `iterations` GRU updates: each update reads its input state up to 11
// cells away (motion encoder 5, separable GRU 4, heads 2), the context
// terms 2 more, the mask head and the convex upsampling 1 each; 1 spare.
int64_t FineBandHalo(int64_t iterations) { return 11 * iterations + 5; }

// Inference: the fine stage and the final upsampling in bands of rows of the
// fine grid, `band_rows` at a time, each run on its rows plus
// FineBandHalo() rows on either side (the reference's features, context and
// start narrowed, its epipolar geometry computed for those rows) and keeping
// its own rows. The stage's maps then never exist for the whole image: at
// 24 megapixels and four sources they would be about 8 GB. Outputs as
// FullResolutionOutputs gives them in eval mode (cropped to height x width);
// they agree with the whole-image pass to float rounding (the same
// arithmetic on the same values; convolutions of maps of another height may
// round differently), which dispmvs_net_test checks.
DispMvsOutput FineStageInBands(const StageInput& fine, UpdateBlock& block, int64_t band_rows,
                               int64_t height, int64_t width, StageTimer* timer) {
  constexpr int64_t f = DispMvsNetImpl::kUpsampleFactor;
  const int64_t h = fine.ref_features.size(2);
  const int64_t halo = FineBandHalo(fine.iterations);
  const torch::TensorOptions opts = fine.ref_features.options();
  const int64_t b = fine.batch;
  // The sources' pyramid (on the CPU also a channels-last copy of every
  // level, 1.4 GB at 24 megapixels) once, not once per band.
  StageInput shared = fine;
  {
    const StageTimer::Section correlation(timer, NetStage::kCorrelation);
    shared.correlation = std::make_shared<const EpipolarCorrelation>(fine.src_features, fine.levels, fine.samples);
  }
  DispMvsOutput out;
  torch::Tensor inv_depth = torch::zeros({b, 1, height, width}, opts);
  out.valid = torch::zeros({b, 1, height, width}, opts.dtype(torch::kBool));
  out.depth = torch::zeros({b, 1, height, width}, opts);
  out.confidence = torch::zeros({b, 1, height, width}, opts);
  for (int64_t r0 = 0; r0 < h; r0 += band_rows) {
    const int64_t r1 = std::min(h, r0 + band_rows);
    const int64_t lo = std::max<int64_t>(0, r0 - halo), hi = std::min(h, r1 + halo);
    StageInput band = shared;
    band.ref_features = fine.ref_features.narrow(2, lo, hi - lo);
    band.context = fine.context.narrow(2, lo, hi - lo);
    band.init_inv_depth = fine.init_inv_depth.narrow(2, lo, hi - lo);
    band.first_row = lo;  // the same cameras, the band's pixel coordinates
    const StageResult result = RunStage(band, block, timer);

    // The band's rows and one more on either side (the convex upsampling's
    // 3x3 neighbourhood), upsampled; their own full-resolution rows kept.
    const StageTimer::Section upsampling(timer, NetStage::kUpsampling);
    const int64_t k0 = std::max<int64_t>(0, r0 - 1), k1 = std::min(h, r1 + 1);
    const auto keep = [&](const torch::Tensor& x) { return x.narrow(2, k0 - lo, k1 - k0); };
    const auto& last = result.iterations.back();
    const FinalMaps maps = UpsampleFinal(MaskedMap{keep(last.inv_depth.value), keep(last.inv_depth.valid)},
                                         keep(last.mask_logits), keep(result.agreement));
    const int64_t first = f * r0, rows = std::min(f * r1, height) - first;
    if (rows <= 0) continue;  // padding rows only
    const auto own = [&](const torch::Tensor& x) {
      return x.narrow(2, first - f * k0, rows).narrow(3, 0, width);
    };
    inv_depth.narrow(2, first, rows).copy_(own(maps.inv_depth));
    out.valid.narrow(2, first, rows).copy_(own(maps.valid));
    out.depth.narrow(2, first, rows).copy_(own(maps.depth));
    out.confidence.narrow(2, first, rows).copy_(own(maps.confidence));
  }
  out.inv_depths.push_back(inv_depth);
  return out;
}

}  // namespace

DispMvsNetImpl::DispMvsNetImpl(const ModelConfig& config) : config_(config) {
  config_.Check();
  if (config_.coarse_iterations < 1 || config_.fine_iterations < 1) {
    throw std::invalid_argument("DispMvsNet: each stage needs at least one iteration");
  }
  matching_encoder_ = register_module("matching_encoder", MatchingEncoder(config_));
  context_encoder_ = register_module("context_encoder", ContextEncoder(config_));
  coarse_block_ = register_module(
      "coarse_update",
      UpdateBlock(config_.coarse_levels * config_.coarse_samples, config_.hidden_coarse,
                  config_.context_input_coarse, kUpsampleFactor));
  fine_block_ = register_module(
      "fine_update", UpdateBlock(config_.fine_levels * config_.fine_samples, config_.hidden_fine,
                                 config_.context_input_fine, kUpsampleFactor));
}

DispMvsOutput DispMvsNetImpl::forward(const DispMvsInput& input, torch::Generator gen) {
  CheckInput(input, config_.NeedsDepthRange());
  const bool v2 = config_.init == ModelConfig::Init::kMatch;
  const torch::TensorOptions opts = input.images.options();
  const int64_t b = input.images.size(0), v = input.images.size(1);
  StageTimer* const timer = stage_timer_;

  // Given the matching features, only the references are encoded here (by
  // the context encoder), so only they are padded: at 24 megapixels a padded
  // copy of five views would be 1.4 GB.
  const bool features_given = input.matching_features.coarse.defined();
  const int64_t padded_views = features_given ? 1 : v;
  const torch::Tensor images = PadViews(input.images.narrow(1, 0, padded_views), kCoarseStride);
  FeaturePyramid matching, context;
  {
    const StageTimer::Section encoders(timer, NetStage::kEncoders);
    if (features_given) {
      CheckMatchingFeatures(input.matching_features, b * v, images, config_);
      matching = input.matching_features;
    } else if (!torch::GradMode::is_enabled()) {
      matching = EncodeOneByOne(matching_encoder_, images);
    } else {
      matching = matching_encoder_->forward(images);
    }
    context = context_encoder_->forward(
        images.view({b, padded_views, 3, images.size(2), images.size(3)}).select(1, 0));
  }
  const StageInput shared = SharedStageInput(input, v2, is_training(), timer);

  // Coarse stage (1/16): model v2 matches along the whole epipolar segments;
  // the paper's design starts from a random inverse depth inside the hint.
  StageInput coarse_input =
      ForStage(shared,
               {kCoarseStride, config_.hidden_coarse, config_.coarse_levels, config_.coarse_samples,
                config_.coarse_iterations},
               matching.coarse, context.coarse);
  coarse_input.use_segment_volume = v2;
  if (!v2) {
    const StageTimer::Section geometry(timer, NetStage::kGeometry);
    const torch::Tensor d_min = input.depth_min.to(opts), d_max = input.depth_max.to(opts);
    coarse_input.init_inv_depth =
        RandomInverseDepth(d_min, d_max, coarse_input.ref_features.size(2),
                           coarse_input.ref_features.size(3), gen)
            .to(opts)
            .detach();
  }
  const StageResult coarse = RunStage(coarse_input, coarse_block_, timer);

  // Fine stage (1/4), from the convex-upsampled coarse state.
  StageInput fine_input = ForStage(shared,
                                   {kFineStride, config_.hidden_fine, config_.fine_levels,
                                    config_.fine_samples, config_.fine_iterations},
                                   matching.fine, context.fine);
  {
    const StageTimer::Section upsampling(timer, NetStage::kUpsampling);
    fine_input.init_inv_depth =
        ConvexUpsample(coarse.state, coarse.iterations.back().mask_logits, kUpsampleFactor).detach();
  }
  const int64_t fine_rows = fine_input.ref_features.size(2), fine_cols = fine_input.ref_features.size(3);
  const int64_t halo = FineBandHalo(fine_input.iterations);
  // Band rows: as many as fit in fine_band_pixels_ with their halo, at least
  // as many as the halo (fewer would spend more on halos than on bands).
  const int64_t band_rows =
      std::max(halo, fine_band_pixels_ / (kFineStride * kFineStride) / std::max<int64_t>(fine_cols, 1) - 2 * halo);
  if (fine_band_pixels_ > 0 && !is_training() && !torch::GradMode::is_enabled() && band_rows < fine_rows) {
    return FineStageInBands(fine_input, fine_block_, band_rows, input.images.size(3), input.images.size(4),
                            timer);
  }
  const StageResult fine = RunStage(fine_input, fine_block_, timer);

  const StageTimer::Section upsampling(timer, NetStage::kUpsampling);
  return FullResolutionOutputs(coarse, fine, v2, is_training(), input.images.size(3),
                               input.images.size(4), opts);
}

FeaturePyramid DispMvsNetImpl::EncodeMatching(const torch::Tensor& images) {
  if (!images.defined() || images.dim() != 4 || images.size(1) != 3 || images.size(0) < 1) {
    throw std::invalid_argument("DispMvsNet::EncodeMatching: images must be [B,3,H,W]");
  }
  const torch::NoGradGuard no_grad;
  return EncodeOneByOne(matching_encoder_, PadViews(images.unsqueeze(1), kCoarseStride));
}

void DispMvsNetImpl::set_iterations(int64_t coarse, int64_t fine) {
  if (coarse < 1 || fine < 1) {
    throw std::invalid_argument("DispMvsNet: each stage needs at least one iteration");
  }
  config_.coarse_iterations = coarse;
  config_.fine_iterations = fine;
}

void DispMvsNetImpl::set_fine_band_pixels(int64_t pixels) {
  if (pixels < 0) throw std::invalid_argument("DispMvsNet: fine_band_pixels must be >= 0");
  fine_band_pixels_ = pixels;
}

void DispMvsNetImpl::set_precision(Precision precision) {
  coarse_block_->set_precision(precision);
  fine_block_->set_precision(precision);
}

StageMatching DispMvsNetImpl::CoarseMatching(const DispMvsInput& input) {
  CheckInput(input, /*needs_depth_range=*/false);
  const torch::TensorOptions opts = input.images.options();
  const int64_t b = input.images.size(0), v = input.images.size(1), n = v - 1;
  const torch::Tensor images = PadViews(input.images, kCoarseStride);
  const torch::Tensor coarse = matching_encoder_->forward(images).coarse;
  const int64_t h = coarse.size(2), w = coarse.size(3);
  torch::Tensor ref, src;
  SplitViews(coarse, b, v, ref, src);
  const torch::Tensor K = input.intrinsics.to(opts);
  const RelativePoses poses = ReferenceToSourcePoses(input.extrinsics.to(opts));
  const double stride = static_cast<double>(kCoarseStride);
  const EpipolarPair pair =
      MakeEpipolarPair(StridedIntrinsics(RepeatPerSource(K.select(1, 0), n), stride),
                       StridedIntrinsics(K.narrow(1, 1, n).reshape({b * n, 3, 3}), stride),
                       poses.R.reshape({b * n, 3, 3}), poses.T.reshape({b * n, 3}), h, w);
  const SegmentCorrelation volume(RepeatPerSource(ref, n), src, ComputeEpipolarSegment(pair, h, w),
                                  config_.coarse_levels, config_.coarse_samples);
  return SegmentMatching(kCoarseStride, volume);
}

}  // namespace dispmvs::model
