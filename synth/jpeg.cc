#include "synth/jpeg.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace dispmvs::synth {
namespace {

namespace F = torch::nn::functional;

// T.81 Annex K.1, Tables K.1 (luminance) and K.2 (chrominance), row-major
// with the row the vertical frequency.
constexpr std::array<int, 64> kLuminanceTable = {
    16, 11, 10, 16, 24,  40,  51,  61,   12, 12, 14, 19, 26,  58,  60,  55,
    14, 13, 16, 24, 40,  57,  69,  56,   14, 17, 22, 29, 51,  87,  80,  62,
    18, 22, 37, 56, 68,  109, 103, 77,   24, 35, 55, 64, 81,  104, 113, 92,
    49, 64, 78, 87, 103, 121, 120, 101,  72, 92, 95, 98, 112, 100, 103, 99};
constexpr std::array<int, 64> kChrominanceTable = {
    17, 18, 24, 47, 99, 99, 99, 99,  18, 21, 26, 66, 99, 99, 99, 99,
    24, 26, 56, 99, 99, 99, 99, 99,  47, 66, 99, 99, 99, 99, 99, 99,
    99, 99, 99, 99, 99, 99, 99, 99,  99, 99, 99, 99, 99, 99, 99, 99,
    99, 99, 99, 99, 99, 99, 99, 99,  99, 99, 99, 99, 99, 99, 99, 99};

torch::Tensor RoundHalfAwayFromZero(const torch::Tensor& x) {
  return torch::sign(x) * torch::floor(torch::abs(x) + 0.5);
}

// Samples are 8-bit in a codec: rounded and clamped after every stage.
torch::Tensor ToSamples(const torch::Tensor& x) { return torch::clamp(torch::floor(x + 0.5), 0, 255); }

// The orthonormal 8-point DCT-II matrix: row u is c(u) cos((2x + 1) u pi / 16).
torch::Tensor DctMatrix(const torch::TensorOptions& options) {
  std::vector<double> m(64);
  for (int u = 0; u < 8; ++u) {
    const double c = u == 0 ? std::sqrt(1.0 / 8.0) : 0.5;
    for (int x = 0; x < 8; ++x) m[static_cast<size_t>(u * 8 + x)] = c * std::cos((2 * x + 1) * u * M_PI / 16.0);
  }
  return torch::tensor(m, torch::kDouble).view({8, 8}).to(options);
}

// One plane [h,w] (h, w multiples of 8) through the quantised DCT and back.
torch::Tensor QuantiseBlocks(const torch::Tensor& plane, const std::array<int, 64>& table) {
  const int64_t h = plane.size(0), w = plane.size(1);
  const torch::Tensor dct = DctMatrix(plane.options());
  const torch::Tensor q =
      torch::tensor(std::vector<double>(table.begin(), table.end()), torch::kDouble).view({8, 8}).to(plane.options());
  const torch::Tensor blocks = plane.view({h / 8, 8, w / 8, 8}).permute({0, 2, 1, 3}) - 128.0;
  const torch::Tensor coefficients = dct.matmul(blocks).matmul(dct.t());
  const torch::Tensor kept = RoundHalfAwayFromZero(coefficients / q) * q;
  const torch::Tensor decoded = ToSamples(dct.t().matmul(kept).matmul(dct) + 128.0);
  return decoded.permute({0, 2, 1, 3}).reshape({h, w});
}

// Doubles the last dimension of x [..., n]: output 2i is 3/4 x[i] + 1/4
// x[i - 1], output 2i + 1 is 3/4 x[i] + 1/4 x[i + 1], the ends repeated.
torch::Tensor TriangleUpsampleLastDim(const torch::Tensor& x) {
  const int64_t n = x.size(-1);
  const torch::Tensor previous = torch::cat({x.narrow(-1, 0, 1), x.narrow(-1, 0, n - 1)}, -1);
  const torch::Tensor next = torch::cat({x.narrow(-1, 1, n - 1), x.narrow(-1, n - 1, 1)}, -1);
  const torch::Tensor even = 0.75 * x + 0.25 * previous, odd = 0.75 * x + 0.25 * next;
  std::vector<int64_t> sizes = x.sizes().vec();
  sizes.back() = 2 * n;
  return torch::stack({even, odd}, -1).reshape(sizes);
}

}  // namespace

std::array<int, 64> JpegQuantisationTable(int quality, bool chroma) {
  if (quality < 1 || quality > 100) {
    throw std::invalid_argument("JPEG quality must be in [1, 100], got " + std::to_string(quality));
  }
  // The IJG scaling: below 50 the tables grow as 50 / quality, above it they
  // shrink linearly to all ones at 100; entries stay in [1, 255] (baseline).
  const int scale = quality < 50 ? 5000 / quality : 200 - 2 * quality;
  std::array<int, 64> out{};
  const std::array<int, 64>& basic = chroma ? kChrominanceTable : kLuminanceTable;
  for (size_t i = 0; i < out.size(); ++i) out[i] = std::clamp((basic[i] * scale + 50) / 100, 1, 255);
  return out;
}

torch::Tensor JpegRoundTrip(const torch::Tensor& image, int quality) {
  if (image.dim() != 3 || image.size(0) != 3 || image.size(1) < 1 || image.size(2) < 1) {
    throw std::invalid_argument("JpegRoundTrip: expected a non-empty [3,H,W] image");
  }
  const std::array<int, 64> luma_table = JpegQuantisationTable(quality, false);
  const std::array<int, 64> chroma_table = JpegQuantisationTable(quality, true);
  const int64_t h = image.size(1), w = image.size(2);
  const int64_t h16 = (h + 15) / 16 * 16, w16 = (w + 15) / 16 * 16;

  const torch::Tensor rgb = ToSamples(torch::clamp(image.to(torch::kDouble), 0, 1) * 255.0);
  const torch::Tensor r = rgb[0], g = rgb[1], b = rgb[2];
  const torch::Tensor y = ToSamples(0.299 * r + 0.587 * g + 0.114 * b);
  const torch::Tensor cb = ToSamples(-0.168736 * r - 0.331264 * g + 0.5 * b + 128.0);
  const torch::Tensor cr = ToSamples(0.5 * r - 0.418688 * g - 0.081312 * b + 128.0);

  const auto pad_to_mcu = [&](const torch::Tensor& planes) {  // [C,h,w] -> [1,C,h16,w16]
    return F::pad(planes.unsqueeze(0), F::PadFuncOptions({0, w16 - w, 0, h16 - h}).mode(torch::kReplicate));
  };
  const torch::Tensor luma = QuantiseBlocks(pad_to_mcu(y.unsqueeze(0))[0][0], luma_table);
  // Sum of each 2 x 2 block over 4, its ties (sums 4k + 2) rounded down in
  // even output columns and up in odd ones (libjpeg's alternating bias), so
  // that ties do not shift the chroma one way.
  const torch::Tensor chroma_sum = F::avg_pool2d(pad_to_mcu(torch::stack({cb, cr})), F::AvgPool2dFuncOptions(2))[0] * 4.0;
  const torch::Tensor tie_bias = 1.0 + torch::arange(w16 / 2, chroma_sum.options()).remainder(2);  // 1, 2, 1, 2, ...
  const torch::Tensor chroma_small = torch::floor((chroma_sum + tie_bias) / 4.0);
  // Decoded chroma, cut to the component's own size (half the image's,
  // rounded up) before upsampling, whose edges repeat from there.
  const int64_t ch = (h + 1) / 2, cw = (w + 1) / 2;
  const torch::Tensor chroma = torch::stack({QuantiseBlocks(chroma_small[0], chroma_table),
                                             QuantiseBlocks(chroma_small[1], chroma_table)})
                                   .narrow(1, 0, ch)
                                   .narrow(2, 0, cw);
  // The filtered values are exact multiples of 1/16; ties round up in even
  // columns and down in odd ones (libjpeg's biases 8/16 and 7/16).
  const torch::Tensor upsampled =
      TriangleUpsampleLastDim(TriangleUpsampleLastDim(chroma.transpose(1, 2)).transpose(1, 2));
  const torch::Tensor round_bias = 0.5 - torch::arange(2 * cw, upsampled.options()).remainder(2) / 16.0;
  const torch::Tensor chroma_full = torch::clamp(torch::floor(upsampled + round_bias), 0, 255);
  const torch::Tensor yy = luma.narrow(0, 0, h).narrow(1, 0, w);
  const torch::Tensor cb_full = chroma_full[0].narrow(0, 0, h).narrow(1, 0, w) - 128.0;
  const torch::Tensor cr_full = chroma_full[1].narrow(0, 0, h).narrow(1, 0, w) - 128.0;
  const torch::Tensor decoded = torch::stack({ToSamples(yy + 1.402 * cr_full),
                                              ToSamples(yy - 0.344136 * cb_full - 0.714136 * cr_full),
                                              ToSamples(yy + 1.772 * cb_full)});
  return (decoded / 255.0).to(image.scalar_type());
}

std::pair<int, int> ParseJpegQualityRange(const std::string& text) {
  if (text.empty() || text == "0") return {0, 0};
  const auto fail = [&]() {
    return std::invalid_argument("JPEG quality must be Q or MIN,MAX with 1 <= MIN <= MAX <= 100 (0: none), got '" +
                                 text + "'");
  };
  const size_t comma = text.find(',');
  const auto parse = [&](const std::string& part) {
    size_t used = 0;
    int value = 0;
    try {
      value = std::stoi(part, &used);
    } catch (const std::exception&) {
      throw fail();
    }
    if (used != part.size() || part.empty() || !std::isdigit(static_cast<unsigned char>(part[0]))) throw fail();
    return value;
  };
  const int low = parse(text.substr(0, comma));
  const int high = comma == std::string::npos ? low : parse(text.substr(comma + 1));
  if (low < 1 || high < low || high > 100) throw fail();
  return {low, high};
}

}  // namespace dispmvs::synth
