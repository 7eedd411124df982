// dispmvs_jpeg_recompress: each image file replaced, in place and in its own
// format, by what a JPEG file of the given quality holds (encoded and decoded
// by OpenCV's libjpeg: 8-bit, 4:2:0 chroma, 8 x 8 blocks), as if the
// photographs had reached the workspace as JPEGs of that quality.
// bench/realval_eval.sh --jpeg_quality uses it to ask how much compression
// costs on the real pairs. Errors print one line "error: <message>" on stderr
// with exit status 1; a file is replaced only once its new bytes are written.
//
//   dispmvs_jpeg_recompress --quality Q --images FILE...

#include <boost/program_options.hpp>

#include <filesystem>
#include <iostream>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>

#include "src/program_main.h"
#include "src/program_options.h"

namespace {

namespace fs = std::filesystem;

constexpr const char* kDescription =
    "dispmvs_jpeg_recompress: replaces each image file (any format OpenCV writes, by its\n"
    "extension) by its JPEG round trip at a quality, keeping name and format.\n"
    "Usage: dispmvs_jpeg_recompress --quality Q --images FILE...\n\nOptions";

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
    namespace po = boost::program_options;
    int quality = 0;
    std::vector<std::string> images;
    po::options_description description(kDescription);
    description.add_options()
        ("help,h", "Print this help and exit.")
        ("quality", po::value<int>(&quality), "JPEG quality, 1-100 (libjpeg's scale; required).")
        ("images", po::value<std::vector<std::string>>(&images)->multitoken(),
         "Image files to replace (required).");
    po::variables_map values;
    if (!dispmvs::cli::ParseCommandLine(argc, argv, description, &values)) return 0;
    if (values.count("quality") == 0 || quality < 1 || quality > 100) {
      throw std::invalid_argument("--quality must be given, in [1, 100] (see --help)");
    }
    if (images.empty()) throw std::invalid_argument("--images must name at least one file (see --help)");
    // Failures are this program's one error line, not OpenCV's warnings.
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    for (const std::string& image : images) Recompress(image, quality);
    return 0;
  });
}
