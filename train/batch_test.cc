#include "train/batch.h"

#include <gtest/gtest.h>

namespace dispmvs::train {
namespace {

// A hand-made sample: V views of H x W, reference depth 3 except one hole.
synth::SynthSample FakeSample(int64_t views, int64_t h, int64_t w, double d_min, double d_max, float fill) {
  synth::SynthSample s;
  s.images = torch::full({views, 3, h, w}, fill);
  s.intrinsics = torch::eye(3).expand({views, 3, 3}).clone();
  s.world_to_camera = torch::eye(4).expand({views, 4, 4}).clone();
  s.depths = torch::full({views, 1, h, w}, 3.0f);
  s.depths[0][0][0][0] = 0;  // no surface at the reference's first pixel
  s.depths[1].fill_(7.0f);   // a source depth must not leak into the GT
  s.depth_min = d_min;
  s.depth_max = d_max;
  return s;
}

TEST(MakeBatchTest, StacksViewsAndTakesReferenceDepth) {
  const auto batch = MakeBatch({FakeSample(3, 4, 5, 2, 8, 0.25f), FakeSample(3, 4, 5, 1, 4, 0.5f)});
  EXPECT_EQ(batch.input.images.sizes(), (std::vector<int64_t>{2, 3, 3, 4, 5}));
  EXPECT_EQ(batch.input.intrinsics.sizes(), (std::vector<int64_t>{2, 3, 3, 3}));
  EXPECT_EQ(batch.input.extrinsics.sizes(), (std::vector<int64_t>{2, 3, 4, 4}));
  EXPECT_EQ(batch.gt_depth.sizes(), (std::vector<int64_t>{2, 1, 4, 5}));
  EXPECT_EQ(batch.input.images[1][2][0][3][4].item<float>(), 0.5f);
  EXPECT_EQ(batch.gt_depth.max().item<float>(), 3.0f);
  EXPECT_EQ(batch.gt_valid.sum().item<int64_t>(), 2 * 20 - 2);
  EXPECT_FALSE(batch.gt_valid[1][0][0][0].item<bool>());
  EXPECT_EQ(batch.input.depth_min[0].item<float>(), 2.0f);
  EXPECT_EQ(batch.input.depth_max[1].item<float>(), 4.0f);
  EXPECT_EQ(batch.input.depth_min.scalar_type(), torch::kFloat);
}

TEST(MakeBatchTest, WideningDividesMinAndMultipliesMax) {
  const auto batch = MakeBatch({FakeSample(2, 2, 2, 2, 8, 0)}, 3.0);
  EXPECT_FLOAT_EQ(batch.input.depth_min[0].item<float>(), 2.0f / 3.0f);
  EXPECT_FLOAT_EQ(batch.input.depth_max[0].item<float>(), 24.0f);
}

TEST(MakeBatchTest, AllViewsDepthsAndNoHintAtZeroWidening) {
  const auto batch = MakeBatch({FakeSample(3, 4, 5, 2, 8, 0.25f)}, 0.0);
  EXPECT_FALSE(batch.input.depth_min.defined());
  EXPECT_FALSE(batch.input.depth_max.defined());
  ASSERT_EQ(batch.gt_depths.sizes(), (std::vector<int64_t>{1, 3, 1, 4, 5}));
  EXPECT_EQ(batch.gt_depths[0][1].max().item<float>(), 7.0f);  // a source's own depth
  EXPECT_TRUE(torch::equal(batch.gt_depths.select(1, 0), batch.gt_depth));
}

TEST(MakeBatchTest, RejectsBadInput) {
  EXPECT_THROW(MakeBatch({}), std::invalid_argument);
  EXPECT_THROW(MakeBatch({FakeSample(2, 2, 2, 0, 0, 0)}), std::invalid_argument);  // empty view
  EXPECT_THROW(MakeBatch({FakeSample(2, 2, 2, 5, 4, 0)}), std::invalid_argument);
  EXPECT_THROW(MakeBatch({FakeSample(2, 2, 2, 1, 4, 0), FakeSample(3, 2, 2, 1, 4, 0)}),
               std::invalid_argument);
  EXPECT_THROW(MakeBatch({FakeSample(2, 2, 2, 1, 4, 0)}, 0.5), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::train
