// dispmvs_jpeg_recompress: each image file replaced, in place and in its own
// format, by what a JPEG file of the given quality holds (encoded and decoded
// by OpenCV's libjpeg: 8-bit, 4:2:0 chroma, 8 x 8 blocks), as if the
// photographs had reached the workspace as JPEGs of that quality.
// bench/realval_eval.sh --jpeg_quality uses it to ask how much compression
// costs on the real pairs. Errors print one line "error: <message>" on stderr
// with exit status 1; a file is replaced only once its new bytes are written.
//
//   dispmvs_jpeg_recompress QUALITY FILE...

#include <filesystem>
#include <iostream>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>

#include "src/program_main.h"

namespace {

namespace fs = std::filesystem;

constexpr const char* kUsage =
    "usage: dispmvs_jpeg_recompress QUALITY FILE...\n"
    "Replaces each image file (any format OpenCV writes, by its extension) by its\n"
    "JPEG round trip at QUALITY (1-100, libjpeg's scale), keeping name and format.\n";

int ParseQuality(const std::string& text) {
  size_t used = 0;
  int quality = 0;
  try {
    quality = std::stoi(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size() || quality < 1 || quality > 100) {
    throw std::invalid_argument("QUALITY must be an integer in [1, 100], got '" + text + "'");
  }
  return quality;
}

void Recompress(const fs::path& path, int quality) {
  if (!fs::is_regular_file(path)) throw std::runtime_error("cannot read an image from " + path.string() + ": no such file");
  const cv::Mat image = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  if (image.empty()) throw std::runtime_error("cannot read an image from " + path.string());
  if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3)) {
    throw std::runtime_error(path.string() + ": only 8-bit grey or colour images (JPEG holds no other)");
  }
  std::vector<uchar> jpeg;
  if (!cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, quality})) {
    throw std::runtime_error("JPEG encoding failed for " + path.string());
  }
  const cv::Mat decoded = cv::imdecode(jpeg, image.channels() == 1 ? cv::IMREAD_GRAYSCALE : cv::IMREAD_COLOR);
  // Written next to the file under a name with the same extension (imwrite
  // picks the format by it), then renamed over it.
  const fs::path temporary = path.parent_path() / (".recompress." + path.filename().string());
  if (!cv::imwrite(temporary.string(), decoded)) {
    fs::remove(temporary);
    throw std::runtime_error("cannot write " + temporary.string());
  }
  fs::rename(temporary, path);
}

}  // namespace

int main(int argc, char** argv) {
  return dispmvs::cli::RunProgram([&]() {
    if (argc == 2 && (std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h")) {
      std::cout << kUsage;
      return 0;
    }
    if (argc < 3) throw std::invalid_argument(std::string("expected QUALITY and at least one FILE\n") + kUsage);
    const int quality = ParseQuality(argv[1]);
    // Failures are this program's one error line, not OpenCV's warnings.
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    for (int i = 2; i < argc; ++i) Recompress(argv[i], quality);
    return 0;
  });
}
