#include "fusion/bounding_box.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "colmap_io/error.h"

namespace dispmvs::fusion {

namespace {

// A bounding-box file is six numbers: anything much longer is not one.
constexpr std::streamsize kMaxFileBytes = 4096;

// The whole token as a finite number, or false.
bool ParseFinite(const std::string& token, double* value) {
  errno = 0;
  char* end = nullptr;
  *value = std::strtod(token.c_str(), &end);
  return end == token.c_str() + token.size() && errno == 0 && std::isfinite(*value);
}

}  // namespace

BoundingBox ReadBoundingBox(const std::filesystem::path& path) {
  const std::string name = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in || std::filesystem::is_directory(path)) {
    throw colmap_io::IoError(name, "cannot open the bounding-box file");
  }
  std::string text(static_cast<std::size_t>(kMaxFileBytes) + 1, '\0');
  in.read(text.data(), kMaxFileBytes + 1);
  text.resize(static_cast<std::size_t>(in.gcount()));
  if (static_cast<std::streamsize>(text.size()) > kMaxFileBytes) {
    throw colmap_io::IoError(name, "not a bounding-box file: longer than " +
                                       std::to_string(kMaxFileBytes) + " bytes");
  }
  std::istringstream tokens(text);
  std::vector<double> numbers;
  std::string token;
  while (tokens >> token) {
    double value = 0;
    if (!ParseFinite(token, &value)) {
      throw colmap_io::IoError(name, "bounding box: '" + token + "' is not a finite number");
    }
    numbers.push_back(value);
  }
  if (numbers.size() != 6) {
    throw colmap_io::IoError(name, "bounding box must be six numbers (min x y z, then max x y z), got " +
                                       std::to_string(numbers.size()));
  }
  BoundingBox box;
  box.min = Eigen::Vector3d(numbers[0], numbers[1], numbers[2]);
  box.max = Eigen::Vector3d(numbers[3], numbers[4], numbers[5]);
  for (int axis = 0; axis < 3; ++axis) {
    if (box.min[axis] > box.max[axis]) {
      throw colmap_io::IoError(name, std::string("bounding box: min ") + "xyz"[axis] + " " +
                                         std::to_string(box.min[axis]) + " is above max " +
                                         std::to_string(box.max[axis]));
    }
  }
  return box;
}

}  // namespace dispmvs::fusion
