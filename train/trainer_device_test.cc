// Training and evaluation on a device: CUDA where there is one (skipped
// elsewhere); the CPU instance runs the same code, so the harness itself is
// checked everywhere. On the device: scenes generated there, the network's
// random start drawn from a seeded CPU generator, the sequence and matching
// losses, checkpoints written from the device and resumed into it (Adam
// moments included), validation, the final weights and the evaluation
// table. A quick check before a long GPU run:
//   build/train/train_device_test --gtest_filter='*cuda*'

#include <cmath>
#include <filesystem>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>
#include <torch/cuda.h>
#include <torch/torch.h>

#include "model/config.h"
#include "model/dispmvs_net.h"
#include "model/safetensors.h"
#include "tests/support/temp_dir.h"
#include "train/step_log_test_util.h"
#include "train/trainer.h"

namespace dispmvs::train {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;

TrainOptions DeviceOptions(const fs::path& dir, const std::string& config, const std::string& device,
                           int64_t steps) {
  TrainOptions o;
  o.config = config;
  o.height = 48;
  o.width = 64;
  o.num_sources = 2;
  o.batch_size = 2;
  o.steps = steps;
  o.threads = 1;
  o.device = device;
  o.checkpoint_dir = dir.string();
  o.checkpoint_every = 1;
  o.validate_every = 2;
  o.num_validation_scenes = 1;
  o.train_widening_max = 2;
  o.scene_reuse = 2;
  if (config == "small_v2") o.matching_warmup_steps = 1;
  return o;
}

class TrainerDeviceTest : public ::testing::TestWithParam<std::tuple<std::string, std::string>> {};

TEST_P(TrainerDeviceTest, TrainResumeValidateAndEvaluate) {
  const auto [device, config] = GetParam();
  if (torch::Device(device).is_cuda() && !torch::cuda::is_available()) GTEST_SKIP() << "no CUDA device";
  const bool v2 = config == "small_v2";
  TempDir tmp;
  const fs::path dir = tmp.path() / "run";
  std::ostringstream first, second;
  Train(DeviceOptions(dir, config, device, 2), first);
  EXPECT_NE(first.str().find("validate step 2"), std::string::npos) << first.str();
  Train(DeviceOptions(dir, config, device, 3), second);
  EXPECT_NE(second.str().find("resumed from"), std::string::npos) << second.str();
  EXPECT_NE(second.str().find("at step 2"), std::string::npos) << second.str();
  EXPECT_NE(second.str().find("step 3/3"), std::string::npos) << second.str();
  EXPECT_NE(second.str().find("validate step 3"), std::string::npos) << second.str();
  EXPECT_TRUE(fs::exists(dir / "checkpoint-000000003.optim.safetensors"));

  // The final weights read back into a CPU network, finite.
  const std::string weights = (dir / "model.safetensors").string();
  model::DispMvsNet net(model::ReadModelConfig(weights));
  model::LoadModuleWeights(*net, weights);
  for (const auto& p : net->named_parameters()) {
    EXPECT_TRUE(torch::isfinite(p.value()).all().item<bool>()) << p.key();
  }
  // The Adam moments too (stored from the device).
  const model::SafetensorsFile optim = model::LoadSafetensors((dir / "checkpoint-000000003.optim.safetensors").string());
  EXPECT_FALSE(optim.tensors.empty());
  EXPECT_EQ(optim.metadata.at("adam_step"), "3");

  const std::vector<double> widenings = v2 ? std::vector<double>{1, 0} : std::vector<double>{1, 3};
  TrainOptions evaluation = DeviceOptions(dir, config, device, 0);
  evaluation.checkpoint_dir.clear();
  const std::vector<WideningResult> rows = EvaluateWeights(weights, evaluation, widenings);
  ASSERT_EQ(rows.size(), widenings.size());
  for (const WideningResult& row : rows) {
    EXPECT_GT(row.metrics.gt_pixels, 0);
    EXPECT_TRUE(std::isfinite(row.metrics.abs_rel));
    EXPECT_TRUE(std::isfinite(row.coarse_top1));
    EXPECT_GT(row.matching_count, 0);
  }

  // Against the CPU (trivially equal for the CPU instance): the first step
  // (same weights, scenes up to float rounding, same random start) and the
  // evaluation of the same weights. Loose: cuDNN may use TF32, and arg-max
  // near-ties may break the other way.
  std::ostringstream cpu_log;
  Train(DeviceOptions(tmp.path() / "cpu", config, "cpu", 1), cpu_log);
  const double expected = LoggedStepLosses(cpu_log.str()).loss;
  EXPECT_NEAR(LoggedStepLosses(first.str()).loss, expected, 0.1 * std::abs(expected));
  evaluation.device = "cpu";
  const std::vector<WideningResult> cpu_rows = EvaluateWeights(weights, evaluation, widenings);
  for (size_t i = 0; i < rows.size(); ++i) {
    SCOPED_TRACE("widening " + std::to_string(widenings[i]));
    EXPECT_NEAR(static_cast<double>(rows[i].metrics.gt_pixels), static_cast<double>(cpu_rows[i].metrics.gt_pixels),
                0.01 * static_cast<double>(cpu_rows[i].metrics.gt_pixels));
    EXPECT_NEAR(rows[i].metrics.coverage, cpu_rows[i].metrics.coverage, 0.05);
    EXPECT_NEAR(rows[i].metrics.abs_rel, cpu_rows[i].metrics.abs_rel, 0.05 + 0.1 * cpu_rows[i].metrics.abs_rel);
    EXPECT_NEAR(rows[i].matching_count, cpu_rows[i].matching_count, 0.02 * cpu_rows[i].matching_count);
  }
}

INSTANTIATE_TEST_SUITE_P(DevicesAndDesigns, TrainerDeviceTest,
                         ::testing::Combine(::testing::Values(std::string("cpu"), std::string("cuda")),
                                            ::testing::Values(std::string("small"), std::string("small_v2"))),
                         [](const ::testing::TestParamInfo<TrainerDeviceTest::ParamType>& info) {
                           return std::get<0>(info.param) + "_" + std::get<1>(info.param);
                         });

}  // namespace
}  // namespace dispmvs::train
