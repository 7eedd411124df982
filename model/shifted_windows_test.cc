#include "model/shifted_windows.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <stdexcept>

#include <torch/torch.h>

namespace dispmvs::model {
namespace {

// The definition, pixel by pixel: the largest of the score at the pixel and
// at the four pixels `shift` away along the axes that lie in the image.
torch::Tensor BestByDefinition(const torch::Tensor& score, int64_t shift) {
  torch::Tensor best = torch::empty_like(score);
  const auto s = score.accessor<float, 4>();
  auto out = best.accessor<float, 4>();
  const int64_t h = score.size(2), w = score.size(3);
  const int64_t dx[5] = {0, shift, -shift, 0, 0}, dy[5] = {0, 0, 0, shift, -shift};
  for (int64_t b = 0; b < score.size(0); ++b) {
    for (int64_t y = 0; y < h; ++y) {
      for (int64_t x = 0; x < w; ++x) {
        float m = s[b][0][y][x];
        for (int k = 1; k < 5; ++k) {
          const int64_t yy = y + dy[k], xx = x + dx[k];
          if (yy >= 0 && yy < h && xx >= 0 && xx < w) m = std::max(m, s[b][0][yy][xx]);
        }
        out[b][0][y][x] = m;
      }
    }
  }
  return best;
}

TEST(ShiftedWindows, TheLoopAndTheOperationsFollowTheDefinition) {
  torch::manual_seed(3);
  // Two images, so that a shift down the rows must not reach the next one;
  // shifts past the width and the height leave the centred window alone.
  const torch::Tensor score = 2.0f * torch::rand({2, 1, 7, 9}) - 1.0f;
  for (const int64_t shift : {0, 1, 2, 3, 6, 7, 8, 9, 12}) {
    SCOPED_TRACE(shift);
    const torch::Tensor expected = BestByDefinition(score, shift);
    EXPECT_TRUE(torch::equal(BestOfShiftedWindows(score, shift), expected));
    EXPECT_TRUE(torch::equal(BestOfShiftedWindowsByOps(score, shift), expected));
  }
  // Never below the centred window's score, and at shift 0 that score.
  EXPECT_TRUE((BestOfShiftedWindows(score, 2) >= score).all().item<bool>());
  EXPECT_TRUE(torch::equal(BestOfShiftedWindows(score, 0), score));
}

TEST(ShiftedWindows, OtherTypesTakeTheOperations) {
  torch::manual_seed(4);
  const torch::Tensor score = torch::rand({1, 1, 5, 6}, torch::kFloat64);
  const torch::Tensor expected = BestByDefinition(score.to(torch::kFloat32), 2);
  EXPECT_TRUE(torch::equal(BestOfShiftedWindows(score, 2).to(torch::kFloat32), expected));
  // A non-contiguous map gives the same as its contiguous copy.
  const torch::Tensor wide = torch::rand({1, 1, 6, 5}).transpose(2, 3);
  EXPECT_TRUE(torch::equal(BestOfShiftedWindows(wide, 1), BestByDefinition(wide.contiguous(), 1)));
}

TEST(ShiftedWindows, RejectsBadInput) {
  EXPECT_THROW(BestOfShiftedWindows(torch::zeros({1, 2, 4, 4}), 1), std::invalid_argument);
  EXPECT_THROW(BestOfShiftedWindows(torch::zeros({4, 4}), 1), std::invalid_argument);
  EXPECT_THROW(BestOfShiftedWindows(torch::zeros({1, 1, 4, 4}, torch::kInt32), 1), std::invalid_argument);
  EXPECT_THROW(BestOfShiftedWindows(torch::zeros({1, 1, 4, 4}), -1), std::invalid_argument);
  EXPECT_THROW(BestOfShiftedWindowsByOps(torch::zeros({1, 1, 4, 4}), -1), std::invalid_argument);
}

}  // namespace
}  // namespace dispmvs::model
