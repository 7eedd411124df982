#include "train/mvsnet_dataset.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <stdexcept>
#include <system_error>

#ifdef DISPMVS_HAVE_OPENCV
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#endif

#include "synth/rng.h"

namespace dispmvs::train {
namespace {

namespace fs = std::filesystem;

[[noreturn]] void Fail(const std::string& message) { throw std::runtime_error(message); }

std::string ReadWholeFile(const fs::path& path) {
  std::error_code error;
  if (!fs::is_regular_file(path, error)) Fail(path.string() + ": no such file");
  std::ifstream in(path, std::ios::binary);
  if (!in) Fail(path.string() + ": cannot open");
  std::ostringstream bytes;
  bytes << in.rdbuf();
  if (in.bad()) Fail(path.string() + ": read error");
  return bytes.str();
}

// ------------------------------------------------------------ text parsing

// A non-blank line of a text file, split at whitespace; `number` is 1-based.
struct TextLine {
  int64_t number = 0;
  std::vector<std::string> tokens;
};

// The non-blank lines of `text` ("\r\n" line ends too), so that the parsers
// can report line numbers while not caring how many blank lines separate
// the parts of a file.
std::vector<TextLine> NonBlankLines(const std::string& text) {
  std::vector<TextLine> lines;
  std::istringstream in(text);
  std::string line;
  int64_t number = 0;
  while (std::getline(in, line)) {
    ++number;
    std::istringstream words(line);
    TextLine parsed{number, {}};
    for (std::string word; words >> word;) parsed.tokens.push_back(word);
    if (!parsed.tokens.empty()) lines.push_back(std::move(parsed));
  }
  return lines;
}

// Reads a file's non-blank lines in order; every error names source:line.
class LineReader {
 public:
  LineReader(const std::string& text, std::string source)
      : lines_(NonBlankLines(text)), source_(std::move(source)) {}

  bool AtEnd() const { return next_ >= lines_.size(); }

  // The next line, which must exist; `what` says what it should hold.
  const TextLine& Next(const std::string& what) {
    if (AtEnd()) {
      const int64_t last = lines_.empty() ? 0 : lines_.back().number;
      Fail(source_ + ": truncated after line " + std::to_string(last) + ": expected " + what);
    }
    return lines_[next_++];
  }

  [[noreturn]] void FailAt(const TextLine& line, const std::string& message) const {
    Fail(source_ + ":" + std::to_string(line.number) + ": " + message);
  }

  double Number(const TextLine& line, size_t index) const {
    const std::string& token = line.tokens.at(index);
    errno = 0;
    char* end = nullptr;
    const double value = std::strtod(token.c_str(), &end);
    if (end == token.c_str() || *end != '\0') FailAt(line, "'" + token + "' is not a number");
    if (!std::isfinite(value)) FailAt(line, "'" + token + "' is not a finite number");
    return value;
  }

  int64_t Integer(const TextLine& line, size_t index) const {
    const std::string& token = line.tokens.at(index);
    errno = 0;
    char* end = nullptr;
    const long long value = std::strtoll(token.c_str(), &end, 10);
    if (end == token.c_str() || *end != '\0' || errno == ERANGE) {
      FailAt(line, "'" + token + "' is not an integer");
    }
    return value;
  }

  void ExpectCount(const TextLine& line, size_t count, const std::string& what) const {
    if (line.tokens.size() != count) {
      FailAt(line, "expected " + what + " (" + std::to_string(count) + " values), found " +
                       std::to_string(line.tokens.size()) + " values");
    }
  }

  const std::string& source() const { return source_; }

 private:
  std::vector<TextLine> lines_;
  size_t next_ = 0;
  std::string source_;
};

std::string ViewFileName(int64_t view, const std::string& suffix) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%08lld", static_cast<long long>(view));
  return buffer + suffix;
}

// ------------------------------------------------------------ PFM

uint32_t LoadU32(const unsigned char* p, bool little_endian) {
  if (little_endian) {
    return uint32_t{p[0]} | uint32_t{p[1]} << 8 | uint32_t{p[2]} << 16 | uint32_t{p[3]} << 24;
  }
  return uint32_t{p[3]} | uint32_t{p[2]} << 8 | uint32_t{p[1]} << 16 | uint32_t{p[0]} << 24;
}

bool IsSpace(char c) { return c == ' ' || c == '\n' || c == '\r' || c == '\t'; }

// ------------------------------------------------------------ data sets

bool IsDirectory(const fs::path& path) {
  std::error_code error;
  return fs::is_directory(path, error);
}

bool IsFile(const fs::path& path) {
  std::error_code error;
  return fs::is_regular_file(path, error);
}

// pair.txt of a scan folder, or empty if it is not one.
fs::path PairFileOf(const fs::path& dir) {
  if (!IsDirectory(dir / "cams")) return {};
  if (IsFile(dir / "pair.txt")) return dir / "pair.txt";
  if (IsFile(dir / "cams" / "pair.txt")) return dir / "cams" / "pair.txt";
  return {};
}

fs::path FirstExistingDirectory(const fs::path& dir, std::initializer_list<const char*> names) {
  for (const char* name : names) {
    if (IsDirectory(dir / name)) return dir / name;
  }
  return {};
}

MvsnetScan OpenScan(const fs::path& dir, const fs::path& pair_file) {
  MvsnetScan scan;
  scan.dir = dir;
  scan.name = dir.filename().string();
  if (scan.name.empty()) scan.name = dir.parent_path().filename().string();  // "root/"
  scan.pairs = ReadMvsnetPairs(pair_file);
  const fs::path image_dir = FirstExistingDirectory(dir, {"images", "blended_images"});
  if (image_dir.empty()) Fail(dir.string() + ": no images/ (or blended_images/) folder");
  const fs::path depth_dir = FirstExistingDirectory(dir, {"depths", "rendered_depth_maps", "depth_gt"});

  const size_t views = scan.pairs.size();  // pair.txt lists every view once
  scan.cameras.resize(views);
  scan.images.resize(views);
  scan.depths.resize(views);
  for (size_t v = 0; v < views; ++v) {
    const auto view = static_cast<int64_t>(v);
    const fs::path cam = dir / "cams" / ViewFileName(view, "_cam.txt");
    if (!IsFile(cam)) {
      Fail(pair_file.string() + ": view " + std::to_string(v) + " has no camera file " + cam.string());
    }
    scan.cameras[v] = ReadMvsnetCamera(cam);
    for (const char* extension : {".jpg", ".png", ".jpeg", ".JPG", ".PNG", ".JPEG"}) {
      if (IsFile(image_dir / ViewFileName(view, extension))) {
        scan.images[v] = image_dir / ViewFileName(view, extension);
        break;
      }
    }
    if (scan.images[v].empty()) {
      Fail(pair_file.string() + ": view " + std::to_string(v) + " has no image " +
           (image_dir / ViewFileName(view, ".jpg|.png")).string());
    }
    if (!depth_dir.empty() && IsFile(depth_dir / ViewFileName(view, ".pfm"))) {
      scan.depths[v] = depth_dir / ViewFileName(view, ".pfm");
    }
  }
  return scan;
}

torch::Tensor MatrixTensor(const double* values, int64_t n) {
  return torch::from_blob(const_cast<double*>(values), {n, n}, torch::kDouble).clone();
}

}  // namespace

// ---------------------------------------------------------------- cam.txt

MvsnetCamera ParseMvsnetCamera(const std::string& text, const std::string& source) {
  LineReader in(text, source);
  MvsnetCamera cam;

  const TextLine& extrinsic = in.Next("'extrinsic'");
  if (extrinsic.tokens != std::vector<std::string>{"extrinsic"}) in.FailAt(extrinsic, "expected 'extrinsic'");
  for (int r = 0; r < 4; ++r) {
    const TextLine& row = in.Next("extrinsic row " + std::to_string(r + 1) + " of 4");
    in.ExpectCount(row, 4, "extrinsic row " + std::to_string(r + 1) + " of 4");
    for (int c = 0; c < 4; ++c) cam.world_to_camera[static_cast<size_t>(4 * r + c)] = in.Number(row, c);
    if (r == 3 && (cam.world_to_camera[12] != 0 || cam.world_to_camera[13] != 0 ||
                   cam.world_to_camera[14] != 0 || cam.world_to_camera[15] != 1)) {
      in.FailAt(row, "the last extrinsic row must be 0 0 0 1");
    }
  }
  // A projection matrix or garbage in place of a rigid motion would train
  // the network on impossible geometry without any other symptom.
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      double dot = 0;
      for (int k = 0; k < 3; ++k) {
        dot += cam.world_to_camera[static_cast<size_t>(4 * a + k)] * cam.world_to_camera[static_cast<size_t>(4 * b + k)];
      }
      if (std::abs(dot - (a == b ? 1.0 : 0.0)) > 1e-2) {
        Fail(source + ": the extrinsic rotation is not orthonormal (row " + std::to_string(a + 1) +
             " . row " + std::to_string(b + 1) + " = " + std::to_string(dot) + ")");
      }
    }
  }

  const TextLine& intrinsic = in.Next("'intrinsic'");
  if (intrinsic.tokens != std::vector<std::string>{"intrinsic"}) in.FailAt(intrinsic, "expected 'intrinsic'");
  for (int r = 0; r < 3; ++r) {
    const TextLine& row = in.Next("intrinsic row " + std::to_string(r + 1) + " of 3");
    in.ExpectCount(row, 3, "intrinsic row " + std::to_string(r + 1) + " of 3");
    for (int c = 0; c < 3; ++c) cam.intrinsics[static_cast<size_t>(3 * r + c)] = in.Number(row, c);
    const auto& k = cam.intrinsics;
    if (r == 0 && !(k[0] > 0)) in.FailAt(row, "fx must be > 0");
    if (r == 1 && !(k[3] == 0 && k[4] > 0)) in.FailAt(row, "the second intrinsic row must be 0 fy cy with fy > 0");
    if (r == 2 && !(k[6] == 0 && k[7] == 0 && k[8] == 1)) in.FailAt(row, "the last intrinsic row must be 0 0 1");
  }

  const TextLine& depth = in.Next("DEPTH_MIN DEPTH_INTERVAL [DEPTH_NUM [DEPTH_MAX]]");
  if (depth.tokens.size() < 2 || depth.tokens.size() > 4) {
    in.FailAt(depth, "expected DEPTH_MIN DEPTH_INTERVAL [DEPTH_NUM [DEPTH_MAX]], found " +
                         std::to_string(depth.tokens.size()) + " values");
  }
  cam.depth_min = in.Number(depth, 0);
  cam.depth_interval = in.Number(depth, 1);
  if (!(cam.depth_min > 0)) in.FailAt(depth, "DEPTH_MIN must be > 0, got " + depth.tokens[0]);
  if (depth.tokens.size() >= 3) {
    // Written as "192" or "192.0" by different tools.
    const double num = in.Number(depth, 2);
    if (num != std::floor(num) || num < 2 || num > 1e6) {
      in.FailAt(depth, "DEPTH_NUM must be a whole number in [2, 1e6], got " + depth.tokens[2]);
    }
    cam.depth_num = static_cast<int64_t>(num);
  }
  if (depth.tokens.size() == 4) {
    cam.depth_max = in.Number(depth, 3);
    if (!(cam.depth_max > cam.depth_min)) {
      in.FailAt(depth, "DEPTH_MAX must be > DEPTH_MIN, got " + depth.tokens[3] + " <= " + depth.tokens[0]);
    }
  } else {
    if (!(cam.depth_interval > 0)) in.FailAt(depth, "DEPTH_INTERVAL must be > 0, got " + depth.tokens[1]);
    cam.depth_max = cam.depth_min + cam.depth_interval * static_cast<double>(cam.depth_num - 1);
    if (!std::isfinite(cam.depth_max)) in.FailAt(depth, "the depth range overflows");
  }
  if (!in.AtEnd()) in.FailAt(in.Next(""), "unexpected content after the depth line");
  return cam;
}

MvsnetCamera ReadMvsnetCamera(const fs::path& path) {
  return ParseMvsnetCamera(ReadWholeFile(path), path.string());
}

// ---------------------------------------------------------------- pair.txt

std::vector<MvsnetViewPair> ParseMvsnetPairs(const std::string& text, const std::string& source) {
  LineReader in(text, source);
  const TextLine& header = in.Next("the view count");
  in.ExpectCount(header, 1, "the view count");
  const int64_t views = in.Integer(header, 0);
  if (views < 1 || views > 10'000'000) in.FailAt(header, "the view count must be in [1, 1e7], got " + header.tokens[0]);

  std::vector<MvsnetViewPair> pairs;
  std::vector<bool> listed(static_cast<size_t>(views), false);
  auto view_index = [&](const TextLine& line, size_t index) {
    const int64_t v = in.Integer(line, index);
    if (v < 0 || v >= views) {
      in.FailAt(line, "view " + line.tokens[index] + " out of range [0, " + std::to_string(views) + ")");
    }
    return v;
  };
  for (int64_t entry = 0; entry < views; ++entry) {
    const std::string which = " of entry " + std::to_string(entry + 1) + " of " + std::to_string(views);
    const TextLine& ref_line = in.Next("the reference view" + which);
    in.ExpectCount(ref_line, 1, "the reference view");
    MvsnetViewPair pair;
    pair.reference = view_index(ref_line, 0);
    if (listed[static_cast<size_t>(pair.reference)]) {
      in.FailAt(ref_line, "reference view " + std::to_string(pair.reference) + " listed twice");
    }
    listed[static_cast<size_t>(pair.reference)] = true;

    const TextLine& src_line = in.Next("the source list" + which);
    const int64_t count = in.Integer(src_line, 0);
    if (count < 0 || count >= views) {
      in.FailAt(src_line, "source count must be in [0, " + std::to_string(views) + "), got " + src_line.tokens[0]);
    }
    in.ExpectCount(src_line, static_cast<size_t>(1 + 2 * count),
                   "a source count and " + std::to_string(count) + " source/score pairs");
    std::set<int64_t> seen;
    for (int64_t k = 0; k < count; ++k) {
      const int64_t src = view_index(src_line, static_cast<size_t>(1 + 2 * k));
      if (src == pair.reference) in.FailAt(src_line, "view " + std::to_string(src) + " is its own source");
      if (!seen.insert(src).second) in.FailAt(src_line, "source view " + std::to_string(src) + " listed twice");
      pair.sources.push_back(src);
      pair.scores.push_back(in.Number(src_line, static_cast<size_t>(2 + 2 * k)));
    }
    pairs.push_back(std::move(pair));
  }
  if (!in.AtEnd()) in.FailAt(in.Next(""), "unexpected content after " + std::to_string(views) + " entries");
  return pairs;
}

std::vector<MvsnetViewPair> ReadMvsnetPairs(const fs::path& path) {
  return ParseMvsnetPairs(ReadWholeFile(path), path.string());
}

// ---------------------------------------------------------------- PFM

PfmImage ParsePfm(const std::string& bytes, const std::string& source) {
  // The header is three whitespace-separated tokens; the data starts after
  // exactly one whitespace byte following the third.
  size_t pos = 0;
  auto token = [&](const char* what) {
    while (pos < bytes.size() && IsSpace(bytes[pos])) ++pos;
    const size_t start = pos;
    while (pos < bytes.size() && !IsSpace(bytes[pos]) && pos - start < 32) ++pos;
    if (start == pos) Fail(source + ": truncated PFM header: no " + what);
    return bytes.substr(start, pos - start);
  };
  auto positive = [&](const std::string& text, const char* what) {
    char* end = nullptr;
    errno = 0;
    const long long v = std::strtoll(text.c_str(), &end, 10);
    if (end == text.c_str() || *end != '\0' || errno == ERANGE || v < 1 || v > 1'000'000) {
      Fail(source + ": PFM " + what + " must be an integer in [1, 1000000], got '" + text + "'");
    }
    return static_cast<int64_t>(v);
  };

  PfmImage image;
  const std::string magic = token("magic");
  if (magic == "Pf") {
    image.channels = 1;
  } else if (magic == "PF") {
    image.channels = 3;
  } else {
    Fail(source + ": not a PFM file (magic '" + magic + "', expected 'Pf' or 'PF')");
  }
  image.width = positive(token("width"), "width");
  image.height = positive(token("height"), "height");
  const std::string scale_text = token("scale");
  char* end = nullptr;
  const double scale = std::strtod(scale_text.c_str(), &end);
  if (end == scale_text.c_str() || *end != '\0' || !std::isfinite(scale) || scale == 0) {
    Fail(source + ": PFM scale must be a finite non-zero number, got '" + scale_text + "'");
  }
  if (pos >= bytes.size() || !IsSpace(bytes[pos])) Fail(source + ": truncated PFM header after the scale");
  ++pos;

  const bool little_endian = scale < 0;
  const int64_t count = image.width * image.height * image.channels;
  const size_t expected = static_cast<size_t>(count) * 4;
  const size_t found = bytes.size() - pos;
  if (found != expected) {
    Fail(source + ": PFM of " + std::to_string(image.width) + "x" + std::to_string(image.height) + "x" +
         std::to_string(image.channels) + " needs " + std::to_string(expected) + " data bytes, found " +
         std::to_string(found) + (found < expected ? " (truncated)" : " (trailing data)"));
  }
  image.values.resize(static_cast<size_t>(count));
  const auto* data = reinterpret_cast<const unsigned char*>(bytes.data() + pos);
  const int64_t row_values = image.width * image.channels;
  for (int64_t file_row = 0; file_row < image.height; ++file_row) {
    const int64_t row = image.height - 1 - file_row;  // stored bottom to top
    for (int64_t k = 0; k < row_values; ++k) {
      const uint32_t bits = LoadU32(data + 4 * (file_row * row_values + k), little_endian);
      float value;
      std::memcpy(&value, &bits, sizeof value);
      image.values[static_cast<size_t>(row * row_values + k)] = value;
    }
  }
  return image;
}

PfmImage ReadPfm(const fs::path& path) { return ParsePfm(ReadWholeFile(path), path.string()); }

torch::Tensor ReadMvsnetDepth(const fs::path& path) {
  PfmImage pfm = ReadPfm(path);
  if (pfm.channels != 1) Fail(path.string() + ": a depth map must have one channel ('Pf'), this is 'PF'");
  for (size_t i = 0; i < pfm.values.size(); ++i) {
    const float d = pfm.values[i];
    if (!std::isfinite(d) || d < 0) {
      const auto row = static_cast<int64_t>(i) / pfm.width, col = static_cast<int64_t>(i) % pfm.width;
      Fail(path.string() + ": depth at row " + std::to_string(row) + ", col " + std::to_string(col) +
           " is " + std::to_string(d) + " (must be finite and >= 0; 0 = no ground truth)");
    }
  }
  return torch::from_blob(pfm.values.data(), {1, pfm.height, pfm.width}, torch::kFloat).clone();
}

// ---------------------------------------------------------------- images

bool MvsnetImageDecodingAvailable() {
#ifdef DISPMVS_HAVE_OPENCV
  return true;
#else
  return false;
#endif
}

void RequireMvsnetImageDecoding() {
  if (!MvsnetImageDecodingAvailable()) Fail("built without OpenCV: MVSNet datasets need image decoding");
}

torch::Tensor ReadMvsnetImage(const fs::path& path) {
  RequireMvsnetImageDecoding();
#ifdef DISPMVS_HAVE_OPENCV
  if (!IsFile(path)) Fail(path.string() + ": no such file");
  cv::Mat raw;
  try {
    // UNCHANGED: IMREAD_COLOR would cut 16-bit images to 8 bits.
    raw = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    Fail(path.string() + ": cannot decode image: " + e.what());
  }
  if (raw.empty()) Fail(path.string() + ": cannot decode image");
  double scale = 0;
  if (raw.depth() == CV_8U) {
    scale = 1.0 / 255.0;
  } else if (raw.depth() == CV_16U) {
    scale = 1.0 / 65535.0;
  } else {
    Fail(path.string() + ": unsupported pixel type (8- and 16-bit images only)");
  }
  cv::Mat rgb;
  switch (raw.channels()) {
    case 1: cv::cvtColor(raw, rgb, cv::COLOR_GRAY2RGB); break;
    case 3: cv::cvtColor(raw, rgb, cv::COLOR_BGR2RGB); break;
    case 4: cv::cvtColor(raw, rgb, cv::COLOR_BGRA2RGB); break;
    default: Fail(path.string() + ": unsupported channel count " + std::to_string(raw.channels()));
  }
  cv::Mat values;
  rgb.convertTo(values, CV_32FC3, scale);
  if (!values.isContinuous()) values = values.clone();
  return torch::from_blob(values.data, {values.rows, values.cols, 3}, torch::kFloat)
      .permute({2, 0, 1})
      .contiguous();  // copies out of the cv::Mat
#else
  (void)path;
  return {};
#endif
}

// ------------------------------------------------- fitting to the input size

ViewFit PlanViewFit(int64_t stored_height, int64_t stored_width, int64_t height, int64_t width) {
  if (stored_height < 1 || stored_width < 1 || height < 1 || width < 1) {
    throw std::invalid_argument("PlanViewFit: sizes must be positive, got " + std::to_string(stored_width) +
                                "x" + std::to_string(stored_height) + " -> " + std::to_string(width) + "x" +
                                std::to_string(height));
  }
  const double s = std::max(static_cast<double>(height) / static_cast<double>(stored_height),
                            static_cast<double>(width) / static_cast<double>(stored_width));
  ViewFit fit;
  // The binding axis rounds to exactly its target; the other to at least it.
  fit.resized_height = std::max(height, static_cast<int64_t>(std::llround(static_cast<double>(stored_height) * s)));
  fit.resized_width = std::max(width, static_cast<int64_t>(std::llround(static_cast<double>(stored_width) * s)));
  fit.crop_top = (fit.resized_height - height) / 2;
  fit.crop_left = (fit.resized_width - width) / 2;
  fit.height = height;
  fit.width = width;
  fit.scale_y = static_cast<double>(fit.resized_height) / static_cast<double>(stored_height);
  fit.scale_x = static_cast<double>(fit.resized_width) / static_cast<double>(stored_width);
  return fit;
}

std::array<double, 9> FitIntrinsics(const std::array<double, 9>& k, const ViewFit& fit) {
  const double sx = fit.scale_x, sy = fit.scale_y;
  const double ox = 0.5 * sx - 0.5 - static_cast<double>(fit.crop_left);
  const double oy = 0.5 * sy - 0.5 - static_cast<double>(fit.crop_top);
  // [[sx, 0, ox], [0, sy, oy], [0, 0, 1]] * K, written out.
  return {sx * k[0] + ox * k[6], sx * k[1] + ox * k[7], sx * k[2] + ox * k[8],
          sy * k[3] + oy * k[6], sy * k[4] + oy * k[7], sy * k[5] + oy * k[8],
          k[6],                  k[7],                  k[8]};
}

torch::Tensor FitImage(const torch::Tensor& image, const ViewFit& fit) {
  if (image.dim() != 3) throw std::invalid_argument("FitImage: expected [C,H,W]");
  torch::Tensor resized = image;
  if (image.size(1) != fit.resized_height || image.size(2) != fit.resized_width) {
    namespace F = torch::nn::functional;
    const bool shrinking = fit.resized_height < image.size(1) || fit.resized_width < image.size(2);
    resized = F::interpolate(image.unsqueeze(0),
                             F::InterpolateFuncOptions()
                                 .size(std::vector<int64_t>{fit.resized_height, fit.resized_width})
                                 .mode(torch::kBilinear)
                                 .align_corners(false)
                                 .antialias(shrinking))
                  .squeeze(0);
  }
  return resized.narrow(1, fit.crop_top, fit.height).narrow(2, fit.crop_left, fit.width).contiguous();
}

torch::Tensor FitDepth(const torch::Tensor& depth, const ViewFit& fit) {
  if (depth.dim() != 3) throw std::invalid_argument("FitDepth: expected [1,H,W]");
  // Fitted pixel centre i is at stored (i + crop + 0.5) / scale - 0.5; the
  // nearest stored pixel is the floor of that + 0.5.
  auto source_index = [](int64_t count, int64_t crop, double scale, int64_t stored) {
    std::vector<int64_t> index(static_cast<size_t>(count));
    for (int64_t i = 0; i < count; ++i) {
      const auto s = static_cast<int64_t>(std::floor((static_cast<double>(i + crop) + 0.5) / scale));
      index[static_cast<size_t>(i)] = std::clamp<int64_t>(s, 0, stored - 1);
    }
    return torch::tensor(index, torch::kLong);
  };
  const auto rows = source_index(fit.height, fit.crop_top, fit.scale_y, depth.size(1)).to(depth.device());
  const auto cols = source_index(fit.width, fit.crop_left, fit.scale_x, depth.size(2)).to(depth.device());
  return depth.index_select(1, rows).index_select(2, cols).contiguous();
}

// ---------------------------------------------------------------- data sets

MvsnetDataset OpenMvsnetDataset(const fs::path& root) {
  if (!IsDirectory(root)) Fail(root.string() + ": MVSNet data set root is not a folder");
  MvsnetDataset dataset;
  dataset.root = root;
  if (const fs::path pair_file = PairFileOf(root); !pair_file.empty()) {
    dataset.scans.push_back(OpenScan(root, pair_file));
    return dataset;
  }
  std::vector<fs::path> dirs;
  for (const auto& entry : fs::directory_iterator(root)) {
    if (entry.is_directory()) dirs.push_back(entry.path());
  }
  std::sort(dirs.begin(), dirs.end());  // directory order is unspecified
  for (const fs::path& dir : dirs) {
    if (const fs::path pair_file = PairFileOf(dir); !pair_file.empty()) {
      dataset.scans.push_back(OpenScan(dir, pair_file));
    }
  }
  if (dataset.scans.empty()) {
    Fail(root.string() + ": no MVSNet scan (a folder with cams/ and pair.txt or cams/pair.txt) in it or its sub-folders");
  }
  return dataset;
}

std::vector<MvsnetViewRef> MvsnetTrainingViews(const MvsnetDataset& dataset, int64_t num_sources) {
  std::vector<MvsnetViewRef> views;
  for (size_t s = 0; s < dataset.scans.size(); ++s) {
    const MvsnetScan& scan = dataset.scans[s];
    for (size_t p = 0; p < scan.pairs.size(); ++p) {
      const MvsnetViewPair& pair = scan.pairs[p];
      if (static_cast<int64_t>(pair.sources.size()) < num_sources) continue;
      if (scan.depths.at(static_cast<size_t>(pair.reference)).empty()) continue;
      views.push_back({s, p});
    }
  }
  return views;
}

void MvsnetSampleOptions::Check() const {
  if (height < 1 || height > 8192) throw std::invalid_argument("MVSNet sample height must be in [1, 8192]");
  if (width < 1 || width > 8192) throw std::invalid_argument("MVSNet sample width must be in [1, 8192]");
  if (num_sources < 1 || num_sources > 64) throw std::invalid_argument("MVSNet num_sources must be in [1, 64]");
  if (dtype != torch::kFloat && dtype != torch::kDouble) {
    throw std::invalid_argument("MVSNet sample dtype must be float or double");
  }
}

synth::SynthSample LoadMvsnetSample(const MvsnetDataset& dataset, const MvsnetViewRef& ref,
                                    const MvsnetSampleOptions& options, torch::Device device) {
  options.Check();
  if (ref.scan >= dataset.scans.size() || ref.pair >= dataset.scans[ref.scan].pairs.size()) {
    throw std::invalid_argument("LoadMvsnetSample: no such view");
  }
  const MvsnetScan& scan = dataset.scans[ref.scan];
  const MvsnetViewPair& pair = scan.pairs[ref.pair];
  if (static_cast<int64_t>(pair.sources.size()) < options.num_sources) {
    throw std::invalid_argument(scan.dir.string() + ": view " + std::to_string(pair.reference) + " has " +
                                std::to_string(pair.sources.size()) + " sources, " +
                                std::to_string(options.num_sources) + " needed");
  }
  std::vector<int64_t> views{pair.reference};
  views.insert(views.end(), pair.sources.begin(), pair.sources.begin() + options.num_sources);

  std::vector<torch::Tensor> images, depths, intrinsics, extrinsics;
  for (size_t i = 0; i < views.size(); ++i) {
    const auto v = static_cast<size_t>(views[i]);
    const torch::Tensor image = ReadMvsnetImage(scan.images[v]);
    const ViewFit fit = PlanViewFit(image.size(1), image.size(2), options.height, options.width);
    images.push_back(FitImage(image, fit));
    torch::Tensor depth;
    if ((i == 0 || options.source_depths) && !scan.depths[v].empty()) {
      const torch::Tensor stored = ReadMvsnetDepth(scan.depths[v]);
      if (stored.size(1) != image.size(1) || stored.size(2) != image.size(2)) {
        Fail(scan.depths[v].string() + ": depth map is " + std::to_string(stored.size(2)) + "x" +
             std::to_string(stored.size(1)) + ", its image " + scan.images[v].string() + " is " +
             std::to_string(image.size(2)) + "x" + std::to_string(image.size(1)));
      }
      depth = FitDepth(stored, fit);
    } else {
      depth = torch::zeros({1, options.height, options.width}, torch::kFloat);
    }
    depths.push_back(depth);
    const MvsnetCamera& cam = scan.cameras[v];
    intrinsics.push_back(MatrixTensor(FitIntrinsics(cam.intrinsics, fit).data(), 3));
    extrinsics.push_back(MatrixTensor(cam.world_to_camera.data(), 4));
  }
  const auto real = torch::TensorOptions().dtype(options.dtype).device(device);
  synth::SynthSample sample;
  sample.images = torch::stack(images).to(real);
  sample.depths = torch::stack(depths).to(real);
  sample.intrinsics = torch::stack(intrinsics).to(real);
  sample.world_to_camera = torch::stack(extrinsics).to(real);
  const MvsnetCamera& ref_cam = scan.cameras[static_cast<size_t>(pair.reference)];
  sample.depth_min = ref_cam.depth_min;
  sample.depth_max = ref_cam.depth_max;
  sample.scale = 1;
  sample.rig = "mvsnet";
  return sample;
}

std::optional<size_t> ChooseMvsnetView(uint64_t sample_seed, double fraction, size_t num_views) {
  if (!(fraction >= 0 && fraction <= 1)) throw std::invalid_argument("ChooseMvsnetView: fraction must be in [0, 1]");
  if (num_views == 0) return std::nullopt;
  // A stream of its own (the generator draws from the seed too), so the two
  // choices do not correlate with the scene drawn from the same seed.
  synth::Rng rng = synth::Rng(sample_seed).Fork(0x3D5E7A11ull);
  if (!(rng.Uniform() < fraction)) return std::nullopt;
  return static_cast<size_t>(rng.NextU64() % num_views);
}

}  // namespace dispmvs::train
