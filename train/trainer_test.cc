#include "train/trainer.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "model/config.h"
#include "model/dispmvs_net.h"
#include "model/safetensors.h"
#include "tests/support/temp_dir.h"
#include "train/error_breakdown.h"
#include "train/step_log_test_util.h"
#include "train/training_samples.h"
#include "train/validation.h"

namespace dispmvs::train {
namespace {

namespace fs = std::filesystem;
using testing::ReadFileBytes;
using testing::TempDir;

// Tiny and fast: Small network, 64x48, two sources, one thread (bit-exact
// comparisons need a fixed thread count).
TrainOptions TinyOptions(const fs::path& dir, int64_t steps) {
  TrainOptions o;
  o.config = "small";
  o.height = 48;
  o.width = 64;
  o.num_sources = 2;
  o.batch_size = 1;
  o.steps = steps;
  o.threads = 1;
  o.checkpoint_dir = dir.string();
  o.checkpoint_every = 2;
  o.num_validation_scenes = 0;
  return o;
}

std::set<std::string> FileNames(const fs::path& dir) {
  std::set<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) names.insert(entry.path().filename().string());
  return names;
}

std::string RunAndReadWeights(const TrainOptions& options) {
  std::ostringstream log;
  Train(options, log);
  return ReadFileBytes(fs::path(options.checkpoint_dir) / "model.safetensors");
}

TEST(TrainerTest, SameSeedSameWeightsDifferentSeedDifferentWeights) {
  TempDir tmp;
  const std::string a = RunAndReadWeights(TinyOptions(tmp.path() / "a", 2));
  const std::string b = RunAndReadWeights(TinyOptions(tmp.path() / "b", 2));
  EXPECT_EQ(a, b);
  auto other = TinyOptions(tmp.path() / "c", 2);
  other.seed = 7;
  EXPECT_NE(a, RunAndReadWeights(other));
}

TEST(TrainerTest, ResumedRunEqualsStraightRunBitForBit) {
  TempDir tmp;
  const std::string straight = RunAndReadWeights(TinyOptions(tmp.path() / "straight", 4));

  const fs::path resumed_dir = tmp.path() / "resumed";
  const std::string after_two = RunAndReadWeights(TinyOptions(resumed_dir, 2));
  EXPECT_NE(after_two, straight);  // the comparison below is not vacuous
  std::ostringstream log;
  Train(TinyOptions(resumed_dir, 4), log);
  EXPECT_NE(log.str().find("resumed from"), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("at step 2"), std::string::npos) << log.str();
  EXPECT_EQ(log.str().find("step 1/4"), std::string::npos) << "steps before the checkpoint were re-run";
  EXPECT_EQ(ReadFileBytes(resumed_dir / "model.safetensors"), straight);
}

TEST(TrainerTest, KeptWeightsAreTheWeightsOfTheirStep) {
  TempDir tmp;
  auto options = TinyOptions(tmp.path() / "run", 5);
  options.checkpoint_every = 1;
  options.keep_weights_every = 2;
  std::ostringstream log;
  Train(options, log);

  const std::set<std::string> names = FileNames(options.checkpoint_dir);
  const std::set<std::string> expected{"weights-000000002.safetensors", "weights-000000004.safetensors",
                                       "checkpoint-000000005.safetensors",
                                       "checkpoint-000000005.optim.safetensors", "model.safetensors",
                                       "train.log"};
  EXPECT_EQ(names, expected);
  // Step 2's kept weights are what a run of two steps ends with.
  const std::string two_steps = RunAndReadWeights(TinyOptions(tmp.path() / "two", 2));
  EXPECT_EQ(ReadFileBytes(fs::path(options.checkpoint_dir) / "weights-000000002.safetensors"), two_steps);
  EXPECT_NE(ReadFileBytes(fs::path(options.checkpoint_dir) / "weights-000000004.safetensors"), two_steps);

  // The kept files do not disturb resuming: the run goes on from step 5.
  options.steps = 6;
  std::ostringstream resumed;
  Train(options, resumed);
  EXPECT_NE(resumed.str().find("at step 5"), std::string::npos) << resumed.str();
  EXPECT_TRUE(fs::exists(fs::path(options.checkpoint_dir) / "weights-000000004.safetensors"));
  EXPECT_FALSE(fs::exists(fs::path(options.checkpoint_dir) / "checkpoint-000000005.safetensors"));
}

TEST(TrainerTest, CheckpointFilesAreCompleteAndOldOnesRemoved) {
  TempDir tmp;
  auto options = TinyOptions(tmp.path() / "run", 3);
  options.checkpoint_every = 1;
  options.num_validation_scenes = 1;
  std::ostringstream log;
  Train(options, log);

  const std::set<std::string> names = FileNames(options.checkpoint_dir);
  const std::set<std::string> expected{"checkpoint-000000003.safetensors",
                                       "checkpoint-000000003.optim.safetensors", "model.safetensors",
                                       "train.log"};
  EXPECT_EQ(names, expected);

  const auto optim = model::LoadSafetensors((fs::path(options.checkpoint_dir) /
                                             "checkpoint-000000003.optim.safetensors").string());
  EXPECT_EQ(optim.metadata.at("step"), "3");
  EXPECT_EQ(optim.metadata.at("adam_step"), "3");
  ASSERT_FALSE(optim.tensors.empty());
  for (const auto& [name, tensor] : optim.tensors) {
    if (name.rfind("exp_avg_sq/", 0) == 0) {
      EXPECT_GE(tensor.min().item<float>(), 0.0f) << name;
    }
  }
  // The checkpoint's weights are the final weights (no step after it).
  EXPECT_EQ(ReadFileBytes(fs::path(options.checkpoint_dir) / "checkpoint-000000003.safetensors"),
            ReadFileBytes(fs::path(options.checkpoint_dir) / "model.safetensors"));

  const std::string log_file = ReadFileBytes(fs::path(options.checkpoint_dir) / "train.log");
  EXPECT_EQ(log_file, log.str());
  EXPECT_NE(log_file.find("step 3/3  loss "), std::string::npos);
  EXPECT_NE(log_file.find("validate step 3  cpu "), std::string::npos);
  EXPECT_NE(log_file.find(" s  x=1  <1%: "), std::string::npos);
  EXPECT_NE(log_file.find("coarse top-1: "), std::string::npos);
}

TEST(TrainerTest, ResumingWithDifferentSettingsIsRefused) {
  TempDir tmp;
  auto options = TinyOptions(tmp.path() / "run", 2);
  std::ostringstream log;
  Train(options, log);
  options.steps = 4;
  options.lr = 1e-3;
  try {
    Train(options, log);
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("different run (lr"), std::string::npos) << e.what();
  }
}

TEST(TrainerTest, EvaluateWeightsGivesOneRowPerWidening) {
  TempDir tmp;
  auto options = TinyOptions(tmp.path() / "run", 1);
  std::ostringstream log;
  Train(options, log);
  options.num_validation_scenes = 1;
  const auto rows = EvaluateWeights((fs::path(options.checkpoint_dir) / "model.safetensors").string(),
                                    options, {1, 3});
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[1].widening, 3);
  EXPECT_EQ(rows[0].metrics.gt_pixels, rows[1].metrics.gt_pixels);
  EXPECT_GT(rows[0].metrics.gt_pixels, 0);
  EXPECT_GE(rows[0].metrics.coverage, rows[0].metrics.within_5);
  // The pixels some source sees are a subset of the ground-truth pixels: the
  // share counts them, and no more of them lie within 2 % than of all.
  for (const auto& row : rows) {
    EXPECT_GT(row.seen_share, 0.0);
    EXPECT_LE(row.seen_share, 1.0);
    EXPECT_EQ(row.seen.gt_pixels,
              std::llround(row.seen_share * static_cast<double>(row.metrics.gt_pixels)));
    EXPECT_LE(row.seen.within_2 * static_cast<double>(row.seen.gt_pixels),
              row.metrics.within_2 * static_cast<double>(row.metrics.gt_pixels) + 0.5);
    EXPECT_LE(row.source_pixels.within_1px, row.source_pixels.within_2px);
    EXPECT_LE(row.source_pixels.within_2px, 1.0);
    EXPECT_LE(row.source_pixels.moves_1px, row.source_pixels.moves_half_px);
    EXPECT_GT(row.source_pixels.moves_half_px, 0.0);  // generated scenes have parallax
  }

  // Fewer GRU iterations change the result: the override reaches the network.
  options.eval_coarse_iterations = 1;
  options.eval_fine_iterations = 1;
  const auto fewer = EvaluateWeights((fs::path(options.checkpoint_dir) / "model.safetensors").string(),
                                     options, {1});
  ASSERT_EQ(fewer.size(), 1u);
  EXPECT_EQ(fewer[0].metrics.gt_pixels, rows[0].metrics.gt_pixels);
  EXPECT_NE(fewer[0].metrics.abs_rel, rows[0].metrics.abs_rel);
}

TrainOptions TinyV2Options(const fs::path& dir, int64_t steps) {
  TrainOptions o = TinyOptions(dir, steps);
  o.config = "small_v2";
  o.matching_warmup_steps = 1;
  o.scene_reuse = 2;
  o.train_coarse_iterations = 2;
  o.difficulty_start = 0.5;
  o.difficulty_ramp_steps = 4;
  return o;
}

TEST(TrainerV2Test, MatchingLossWarmupSceneReuseAndCurriculumResumeBitForBit) {
  TempDir tmp;
  std::ostringstream log;
  const auto straight_options = TinyV2Options(tmp.path() / "straight", 4);
  Train(straight_options, log);
  const std::string straight = ReadFileBytes(tmp.path() / "straight" / "model.safetensors");
  // The matching loss is on (its value is logged, > 0) and the depth loss
  // enters only after the warm-up step.
  EXPECT_NE(log.str().find("step 1/4  loss "), std::string::npos) << log.str();
  EXPECT_EQ(log.str().find("match 0.0000"), std::string::npos) << log.str();

  const fs::path resumed_dir = tmp.path() / "resumed";
  Train(TinyV2Options(resumed_dir, 2), log);
  Train(TinyV2Options(resumed_dir, 4), log);
  EXPECT_EQ(ReadFileBytes(resumed_dir / "model.safetensors"), straight);

  // The saved configuration is the v2 one, with the config's iterations (not
  // the 2 coarse iterations of the training steps).
  const model::ModelConfig saved = model::ReadModelConfig((tmp.path() / "straight" / "model.safetensors").string());
  EXPECT_EQ(saved.init, model::ModelConfig::Init::kMatch);
  EXPECT_EQ(saved.coarse_iterations, model::ModelConfig::SmallV2().coarse_iterations);

  // Other v2 settings are another run.
  auto changed = TinyV2Options(resumed_dir, 6);
  changed.scene_reuse = 3;
  EXPECT_THROW(Train(changed, log), std::runtime_error);
}

// The matching warm-up trains the matching features alone: after a warm-up
// step the matching encoder has moved, and nothing that only the depth loss
// reaches (the context encoder, both update blocks) has.
TEST(TrainerV2Test, MatchingWarmupStepMovesOnlyTheMatchingEncoder) {
  TempDir tmp;
  const auto options = TinyV2Options(tmp.path() / "run", 1);
  ASSERT_EQ(options.matching_warmup_steps, 1);
  RunAndReadWeights(options);
  torch::manual_seed(options.seed);  // the run's initial weights
  model::DispMvsNet initial(model::ModelConfig::SmallV2());
  const model::SafetensorsFile trained =
      model::LoadSafetensors((tmp.path() / "run" / "model.safetensors").string());
  const std::map<std::string, torch::Tensor> by_name(trained.tensors.begin(), trained.tensors.end());
  int moved = 0, kept = 0;
  for (const auto& p : initial->named_parameters()) {
    const auto found = by_name.find(p.key());
    ASSERT_NE(found, by_name.end()) << p.key();
    const bool unchanged = torch::equal(found->second, p.value());
    if (p.key().rfind("matching_encoder.", 0) == 0) {
      moved += unchanged ? 0 : 1;
    } else {
      EXPECT_TRUE(unchanged) << p.key() << " moved during the matching warm-up";
      ++kept;
    }
  }
  EXPECT_GT(moved, 0);
  EXPECT_GT(kept, 0);
}

TEST(TrainerV2Test, CpuOrWallClockBudgetStopsTheRunWithAModel) {
  for (const std::string budget : {"--max_cpu_minutes", "--max_minutes"}) {
    SCOPED_TRACE(budget);
    TempDir tmp;
    auto options = TinyV2Options(tmp.path() / "run", 50);
    (budget == "--max_minutes" ? options.max_minutes : options.max_cpu_minutes) = 1e-6;
    options.num_validation_scenes = 1;
    std::ostringstream log;
    Train(options, log);
    EXPECT_NE(log.str().find("stopping after step 1: " + budget + " reached"), std::string::npos) << log.str();
    EXPECT_NE(log.str().find("validate step 1  cpu "), std::string::npos) << log.str();
    EXPECT_TRUE(fs::exists(tmp.path() / "run" / "model.safetensors"));
    EXPECT_TRUE(fs::exists(tmp.path() / "run" / "checkpoint-000000001.safetensors"));
  }
}

// The log depth loss and the flow loss train a v2 network: finite losses,
// and they are run settings (a checkpoint does not resume under others).
TEST(TrainerV2Test, LogDepthAndFlowLossesTrainAndAreRunSettings) {
  TempDir tmp;
  std::ostringstream log;
  TrainOptions o = TinyV2Options(tmp.path() / "v2", 2);
  o.depth_loss = "log";
  o.flow_loss_weight = 0.5;
  Train(o, log);
  EXPECT_NE(log.str().find("step 2/2  loss "), std::string::npos) << log.str();
  EXPECT_EQ(log.str().find("nan"), std::string::npos) << log.str();
  o.steps = 3;
  o.flow_loss_weight = 0.25;
  std::ostringstream again;
  EXPECT_THROW(Train(o, again), std::runtime_error);
}

TEST(TrainerV2Test, SourceCountsDrawFewerSourcesAsASubsetAndAreARunSetting) {
  TempDir tmp;
  TrainOptions o = TinyV2Options(tmp.path() / "counts", 2);
  o.num_sources = 3;
  EXPECT_EQ(TrainingSourceCountAt(o, 5), 3);  // off by default: every step all sources
  o.source_counts = {1, 3};
  std::map<int64_t, int> drawn;
  for (int64_t step = 0; step < 400; ++step) {
    const int64_t count = TrainingSourceCountAt(o, step);
    ASSERT_EQ(count, TrainingSourceCountAt(o, step));
    ++drawn[count];
  }
  ASSERT_EQ(drawn.size(), 2u);
  EXPECT_NEAR(drawn[1], 200, 50);  // uniform over the list (binomial sd 10)

  // A step with fewer sources keeps the reference and a subset of the same
  // scene's sources, in their order.
  fs::create_directories(o.checkpoint_dir);
  std::ostringstream console;
  internal::Logger log(console, tmp.path() / "log.txt");
  TrainOptions all = o;
  all.source_counts.clear();
  internal::TrainingSamples with_all(all, torch::kCPU, log);
  internal::TrainingSamples with_counts(o, torch::kCPU, log);
  int steps_with_one = 0;
  for (int64_t step = 0; step < 8; ++step) {
    const auto full = with_all.ForStep(step);
    const auto fewer = with_counts.ForStep(step);
    ASSERT_EQ(full.size(), fewer.size());
    const int64_t count = TrainingSourceCountAt(o, step);
    steps_with_one += count == 1;
    for (size_t i = 0; i < full.size(); ++i) {
      ASSERT_EQ(full[i].images.size(0), 4);
      ASSERT_EQ(fewer[i].images.size(0), count + 1);
      EXPECT_TRUE(torch::equal(fewer[i].images[0], full[i].images[0]));
      EXPECT_TRUE(torch::equal(fewer[i].depths[0], full[i].depths[0]));
      EXPECT_EQ(fewer[i].depth_min, full[i].depth_min);
      int64_t previous = 0;
      for (int64_t v = 1; v <= count; ++v) {
        int64_t match = 0;
        for (int64_t u = 1; u < 4; ++u) {
          if (torch::equal(fewer[i].world_to_camera[v], full[i].world_to_camera[u]) &&
              torch::equal(fewer[i].images[v], full[i].images[u]) &&
              torch::equal(fewer[i].intrinsics[v], full[i].intrinsics[u])) {
            match = u;
          }
        }
        EXPECT_GT(match, previous) << "step " << step << " view " << v;
        previous = match;
      }
    }
  }
  EXPECT_GT(steps_with_one, 0);
  EXPECT_LT(steps_with_one, 8);

  // It trains, and resuming with another list is refused.
  std::ostringstream train_log;
  Train(o, train_log);
  EXPECT_NE(train_log.str().find("step 2/2  loss "), std::string::npos) << train_log.str();
  EXPECT_EQ(train_log.str().find("nan"), std::string::npos) << train_log.str();
  o.steps = 3;
  o.source_counts = {2, 3};
  std::ostringstream again;
  EXPECT_THROW(Train(o, again), std::runtime_error);
}

// --photometry wide changes the training scenes' images, not their
// geometry, and is a run setting.
TEST(TrainerV2Test, WidePhotometryChangesTrainingImagesOnly) {
  TempDir tmp;
  TrainOptions o = TinyV2Options(tmp.path() / "wide", 2);
  fs::create_directories(o.checkpoint_dir);
  std::ostringstream console;
  internal::Logger log(console, tmp.path() / "log.txt");
  TrainOptions wide = o;
  wide.photometry = "wide";
  internal::TrainingSamples plain_samples(o, torch::kCPU, log);
  internal::TrainingSamples wide_samples(wide, torch::kCPU, log);
  const auto plain = plain_samples.ForStep(0);
  const auto widened = wide_samples.ForStep(0);
  ASSERT_EQ(plain.size(), widened.size());
  for (size_t i = 0; i < plain.size(); ++i) {
    EXPECT_TRUE(torch::equal(plain[i].depths, widened[i].depths));
    EXPECT_TRUE(torch::equal(plain[i].world_to_camera, widened[i].world_to_camera));
    EXPECT_FALSE(torch::equal(plain[i].images, widened[i].images));
  }
  EXPECT_NE(console.str().find("photometry: wide"), std::string::npos);
  // "mixed": every scene is the default's or the wide one's, and both occur.
  TrainOptions mixed = o;
  mixed.photometry = "mixed";
  mixed.scene_reuse = 1;
  TrainOptions plain_one = o, wide_one = wide;
  plain_one.scene_reuse = wide_one.scene_reuse = 1;
  internal::TrainingSamples mixed_samples(mixed, torch::kCPU, log);
  internal::TrainingSamples plain_each(plain_one, torch::kCPU, log);
  internal::TrainingSamples wide_each(wide_one, torch::kCPU, log);
  int as_default = 0, as_wide = 0;
  for (int64_t step = 0; step < 8; ++step) {
    const auto m = mixed_samples.ForStep(step), d = plain_each.ForStep(step), v = wide_each.ForStep(step);
    for (size_t i = 0; i < m.size(); ++i) {
      const bool is_default = torch::equal(m[i].images, d[i].images), is_wide = torch::equal(m[i].images, v[i].images);
      EXPECT_NE(is_default, is_wide) << "step " << step;
      as_default += is_default;
      as_wide += is_wide;
    }
  }
  EXPECT_GT(as_default, 0);
  EXPECT_GT(as_wide, 0);

  std::ostringstream train_log;
  Train(wide, train_log);
  EXPECT_NE(train_log.str().find("step 2/2  loss "), std::string::npos) << train_log.str();
  wide.steps = 3;
  wide.photometry = "default";
  std::ostringstream again;
  EXPECT_THROW(Train(wide, again), std::runtime_error);
}

// The first step's training samples of `o` and of `other`, which differ
// only in what the generator renders: the geometry must be the same.
std::pair<std::vector<synth::SynthSample>, std::vector<synth::SynthSample>> FirstStepsWithSameGeometry(
    const TrainOptions& o, const TrainOptions& other, internal::Logger& log) {
  internal::TrainingSamples a(o, torch::kCPU, log), b(other, torch::kCPU, log);
  auto pair = std::make_pair(a.ForStep(0), b.ForStep(0));
  EXPECT_EQ(pair.first.size(), pair.second.size());
  for (size_t i = 0; i < std::min(pair.first.size(), pair.second.size()); ++i) {
    EXPECT_TRUE(torch::equal(pair.first[i].depths, pair.second[i].depths));
    EXPECT_TRUE(torch::equal(pair.first[i].world_to_camera, pair.second[i].world_to_camera));
  }
  return pair;
}

// --supersampling renders the training scenes' colours from 3 x 3 rays per
// pixel: same geometry, other images, a run setting; the validation scenes
// follow --val_supersampling alone.
TEST(TrainerV2Test, SupersamplingChangesTrainingImagesOnlyAndValidationFollowsItsOwnKnob) {
  TempDir tmp;
  TrainOptions o = TinyV2Options(tmp.path() / "ss", 2);
  fs::create_directories(o.checkpoint_dir);
  std::ostringstream console;
  internal::Logger log(console, tmp.path() / "log.txt");
  TrainOptions fine = o;
  fine.supersampling = 3;
  const auto [plain, sharp] = FirstStepsWithSameGeometry(o, fine, log);
  for (size_t i = 0; i < plain.size(); ++i) EXPECT_FALSE(torch::equal(plain[i].images, sharp[i].images));
  EXPECT_NE(console.str().find("supersampling: 3 x 3 rays per pixel"), std::string::npos);

  // Validation: the same scenes whatever the training's supersampling.
  const auto val_plain = internal::ValidationScenes(o, torch::kCPU);
  const auto val_fine_training = internal::ValidationScenes(fine, torch::kCPU);
  TrainOptions val_fine = o;
  val_fine.val_supersampling = 3;
  const auto val_sharp = internal::ValidationScenes(val_fine, torch::kCPU);
  ASSERT_EQ(val_plain.size(), val_sharp.size());
  for (size_t i = 0; i < val_plain.size(); ++i) {
    EXPECT_TRUE(torch::equal(val_plain[i].images, val_fine_training[i].images));
    EXPECT_TRUE(torch::equal(val_plain[i].depths, val_sharp[i].depths));
    EXPECT_FALSE(torch::equal(val_plain[i].images, val_sharp[i].images));
  }

  std::ostringstream train_log;
  Train(fine, train_log);
  EXPECT_NE(train_log.str().find("step 2/2  loss "), std::string::npos) << train_log.str();
  fine.steps = 3;
  fine.supersampling = 1;  // resuming with other training images is refused
  std::ostringstream again;
  EXPECT_THROW(Train(fine, again), std::runtime_error);
}

// --specular_probability gives the training scenes glossy surfaces: same
// geometry, other images, said in the log; the validation scenes stay matte.
TEST(TrainerV2Test, GlossySurfacesChangeTrainingImagesOnly) {
  TempDir tmp;
  TrainOptions o = TinyV2Options(tmp.path() / "gloss", 2);
  std::ostringstream console;
  internal::Logger log(console, tmp.path() / "log.txt");
  TrainOptions glossy = o;
  glossy.specular_probability = 1;
  const auto [plain, shiny] = FirstStepsWithSameGeometry(o, glossy, log);
  bool any_brighter = false;
  for (size_t i = 0; i < plain.size(); ++i) any_brighter = any_brighter || !torch::equal(plain[i].images, shiny[i].images);
  EXPECT_TRUE(any_brighter);
  EXPECT_NE(console.str().find("glossy surfaces: 1.0"), std::string::npos) << console.str();
  const auto val_plain = internal::ValidationScenes(o, torch::kCPU), val_glossy = internal::ValidationScenes(glossy, torch::kCPU);
  for (size_t i = 0; i < val_plain.size(); ++i) EXPECT_TRUE(torch::equal(val_plain[i].images, val_glossy[i].images));
}

// --background_at_infinity takes the depth off the training scenes' outdoor
// sky (which no longer shows parallax) and changes no other scene; said in
// the log, a run setting; the validation scenes keep their finite sky.
TEST(TrainerV2Test, BackgroundAtInfinityTakesTheOutdoorSkysDepthOnly) {
  TempDir tmp;
  TrainOptions o = TinyV2Options(tmp.path() / "sky", 2);
  o.difficulty_start = 1;
  std::ostringstream console;
  internal::Logger log(console, tmp.path() / "log.txt");
  TrainOptions sky = o;
  sky.background_at_infinity = true;
  internal::TrainingSamples finite_samples(o, torch::kCPU, log), sky_samples(sky, torch::kCPU, log);
  int outdoor = 0;
  for (int64_t step = 0; step < 8; ++step) {
    const auto finite = finite_samples.ForStep(step), infinite = sky_samples.ForStep(step);
    ASSERT_EQ(finite.size(), infinite.size());
    for (size_t i = 0; i < finite.size(); ++i) {
      EXPECT_TRUE(torch::equal(finite[i].world_to_camera, infinite[i].world_to_camera));
      if (finite[i].rig != "outdoor") {
        EXPECT_TRUE(torch::equal(finite[i].depths, infinite[i].depths));
        EXPECT_TRUE(torch::equal(finite[i].images, infinite[i].images));
        continue;
      }
      const torch::Tensor lost = (infinite[i].depths == 0) & (finite[i].depths > 0);
      if (lost.any().item<bool>()) ++outdoor;
      EXPECT_TRUE((finite[i].depths.masked_select(lost) > 300 * finite[i].scale).all().item<bool>());
    }
  }
  EXPECT_GE(outdoor, 1);
  EXPECT_NE(console.str().find("outdoor sky at infinity"), std::string::npos) << console.str();
  const auto val_finite = internal::ValidationScenes(o, torch::kCPU), val_sky = internal::ValidationScenes(sky, torch::kCPU);
  for (size_t i = 0; i < val_finite.size(); ++i) EXPECT_TRUE(torch::equal(val_finite[i].depths, val_sky[i].depths));

  TrainOptions run = TinyV2Options(tmp.path() / "sky_run", 1);
  run.background_at_infinity = true;
  std::ostringstream first;
  Train(run, first);
  run.steps = 2;
  run.background_at_infinity = false;  // resuming with other training scenes is refused
  std::ostringstream again;
  EXPECT_THROW(Train(run, again), std::runtime_error);
}

// --jpeg_quality compresses the training scenes' views (8-bit samples),
// with the default and the wide photometry alike: same geometry, said in the
// log, a run setting; the validation scenes stay uncompressed.
TEST(TrainerV2Test, JpegCompressionChangesTrainingImagesOnly) {
  TempDir tmp;
  for (const std::string photometry : {"default", "wide"}) {
    SCOPED_TRACE(photometry);
    TrainOptions o = TinyV2Options(tmp.path() / ("jpeg_" + photometry), 2);
    o.photometry = photometry;
    fs::create_directories(o.checkpoint_dir);
    std::ostringstream console;
    internal::Logger log(console, tmp.path() / ("log_" + photometry + ".txt"));
    TrainOptions jpeg = o;
    jpeg.jpeg_quality_min = 30;
    jpeg.jpeg_quality_max = 60;
    const auto [plain, compressed] = FirstStepsWithSameGeometry(o, jpeg, log);
    for (size_t i = 0; i < plain.size(); ++i) {
      EXPECT_FALSE(torch::equal(plain[i].images, compressed[i].images));
      const torch::Tensor levels = compressed[i].images.to(torch::kDouble) * 255.0;
      EXPECT_LT((levels - torch::round(levels)).abs().max().item<double>(), 1e-3);
    }
    EXPECT_NE(console.str().find("JPEG compression: quality 30-60"), std::string::npos) << console.str();
    const auto val_plain = internal::ValidationScenes(o, torch::kCPU);
    const auto val_jpeg = internal::ValidationScenes(jpeg, torch::kCPU);
    for (size_t i = 0; i < val_plain.size(); ++i) EXPECT_TRUE(torch::equal(val_plain[i].images, val_jpeg[i].images));
  }
  TrainOptions run = TinyV2Options(tmp.path() / "jpeg_run", 1);
  run.jpeg_quality_min = run.jpeg_quality_max = 80;
  std::ostringstream first;
  Train(run, first);
  run.steps = 2;
  run.jpeg_quality_max = 90;  // resuming with other training images is refused
  std::ostringstream again;
  EXPECT_THROW(Train(run, again), std::runtime_error);
}

TEST(TrainerV2Test, ErrorBreakdownEndsOnTheEvaluationTableAndSplitsEveryPixelOnce) {
  TempDir tmp;
  std::ostringstream log;
  Train(TinyV2Options(tmp.path() / "v2", 1), log);
  const std::string weights = (tmp.path() / "v2" / "model.safetensors").string();
  TrainOptions eval = TinyOptions(tmp.path() / "unused", 1);
  eval.checkpoint_dir.clear();
  eval.num_validation_scenes = 2;
  eval.eval_coarse_iterations = 2;
  eval.eval_fine_iterations = 3;
  const ErrorBreakdown breakdown = EvaluateErrorBreakdown(weights, eval, 0);
  ASSERT_EQ(breakdown.iterations.size(), 5u);
  EXPECT_EQ(breakdown.iterations[0].label, "coarse 1");
  EXPECT_EQ(breakdown.iterations[1].label, "coarse 2");
  EXPECT_EQ(breakdown.iterations[2].label, "fine 1");
  EXPECT_EQ(breakdown.iterations[4].label, "fine 3");
  // The last iteration is the output the evaluation table scores (same
  // scenes, same seeds), computed independently by the eval-mode pass.
  const WideningResult table = EvaluateWeights(weights, eval, {0}).front();
  const BreakdownRow& last = breakdown.iterations.back();
  EXPECT_EQ(last.depth.gt_pixels, table.metrics.gt_pixels);
  EXPECT_DOUBLE_EQ(last.depth.within_1, table.metrics.within_1);
  EXPECT_DOUBLE_EQ(last.depth.within_2, table.metrics.within_2);
  EXPECT_DOUBLE_EQ(last.depth.abs_rel, table.metrics.abs_rel);
  EXPECT_DOUBLE_EQ(last.source_pixels.within_1px, table.source_pixels.within_1px);
  // Texture and depth thirds: every ground-truth pixel in exactly one band,
  // each band about a third, and the bands' hits add up to the whole.
  for (const auto* bands : {&breakdown.texture, &breakdown.depth}) {
    ASSERT_EQ(bands->size(), 3u);
    int64_t pixels = 0;
    double within_2 = 0;
    for (const BreakdownRow& band : *bands) {
      pixels += band.depth.gt_pixels;
      within_2 += band.depth.within_2 * static_cast<double>(band.depth.gt_pixels);
      EXPECT_NEAR(static_cast<double>(band.depth.gt_pixels) / table.metrics.gt_pixels, 1.0 / 3, 0.05)
          << band.label;
    }
    EXPECT_EQ(pixels, table.metrics.gt_pixels);
    EXPECT_NEAR(within_2, table.metrics.within_2 * static_cast<double>(pixels), 1e-6);
  }
  // The coarse matches: "all" is the table's coarse top-1; every counted
  // pair's cell is in exactly one texture and one depth third, so the
  // thirds' pairs and hits add up to all's; more peaks, more hits.
  ASSERT_EQ(breakdown.coarse_matches.size(), 7u);
  const CoarseMatchRow& all = breakdown.coarse_matches[0];
  EXPECT_EQ(all.label, "all");
  EXPECT_NEAR(all.top1, table.coarse_top1, 1e-12);
  EXPECT_NEAR(all.top4_peaks, table.coarse_top4_peaks, 1e-12);
  EXPECT_EQ(static_cast<double>(all.pairs), table.matching_count);
  EXPECT_GT(all.pairs, 0);
  for (size_t first : {1u, 4u}) {
    int64_t pairs = 0;
    double top1 = 0, top2 = 0;
    for (size_t b = first; b < first + 3; ++b) {
      const CoarseMatchRow& row = breakdown.coarse_matches[b];
      pairs += row.pairs;
      top1 += row.top1 * static_cast<double>(row.pairs);
      top2 += row.top2_peaks * static_cast<double>(row.pairs);
      EXPECT_LE(row.top1, row.top2_peaks) << row.label;
      EXPECT_LE(row.top2_peaks, row.top4_peaks) << row.label;
    }
    EXPECT_EQ(pairs, all.pairs);
    EXPECT_NEAR(top1, all.top1 * static_cast<double>(all.pairs), 1e-6);
    EXPECT_NEAR(top2, all.top2_peaks * static_cast<double>(all.pairs), 1e-6);
  }
  EXPECT_EQ(breakdown.coarse_matches[1].label, "texture weak");
  EXPECT_EQ(breakdown.coarse_matches[6].label, "depth far");
  // The true matches through the geometry give the true depth (float
  // rounding); the true depth on the fine grid, upsampled, comes close.
  ASSERT_EQ(breakdown.oracles.size(), 2u);
  EXPECT_EQ(breakdown.oracles[0].label, "oracle matches");
  EXPECT_GT(breakdown.oracles[0].depth.within_1, 0.999);
  EXPECT_LT(breakdown.oracles[0].depth.abs_rel, 1e-4);
  EXPECT_GT(breakdown.oracles[0].source_pixels.within_1px, 0.999);
  EXPECT_EQ(breakdown.oracles[1].depth.gt_pixels, table.metrics.gt_pixels);
  // Measured 0.687 on these tiny scenes (a 1/4 grid of a few cells per
  // surface: edges everywhere); 0.964 on the 640x512 validation scenes.
  EXPECT_GT(breakdown.oracles[1].depth.within_5, 0.6);
  EXPECT_LT(breakdown.oracles[1].depth.within_1, breakdown.oracles[0].depth.within_1);
  EXPECT_EQ(breakdown.texture[0].label, "texture weak");
  EXPECT_EQ(breakdown.depth[2].label, "depth far");
  const std::string text = FormatBreakdown(breakdown);
  EXPECT_NE(text.find("fine 3          <1%: "), std::string::npos) << text;
  EXPECT_NE(text.find("texture strong  <1%: "), std::string::npos) << text;

  // With the photometric refinement: one more row, the evaluation table's
  // with it (validation.cc refines the eval-mode output; the breakdown its
  // last iteration), and the rows before it unchanged.
  eval.eval_refinement = "ncc";
  const ErrorBreakdown refined = EvaluateErrorBreakdown(weights, eval, 0);
  ASSERT_EQ(refined.iterations.size(), 6u);
  EXPECT_EQ(refined.iterations.back().label, "refined");
  EXPECT_DOUBLE_EQ(refined.iterations[4].depth.within_2, last.depth.within_2);
  const WideningResult refined_table = EvaluateWeights(weights, eval, {0}).front();
  EXPECT_EQ(refined.iterations.back().depth.gt_pixels, refined_table.metrics.gt_pixels);
  EXPECT_DOUBLE_EQ(refined.iterations.back().depth.within_1, refined_table.metrics.within_1);
  EXPECT_DOUBLE_EQ(refined.iterations.back().depth.within_2, refined_table.metrics.within_2);
}

TEST(TrainerV2Test, EvaluationWithoutAHintOnlyForV2Weights) {
  TempDir tmp;
  std::ostringstream log;
  auto v2 = TinyV2Options(tmp.path() / "v2", 1);
  Train(v2, log);
  auto paper = TinyOptions(tmp.path() / "paper", 1);
  Train(paper, log);
  TrainOptions eval = TinyOptions(tmp.path() / "unused", 1);
  eval.checkpoint_dir.clear();
  eval.num_validation_scenes = 1;
  const auto rows = EvaluateWeights((tmp.path() / "v2" / "model.safetensors").string(), eval, {1, 0});
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[1].widening, 0);
  EXPECT_GT(rows[1].metrics.gt_pixels, 0);
  EXPECT_GT(rows[1].matching_count, 0);
  EXPECT_GE(rows[1].coarse_top1, 0.0);
  EXPECT_LE(rows[1].coarse_top1, rows[1].coarse_top2_peaks);
  EXPECT_LE(rows[1].coarse_top2_peaks, rows[1].coarse_top4_peaks);
  EXPECT_LE(rows[1].coarse_top4_peaks, 1.0);
  EXPECT_THROW(EvaluateWeights((tmp.path() / "paper" / "model.safetensors").string(), eval, {0}),
               std::invalid_argument);
}

// bf16 training steps. Step 1 (the matching warm-up) starts both runs from
// the same weights on the same scene, and its logged depth loss is the
// network's forward pass through the GRU: bf16 must change it (the rounding
// is in effect) but by less than 1 %. bf16 keeps 8 bits of mantissa, a
// relative rounding of 2^-9 per operand that averages out over the loss; 1 %
// off fp32 would mean the arithmetic biases training rather than rounds it
// (measured: 8e-5 at step 1, 3e-6 at step 2). The run says which arithmetic
// it used.
TEST(TrainerV2Test, Bf16StepsTrainTheSameLossInOtherArithmetic) {
  TempDir tmp;
  std::ostringstream fp32_log, bf16_log;
  const auto fp32_options = TinyV2Options(tmp.path() / "fp32", 2);
  auto bf16_options = TinyV2Options(tmp.path() / "bf16", 2);
  bf16_options.precision = "bf16";
  Train(fp32_options, fp32_log);
  Train(bf16_options, bf16_log);
  EXPECT_NE(fp32_log.str().find("GRU convolutions in fp32"), std::string::npos) << fp32_log.str();
  EXPECT_NE(bf16_log.str().find("GRU convolutions in bf16"), std::string::npos) << bf16_log.str();
  EXPECT_NE(ReadFileBytes(tmp.path() / "fp32" / "model.safetensors"),
            ReadFileBytes(tmp.path() / "bf16" / "model.safetensors"));
  const StepLosses fp32_first = LoggedStepLosses(fp32_log.str(), 1);
  const StepLosses bf16_first = LoggedStepLosses(bf16_log.str(), 1);
  EXPECT_NE(bf16_first.depth, fp32_first.depth) << "the bf16 forward pass rounded nothing";
  EXPECT_NEAR(bf16_first.depth, fp32_first.depth, 0.01 * std::abs(fp32_first.depth));
  const StepLosses fp32_second = LoggedStepLosses(fp32_log.str(), 2);
  const StepLosses bf16_second = LoggedStepLosses(bf16_log.str(), 2);
  ASSERT_TRUE(std::isfinite(bf16_second.loss)) << bf16_log.str();
  EXPECT_NEAR(bf16_second.loss, fp32_second.loss, 0.01 * std::abs(fp32_second.loss));
}

// The validation inside a bf16 run is fp32 (its numbers compare across
// runs whatever their --precision), and it puts the steps back in bf16.
TEST(TrainerV2Test, InRunValidationIsFp32AndTheStepsStayBf16) {
  TempDir tmp;
  auto plain = TinyV2Options(tmp.path() / "plain", 3);
  plain.precision = "bf16";
  plain.height = 96;
  plain.width = 128;
  plain.num_validation_scenes = 2;
  auto validated = plain;
  validated.checkpoint_dir = (tmp.path() / "validated").string();
  validated.validate_every = 1;
  validated.checkpoint_every = 1;
  validated.keep_weights_every = 1;
  std::ostringstream plain_log, validated_log;
  Train(plain, plain_log);
  Train(validated, validated_log);
  // Steps 2 and 3 ran after a validation: in fp32 they would end elsewhere.
  EXPECT_TRUE(ReadFileBytes(tmp.path() / "validated" / "model.safetensors") ==
              ReadFileBytes(tmp.path() / "plain" / "model.safetensors"))
      << "the steps after a validation ran in another arithmetic";

  // Step 1's logged metrics are fp32's evaluation of step 1's weights.
  const std::string step1 = (tmp.path() / "validated" / "weights-000000001.safetensors").string();
  auto eval_options = validated;
  eval_options.precision = "fp32";
  const std::string fp32 = FormatMetrics(EvaluateWeights(step1, eval_options, {1.0}).front().metrics);
  eval_options.precision = "bf16";
  const std::string bf16 = FormatMetrics(EvaluateWeights(step1, eval_options, {1.0}).front().metrics);
  ASSERT_NE(fp32, bf16) << "bf16 and fp32 evaluations agree to the logged digits";
  const size_t at = validated_log.str().find("validate step 1  cpu");
  ASSERT_NE(at, std::string::npos) << validated_log.str();
  const std::string line = validated_log.str().substr(at, validated_log.str().find('\n', at) - at);
  EXPECT_NE(line.find(fp32), std::string::npos) << line << "\nfp32: " << fp32 << "\nbf16: " << bf16;
}

TEST(TrainerV2Test, DifficultyRampsLinearlyToOne) {
  TrainOptions o;
  EXPECT_EQ(TrainingDifficultyAt(o, 0), 1.0);
  o.difficulty_start = 0.2;
  o.difficulty_ramp_steps = 10;
  EXPECT_DOUBLE_EQ(TrainingDifficultyAt(o, 0), 0.2);
  EXPECT_DOUBLE_EQ(TrainingDifficultyAt(o, 5), 0.6);
  EXPECT_EQ(TrainingDifficultyAt(o, 10), 1.0);
  EXPECT_EQ(TrainingDifficultyAt(o, 1000), 1.0);
}

void ExpectRejected(const TrainOptions& options, const std::string& needle) {
  try {
    options.Check();
    FAIL() << "expected rejection mentioning " << needle;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(TrainerTest, BadOptionsAreRejectedByName) {
  const auto good = TinyOptions("some_dir", 2);
  EXPECT_NO_THROW(good.Check());
  auto o = good;
  o.config = "huge";
  ExpectRejected(o, "config");
  o = good;
  o.height = 0;
  ExpectRejected(o, "height");
  o = good;
  o.num_sources = 0;
  ExpectRejected(o, "num_sources");
  o = good;
  o.lr = -1;
  ExpectRejected(o, "lr");
  o = good;
  o.grad_clip = std::nan("");
  ExpectRejected(o, "grad_clip");
  o = good;
  o.device = "tpu";
  ExpectRejected(o, "device");
  o = good;
  o.train_widening_max = 0.5;
  ExpectRejected(o, "train_widening_max");
  o = good;
  o.source_counts = {1, 3};  // more than num_sources = 2
  ExpectRejected(o, "source_counts");
  o.source_counts = {0};
  ExpectRejected(o, "source_counts");
  o = good;
  o.photometry = "vivid";
  ExpectRejected(o, "photometry");
  o = good;
  o.specular_probability = -0.1;
  ExpectRejected(o, "specular_probability");
  o = good;
  o.supersampling = 2;
  ExpectRejected(o, "supersampling");
  o = good;
  o.jpeg_quality_min = 0;
  o.jpeg_quality_max = 80;
  ExpectRejected(o, "jpeg_quality");
  o.jpeg_quality_min = 90;
  ExpectRejected(o, "jpeg_quality");
  o = good;
  o.val_supersampling = 9;
  ExpectRejected(o, "val_supersampling must be odd");
  o = good;
  o.depth_loss = "l2";
  ExpectRejected(o, "depth_loss");
  o = good;  // the paper's design has no fine-stage matches to supervise
  o.flow_loss_weight = 0.5;
  ExpectRejected(o, "flow_loss_weight needs a v2 config");
  o = TinyV2Options("some_dir", 2);
  o.flow_loss_weight = -1;
  ExpectRejected(o, "flow_loss_weight must be");
  o.train_widening_max = std::nan("");
  ExpectRejected(o, "train_widening_max");
  o = good;
  o.checkpoint_every = 0;
  ExpectRejected(o, "checkpoint_every");
  o = good;
  o.checkpoint_every = 2;
  o.keep_weights_every = 3;
  ExpectRejected(o, "keep_weights_every must be 0 or a multiple of checkpoint_every (2), got 3");
  o.keep_weights_every = -2;
  ExpectRejected(o, "keep_weights_every");
  o = good;
  o.lr_warmup_steps = -1;
  ExpectRejected(o, "lr_warmup_steps");
  o = good;
  o.eval_fine_iterations = 1;
  ExpectRejected(o, "eval_fine_iterations is for evaluation only");
  o = good;
  o.eval_coarse_iterations = -1;
  ExpectRejected(o, "eval_coarse_iterations");
  o = good;
  o.precision = "fp16";
  ExpectRejected(o, "precision must be auto, fp32 or bf16");
  o = good;
  o.checkpoint_dir.clear();
  ExpectRejected(o, "checkpoint_dir");
  EXPECT_NO_THROW(o.Check(/*for_training=*/false));
  o.eval_fine_iterations = 1;
  EXPECT_NO_THROW(o.Check(/*for_training=*/false));
}

TEST(TrainerTest, LearningRateHalvesEveryKStepsAndSeedsAreDisjoint) {
  TrainOptions o;
  o.lr = 2e-4;
  o.lr_halve_every = 10;
  EXPECT_EQ(LearningRateAt(o, 0), 2e-4);
  EXPECT_EQ(LearningRateAt(o, 9), 2e-4);
  EXPECT_EQ(LearningRateAt(o, 10), 1e-4);
  EXPECT_EQ(LearningRateAt(o, 25), 5e-5);
  o.lr_halve_every = 0;
  EXPECT_EQ(LearningRateAt(o, 1000), 2e-4);
  // Warm-up: linear from lr / K at step 0 to lr at step K - 1, then constant.
  o.lr_warmup_steps = 4;
  EXPECT_DOUBLE_EQ(LearningRateAt(o, 0), 0.5e-4);
  EXPECT_DOUBLE_EQ(LearningRateAt(o, 2), 1.5e-4);
  EXPECT_DOUBLE_EQ(LearningRateAt(o, 3), 2e-4);
  EXPECT_DOUBLE_EQ(LearningRateAt(o, 4), 2e-4);
  o.lr_halve_every = 2;  // both: the halving applies under the warm-up
  EXPECT_DOUBLE_EQ(LearningRateAt(o, 2), 2e-4 * 0.5 * 0.75);
  o.lr_warmup_steps = 0;
  o.lr_halve_every = 0;
  // Training seeds have the top bit set; validation seeds are small.
  EXPECT_GE(TrainingSampleSeed(0, 0, 0), uint64_t{1} << 63);
  EXPECT_NE(TrainingSampleSeed(0, 0, 1), TrainingSampleSeed(0, 1, 0));
  EXPECT_NE(TrainingSampleSeed(0, 1, 0), TrainingSampleSeed(1, 1, 0));
}

TEST(TrainerTest, TrainingWideningIsLogUniformAndDeterministic) {
  TrainOptions o;
  EXPECT_EQ(TrainingWideningAt(o, 7), 1.0);  // off by default
  o.train_widening_max = 3;
  int below_sqrt3 = 0;
  const int n = 4000;
  for (int step = 0; step < n; ++step) {
    const double x = TrainingWideningAt(o, step);
    ASSERT_GE(x, 1.0);
    ASSERT_LT(x, 3.0);
    ASSERT_EQ(x, TrainingWideningAt(o, step));
    below_sqrt3 += x < std::sqrt(3.0);
  }
  // Log-uniform: half the draws below sqrt(3) (binomial sd ~ 32 of 4000).
  EXPECT_NEAR(below_sqrt3, n / 2, 160);
  TrainOptions other = o;
  other.seed = 1;
  EXPECT_NE(TrainingWideningAt(o, 3), TrainingWideningAt(other, 3));
}

// The depth loss of the first step of a one-step run.
double FirstStepDepthLoss(const TrainOptions& options) {
  std::ostringstream log;
  Train(options, log);
  return LoggedStepLosses(log.str()).depth;
}

// The widened hint reaches the network, the loss stays normalised by the
// true range, and resuming with another widening is refused. The paper's
// design draws its start inside the hint, so its first step changes; model
// v2 uses no hint (only as a fallback where nothing matched), so its first
// step's depth loss stays what it was unwidened, which it would not if the
// loss were normalised by the widened range.
TEST(TrainerTest, WideningReachesTheStartNotTheLossAndIsARunSetting) {
  TempDir tmp;
  auto plain = TinyOptions(tmp.path() / "plain", 1);
  auto widened = TinyOptions(tmp.path() / "widened", 1);
  widened.train_widening_max = 100;
  ASSERT_GT(TrainingWideningAt(widened, 0), 2.0);  // a real widening at the first step
  const double plain_loss = FirstStepDepthLoss(plain);
  EXPECT_NE(FirstStepDepthLoss(widened), plain_loss);

  auto plain_v2 = TinyOptions(tmp.path() / "plain_v2", 1);
  plain_v2.config = "small_v2";
  auto widened_v2 = plain_v2;
  widened_v2.checkpoint_dir = (tmp.path() / "widened_v2").string();
  widened_v2.train_widening_max = widened.train_widening_max;
  const double plain_v2_loss = FirstStepDepthLoss(plain_v2);
  EXPECT_NEAR(FirstStepDepthLoss(widened_v2), plain_v2_loss, 1e-4 * plain_v2_loss + 1e-5);

  std::ostringstream log;
  widened.steps = 3;
  widened.train_widening_max = 2;
  try {
    Train(widened, log);
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("different run (train_widening_max"), std::string::npos) << e.what();
  }
}

// Largest absolute difference between the same-named tensors of two weights
// files (which must hold the same names).
double MaxWeightDifference(const fs::path& a, const fs::path& b) {
  const model::SafetensorsFile fa = model::LoadSafetensors(a.string());
  const model::SafetensorsFile fb = model::LoadSafetensors(b.string());
  std::map<std::string, torch::Tensor> by_name(fb.tensors.begin(), fb.tensors.end());
  double worst = 0;
  for (const auto& [name, tensor] : fa.tensors) {
    const auto other = by_name.find(name);
    if (other == by_name.end()) return INFINITY;
    worst = std::max(worst, (tensor - other->second).abs().max().item<double>());
  }
  return worst;
}

// --init_weights: a run starts from the given weights (one step at a tiny
// learning rate stays next to them, far from a random start), the weights
// are a run setting, and a missing or unfitting file is refused up front.
TEST(TrainerTest, InitWeightsStartFromTheFileAndAreARunSetting) {
  TempDir tmp;
  auto source = TinyOptions(tmp.path() / "source", 2);
  source.seed = 5;  // another random start than the runs below (seed 0)
  RunAndReadWeights(source);
  const fs::path source_weights = tmp.path() / "source" / "model.safetensors";

  auto tuned = TinyOptions(tmp.path() / "tuned", 1);
  tuned.lr = 1e-9;
  tuned.init_weights = source_weights.string();
  std::ostringstream log;
  Train(tuned, log);
  EXPECT_NE(log.str().find("initialised from " + source_weights.string()), std::string::npos)
      << log.str();
  auto fresh = TinyOptions(tmp.path() / "fresh", 1);
  fresh.lr = 1e-9;
  RunAndReadWeights(fresh);
  EXPECT_LT(MaxWeightDifference(tmp.path() / "tuned" / "model.safetensors", source_weights), 1e-6);
  EXPECT_GT(MaxWeightDifference(tmp.path() / "fresh" / "model.safetensors", source_weights), 1e-3);

  // Same bytes under another path resume; other weights do not.
  const fs::path copy = tmp.path() / "copy.safetensors";
  fs::copy_file(source_weights, copy);
  tuned.init_weights = copy.string();
  tuned.steps = 2;
  Train(tuned, log);
  tuned.init_weights = (tmp.path() / "fresh" / "model.safetensors").string();
  tuned.steps = 3;
  try {
    Train(tuned, log);
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("different run (init_weights"), std::string::npos) << e.what();
  }

  auto missing = TinyOptions(tmp.path() / "missing", 1);
  missing.init_weights = (tmp.path() / "nothing.safetensors").string();
  try {
    Train(missing, log);
    FAIL() << "expected a refusal";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("init_weights: no such file"), std::string::npos) << e.what();
  }
  // Paper-size weights do not fit the small network: refused before step 1.
  const fs::path paper_weights = tmp.path() / "paper.safetensors";
  model::DispMvsNet paper(model::ModelConfig::Paper());
  model::SaveModuleWeights(*paper, model::ModelConfig::Paper(), paper_weights.string());
  auto unfitting = TinyOptions(tmp.path() / "unfitting", 1);
  unfitting.init_weights = paper_weights.string();
  std::ostringstream unfitting_log;
  EXPECT_ANY_THROW(Train(unfitting, unfitting_log));
  EXPECT_EQ(unfitting_log.str().find("step 1/1"), std::string::npos) << unfitting_log.str();
  EXPECT_FALSE(fs::exists(tmp.path() / "unfitting" / "model.safetensors"));
}

}  // namespace
}  // namespace dispmvs::train
