#include "train/training_samples.h"

#include <algorithm>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <tuple>

#include "synth/photo_folder.h"
#include "synth/rng.h"
#include "synth/shading.h"

namespace dispmvs::train::internal {
namespace {

// A generated scene can show no surface at all in the reference view (no
// usable depth range); such draws are replaced by the next seed in a fixed
// sequence, so the replacement is deterministic too.
constexpr int kMaxDrawAttempts = 16;

// The sample with the views `order` (the first is the reference), in that
// order; the depth-range hint recomputed for the reference.
synth::SynthSample WithViews(const synth::SynthSample& sample, const std::vector<int64_t>& order) {
  const torch::Tensor index = torch::tensor(order, torch::kLong).to(sample.images.device());
  synth::SynthSample out = sample;
  out.images = sample.images.index_select(0, index);
  out.intrinsics = sample.intrinsics.index_select(0, index);
  out.world_to_camera = sample.world_to_camera.index_select(0, index);
  out.depths = sample.depths.index_select(0, index);
  std::tie(out.depth_min, out.depth_max) = synth::RobustDepthRange(out.depths[0]);
  return out;
}

// The sample with view `reference` as its reference and the other views, in
// their order, as sources. Returns the sample unchanged for reference 0, or
// when that view sees no surface.
synth::SynthSample WithReference(const synth::SynthSample& sample, int64_t reference) {
  const int64_t views = sample.images.size(0);
  if (reference % views == 0) return sample;
  std::vector<int64_t> order{reference % views};
  for (int64_t v = 0; v < views; ++v) {
    if (v != reference % views) order.push_back(v);
  }
  synth::SynthSample out = WithViews(sample, order);
  if (!(out.depth_min > 0 && out.depth_min < out.depth_max)) return sample;
  return out;
}

}  // namespace

uint64_t Mix(uint64_t a, uint64_t b) { return synth::SplitMix64(a ^ synth::SplitMix64(b)); }

synth::SynthSample WithSourceCount(const synth::SynthSample& sample, int64_t count, uint64_t seed) {
  const int64_t sources = sample.images.size(0) - 1;
  if (count >= sources) return sample;
  std::vector<int64_t> pool(static_cast<size_t>(sources));
  for (int64_t s = 0; s < sources; ++s) pool[static_cast<size_t>(s)] = s + 1;
  // Partial Fisher-Yates: the first `count` places hold the draw.
  for (int64_t i = 0; i < count; ++i) {
    const uint64_t r = synth::SplitMix64(seed + static_cast<uint64_t>(i));
    const int64_t j = i + static_cast<int64_t>(r % static_cast<uint64_t>(sources - i));
    std::swap(pool[static_cast<size_t>(i)], pool[static_cast<size_t>(j)]);
  }
  std::vector<int64_t> order(pool.begin(), pool.begin() + count);
  std::sort(order.begin(), order.end());
  order.insert(order.begin(), 0);
  return WithViews(sample, order);
}


synth::SynthConfig SynthConfigFor(const TrainOptions& options) {
  synth::SynthConfig config;
  config.height = options.height;
  config.width = options.width;
  config.num_views = static_cast<int>(options.num_sources + 1);
  config.Check();
  return config;
}

synth::SynthSample GenerateUsableSample(const synth::SynthConfig& config, uint64_t seed,
                                        torch::Device device) {
  const uint64_t top = seed & kTopBit;
  uint64_t attempt_seed = seed;
  for (int attempt = 0; attempt < kMaxDrawAttempts; ++attempt) {
    auto sample = synth::GenerateSample(config, attempt_seed, device);
    if (sample.depth_min > 0 && sample.depth_min < sample.depth_max) return sample;
    attempt_seed = (Mix(seed, static_cast<uint64_t>(attempt + 1)) & ~kTopBit) | top;
  }
  throw std::runtime_error("no usable synthetic scene after " + std::to_string(kMaxDrawAttempts) +
                           " draws from seed " + std::to_string(seed));
}

namespace {

// Opened once, before the first step, so that a bad data set fails the run
// at once rather than at the first step that happens to draw from it.
std::optional<MvsnetSource> OpenMvsnetSource(const TrainOptions& options, const synth::SynthConfig& synth_config) {
  if (options.mvsnet_root.empty()) return std::nullopt;
  RequireMvsnetImageDecoding();
  MvsnetSource source;
  source.dataset = OpenMvsnetDataset(options.mvsnet_root);
  source.views = MvsnetTrainingViews(source.dataset, options.num_sources);
  if (source.views.empty()) {
    throw std::runtime_error(options.mvsnet_root + ": no reference view with a ground-truth depth map and at least " +
                             std::to_string(options.num_sources) + " source views");
  }
  source.sample_options.height = options.height;
  source.sample_options.width = options.width;
  source.sample_options.num_sources = options.num_sources;
  source.sample_options.dtype = synth_config.dtype;  // batches mix both kinds
  return source;
}

// Sample `index` of scene group `group` (= step / scene_reuse): from the data
// set with probability mvsnet_fraction, else a generated scene; both the
// choice and the reference view follow from TrainingSampleSeed alone, so runs
// stay reproducible.
synth::SynthSample TrainingSample(const TrainOptions& options, const synth::SynthConfig& synth_config,
                                  const std::optional<MvsnetSource>& mvsnet, int64_t group, int64_t index,
                                  torch::Device device) {
  const uint64_t seed = TrainingSampleSeed(options.seed, group, index);
  if (mvsnet) {
    if (const auto view = ChooseMvsnetView(seed, options.mvsnet_fraction, mvsnet->views.size())) {
      return LoadMvsnetSample(mvsnet->dataset, mvsnet->views[*view], mvsnet->sample_options, device);
    }
  }
  // The photometry setting: "wide" for every scene, "mixed" for half of
  // them (by their seed); the geometry is the same either way.
  const bool wide = options.photometry == "wide" ||
                    (options.photometry == "mixed" && (synth::SplitMix64(seed ^ 0x70686f746f6dULL) >> 63) != 0);
  if (wide) {
    synth::SynthConfig wide_config = synth_config;
    wide_config.photometry = synth::WidePhotometry();
    return GenerateUsableSample(wide_config, seed, device);
  }
  return GenerateUsableSample(synth_config, seed, device);
}

}  // namespace

TrainingSamples::TrainingSamples(const TrainOptions& options, torch::Device device, Logger& log)
    : options_(options), device_(device), synth_config_(SynthConfigFor(options)) {
  // Training scenes only (TrainingSample): validation and the confidence
  // fit keep SynthConfigFor's defaults.
  synth_config_.supersampling = static_cast<int>(options.supersampling);
  synth_config_.specular_probability = options.specular_probability;
  synth_config_.jpeg_quality_min = static_cast<int>(options.jpeg_quality_min);
  synth_config_.jpeg_quality_max = static_cast<int>(options.jpeg_quality_max);
  synth_config_.background_at_infinity = options.background_at_infinity;
  if (options.background_at_infinity) {
    log.Line("outdoor sky at infinity: no parallax and no depth (unsupervised) in the generated training scenes");
  }
  if (options.jpeg_quality_max > 0) {
    log.Line("JPEG compression: quality " + std::to_string(options.jpeg_quality_min) + "-" +
             std::to_string(options.jpeg_quality_max) + " per view of the generated training scenes");
  }
  if (options.specular_probability > 0) {
    log.Line("glossy surfaces: " + std::to_string(options.specular_probability) +
             " of the primitives in the generated training scenes");
  }
  if (options.supersampling > 1) {
    log.Line("supersampling: " + std::to_string(options.supersampling) + " x " + std::to_string(options.supersampling) +
             " rays per pixel in the generated training scenes");
  }
  if (options.photometry == "wide") {
    log.Line("photometry: wide (exposure 0.5-2x, white balance +-15 %, gamma 0.7-1.4, vignetting <= 0.4)");
  } else if (options.photometry == "mixed") {
    log.Line("photometry: mixed (half the generated scenes wide, half the defaults)");
  }
  if (!options.texture_dir.empty()) {
    std::ostringstream warnings;
    synth_config_.photos = std::make_shared<const synth::PhotoSet>(
        synth::LoadPhotoFolder(options.texture_dir, {}, &warnings));
    synth_config_.photo_probability = options.photo_probability;
    std::istringstream lines(warnings.str());
    for (std::string line; std::getline(lines, line);) log.Line(line);
    log.Line("photo textures: " + std::to_string(synth_config_.photos->size()) + " photos from " +
             options.texture_dir + ", probability " + std::to_string(options.photo_probability));
  }
  mvsnet_ = OpenMvsnetSource(options, synth_config_);
  if (mvsnet_) {
    log.Line("MVSNet data set " + options.mvsnet_root + ": " +
             std::to_string(mvsnet_->dataset.scans.size()) + " scans, " +
             std::to_string(mvsnet_->views.size()) + " reference views with ground truth, fraction " +
             std::to_string(options.mvsnet_fraction));
  }
}

std::vector<synth::SynthSample> TrainingSamples::ForStep(int64_t step) {
  const int64_t group = step / options_.scene_reuse;
  if (group != cached_group_) {
    synth_config_.difficulty = TrainingDifficultyAt(options_, group * options_.scene_reuse);
    cached_scenes_.clear();
    for (int64_t j = 0; j < options_.batch_size; ++j) {
      cached_scenes_.push_back(TrainingSample(options_, synth_config_, mvsnet_, group, j, device_));
    }
    cached_group_ = group;
  }
  const int64_t sources = TrainingSourceCountAt(options_, step);
  const uint64_t subset_seed = Mix(TrainingSampleSeed(options_.seed, step, 0), 0x5eedu);
  std::vector<synth::SynthSample> samples;
  for (const auto& scene : cached_scenes_) {
    samples.push_back(WithSourceCount(WithReference(scene, step % options_.scene_reuse), sources,
                                      Mix(subset_seed, samples.size())));
  }
  return samples;
}

}  // namespace dispmvs::train::internal
