#include "train/error_breakdown.h"

#include <algorithm>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "model/geometry.h"
#include "model/matching_loss.h"
#include "model/photometric_refinement.h"
#include "train/batch.h"
#include "train/validation.h"

namespace dispmvs::train {
namespace {

using model::DispMvsNet;
namespace F = torch::nn::functional;

// What one row adds up over the scenes.
struct RowSums {
  ValidationDepthSums depth;
  SourcePixelCounts source_pixels;
};

// Adds the depth and source-pixel sums of `depth` (valid where > 0) over the
// reference pixels with ground truth, or only those of `band` ([1,1,H,W]
// bool) when it is defined.
void AddScores(const TrainingBatch& batch, const torch::Tensor& depth, const torch::Tensor& band,
               RowSums* sums) {
  const torch::Tensor valid = depth > 0;
  torch::Tensor gt_valid = batch.gt_valid, gt_depths = batch.gt_depths;
  if (band.defined()) {
    gt_valid = gt_valid & band;
    // The reference's ground truth outside the band reads "no depth", so that
    // only the band's pixels are looked at from the sources.
    gt_depths = gt_depths.clone();
    gt_depths.select(1, 0).mul_(band.to(gt_depths.dtype()));
  }
  sums->depth += SumValidationDepth(depth, valid, batch.gt_depth, gt_valid);
  sums->source_pixels += CountSourcePixels(gt_depths, batch.input.intrinsics,
                                           batch.input.extrinsics, depth, valid);
}

// Depth from the network's inverse depth, 0 where it has none.
torch::Tensor DepthOf(const torch::Tensor& inv_depth) {
  return torch::where(inv_depth > 0, inv_depth.reciprocal(), torch::zeros_like(inv_depth));
}

// Local texture of the reference image: the magnitude of the grey image's
// gradient (central differences), averaged over 5x5 pixels. [1,1,H,W].
torch::Tensor LocalTexture(const torch::Tensor& images) {
  const torch::Tensor grey = images.select(1, 0).mean(1, /*keepdim=*/true).to(torch::kFloat);
  const torch::Tensor padded = F::pad(grey, F::PadFuncOptions({1, 1, 1, 1}).mode(torch::kReplicate));
  using torch::indexing::Slice;
  const torch::Tensor gx = (padded.index({Slice(), Slice(), Slice(1, -1), Slice(2, torch::indexing::None)}) -
                            padded.index({Slice(), Slice(), Slice(1, -1), Slice(0, -2)})) / 2;
  const torch::Tensor gy = (padded.index({Slice(), Slice(), Slice(2, torch::indexing::None), Slice(1, -1)}) -
                            padded.index({Slice(), Slice(), Slice(0, -2), Slice(1, -1)})) / 2;
  const torch::Tensor magnitude = (gx * gx + gy * gy).sqrt();
  return F::avg_pool2d(magnitude, F::AvgPool2dFuncOptions(5).stride(1).padding(2)
                                      .count_include_pad(false));
}

// Thirds of `value` over the pixels of `mask`: three [1,1,H,W] bool masks,
// lowest values first (empty when the mask is).
std::vector<torch::Tensor> Thirds(const torch::Tensor& value, const torch::Tensor& mask) {
  const torch::Tensor values = value.masked_select(mask).to(torch::kDouble);
  if (values.numel() == 0) return {mask, mask, mask};  // all false
  const torch::Tensor cuts =
      torch::quantile(values, torch::tensor({1.0 / 3, 2.0 / 3}, values.options()));
  const double low = cuts[0].item<double>(), high = cuts[1].item<double>();
  const torch::Tensor v = value.to(torch::kDouble);
  return {mask & (v <= low), mask & (v > low) & (v <= high), mask & (v > high)};
}

// The ground truth's inverse depth, 0 where it has none.
torch::Tensor TrueInverseDepth(const TrainingBatch& batch) {
  return torch::where(batch.gt_valid, batch.gt_depth.reciprocal(), torch::zeros_like(batch.gt_depth));
}

// Every source's true match, triangulated and fused with equal weights by
// the network's geometry, at full resolution: the depth (0 where no source
// triangulates).
torch::Tensor DepthFromTrueMatches(const TrainingBatch& batch) {
  const model::DispMvsInput& input = batch.input;
  const int64_t height = batch.gt_depth.size(2), width = batch.gt_depth.size(3);
  const torch::Tensor true_inverse = TrueInverseDepth(batch);
  const model::RelativePoses poses = model::ReferenceToSourcePoses(input.extrinsics);
  const torch::Tensor K = input.intrinsics.to(true_inverse.dtype());
  std::vector<torch::Tensor> inverse_depths, valid;
  for (int64_t s = 0; s < poses.R.size(1); ++s) {
    const model::EpipolarPair pair =
        model::MakeEpipolarPair(K.select(1, 0), K.select(1, s + 1), poses.R.select(1, s).to(K.dtype()),
                                poses.T.select(1, s).to(K.dtype()), height, width);
    const model::SourcePixels match = model::ProjectInverseDepth(pair, true_inverse);
    const model::InverseDepth triangulated = model::TriangulateInverseDepth(pair, match.xy);
    inverse_depths.push_back(triangulated.inv_depth);
    valid.push_back(triangulated.valid & match.valid & batch.gt_valid);
  }
  const torch::Tensor all = torch::cat(inverse_depths, 1);
  return DepthOf(model::FuseInverseDepths(all, torch::zeros_like(all), torch::cat(valid, 1)).inv_depth);
}

// The true inverse depth at the cells of a stage of `stride` (full-resolution
// pixel (stride*i, stride*j)), upsampled bilinearly back to full resolution
// with the cells where they are (pixel x reads cell x / stride); cells
// without ground truth are left out of the interpolation.
torch::Tensor DepthFromTrueGrid(const TrainingBatch& batch, int64_t stride) {
  using torch::indexing::None;
  using torch::indexing::Slice;
  const torch::Tensor true_inverse = TrueInverseDepth(batch);
  const int64_t height = true_inverse.size(2), width = true_inverse.size(3);
  const torch::Tensor cells =
      true_inverse.index({Slice(), Slice(), Slice(None, None, stride), Slice(None, None, stride)});
  const torch::Tensor known = (cells > 0).to(cells.dtype());
  const int64_t cell_rows = cells.size(2), cell_cols = cells.size(3);
  // align_corners: normalised -1 and 1 are the first and last cells' centres.
  const auto normalised = [&](int64_t count, int64_t cell_count) {
    const torch::Tensor cell = torch::arange(count, cells.options()) / static_cast<double>(stride);
    return cell_count > 1 ? cell * (2.0 / static_cast<double>(cell_count - 1)) - 1.0 : torch::zeros_like(cell);
  };
  const torch::Tensor x = normalised(width, cell_cols).view({1, 1, width}).expand({1, height, width});
  const torch::Tensor y = normalised(height, cell_rows).view({1, height, 1}).expand({1, height, width});
  const torch::Tensor grid = torch::stack({x, y}, -1).expand({cells.size(0), height, width, 2});
  const auto options = F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kBorder)
                           .align_corners(true);
  const torch::Tensor sum = F::grid_sample(cells * known, grid, options);
  const torch::Tensor weight = F::grid_sample(known, grid, options);
  return DepthOf(torch::where(weight > 1e-6, sum / weight.clamp_min(1e-6), torch::zeros_like(sum)));
}

BreakdownRow Finish(const std::string& label, const RowSums& sums) {
  return {label, FinalizeValidation(sums.depth), SharesOf(sums.source_pixels)};
}

// A full-resolution mask [1,1,H,W] at the cells of the coarse volume
// `matching` (cell (i, j) is pixel (stride i, stride j); cells past the
// image, in the network's padding, are false), one copy per source:
// [N,1,h,w], the volume's (pair) layout for a batch of one.
torch::Tensor AtCoarseCells(const torch::Tensor& mask, const model::StageMatching& matching) {
  using torch::indexing::None;
  using torch::indexing::Slice;
  const int64_t stride = matching.stride, sources = matching.logits.size(0);
  const int64_t rows = matching.logits.size(2), cols = matching.logits.size(3);
  const torch::Tensor sampled = mask.index({Slice(), Slice(), Slice(None, None, stride), Slice(None, None, stride)});
  torch::Tensor cells = torch::zeros({1, 1, rows, cols}, mask.options());
  const int64_t r = std::min(rows, sampled.size(2)), c = std::min(cols, sampled.size(3));
  cells.narrow(2, 0, r).narrow(3, 0, c).copy_(sampled.narrow(2, 0, r).narrow(3, 0, c));
  return cells.expand({sources, 1, rows, cols});
}

CoarseMatchRow FinishMatches(const std::string& label, const model::MatchingLossResult& sums) {
  const double pairs = std::max(sums.count, 1.0);
  return {label, sums.top1 / pairs, sums.top2_peaks / pairs, sums.top4_peaks / pairs,
          static_cast<int64_t>(sums.count)};
}

}  // namespace

ErrorBreakdown BreakDownErrors(DispMvsNet& net, const std::vector<synth::SynthSample>& scenes,
                               const TrainOptions& options, double widening) {
  internal::CheckHintAvailable(net, widening, "no breakdown without one");
  // config() holds the iterations the passes run with (set_iterations).
  const int64_t coarse_count = net->config().coarse_iterations;
  const size_t iteration_count = static_cast<size_t>(coarse_count + net->config().fine_iterations);
  // Training mode keeps every iteration's output (DispMvsOutput::inv_depths);
  // it changes nothing else in a forward pass. No gradient is needed.
  const bool was_training = net->is_training();
  net->train();
  torch::NoGradGuard no_grad;
  std::vector<RowSums> iterations(iteration_count), texture(3), depth(3), oracles(2);
  RowSums refined;
  // All, then the texture thirds, then the depth thirds.
  std::vector<model::MatchingLossResult> coarse_matches(7);
  for (size_t i = 0; i < scenes.size(); ++i) {
    const TrainingBatch batch = MakeBatch({scenes[i]}, widening);
    // The seeds of the validation table (validation.cc), so the last
    // iteration is that table's output.
    const auto output =
        net->forward(batch.input, internal::CpuGenerator(options.validation_seed_base + i));
    if (output.inv_depths.size() != iteration_count) {
      throw std::logic_error("the network returned another number of iterations than it runs");
    }
    for (size_t k = 0; k < iteration_count; ++k) {
      AddScores(batch, DepthOf(output.inv_depths[k]), torch::Tensor(), &iterations[k]);
    }
    torch::Tensor final_depth = DepthOf(output.inv_depths.back());
    if (options.eval_refinement == "ncc") {
      final_depth =
          model::RefineDepthPhotometrically(batch.input, output, options.eval_refinement_options).depth;
      AddScores(batch, final_depth, torch::Tensor(), &refined);
    }
    const auto texture_bands = Thirds(LocalTexture(batch.input.images), batch.gt_valid);
    const auto depth_bands = Thirds(batch.gt_depth, batch.gt_valid);
    for (size_t b = 0; b < 3; ++b) {
      AddScores(batch, final_depth, texture_bands[b], &texture[b]);
      AddScores(batch, final_depth, depth_bands[b], &depth[b]);
    }
    {
      // The coarse volume as the validation table measures it (eval mode).
      net->eval();
      const model::StageMatching matching = net->CoarseMatching(batch.input);
      net->train();
      const model::GroundTruthMatches truth = model::ComputeGroundTruthMatches(
          batch.gt_depths, batch.input.intrinsics, batch.input.extrinsics, matching.stride,
          matching.logits.size(2), matching.logits.size(3));
      internal::AddMatchCounts(model::MatchingLoss(matching, truth), &coarse_matches[0]);
      for (size_t b = 0; b < 3; ++b) {
        for (const auto& [bands, first] : {std::make_pair(&texture_bands, 1), std::make_pair(&depth_bands, 4)}) {
          model::GroundTruthMatches in_band = truth;
          in_band.valid = truth.valid & AtCoarseCells((*bands)[b], matching);
          internal::AddMatchCounts(model::MatchingLoss(matching, in_band),
                                   &coarse_matches[static_cast<size_t>(first) + b]);
        }
      }
    }
    AddScores(batch, DepthFromTrueMatches(batch), torch::Tensor(), &oracles[0]);
    AddScores(batch, DepthFromTrueGrid(batch, DispMvsNet::Impl::kFineStride), torch::Tensor(), &oracles[1]);
  }
  net->train(was_training);

  ErrorBreakdown breakdown;
  for (int64_t k = 0; k < static_cast<int64_t>(iteration_count); ++k) {
    const std::string label = k < coarse_count ? "coarse " + std::to_string(k + 1)
                                               : "fine " + std::to_string(k - coarse_count + 1);
    breakdown.iterations.push_back(Finish(label, iterations[static_cast<size_t>(k)]));
  }
  if (options.eval_refinement == "ncc") breakdown.iterations.push_back(Finish("refined", refined));
  const char* texture_names[] = {"texture weak", "texture medium", "texture strong"};
  const char* depth_names[] = {"depth near", "depth middle", "depth far"};
  for (int b = 0; b < 3; ++b) {
    breakdown.texture.push_back(Finish(texture_names[b], texture[b]));
    breakdown.depth.push_back(Finish(depth_names[b], depth[b]));
  }
  breakdown.coarse_matches.push_back(FinishMatches("all", coarse_matches[0]));
  for (size_t b = 0; b < 3; ++b) breakdown.coarse_matches.push_back(FinishMatches(texture_names[b], coarse_matches[1 + b]));
  for (size_t b = 0; b < 3; ++b) breakdown.coarse_matches.push_back(FinishMatches(depth_names[b], coarse_matches[4 + b]));
  breakdown.oracles.push_back(Finish("oracle matches", oracles[0]));
  breakdown.oracles.push_back(Finish("oracle 1/4 grid", oracles[1]));
  return breakdown;
}

std::string FormatBreakdown(const ErrorBreakdown& breakdown) {
  std::ostringstream out;
  const auto line = [&out](const BreakdownRow& row) {
    char text[256];
    std::snprintf(text, sizeof text,
                  "%-15s <1%%: %.4f  <2%%: %.4f  <5%%: %.4f  AbsRel: %.4f  coverage: %.4f  |  "
                  "source <1px: %.4f  <2px: %.4f  (%lld GT pixels)\n",
                  row.label.c_str(), row.depth.within_1, row.depth.within_2, row.depth.within_5,
                  row.depth.abs_rel, row.depth.coverage, row.source_pixels.within_1px,
                  row.source_pixels.within_2px, static_cast<long long>(row.depth.gt_pixels));
    out << text;
  };
  out << "after each iteration (fused, upsampled to full resolution; the last is the output):\n";
  for (const BreakdownRow& row : breakdown.iterations) line(row);
  out << "the output by local texture of the reference (gradient, thirds per scene):\n";
  for (const BreakdownRow& row : breakdown.texture) line(row);
  out << "the output by ground-truth depth (thirds per scene):\n";
  for (const BreakdownRow& row : breakdown.depth) line(row);
  out << "coarse matches ((cell, source) pairs with a visible true match, by the cell's pixel's third):\n"
         "right within a 1/16 pixel: the arg-max, one of the 2 / 4 highest peaks along the segment\n";
  for (const CoarseMatchRow& row : breakdown.coarse_matches) {
    char text[192];
    std::snprintf(text, sizeof text, "%-15s top-1: %.4f  2 peaks: %.4f  4 peaks: %.4f  (%lld pairs)\n",
                  row.label.c_str(), row.top1, row.top2_peaks, row.top4_peaks, static_cast<long long>(row.pairs));
    out << text;
  }
  out << "oracles: the true matches through the network's geometry (must be exact); the true depth\n"
         "at the fine stage's cells, upsampled bilinearly (a perfect fine stage, a smooth upsampler):\n";
  for (const BreakdownRow& row : breakdown.oracles) line(row);
  return out.str();
}

}  // namespace dispmvs::train
