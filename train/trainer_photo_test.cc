// Training with photo textures (--texture_dir): writes its photos with
// OpenCV, so it is part of the full build.

#include <filesystem>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "tests/support/temp_dir.h"
#include "train/step_log_test_util.h"
#include "train/trainer.h"

namespace dispmvs::train {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;

TrainOptions TinyOptions(const fs::path& dir) {
  TrainOptions o;
  o.height = 48;
  o.width = 64;
  o.num_sources = 2;
  o.steps = 2;
  o.threads = 1;
  o.checkpoint_dir = dir.string();
  o.checkpoint_every = 1;
  o.num_validation_scenes = 0;
  return o;
}

// Photos reach the training scenes: the first step, from the same weights on
// the same geometry, sees other images than a procedural run's and so has
// another loss, while a second procedural run repeats the first exactly. The
// folder is a run setting (a changed folder is refused on resume), and a
// missing folder is refused up front.
TEST(TrainerPhotoTest, PhotoTexturesTrainDifferentlyAndAreARunSetting) {
  TempDir tmp;
  const fs::path photos = tmp.path() / "photos";
  fs::create_directories(photos);
  cv::Mat noise(64, 96, CV_8UC3);
  cv::randu(noise, cv::Scalar::all(0), cv::Scalar::all(255));
  cv::imwrite((photos / "noise.png").string(), noise);
  cv::imwrite((photos / "stripes.png").string(), cv::Mat(40, 40, CV_8UC3, cv::Scalar(30, 160, 90)));

  auto procedural = TinyOptions(tmp.path() / "procedural");
  auto procedural_again = TinyOptions(tmp.path() / "procedural_again");
  auto with_photos = TinyOptions(tmp.path() / "photos_run");
  with_photos.texture_dir = photos.string();
  with_photos.photo_probability = 1;
  std::ostringstream procedural_log, again_log, log;
  Train(procedural, procedural_log);
  Train(procedural_again, again_log);
  Train(with_photos, log);
  EXPECT_NE(log.str().find("photo textures: 2 photos from " + photos.string()), std::string::npos)
      << log.str();
  const double procedural_loss = LoggedStepLosses(procedural_log.str()).loss;
  EXPECT_EQ(LoggedStepLosses(again_log.str()).loss, procedural_loss);
  EXPECT_NE(LoggedStepLosses(log.str()).loss, procedural_loss);

  cv::imwrite((photos / "third.png").string(), noise);
  with_photos.steps = 3;
  try {
    Train(with_photos, log);
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("different run (texture_dir"), std::string::npos) << e.what();
  }
  auto missing = TinyOptions(tmp.path() / "missing");
  missing.texture_dir = (tmp.path() / "no_such_folder").string();
  EXPECT_THROW(Train(missing, log), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::train
