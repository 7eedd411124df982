#pragma once
// Training DispMVS on generated scenes (synth/), and evaluating weights on a
// fixed validation set.
//
// Samples are generated on the fly; sample j of step s has a seed derived
// from (seed, s, j) alone, and the network's random initialisation at step s
// from (seed, s), so a run is deterministic and can stop and resume anywhere
// with the same result bit for bit (on the CPU, same thread count).
//
// Checkpoint directory layout:
//   checkpoint-<step>.optim.safetensors  Adam moments per parameter, step and
//                                        run settings in the metadata
//   checkpoint-<step>.safetensors        the weights (SaveModuleWeights)
//   weights-<step>.safetensors           with keep_weights_every K: the weights
//                                        of every step that is a multiple of K,
//                                        kept when a newer checkpoint replaces it
//   model.safetensors                    the final weights
//   train.log                            the log lines, appended
// Both checkpoint files are written temp-then-rename; the weights file is
// written last, so a checkpoint counts (for resuming) only once its weights
// file exists. Older checkpoints are removed after a newer one is complete.

#include <cstdint>
#include <ostream>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "model/photometric_refinement_options.h"
#include "train/source_pixel_metrics.h"
#include "train/validation_metrics.h"

namespace dispmvs::train {

// Validation seeds start here; training seeds have the top bit set, so the
// two sets are disjoint whatever the base.
constexpr uint64_t kDefaultValidationSeedBase = 1'000'000'000;

struct TrainOptions {
  // model::ModelConfig: "paper", "small" (the paper's random start) or
  // "paper_v2", "small_v2" (model v2: range-free start from the best match
  // along the epipolar segment, matching loss).
  std::string config = "small";
  int64_t height = 128, width = 160;
  int64_t num_sources = 4;  // N: views per sample = N + 1
  int64_t batch_size = 1;
  int64_t steps = 1000;  // total, counted from step 0 (a resumed run goes on to here)
  double lr = 2e-4;
  int64_t lr_halve_every = 0;  // halve lr every K steps; 0 = constant
  // Linear warm-up over the run's first K steps (from lr / K to lr). A run
  // that starts from --init_weights has fresh Adam moments (checkpoints keep
  // them, shipped weights do not); full-size first steps on those moments
  // can undo what the weights had learned. 0 = off.
  int64_t lr_warmup_steps = 0;
  double grad_clip = 1.0;      // max global gradient norm; 0 = no clipping
  // Depth-range augmentation: each step widens the hint of its samples to
  // (d_min / x, d_max * x) with x log-uniform in [1, train_widening_max], so
  // the network learns not to lean on a tight range (the robustness protocol
  // evaluates x = 2, 3). The loss stays normalised by the unwidened range,
  // so widened steps weigh as much as the others. 1 = off.
  double train_widening_max = 1.0;
  // Real images next to the generated scenes: an MVSNet-format data set
  // (train/mvsnet_dataset.h; empty = generated scenes only). Each training
  // sample comes from it with probability mvsnet_fraction, drawn from the
  // sample's seed, like the reference view it uses; only references with
  // ground-truth depth and >= num_sources sources are drawn. Validation
  // stays on generated scenes, so its numbers stay comparable across runs.
  std::string mvsnet_root;
  double mvsnet_fraction = 1.0;  // in [0, 1]; must stay 1 without mvsnet_root
  // Photographs for photo textures of the generated training scenes
  // (synth/photo_folder.h; empty = procedural textures only): each texture is
  // a photo with photo_probability. Validation stays procedural. A run
  // setting, identified by the folder's path and its files' names and sizes.
  std::string texture_dir;
  double photo_probability = 0.5;
  // Weights to start from instead of the random initialisation (fine-tuning,
  // e.g. at a larger size from the shipped model); empty = random. The file's
  // tensors must fit `config`. A run setting, identified by the file's
  // content (not its path); a resumed run takes the checkpoint's weights.
  std::string init_weights;
  // Model v2 only: weight of the matching loss (cross-entropy of the
  // correlation along the epipolar segment against the ground-truth match,
  // coarse and fine stage; model/matching_loss.h) added to the sequence
  // loss; and the first steps train with the matching loss alone (the
  // features learn to match before the GRU learns to refine).
  double matching_loss_weight = 0.5;
  // The depth loss (model/loss.h): "inverse", the paper's L1 of
  // range-normalised inverse depth, or "log", L1 of log depth (the relative
  // error every pixel alike, which the < 2 % metric counts). A run setting.
  std::string depth_loss = "inverse";
  // Model v2 only: weight of the flow loss (model/matching_loss.h,
  // SourceFlowLoss): every fine iteration's match in every source against
  // the true one, in fine-stage pixels. 0 = off (the paper's losses alone).
  double flow_loss_weight = 0;
  int64_t matching_warmup_steps = 0;
  // Each generated scene serves this many consecutive steps, each time with
  // another of its views as the reference (the others its sources): the
  // ray-casting is paid once for R samples. 1 = a new scene every step.
  int64_t scene_reuse = 1;
  // Source views per step: each step draws one count from this list
  // (uniformly, from the seed and the step) and trains on that many of the
  // sample's num_sources sources, a random subset. Two-view workspaces and
  // references at the end of a sequence are common in practice; a network
  // trained only with num_sources sources rarely sees one. Empty = every
  // step uses all num_sources. Each count in [1, num_sources].
  std::vector<int64_t> source_counts;
  // Per-view photometry of the generated training scenes: "default" (the
  // generator's PhotometryRanges) or "wide" (synth::WidePhotometry: larger
  // exposure, white-balance and tone-curve differences and vignetting, as
  // between real photographs) or "mixed" (each scene one of the two, by its
  // seed). Validation scenes keep the defaults.
  std::string photometry = "default";
  // Rays per pixel along each axis in the generated training scenes
  // (synth::SynthConfig::supersampling, odd, 1 to 7): > 1 renders each
  // pixel as the mean of s x s rays, as a camera integrates light over the
  // pixel, instead of one ray that aliases textures finer than a pixel.
  // Rendering costs about s^2 as much. Validation follows val_supersampling.
  int64_t supersampling = 1;
  // The same for the validation scenes (and EvaluateWeights' table). 1 keeps
  // the table comparable with earlier runs (point-sampled images).
  int64_t val_supersampling = 1;
  // Share of glossy primitives in the generated training scenes
  // (synth::SynthConfig::specular_probability): highlights that move with
  // the viewpoint. Validation keeps matte scenes.
  double specular_probability = 0;
  // JPEG quality range of the generated training scenes' views
  // (synth::SynthConfig::jpeg_quality_min/max, drawn per view, with
  // any photometry setting): both 0 = none. Validation stays uncompressed.
  int64_t jpeg_quality_min = 0, jpeg_quality_max = 0;
  // The generated training scenes' outdoor sky at infinity
  // (synth::SynthConfig::background_at_infinity): no parallax and no depth,
  // so not supervised. Validation keeps the finite sky.
  bool background_at_infinity = false;
  // GRU iterations of the coarse stage in training steps (0 = the config's):
  // cheaper steps; validation and the saved weights keep the config's.
  int64_t train_coarse_iterations = 0;
  // Evaluation only (EvaluateWeights): GRU iterations of each stage, 0 = the
  // weights' config's. Fewer fine iterations are the network's speed knob
  // (dispmvs_colmap --fine_iterations); this measures what they cost.
  int64_t eval_coarse_iterations = 0;
  int64_t eval_fine_iterations = 0;
  // Evaluation only: what follows the network, "none" or "ncc" (the
  // photometric refinement of dispmvs_colmap --refinement ncc,
  // model/photometric_refinement.h, with these settings).
  std::string eval_refinement = "none";
  model::PhotometricRefinementOptions eval_refinement_options;
  // Evaluation only (EvaluateWeights), with ncc and weights that carry a
  // confidence model: the plane fill after it (model/confident_plane_fill.h,
  // dispmvs_colmap --fill_*, the same defaults); below = 0 leaves it off.
  model::ConfidentPlaneFillOptions eval_fill_options;
  // The arithmetic of the GRU update's convolutions, "fp32", "bf16" or
  // "auto" (model/precision.h). In evaluation: what bf16 costs in accuracy.
  // In training: the forward and backward passes of those convolutions, about
  // 1.3x faster per step on a CPU with native bf16 (models/README.md); the
  // weights, their gradients and the optimiser stay fp32, and the validation
  // inside a run is fp32, so that its numbers compare across runs.
  std::string precision = "fp32";
  // Curriculum (synth::SynthConfig::difficulty): generated training scenes
  // start at difficulty_start and reach full difficulty (1) linearly over
  // difficulty_ramp_steps steps. Validation is always at full difficulty.
  double difficulty_start = 1.0;
  int64_t difficulty_ramp_steps = 0;
  // Stop (checkpoint, validate, write model.safetensors) once this process
  // has used this much CPU time (all threads) since the first step, 0 = no
  // limit: equal-CPU-time comparisons, and runs that must end before a
  // deadline.
  double max_cpu_minutes = 0;
  // The same in wall-clock minutes since the first step (a GPU run with a
  // fixed device lease), 0 = no limit. Both budgets leave out the setup
  // (restoring, textures, validation scenes), which can take minutes on a
  // busy CPU: a caller with a hard deadline leaves room for it.
  double max_minutes = 0;
  // CPU training: return freed blocks above 32 MiB to the system after each
  // use, as glibc does by default, instead of keeping every freed block for
  // the next step (model/host_allocator.h). Less resident memory (5.2 against
  // 7.6 GB at 640x480, batch 2, 5 sources) for twice the step time (the
  // kernel maps and zero-fills those blocks again on every use;
  // bench/train_step_memory.sh). Not a run setting: it changes no step's
  // arithmetic.
  bool low_memory = false;
  uint64_t seed = 0;
  std::string device = "cpu";  // "cpu", "cuda" or "cuda:<i>"
  int64_t threads = 0;         // intra-op threads; 0 = one per core
  std::string checkpoint_dir;  // required for training
  int64_t checkpoint_every = 100;
  // Keep the weights of the checkpoints at multiples of K steps (renamed to
  // weights-<step>.safetensors when a newer checkpoint replaces them; their
  // optimiser state is still removed), so that a run's checkpoints can be
  // compared afterwards and the best one chosen. 0 = keep only the latest.
  // A multiple of checkpoint_every. Not a run setting: it changes no step.
  int64_t keep_weights_every = 0;
  int64_t validate_every = 0;  // 0 = only at the end
  int64_t num_validation_scenes = 8;
  uint64_t validation_seed_base = kDefaultValidationSeedBase;

  // Throws std::invalid_argument naming the first bad field. With
  // for_training false, the training-only fields (checkpoint dir) are not
  // required.
  void Check(bool for_training = true) const;
};

// The learning rate in effect at `step` (0-based).
double LearningRateAt(const TrainOptions& options, int64_t step);

// Seed of sample `index` of training step `step`: top bit set, disjoint from
// every validation seed.
uint64_t TrainingSampleSeed(uint64_t seed, int64_t step, int64_t index);

// The depth-range widening x of training step `step`: log-uniform in
// [1, options.train_widening_max], a function of (seed, step) alone.
double TrainingWideningAt(const TrainOptions& options, int64_t step);

// The number of sources training step `step` uses (TrainOptions::source_counts).
int64_t TrainingSourceCountAt(const TrainOptions& options, int64_t step);

// The difficulty of the generated scenes of training step `step`.
double TrainingDifficultyAt(const TrainOptions& options, int64_t step);

// Runs (or resumes) training as described above. Log lines go to `log` and
// to train.log. Throws std::invalid_argument on bad options and
// std::runtime_error on I/O failure or a checkpoint from a different run.
void Train(const TrainOptions& options, std::ostream& log);

struct WideningResult {
  double widening = 1;  // x: depth range hint (d_min / x, d_max * x); 0 = no hint
  ValidationDepthMetrics metrics;
  // The same metrics over the ground-truth pixels that at least one source
  // sees (in its frame and not occluded there: model::ComputeGroundTruthMatches
  // at full resolution), and their share of the ground-truth pixels. Matching
  // can only reach these; the others the network has to guess. So `seen`
  // says how well the network matches, and the gap to `metrics` how much of
  // the error no matcher could avoid.
  ValidationDepthMetrics seen;
  double seen_share = 0;
  SourcePixelShares source_pixels;
  // Coarse matching: share of ground-truth matches whose arg-max along the
  // segment volume is within one 1/16 pixel (pairs counted: matching_count),
  // and whose 2 / 4 highest peaks hold one that is
  // (model::MatchingLossResult::top2_peaks, top4_peaks).
  double coarse_top1 = 0;
  double coarse_top2_peaks = 0;
  double coarse_top4_peaks = 0;
  double matching_count = 0;
};

// Evaluates the weights file (its config comes from the file's metadata) on
// the fixed validation scenes of `options` (size, N, count, seed base,
// device), once per widening factor. Eval mode, no gradients; the network's
// random initialisation is seeded per scene, so the table is reproducible.
std::vector<WideningResult> EvaluateWeights(const std::string& weights_path,
                                            const TrainOptions& options,
                                            const std::vector<double>& widenings);

// One line per result: "x=2  <1%: 0.123  <2%: ...  AbsRel: ...  coverage: ...".
std::string FormatMetrics(const ValidationDepthMetrics& metrics);
// "seen by a source (0.8123 of the pixels): <1%: ..." for WideningResult::seen.
std::string FormatSeenMetrics(const WideningResult& result);
// "coarse top-1: 0.4321".
std::string FormatMatching(const WideningResult& result);

}  // namespace dispmvs::train
