// dispmvs_train: trains DispMVS on generated scenes (optionally mixed with an
// MVSNet-format data set), or evaluates weights on the fixed validation
// scenes with the depth-range hint widened x = 1, 2, 3.
//
//   dispmvs_train --checkpoint_dir DIR [options]     train (resumes from DIR)
//   dispmvs_train --evaluate WEIGHTS [options]        print the validation table
//
// LibTorch and the standard library only (no Boost): the command line is
// parsed by hand, strictly: every option takes one value, unknown options
// and malformed values are errors.

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "src/program_main.h"
#include "synth/jpeg.h"
#include "train/confidence_fit.h"
#include "train/error_breakdown.h"
#include "train/source_pixel_metrics.h"
#include "train/trainer.h"

namespace {

using dispmvs::train::TrainOptions;

constexpr const char* kUsage = R"(usage:
  dispmvs_train --checkpoint_dir DIR [options]   train, resuming from DIR's latest checkpoint
  dispmvs_train --evaluate WEIGHTS [options]     validation table for depth-range widenings x; under
                                                 each row the same over the ground-truth pixels some
                                                 source sees (in frame, not occluded): what matching
                                                 can reach; and the error in those sources' pixels
                                                 (<1 / 2 px) beside how far 2 % of depth moves a match

  dispmvs_train --fit_confidence WEIGHTS --output OUT [options]
                                                 fit the confidence model (the probability that a
                                                 pixel's depth is within 2 %, from the network's
                                                 confidence and the photometric refinement's
                                                 correlation and texture; model/confidence_model.h)
                                                 on --fit_scenes generated scenes (training seeds,
                                                 the --source_counts mix), rank it against the
                                                 network's confidence on the validation scenes, and
                                                 write WEIGHTS with it to OUT (dispmvs_colmap then
                                                 writes it as the confidence map)

options (default):
  --fit_scenes M              --fit_confidence only: scenes to fit on (40)
  --config NAME               network (small): paper | small (the paper's design: random start inside
                              the depth-range hint) or paper_v2 | small_v2 (model v2: range-free start
                              from the best match along each epipolar segment, matching loss);
                              training only, evaluation reads it from WEIGHTS
  --widenings LIST            evaluation only: comma-separated x values, 'none' = no hint at all
                              (v2 weights only) (1,2,3)
  --breakdown X               evaluation only: instead of the table, where the error comes from at
                              widening X (or 'none'): the scores after every coarse and fine
                              iteration, and the output by texture and by depth (thirds per scene);
                              see train/error_breakdown.h
  --eval_coarse_iterations K  evaluation only: GRU iterations of the coarse stage, 0 = the weights' (0)
  --eval_fine_iterations K    evaluation only: the same for the fine stage (the speed knob of
                              dispmvs_colmap --fine_iterations) (0)
  --eval_refinement R         evaluation only: what follows the network, none or ncc (dispmvs_colmap
                              --refinement: a search along the epipolar lines around its depth,
                              scored by normalised cross-correlation of the images) (none)
  --eval_refine_steps K       evaluation only, with ncc: hypotheses on each side (dispmvs_colmap
                              --refine_steps)
  --eval_refine_min_ncc C     evaluation only, with ncc: correlation needed (--refine_min_ncc)
  --eval_refine_min_texture T evaluation only, with ncc: the reference window's grey-value standard
                              deviation needed (--refine_min_texture)
  --eval_refine_propagation_rounds K
                              evaluation only, with ncc: rounds of propagation
                              (--refine_propagation_rounds)
  --eval_refine_propagation_scale S
                              evaluation only, with ncc: 1, 2 or 4, the resolution propagation runs
                              at (--refine_propagation_scale)
  --eval_refine_full_resolution_rounds K
                              evaluation only, with ncc and scale 2 or 4: propagation rounds at full
                              resolution after the search (--refine_full_resolution_rounds)
  --eval_refine_full_resolution_levels K
                              evaluation only, with ncc: jumps per full-resolution round
                              (--refine_full_resolution_levels)
  --eval_refine_sweep_hypotheses K
                              evaluation only, with ncc: the sweep's most depths, 0 = off
                              (--refine_sweep_hypotheses)
  --eval_fill_below_confidence C
                              evaluation only, with ncc and weights that carry a confidence model:
                              pixels below C take the nearest confident pixel's plane, 0 = off
                              (dispmvs_colmap --fill_below_confidence) (0)
  --eval_fill_anchor_confidence C
                              evaluation only: the confidence a pixel needs to lend its plane
                              (dispmvs_colmap --fill_anchor_confidence)
  --eval_fill_max_change R    evaluation only: the largest relative change of inverse depth the
                              fill makes, 0 = any (dispmvs_colmap --fill_max_change) (0)
  --eval_refine_unseen_slope_radius R
                              evaluation only, with ncc: planes extended over pixels no source sees,
                              0 = off (--refine_unseen_slope_radius)
  --eval_refine_trusted_plane_ncc C
                              evaluation only, with ncc: long-range planes from pixels with NCC >= C,
                              0 = off (--refine_trusted_plane_ncc)
  --eval_refine_trusted_plane_axis_anchors K
                              evaluation only, with ncc: long-range planes also from the nearest
                              anchors along the row (2), row and column (4); 0 = the nearest alone
                              (--refine_trusted_plane_axis_anchors)
  --eval_refine_window_shift S
                              evaluation only, with ncc: the best of windows shifted by S pixels,
                              0 = the centred window alone (--refine_window_shift)
  --eval_refine_local_plane_radius R
                              evaluation only, with ncc: local planes over (2R+1)^2 pixels, 0 = off
                              (--refine_local_plane_radius)
  --eval_refine_local_plane_max_change C
                              evaluation only, with ncc: their largest relative change
                              (--refine_local_plane_max_change)
  --precision P               the GRU update's convolutions in fp32, bf16 or auto (bf16 on a CPU
                              with native bf16, as dispmvs_colmap's default). Training: bf16 steps
                              are ~1.3x faster there; weights, gradients and Adam stay fp32 and the
                              in-run validation is fp32 (fp32)
  --height H --width W        image size (128, 160)
  --sources N                 source views per sample (4)
  --source_counts LIST        training: each step trains with one of these source counts (drawn
                              uniformly, a random subset of the sample's --sources), e.g. 1,2,5,5
                              mixes two-view and three-view samples into five-source training
                              (all --sources)
  --photometry P              training: per-view photometry of the generated scenes, default,
                              wide (exposure 0.5-2x, white balance +-15 %, gamma 0.7-1.4,
                              vignetting up to 0.4, as between real photographs) or mixed (half
                              the scenes each); validation keeps the defaults (default)
  --specular_probability P    training: share of the generated scenes' objects and walls with a
                              glossy coat, a highlight that moves with the viewpoint (0)
  --supersampling S           training: rays per pixel along each axis of the generated scenes
                              (odd, 1-7): each pixel the mean of S x S rays, as a camera
                              integrates light, instead of one ray that aliases textures finer
                              than a pixel; rendering costs about S^2 as much (1)
  --jpeg_quality Q|MIN,MAX    training: each view of the generated scenes compressed as a JPEG
                              of this quality (1-100, drawn per view): 8-bit samples, 4:2:0
                              chroma, 8 x 8 block artefacts, as photographs; 0 = none (0)
  --background_at_infinity 0|1
                              training: the generated outdoor scenes' sky at infinity, with no
                              parallax and no depth (so not supervised), as a real sky; 0 keeps
                              a finite sky 700-1200 units away with its depth (0)
  --batch B                   samples per step (1)
  --steps S                   total steps (1000)
  --lr LR                     Adam learning rate (2e-4)
  --lr_halve_every K          halve the learning rate every K steps, 0 = never (0)
  --lr_warmup_steps K         raise the learning rate linearly over the first K steps (use it with
                              --init_weights: the optimiser's moments start empty), 0 = off (0)
  --grad_clip C               max gradient norm, 0 = off (1)
  --train_widening_max X      widen each step's depth-range hint by x, log-uniform in [1, X],
                              so the model does not lean on a tight range; 1 = off (1)
  --mvsnet_root DIR           also train on an MVSNet-format data set (DTU/BlendedMVS layout:
                              images/, cams/*_cam.txt, pair.txt, depths/*.pfm; one scan or a
                              folder of scans); validation stays on generated scenes (none)
  --mvsnet_fraction F         share of samples drawn from that data set, the rest generated (1)
  --texture_dir DIR           photographs for photo textures of the training scenes (png, jpg, ...;
                              e.g. the photos of Debian's python3-skimage data folder, without
                              motorcycle_*, which bench/motorcycle_check.sh evaluates on);
                              validation stays procedural (none)
  --photo_probability P       share of textures that are photos, with --texture_dir (0.5)
  --matching_loss_weight W    v2: weight of the matching loss (cross-entropy along the epipolar
                              segment, coarse and fine) added to the depth loss (0.5)
  --matching_warmup_steps K   v2: the first K steps train with the matching loss alone (0)
  --depth_loss L              inverse: the paper's L1 of range-normalised inverse depth, which
                              weighs a relative error at depth d by d_min / d; log: L1 of log
                              depth, every pixel's relative error alike (inverse)
  --flow_loss_weight W        v2: weight of the flow loss, every fine iteration's match in every
                              source against the true one in fine-stage pixels, as RAFT supervises
                              its flow (0 = off)
  --scene_reuse R             each generated scene serves R consecutive steps, each time with
                              another view as the reference (1)
  --difficulty_start D        curriculum: generated scenes start at difficulty D in [0, 1] (smaller
                              baselines, fewer occluders, softer light, milder photometry) (1)
  --difficulty_ramp_steps K   ... and reach full difficulty linearly over K steps (0)
  --train_coarse_iterations K coarse GRU iterations in training steps, 0 = the config's; validation
                              and the saved weights keep the config's (0)
  --max_cpu_minutes M         stop (checkpoint, validate, write the model) after M minutes of
                              process CPU time; 0 = no limit (0)
  --max_minutes M             the same after M minutes of wall-clock time (0). Both budgets count
                              from the first step: setup (restoring the checkpoint, loading
                              textures, generating the validation scenes) comes on top
  --init_weights FILE         start from these weights (e.g. models/dispmvs_small.safetensors,
                              to fine-tune at a larger size) instead of a random initialisation;
                              the file must fit --config (none)
  --low_memory 0|1            CPU training: return freed maps above 32 MiB to the system after
                              each use (glibc's default) instead of keeping every freed block for
                              the next step: a third less resident memory for twice the step
                              time (docs/benchmarks.md) (0)
  --seed S                    run seed (0)
  --device cpu|cuda|cuda:I    (cpu)
  --threads T                 intra-op threads, 0 = one per core (0)
  --checkpoint_every K        (100)
  --keep_weights_every K      keep the weights of every K-th step (a multiple of
                              --checkpoint_every) as weights-<step>.safetensors, to choose the
                              best checkpoint afterwards; 0 = only the latest checkpoint (0)
  --validate_every K          0 = only at the end (0)
  --val_scenes M              validation scenes (8)
  --val_seed_base S           first validation seed (1000000000)
  --val_supersampling S       rays per pixel along each axis of the validation scenes, as
                              --supersampling; 1 keeps the table of earlier runs (1)
  --help                      this text
)";

int64_t ParseInt(const std::string& flag, const std::string& value) {
  size_t used = 0;
  long long v = 0;
  try {
    v = std::stoll(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (value.empty() || used != value.size()) {
    throw std::invalid_argument(flag + " expects an integer, got '" + value + "'");
  }
  return v;
}

uint64_t ParseUnsigned(const std::string& flag, const std::string& value) {
  size_t used = 0;
  unsigned long long v = 0;
  try {
    v = std::stoull(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (value.empty() || value[0] == '-' || used != value.size()) {
    throw std::invalid_argument(flag + " expects a non-negative integer, got '" + value + "'");
  }
  return v;
}

bool ParseSwitch(const std::string& flag, const std::string& value) {
  if (value != "0" && value != "1") {
    throw std::invalid_argument(flag + " expects 0 or 1, got '" + value + "'");
  }
  return value == "1";
}

double ParseDouble(const std::string& flag, const std::string& value) {
  size_t used = 0;
  double v = 0;
  try {
    v = std::stod(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (value.empty() || used != value.size() || !std::isfinite(v)) {
    throw std::invalid_argument(flag + " expects a finite number, got '" + value + "'");
  }
  return v;
}

// "1,3,10,none": widening factors >= 1, or none (0: no hint).
std::vector<double> ParseWidenings(const std::string& flag, const std::string& value) {
  std::vector<double> out;
  size_t begin = 0;
  while (begin <= value.size()) {
    const size_t comma = value.find(',', begin);
    const std::string item = value.substr(begin, comma == std::string::npos ? std::string::npos : comma - begin);
    if (item == "none") {
      out.push_back(0.0);
    } else {
      const double x = ParseDouble(flag, item);
      if (x < 1) throw std::invalid_argument(flag + ": each x must be >= 1 or 'none', got '" + item + "'");
      out.push_back(x);
    }
    if (comma == std::string::npos) break;
    begin = comma + 1;
  }
  return out;
}

// "1,2,5": integers, comma-separated.
std::vector<int64_t> ParseCounts(const std::string& flag, const std::string& value) {
  std::vector<int64_t> out;
  size_t begin = 0;
  while (begin <= value.size()) {
    const size_t comma = value.find(',', begin);
    out.push_back(ParseInt(flag, value.substr(begin, comma == std::string::npos ? std::string::npos : comma - begin)));
    if (comma == std::string::npos) break;
    begin = comma + 1;
  }
  return out;
}

struct CommandLine {
  std::vector<double> widenings{1, 2, 3};
  std::vector<double> breakdown;  // one widening: --evaluate prints the error breakdown
  TrainOptions options;
  std::string evaluate_weights;  // empty: train
  std::string fit_confidence_weights;  // non-empty: fit the confidence model to these weights
  std::string output;                  // ... and write them with it here
  int64_t fit_scenes = 40;
  bool help = false;
};

CommandLine Parse(int argc, char** argv) {
  CommandLine cl;
  TrainOptions& o = cl.options;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--help" || flag == "-h") {
      cl.help = true;
      return cl;
    }
    if (flag.rfind("--", 0) != 0) throw std::invalid_argument("unexpected argument '" + flag + "'");
    if (i + 1 >= argc) throw std::invalid_argument("missing value after " + flag);
    const std::string value = argv[++i];
    if (flag == "--checkpoint_dir") o.checkpoint_dir = value;
    else if (flag == "--evaluate") cl.evaluate_weights = value;
    else if (flag == "--fit_confidence") cl.fit_confidence_weights = value;
    else if (flag == "--output") cl.output = value;
    else if (flag == "--fit_scenes") cl.fit_scenes = ParseInt(flag, value);
    else if (flag == "--config") o.config = value;
    else if (flag == "--height") o.height = ParseInt(flag, value);
    else if (flag == "--width") o.width = ParseInt(flag, value);
    else if (flag == "--sources") o.num_sources = ParseInt(flag, value);
    else if (flag == "--source_counts") o.source_counts = ParseCounts(flag, value);
    else if (flag == "--photometry") o.photometry = value;
    else if (flag == "--supersampling") o.supersampling = ParseInt(flag, value);
    else if (flag == "--specular_probability") o.specular_probability = ParseDouble(flag, value);
    else if (flag == "--val_supersampling") o.val_supersampling = ParseInt(flag, value);
    else if (flag == "--background_at_infinity") o.background_at_infinity = ParseSwitch(flag, value);
    else if (flag == "--jpeg_quality") {
      const auto [low, high] = dispmvs::synth::ParseJpegQualityRange(value);
      o.jpeg_quality_min = low;
      o.jpeg_quality_max = high;
    }
    else if (flag == "--batch") o.batch_size = ParseInt(flag, value);
    else if (flag == "--steps") o.steps = ParseInt(flag, value);
    else if (flag == "--lr") o.lr = ParseDouble(flag, value);
    else if (flag == "--lr_halve_every") o.lr_halve_every = ParseInt(flag, value);
    else if (flag == "--lr_warmup_steps") o.lr_warmup_steps = ParseInt(flag, value);
    else if (flag == "--grad_clip") o.grad_clip = ParseDouble(flag, value);
    else if (flag == "--train_widening_max") o.train_widening_max = ParseDouble(flag, value);
    else if (flag == "--mvsnet_root") o.mvsnet_root = value;
    else if (flag == "--mvsnet_fraction") o.mvsnet_fraction = ParseDouble(flag, value);
    else if (flag == "--init_weights") o.init_weights = value;
    else if (flag == "--matching_loss_weight") o.matching_loss_weight = ParseDouble(flag, value);
    else if (flag == "--matching_warmup_steps") o.matching_warmup_steps = ParseInt(flag, value);
    else if (flag == "--depth_loss") o.depth_loss = value;
    else if (flag == "--flow_loss_weight") o.flow_loss_weight = ParseDouble(flag, value);
    else if (flag == "--scene_reuse") o.scene_reuse = ParseInt(flag, value);
    else if (flag == "--eval_coarse_iterations") o.eval_coarse_iterations = ParseInt(flag, value);
    else if (flag == "--eval_fine_iterations") o.eval_fine_iterations = ParseInt(flag, value);
    else if (flag == "--precision") o.precision = value;
    else if (flag == "--eval_refinement") o.eval_refinement = value;
    else if (flag == "--eval_refine_steps") o.eval_refinement_options.steps = ParseInt(flag, value);
    else if (flag == "--eval_refine_min_ncc") o.eval_refinement_options.min_ncc = ParseDouble(flag, value);
    else if (flag == "--eval_refine_min_texture") {
      o.eval_refinement_options.min_texture = ParseDouble(flag, value);
    }
    else if (flag == "--eval_refine_propagation_rounds") {
      o.eval_refinement_options.propagation_rounds = ParseInt(flag, value);
    }
    else if (flag == "--eval_refine_propagation_scale") {
      o.eval_refinement_options.propagation_scale = ParseInt(flag, value);
    }
    else if (flag == "--eval_refine_full_resolution_rounds") {
      o.eval_refinement_options.full_resolution_rounds = ParseInt(flag, value);
    }
    else if (flag == "--eval_refine_full_resolution_levels") {
      o.eval_refinement_options.full_resolution_levels = ParseInt(flag, value);
    }
    else if (flag == "--eval_refine_sweep_hypotheses") {
      o.eval_refinement_options.sweep_hypotheses = ParseInt(flag, value);
    }
    else if (flag == "--eval_fill_below_confidence") {
      o.eval_fill_options.below = ParseDouble(flag, value);
    }
    else if (flag == "--eval_fill_anchor_confidence") {
      o.eval_fill_options.anchor = ParseDouble(flag, value);
    }
    else if (flag == "--eval_fill_max_change") {
      o.eval_fill_options.max_change = ParseDouble(flag, value);
    }
    else if (flag == "--eval_refine_unseen_slope_radius") {
      o.eval_refinement_options.unseen_slope_radius = ParseInt(flag, value);
    }
    else if (flag == "--eval_refine_trusted_plane_ncc") {
      o.eval_refinement_options.trusted_plane_min_ncc = ParseDouble(flag, value);
    }
    else if (flag == "--eval_refine_trusted_plane_axis_anchors") {
      o.eval_refinement_options.trusted_plane_axis_anchors = ParseInt(flag, value);
    }
    else if (flag == "--eval_refine_window_shift") {
      o.eval_refinement_options.window_shift = ParseInt(flag, value);
    }
    else if (flag == "--eval_refine_local_plane_radius") {
      o.eval_refinement_options.local_plane_radius = ParseInt(flag, value);
    }
    else if (flag == "--eval_refine_local_plane_max_change") {
      o.eval_refinement_options.local_plane_max_change = ParseDouble(flag, value);
    }
    else if (flag == "--train_coarse_iterations") o.train_coarse_iterations = ParseInt(flag, value);
    else if (flag == "--difficulty_start") o.difficulty_start = ParseDouble(flag, value);
    else if (flag == "--difficulty_ramp_steps") o.difficulty_ramp_steps = ParseInt(flag, value);
    else if (flag == "--max_cpu_minutes") o.max_cpu_minutes = ParseDouble(flag, value);
    else if (flag == "--max_minutes") o.max_minutes = ParseDouble(flag, value);
    else if (flag == "--widenings") cl.widenings = ParseWidenings(flag, value);
    else if (flag == "--breakdown") {
      cl.breakdown = ParseWidenings(flag, value);
      if (cl.breakdown.size() != 1) throw std::invalid_argument("--breakdown takes one x (or 'none')");
    }
    else if (flag == "--texture_dir") o.texture_dir = value;
    else if (flag == "--photo_probability") o.photo_probability = ParseDouble(flag, value);
    else if (flag == "--low_memory") o.low_memory = ParseSwitch(flag, value);
    else if (flag == "--seed") o.seed = ParseUnsigned(flag, value);
    else if (flag == "--device") o.device = value;
    else if (flag == "--threads") o.threads = ParseInt(flag, value);
    else if (flag == "--checkpoint_every") o.checkpoint_every = ParseInt(flag, value);
    else if (flag == "--keep_weights_every") o.keep_weights_every = ParseInt(flag, value);
    else if (flag == "--validate_every") o.validate_every = ParseInt(flag, value);
    else if (flag == "--val_scenes") o.num_validation_scenes = ParseInt(flag, value);
    else if (flag == "--val_seed_base") o.validation_seed_base = ParseUnsigned(flag, value);
    else throw std::invalid_argument("unknown option " + flag + " (see --help)");
  }
  const int modes = !cl.evaluate_weights.empty() + !o.checkpoint_dir.empty() + !cl.fit_confidence_weights.empty();
  if (modes == 0) {
    throw std::invalid_argument(
        "give --checkpoint_dir DIR (train), --evaluate WEIGHTS or --fit_confidence WEIGHTS (see --help)");
  }
  if (modes > 1) {
    throw std::invalid_argument("--checkpoint_dir, --evaluate and --fit_confidence exclude each other");
  }
  if (!cl.fit_confidence_weights.empty()) {
    if (cl.output.empty()) throw std::invalid_argument("--fit_confidence needs --output FILE");
    if (cl.fit_scenes < 1) throw std::invalid_argument("--fit_scenes must be >= 1");
    // The model reads the refinement: it is on unless asked otherwise.
    if (o.eval_refinement == "none") o.eval_refinement = "ncc";
  } else if (!cl.output.empty()) {
    throw std::invalid_argument("--output goes with --fit_confidence WEIGHTS");
  }
  if (!cl.breakdown.empty() && cl.evaluate_weights.empty()) {
    throw std::invalid_argument("--breakdown goes with --evaluate WEIGHTS");
  }
  return cl;
}

// ", S x S rays per pixel" when the validation scenes are supersampled; the
// table's header says so, since such a table is not comparable with one of
// point-sampled scenes.
std::string SupersamplingNote(const dispmvs::train::TrainOptions& o) {
  if (o.val_supersampling == 1) return "";
  return ", " + std::to_string(o.val_supersampling) + " x " + std::to_string(o.val_supersampling) + " rays per pixel";
}

void PrintEvaluation(const CommandLine& cl) {
  const auto& o = cl.options;
  if (!cl.breakdown.empty()) {
    const double x = cl.breakdown.front();
    std::cout << "weights " << cl.evaluate_weights << ": error breakdown on " << o.num_validation_scenes
              << " validation scenes (seeds " << o.validation_seed_base << "..), " << o.width << "x"
              << o.height << ", N = " << o.num_sources << SupersamplingNote(o) << ", x="
              << (x == 0 ? std::string("none") : std::to_string(x).substr(0, 5)) << "\n"
              << dispmvs::train::FormatBreakdown(
                     dispmvs::train::EvaluateErrorBreakdown(cl.evaluate_weights, o, x));
    return;
  }
  const auto rows = dispmvs::train::EvaluateWeights(cl.evaluate_weights, o, cl.widenings);
  std::cout << "weights " << cl.evaluate_weights << ": " << o.num_validation_scenes
            << " validation scenes (seeds " << o.validation_seed_base << "..), " << o.width << "x"
            << o.height << ", N = " << o.num_sources << SupersamplingNote(o) << "\n";
  for (const auto& row : rows) {
    const std::string x = row.widening == 0 ? std::string("none") : std::to_string(row.widening).substr(0, 5);
    std::printf("x=%s  %s  %s\n", x.c_str(), dispmvs::train::FormatMetrics(row.metrics).c_str(),
                dispmvs::train::FormatMatching(row).c_str());
    std::printf("      %s\n", dispmvs::train::FormatSeenMetrics(row).c_str());
    std::printf("      %s\n", dispmvs::train::FormatSourcePixels(row.source_pixels).c_str());
  }
}

void FitAndWriteConfidence(const CommandLine& cl) {
  const auto& o = cl.options;
  std::cout << "weights " << cl.fit_confidence_weights << ": fitting the confidence model on " << cl.fit_scenes
            << " generated scenes (training seeds from " << o.seed << "), " << o.width << "x" << o.height
            << ", N = " << o.num_sources << " (source counts drawn from --source_counts), then ranking on "
            << o.num_validation_scenes << " validation scenes" << std::endl;
  const auto fit = dispmvs::train::FitConfidence(cl.fit_confidence_weights, o, cl.fit_scenes, std::cout);
  std::printf("fit: %lld pixels of %lld scenes, %.4f within 2 %%\n", static_cast<long long>(fit.fit_pixels),
              static_cast<long long>(fit.fit_scenes), fit.fit_share_correct);
  std::printf("coefficients (%s): %s\n", dispmvs::model::kConfidenceModelKey, fit.model.ToText().c_str());
  std::printf("%s\n%s\n", dispmvs::train::FormatConfidenceCurves("fit scenes", fit.fit).c_str(),
              dispmvs::train::FormatConfidenceCurves("validation scenes", fit.validation).c_str());
  dispmvs::model::WriteConfidenceModel(cl.fit_confidence_weights, cl.output, fit.model);
  std::cout << "wrote " << cl.output << std::endl;
}

}  // namespace

int main(int argc, char** argv) {
  return dispmvs::cli::RunProgram([&] {
    const CommandLine cl = Parse(argc, argv);
    if (cl.help) {
      std::cout << kUsage;
      return 0;
    }
    if (!cl.fit_confidence_weights.empty()) {
      FitAndWriteConfidence(cl);
    } else if (!cl.evaluate_weights.empty()) {
      PrintEvaluation(cl);
    } else {
      dispmvs::train::Train(cl.options, std::cout);
    }
    return 0;
  });
}
