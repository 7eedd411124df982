#include "train/trainer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <cstdio>
#include <filesystem>
#include <map>
#include <stdexcept>
#include <thread>

#include "model/config.h"
#include "model/device.h"
#include "model/dispmvs_net.h"
#include "model/host_allocator.h"
#include "model/loss.h"
#include "model/matching_loss.h"
#include "model/safetensors.h"
#include "synth/generator.h"
#include "train/batch.h"
#include "train/checkpoint.h"
#include "train/confidence_fit.h"
#include "train/error_breakdown.h"
#include "train/train_log.h"
#include "train/training_samples.h"
#include "train/validation.h"

namespace dispmvs::train {
namespace {

namespace fs = std::filesystem;
using model::DispMvsNet;
using model::ModelConfig;
using internal::CpuGenerator;
using internal::kTopBit;
using internal::Logger;
using internal::Mix;
using internal::RestoreRun;
using internal::RunSettings;
using internal::SaveCheckpoint;
using internal::Settings;
using internal::SynthConfigFor;
using internal::TrainingSamples;
using internal::Validate;
using internal::ValidationScenes;

// Seed of the network's random initialisation at training step `step`.
uint64_t TrainingInitSeed(uint64_t seed, int64_t step) {
  return Mix(Mix(seed, 0xD15A11u), static_cast<uint64_t>(step));
}

// Process CPU time (all threads), seconds.
double CpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

void SetThreads(int64_t threads) {
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  torch::set_num_threads(static_cast<int>(threads));
}

std::string FormatDuration(double seconds) {
  const auto total = static_cast<int64_t>(std::max(0.0, seconds) + 0.5);
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%lld:%02lld:%02lld", static_cast<long long>(total / 3600),
                static_cast<long long>(total / 60 % 60), static_cast<long long>(total % 60));
  return buffer;
}

}  // namespace

// ---------------------------------------------------------------- public API

void TrainOptions::Check(bool for_training) const {
  auto fail = [](const std::string& what) { throw std::invalid_argument(what); };
  ModelConfig::ByName(config);
  if (height < 1 || height > 8192) fail("height must be in [1, 8192], got " + std::to_string(height));
  if (width < 1 || width > 8192) fail("width must be in [1, 8192], got " + std::to_string(width));
  if (num_sources < 1 || num_sources > 64) {
    fail("num_sources must be in [1, 64], got " + std::to_string(num_sources));
  }
  if (batch_size < 1 || batch_size > 1024) fail("batch_size must be in [1, 1024], got " + std::to_string(batch_size));
  if (steps < 0 || steps > 999'999'999) fail("steps must be in [0, 999999999], got " + std::to_string(steps));
  if (!(std::isfinite(lr) && lr > 0 && lr < 1)) fail("lr must be in (0, 1), got " + std::to_string(lr));
  if (lr_halve_every < 0) fail("lr_halve_every must be >= 0, got " + std::to_string(lr_halve_every));
  if (lr_warmup_steps < 0) fail("lr_warmup_steps must be >= 0, got " + std::to_string(lr_warmup_steps));
  if (!(std::isfinite(grad_clip) && grad_clip >= 0)) {
    fail("grad_clip must be a finite number >= 0, got " + std::to_string(grad_clip));
  }
  if (!(std::isfinite(train_widening_max) && train_widening_max >= 1 && train_widening_max <= 1000)) {
    fail("train_widening_max must be in [1, 1000], got " + std::to_string(train_widening_max));
  }
  model::ParseDevice(device);  // usable or not: checked when training starts
  if (threads < 0 || threads > 1024) fail("threads must be in [0, 1024], got " + std::to_string(threads));
  if (checkpoint_every < 1) fail("checkpoint_every must be >= 1, got " + std::to_string(checkpoint_every));
  if (keep_weights_every < 0 || keep_weights_every % checkpoint_every != 0) {
    fail("keep_weights_every must be 0 or a multiple of checkpoint_every (" + std::to_string(checkpoint_every) +
         "), got " + std::to_string(keep_weights_every));
  }
  if (validate_every < 0) fail("validate_every must be >= 0, got " + std::to_string(validate_every));
  if (num_validation_scenes < 0 || num_validation_scenes > 100'000) {
    fail("num_validation_scenes must be in [0, 100000], got " + std::to_string(num_validation_scenes));
  }
  if (validation_seed_base >= kTopBit - 100'000) {
    fail("validation_seed_base must be below 2^63 - 100000 (training seeds use the top bit)");
  }
  if (for_training && checkpoint_dir.empty()) fail("checkpoint_dir is required for training");
  if (!(mvsnet_fraction >= 0 && mvsnet_fraction <= 1)) {
    fail("mvsnet_fraction must be in [0, 1], got " + std::to_string(mvsnet_fraction));
  }
  // A fraction of a data set that is not there is a mistake, not a request.
  if (mvsnet_root.empty() && mvsnet_fraction != 1) fail("mvsnet_fraction needs mvsnet_root");
  if (!texture_dir.empty() && !fs::is_directory(texture_dir)) {
    fail("texture_dir: no such folder " + texture_dir);
  }
  for (const int64_t count : source_counts) {
    if (count < 1 || count > num_sources) {
      fail("each of source_counts must be in [1, num_sources = " + std::to_string(num_sources) + "], got " +
           std::to_string(count));
    }
  }
  for (const auto& [name, s] : {std::pair<const char*, int64_t>{"supersampling", supersampling},
                                 {"val_supersampling", val_supersampling}}) {
    if (s < 1 || s > 7 || s % 2 == 0) fail(std::string(name) + " must be odd and in [1, 7], got " + std::to_string(s));
  }
  if (!(specular_probability >= 0 && specular_probability <= 1)) {
    fail("specular_probability must be in [0, 1], got " + std::to_string(specular_probability));
  }
  if (!(jpeg_quality_min == 0 && jpeg_quality_max == 0) &&
      !(jpeg_quality_min >= 1 && jpeg_quality_max >= jpeg_quality_min && jpeg_quality_max <= 100)) {
    fail("jpeg_quality must be 1 <= min <= max <= 100 (or both 0: none), got " + std::to_string(jpeg_quality_min) +
         "," + std::to_string(jpeg_quality_max));
  }
  if (photometry != "default" && photometry != "wide" && photometry != "mixed") {
    fail("photometry must be default, wide or mixed, got '" + photometry + "'");
  }
  if (!(photo_probability >= 0 && photo_probability <= 1)) {
    fail("photo_probability must be in [0, 1], got " + std::to_string(photo_probability));
  }
  if (!init_weights.empty() && !fs::is_regular_file(init_weights)) {
    fail("init_weights: no such file " + init_weights);
  }
  if (!(std::isfinite(matching_loss_weight) && matching_loss_weight >= 0)) {
    fail("matching_loss_weight must be a finite number >= 0, got " + std::to_string(matching_loss_weight));
  }
  try {
    model::ParseDepthLoss(depth_loss);
  } catch (const std::invalid_argument& e) {
    fail(std::string("depth_loss: ") + e.what());
  }
  if (!(std::isfinite(flow_loss_weight) && flow_loss_weight >= 0)) {
    fail("flow_loss_weight must be a finite number >= 0, got " + std::to_string(flow_loss_weight));
  }
  if (flow_loss_weight > 0 && ModelConfig::ByName(config).NeedsDepthRange()) {
    fail("flow_loss_weight needs a v2 config (the fine stage's matches of model v2)");
  }
  if (matching_warmup_steps < 0) {
    fail("matching_warmup_steps must be >= 0, got " + std::to_string(matching_warmup_steps));
  }
  if (matching_warmup_steps > 0 && (matching_loss_weight == 0 || ModelConfig::ByName(config).NeedsDepthRange())) {
    fail("matching_warmup_steps needs a v2 config and matching_loss_weight > 0");
  }
  if (!(difficulty_start >= 0 && difficulty_start <= 1)) {
    fail("difficulty_start must be in [0, 1], got " + std::to_string(difficulty_start));
  }
  if (difficulty_ramp_steps < 0) fail("difficulty_ramp_steps must be >= 0");
  if (train_coarse_iterations < 0 || train_coarse_iterations > 1000) {
    fail("train_coarse_iterations must be in [0, 1000], got " + std::to_string(train_coarse_iterations));
  }
  for (const auto& [name, value] : {std::pair<const char*, int64_t>{"eval_coarse_iterations",
                                                                     eval_coarse_iterations},
                                    {"eval_fine_iterations", eval_fine_iterations}}) {
    if (value < 0 || value > 1000) {
      fail(std::string(name) + " must be in [0, 1000], got " + std::to_string(value));
    }
    if (value > 0 && for_training) fail(std::string(name) + " is for evaluation only");
  }
  if (model::ParseRefinementMode(eval_refinement, "eval_refinement") && for_training) {
    fail("eval_refinement is for evaluation only");
  }
  eval_refinement_options.Check();
  eval_fill_options.Check();
  try {
    model::ResolvePrecision(precision, torch::kCPU);
  } catch (const std::invalid_argument& error) {
    fail(error.what());
  }
  if (scene_reuse < 1 || scene_reuse > 64) fail("scene_reuse must be in [1, 64], got " + std::to_string(scene_reuse));
  if (!(std::isfinite(max_cpu_minutes) && max_cpu_minutes >= 0)) {
    fail("max_cpu_minutes must be a finite number >= 0, got " + std::to_string(max_cpu_minutes));
  }
  if (!(std::isfinite(max_minutes) && max_minutes >= 0)) {
    fail("max_minutes must be a finite number >= 0, got " + std::to_string(max_minutes));
  }
  SynthConfigFor(*this);  // the generator's own limits
}

double TrainingDifficultyAt(const TrainOptions& options, int64_t step) {
  if (options.difficulty_ramp_steps <= 0 || step >= options.difficulty_ramp_steps) return 1.0;
  const double t = static_cast<double>(step) / static_cast<double>(options.difficulty_ramp_steps);
  return options.difficulty_start + (1.0 - options.difficulty_start) * t;
}

double LearningRateAt(const TrainOptions& options, int64_t step) {
  double lr = options.lr;
  if (options.lr_halve_every > 0) lr *= std::pow(0.5, static_cast<double>(step / options.lr_halve_every));
  if (step < options.lr_warmup_steps) {
    lr *= static_cast<double>(step + 1) / static_cast<double>(options.lr_warmup_steps);
  }
  return lr;
}

uint64_t TrainingSampleSeed(uint64_t seed, int64_t step, int64_t index) {
  return Mix(Mix(seed, static_cast<uint64_t>(step)), static_cast<uint64_t>(index)) | kTopBit;
}

int64_t TrainingSourceCountAt(const TrainOptions& options, int64_t step) {
  if (options.source_counts.empty()) return options.num_sources;
  const uint64_t bits = Mix(Mix(options.seed, 0x50C7u), static_cast<uint64_t>(step));
  return options.source_counts[bits % options.source_counts.size()];
}

double TrainingWideningAt(const TrainOptions& options, int64_t step) {
  if (options.train_widening_max <= 1.0) return 1.0;
  // 53 random bits -> u in [0, 1).
  const uint64_t bits = Mix(Mix(options.seed, 0x1D3A7Eu), static_cast<uint64_t>(step)) >> 11;
  const double u = static_cast<double>(bits) * (1.0 / 9007199254740992.0);
  return std::exp(u * std::log(options.train_widening_max));
}

std::string FormatMatching(const WideningResult& r) {
  char buffer[96];
  std::snprintf(buffer, sizeof buffer, "coarse top-1: %.4f  in the 2 / 4 best peaks: %.4f / %.4f", r.coarse_top1,
                r.coarse_top2_peaks, r.coarse_top4_peaks);
  return buffer;
}

std::string FormatMetrics(const ValidationDepthMetrics& m) {
  char buffer[160];
  std::snprintf(buffer, sizeof buffer, "<1%%: %.4f  <2%%: %.4f  <5%%: %.4f  AbsRel: %.4f  coverage: %.4f",
                m.within_1, m.within_2, m.within_5, m.abs_rel, m.coverage);
  return buffer;
}

std::string FormatSeenMetrics(const WideningResult& r) {
  char share[64];
  std::snprintf(share, sizeof share, "seen by a source (%.4f of the pixels): ", r.seen_share);
  return share + FormatMetrics(r.seen);
}

namespace {

// The loss of one training step and what the log reports of it.
struct StepLoss {
  torch::Tensor loss;        // what is minimised
  torch::Tensor depth_loss;  // the sequence loss
  double match_loss = 0;     // the matching loss (model v2), 0 without one
  double top1 = 0;           // coarse matches whose arg-max is right, of `counted`
  double counted = 0;
};

StepLoss ComputeStepLoss(const TrainOptions& options, const model::DispMvsOutput& output,
                         const TrainingBatch& batch, double widening, bool matching_loss, int64_t step) {
  StepLoss result;
  if (model::ParseDepthLoss(options.depth_loss) == model::DepthLoss::kLog) {
    result.depth_loss = model::LogDepthSequenceLoss(output.inv_depths, batch.gt_depth, batch.gt_valid);
  } else {
    // Normalised by the unwidened range (see TrainOptions::train_widening_max).
    result.depth_loss = model::SequenceLoss(output.inv_depths, batch.gt_depth, batch.gt_valid,
                                            batch.input.depth_min * widening, batch.input.depth_max / widening);
  }
  result.loss = result.depth_loss;
  // The true matches on a stage's grid, computed once per grid: the fine
  // window's matching loss and the flow loss share the fine one.
  std::map<int64_t, model::GroundTruthMatches> truths;
  const auto truth_at = [&](int64_t stride, int64_t height, int64_t width) -> const model::GroundTruthMatches& {
    auto found = truths.find(stride);
    if (found == truths.end()) {
      found = truths
                  .emplace(stride, model::ComputeGroundTruthMatches(batch.gt_depths, batch.input.intrinsics,
                                                                    batch.input.extrinsics, stride, height, width))
                  .first;
    }
    return found->second;
  };
  if (matching_loss) {
    torch::Tensor match_loss = torch::zeros({}, result.depth_loss.options());
    for (const auto& stage : output.matching) {
      const auto stage_result =
          model::MatchingLoss(stage, truth_at(stage.stride, stage.logits.size(2), stage.logits.size(3)));
      match_loss = match_loss + stage_result.loss;
      if (stage.stride == model::DispMvsNetImpl::kCoarseStride) {
        result.top1 = stage_result.top1;
        result.counted = stage_result.count;
      }
    }
    result.match_loss = match_loss.item<double>();
    const bool warmup = step < options.matching_warmup_steps;
    // During the warm-up the depth loss enters with weight 0: every
    // parameter still receives a (zero) gradient, so Adam steps them all
    // alike and the checkpoint's single step count stays true.
    result.loss = warmup ? match_loss + 0.0 * result.depth_loss
                         : result.depth_loss + options.matching_loss_weight * match_loss;
  }
  // The flow loss (model v2 only, checked with the options) joins whatever
  // else is minimised, warm-up included.
  if (options.flow_loss_weight > 0 && !output.fine_source_xy.empty()) {
    const torch::Tensor& first = output.fine_source_xy.front();
    const auto flow = model::SourceFlowLoss(
        output.fine_source_xy, truth_at(model::DispMvsNetImpl::kFineStride, first.size(2), first.size(3)));
    result.loss = result.loss + options.flow_loss_weight * flow.loss;
  }
  return result;
}

double SecondsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

// Where a step's wall time went.
struct StepTimes {
  double total = 0, scenes = 0, forward = 0, backward = 0, cpu = 0;
};

std::string StepLine(const TrainOptions& options, int64_t step, const StepLoss& loss, double lr,
                     const StepTimes& times, double eta_seconds) {
  char line[384];
  std::snprintf(line, sizeof line,
                "step %lld/%lld  loss %.5f  depth %.5f  match %.4f  top1 %.3f  lr %.3e  %.2f s/step "
                "(scenes %.2f, forward %.2f, backward %.2f; cpu %.2f s)  ETA %s",
                static_cast<long long>(step + 1), static_cast<long long>(options.steps),
                loss.loss.item<double>(), loss.depth_loss.item<double>(), loss.match_loss,
                loss.counted > 0 ? loss.top1 / loss.counted : 0.0, lr, times.total, times.scenes,
                times.forward, times.backward, times.cpu, FormatDuration(eta_seconds).c_str());
  return line;
}

// Validation runs the iterations the weights are saved with, then training
// goes on with its own.
void ValidateAndLog(DispMvsNet& net, const ModelConfig& config, const std::vector<synth::SynthSample>& scenes,
                    const TrainOptions& options, int64_t step, double cpu_start, Logger& log) {
  if (scenes.empty()) return;
  net->set_iterations(config.coarse_iterations, config.fine_iterations);
  const model::Precision training_precision = net->precision();
  net->set_precision(model::Precision::kFloat32);
  const WideningResult result = Validate(net, scenes, options, {1.0}, /*look_from_sources=*/false).front();
  net->set_precision(training_precision);
  if (options.train_coarse_iterations > 0) {
    net->set_iterations(options.train_coarse_iterations, config.fine_iterations);
  }
  char cpu[64];
  std::snprintf(cpu, sizeof cpu, "  cpu %.0f s", CpuSeconds() - cpu_start);
  log.Line("validate step " + std::to_string(step) + cpu + "  x=1  " + FormatMetrics(result.metrics) +
           "  " + FormatMatching(result));
}

}  // namespace

void Train(const TrainOptions& options, std::ostream& console) {
  options.Check(/*for_training=*/true);
  const torch::Device device = model::ParseUsableDevice(options.device);
  SetThreads(options.threads);
  const fs::path dir = options.checkpoint_dir;
  fs::create_directories(dir);
  Logger log(console, dir / "train.log");
  if (device.is_cpu()) {
    if (options.low_memory) {
      model::KeepFreedTensorMemory();
      log.Line("CPU memory: freed blocks above 32 MiB returned to the system (--low_memory 1)");
    } else {
      model::KeepAllFreedTensorMemory();
      log.Line("CPU memory: every freed block kept for the next step (--low_memory 1 saves memory)");
    }
  }

  const ModelConfig config = ModelConfig::ByName(options.config);
  torch::manual_seed(options.seed);  // the initial weights
  DispMvsNet net(config);
  net->to(device);
  torch::optim::Adam optimizer(net->parameters(), torch::optim::AdamOptions(options.lr));
  const Settings settings = RunSettings(options);
  const int64_t start = RestoreRun(options, dir, settings, net, optimizer, device, log);

  TrainingSamples training_samples(options, device, log);
  const auto validation_scenes = ValidationScenes(options, device);
  const double cpu_start = CpuSeconds();
  const bool matching_loss = !config.NeedsDepthRange() && options.matching_loss_weight > 0;
  if (options.train_coarse_iterations > 0) {
    net->set_iterations(options.train_coarse_iterations, config.fine_iterations);
  }
  net->train();
  net->set_precision(model::ResolvePrecision(options.precision, device));
  log.Line(std::string("GRU convolutions in ") + model::PrecisionName(net->precision()));
  const auto run_start = std::chrono::steady_clock::now();
  int64_t last_validated = -1;
  int64_t final_step = std::max(start, options.steps);
  for (int64_t step = start; step < options.steps; ++step) {
    const auto step_start = std::chrono::steady_clock::now();
    const double step_cpu_start = CpuSeconds();
    StepTimes times;
    const double lr = LearningRateAt(options, step);
    for (auto& group : optimizer.param_groups()) {
      static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);
    }
    const double widening = TrainingWideningAt(options, step);
    const auto batch = MakeBatch(training_samples.ForStep(step), widening);
    times.scenes = SecondsSince(step_start);

    const auto forward_start = std::chrono::steady_clock::now();
    const auto output = net->forward(batch.input, CpuGenerator(TrainingInitSeed(options.seed, step)));
    const StepLoss loss = ComputeStepLoss(options, output, batch, widening, matching_loss, step);
    times.forward = SecondsSince(forward_start);

    const auto backward_start = std::chrono::steady_clock::now();
    optimizer.zero_grad();
    loss.loss.backward();
    if (options.grad_clip > 0) torch::nn::utils::clip_grad_norm_(net->parameters(), options.grad_clip);
    optimizer.step();
    times.backward = SecondsSince(backward_start);

    times.total = SecondsSince(step_start);
    times.cpu = CpuSeconds() - step_cpu_start;
    const double mean_seconds = SecondsSince(run_start) / static_cast<double>(step + 1 - start);
    log.Line(StepLine(options, step, loss, lr, times, mean_seconds * static_cast<double>(options.steps - step - 1)));

    const int64_t done = step + 1;
    const bool out_of_cpu_time =
        options.max_cpu_minutes > 0 && CpuSeconds() - cpu_start >= 60.0 * options.max_cpu_minutes;
    const bool out_of_wall_time = options.max_minutes > 0 && SecondsSince(run_start) >= 60.0 * options.max_minutes;
    const bool out_of_time = out_of_cpu_time || out_of_wall_time;
    if (done % options.checkpoint_every == 0 || done == options.steps || out_of_time) {
      SaveCheckpoint(dir, done, net, config, optimizer, settings, options.keep_weights_every);
    }
    if (options.validate_every > 0 && done % options.validate_every == 0) {
      ValidateAndLog(net, config, validation_scenes, options, done, cpu_start, log);
      last_validated = done;
    }
    if (out_of_time) {
      log.Line("stopping after step " + std::to_string(done) + ": " +
               (out_of_cpu_time ? "--max_cpu_minutes" : "--max_minutes") + " reached");
      final_step = done;
      break;
    }
  }
  if (last_validated != final_step) {
    ValidateAndLog(net, config, validation_scenes, options, final_step, cpu_start, log);
  }
  model::SaveModuleWeights(*net, config, (dir / "model.safetensors").string());
  log.Line("wrote " + (dir / "model.safetensors").string());
}

namespace {

// The weights at `weights_path` as the evaluation options ask (iterations,
// precision, device), and the validation scenes on that device.
std::pair<DispMvsNet, std::vector<synth::SynthSample>> LoadForEvaluation(
    const std::string& weights_path, const TrainOptions& options) {
  options.Check(/*for_training=*/false);
  const torch::Device device = model::ParseUsableDevice(options.device);
  if (options.num_validation_scenes < 1) throw std::invalid_argument("num_validation_scenes must be >= 1");
  SetThreads(options.threads);
  if (device.is_cpu()) model::KeepFreedTensorMemory();
  const ModelConfig config = model::ReadModelConfig(weights_path);
  DispMvsNet net(config);
  model::LoadModuleWeights(*net, weights_path);
  net->set_iterations(
      options.eval_coarse_iterations > 0 ? options.eval_coarse_iterations : config.coarse_iterations,
      options.eval_fine_iterations > 0 ? options.eval_fine_iterations : config.fine_iterations);
  net->set_precision(model::ResolvePrecision(options.precision, device));
  net->to(device);
  return {net, ValidationScenes(options, device)};
}

}  // namespace

std::vector<WideningResult> EvaluateWeights(const std::string& weights_path, const TrainOptions& options,
                                            const std::vector<double>& widenings) {
  auto [net, scenes] = LoadForEvaluation(weights_path, options);
  // The plane fill reads the confidence model the weights carry (none: no
  // fill, as in dispmvs_colmap).
  model::ConfidenceModel fill_model;
  if (options.eval_refinement == "ncc" && options.eval_fill_options.below > 0) {
    fill_model = model::ReadConfidenceModel(weights_path);
  }
  return Validate(net, scenes, options, widenings, /*look_from_sources=*/true,
                  fill_model.empty() ? nullptr : &fill_model);
}

ConfidenceFit FitConfidence(const std::string& weights_path, const TrainOptions& options,
                            int64_t fit_scene_count, std::ostream& log) {
  if (fit_scene_count < 1) throw std::invalid_argument("the confidence fit needs at least one scene");
  auto [net, validation_scenes] = LoadForEvaluation(weights_path, options);
  const auto fit_scenes = ConfidenceFitScenes(options, fit_scene_count, model::ParseUsableDevice(options.device));
  return FitConfidenceOnScenes(net, fit_scenes, validation_scenes, options, log);
}

ErrorBreakdown EvaluateErrorBreakdown(const std::string& weights_path, const TrainOptions& options,
                                      double widening) {
  auto [net, scenes] = LoadForEvaluation(weights_path, options);
  return BreakDownErrors(net, scenes, options, widening);
}

}  // namespace dispmvs::train
