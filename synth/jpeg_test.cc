// The simulated JPEG round trip (synth/jpeg.h) against a real codec: OpenCV's
// libjpeg encoding and decoding the same 8-bit image at the same quality.

#include "synth/jpeg.h"

#include <cmath>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

namespace dispmvs::synth {
namespace {

// A test card [3,H,W] in [0, 1]: smooth colour ramps, a sharp-edged
// saturated disc (colour edges smear under 4:2:0) and fine pseudo-random
// texture (high frequencies the tables quantise away).
torch::Tensor TestCard(int64_t h, int64_t w) {
  const torch::Tensor y = torch::arange(h, torch::kDouble).view({h, 1}).expand({h, w}) / static_cast<double>(h);
  const torch::Tensor x = torch::arange(w, torch::kDouble).view({1, w}).expand({h, w}) / static_cast<double>(w);
  const torch::Tensor texture = 0.5 + 0.5 * torch::sin(37.0 * x * x + 53.0 * y + 91.0 * x * y);
  const torch::Tensor disc = ((x - 0.6) * (x - 0.6) + (y - 0.4) * (y - 0.4) < 0.04).to(torch::kDouble);
  torch::Tensor r = 0.2 + 0.5 * x + 0.3 * texture * (1 - disc);
  torch::Tensor g = 0.1 + 0.6 * y * (1 - disc) + 0.2 * texture;
  torch::Tensor b = 0.8 - 0.5 * x * y + 0.15 * disc;
  return torch::clamp(torch::stack({r, g, b}), 0, 1);
}

// The 8-bit RGB image as libjpeg decodes the JPEG file it wrote: [3,H,W] in [0, 1].
torch::Tensor LibjpegRoundTrip(const torch::Tensor& image, int quality) {
  const int64_t h = image.size(1), w = image.size(2);
  const torch::Tensor bgr8 = torch::floor(torch::clamp(image, 0, 1) * 255.0 + 0.5)
                                 .flip(0).permute({1, 2, 0}).contiguous().to(torch::kUInt8);
  const cv::Mat mat(static_cast<int>(h), static_cast<int>(w), CV_8UC3, bgr8.data_ptr<uint8_t>());
  std::vector<uchar> file;
  EXPECT_TRUE(cv::imencode(".jpg", mat, file, {cv::IMWRITE_JPEG_QUALITY, quality}));
  const cv::Mat decoded = cv::imdecode(file, cv::IMREAD_COLOR);
  EXPECT_EQ(decoded.rows, h);
  EXPECT_EQ(decoded.cols, w);
  return torch::from_blob(decoded.data, {h, w, 3}, torch::kUInt8).permute({2, 0, 1}).flip(0).to(torch::kDouble) / 255.0;
}

TEST(JpegTest, QuantisationTablesFollowTheQualityScaling) {
  const std::array<int, 64> luma50 = JpegQuantisationTable(50, false), chroma50 = JpegQuantisationTable(50, true);
  EXPECT_EQ(luma50[0], 16);  // Annex K.1 as printed
  EXPECT_EQ(luma50[1], 11);
  EXPECT_EQ(luma50[63], 99);
  EXPECT_EQ(chroma50[0], 17);
  EXPECT_EQ(chroma50[63], 99);
  // 75: half the entries, rounded (16 -> 8, 11 -> 5.5 -> 6, 99 -> 49.5 -> 50).
  const std::array<int, 64> luma75 = JpegQuantisationTable(75, false);
  EXPECT_EQ(luma75[0], 8);
  EXPECT_EQ(luma75[1], 6);
  EXPECT_EQ(luma75[63], 50);
  // 10: five times, capped at 255 for baseline files.
  const std::array<int, 64> luma10 = JpegQuantisationTable(10, false);
  EXPECT_EQ(luma10[0], 80);
  EXPECT_EQ(luma10[63], 255);
  for (int entry : JpegQuantisationTable(100, true)) EXPECT_EQ(entry, 1);
  EXPECT_THROW(JpegQuantisationTable(0, false), std::invalid_argument);
  EXPECT_THROW(JpegQuantisationTable(101, true), std::invalid_argument);
}

// The round trip reproduces libjpeg's decoded pixels up to its integer DCT
// and fixed-point colour conversion: the same compression error within 3 %,
// and per pixel within a tenth of that error (well under a grey level), on
// image sizes that fill whole 16 x 16 blocks and on sizes that do not.
TEST(JpegTest, MatchesLibjpegAtSeveralQualities) {
  for (const auto& [h, w] : {std::pair<int64_t, int64_t>{64, 96}, {50, 73}, {240, 320}}) {
    const torch::Tensor card = TestCard(h, w);
    const torch::Tensor card8 = torch::floor(card * 255.0 + 0.5) / 255.0;
    for (int quality : {10, 30, 50, 75, 95}) {
      SCOPED_TRACE(testing::Message() << h << "x" << w << " quality " << quality);
      const torch::Tensor ours = JpegRoundTrip(card, quality);
      const torch::Tensor theirs = LibjpegRoundTrip(card, quality);
      ASSERT_EQ(ours.sizes(), card.sizes());
      EXPECT_TRUE(torch::equal(torch::round(ours * 255.0), ours * 255.0));  // 8-bit samples
      // Mean absolute errors in grey levels.
      const double their_error = (theirs - card8).abs().mean().item<double>() * 255.0;
      const double our_error = (ours - card8).abs().mean().item<double>() * 255.0;
      const double difference = (ours - theirs).abs().mean().item<double>() * 255.0;
      EXPECT_GT(their_error, 1.0);
      EXPECT_NEAR(our_error / their_error, 1.0, 0.03);
      EXPECT_LT(difference, 0.6);
      if (their_error >= 2.0) {
        EXPECT_LT(difference, 0.1 * their_error);
      }
    }
  }
}

TEST(JpegTest, KeepsDtypeAndRejectsBadInput) {
  const torch::Tensor card = TestCard(16, 16).to(torch::kFloat);
  EXPECT_EQ(JpegRoundTrip(card, 90).scalar_type(), torch::kFloat);
  EXPECT_THROW(JpegRoundTrip(card, 0), std::invalid_argument);
  EXPECT_THROW(JpegRoundTrip(card[0], 90), std::invalid_argument);
  EXPECT_THROW(JpegRoundTrip(torch::zeros({3, 0, 5}), 90), std::invalid_argument);
  // A 1 x 1 image is one padded block.
  const torch::Tensor dot = torch::full({3, 1, 1}, 0.5, torch::kDouble);
  EXPECT_NEAR(JpegRoundTrip(dot, 90).mean().item<double>(), 0.5, 2.0 / 255.0);
}

}  // namespace
}  // namespace dispmvs::synth
