#include "synth/netpbm.h"

#include <cctype>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <vector>

namespace dispmvs::synth {
namespace {

[[noreturn]] void Fail(const std::string& path, const std::string& what) {
  throw std::runtime_error(path + ": " + what);
}

// Reads one header number, skipping whitespace and '#' comments to the end of
// their line. Returns -1 when there is no number (or it is absurdly long).
long ReadHeaderNumber(const std::vector<unsigned char>& bytes, size_t& at) {
  while (at < bytes.size()) {
    if (bytes[at] == '#') {
      while (at < bytes.size() && bytes[at] != '\n' && bytes[at] != '\r') ++at;
    } else if (std::isspace(bytes[at])) {
      ++at;
    } else {
      break;
    }
  }
  long value = 0;
  int digits = 0;
  while (at < bytes.size() && std::isdigit(bytes[at])) {
    if (++digits > 9) return -1;
    value = value * 10 + (bytes[at++] - '0');
  }
  return digits == 0 ? -1 : value;
}

}  // namespace

torch::Tensor ReadNetpbm(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) Fail(path, "cannot open");
  const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (bytes.size() < 2 || bytes[0] != 'P' || (bytes[1] != '5' && bytes[1] != '6')) {
    Fail(path, "not a binary PPM (P6) or PGM (P5) file");
  }
  const int64_t channels = bytes[1] == '6' ? 3 : 1;
  size_t at = 2;
  const long width = ReadHeaderNumber(bytes, at);
  const long height = ReadHeaderNumber(bytes, at);
  const long maxval = ReadHeaderNumber(bytes, at);
  if (width < 1 || height < 1 || width > 65536 || height > 65536) Fail(path, "bad width or height in the header");
  if (maxval < 1 || maxval > 65535) Fail(path, "maxval must be in [1, 65535]");
  // Exactly one whitespace byte separates the header from the samples.
  if (at >= bytes.size() || !std::isspace(bytes[at])) Fail(path, "truncated header");
  ++at;
  const int64_t sample_bytes = maxval > 255 ? 2 : 1;
  const int64_t count = static_cast<int64_t>(width) * height * channels;
  if (static_cast<int64_t>(bytes.size() - at) < count * sample_bytes) {
    Fail(path, "truncated: " + std::to_string(bytes.size() - at) + " sample bytes, expected " +
                   std::to_string(count * sample_bytes));
  }
  std::vector<float> samples(static_cast<size_t>(count));
  const float scale = 1.0f / static_cast<float>(maxval);
  for (int64_t i = 0; i < count; ++i) {
    const size_t p = at + static_cast<size_t>(i * sample_bytes);
    const unsigned value = sample_bytes == 2 ? (unsigned{bytes[p]} << 8) | bytes[p + 1] : bytes[p];
    if (value > static_cast<unsigned>(maxval)) Fail(path, "a sample exceeds maxval");
    samples[static_cast<size_t>(i)] = static_cast<float>(value) * scale;
  }
  // Interleaved HWC -> CHW, owning its memory.
  torch::Tensor image = torch::from_blob(samples.data(), {height, width, channels}, torch::kFloat)
                            .permute({2, 0, 1})
                            .clone();
  return channels == 3 ? image : image.expand({3, height, width}).contiguous();
}

}  // namespace dispmvs::synth
