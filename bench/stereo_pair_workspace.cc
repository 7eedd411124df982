#include "bench/stereo_pair_workspace.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <system_error>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "colmap_io/atomic_file.h"
#include "colmap_io/camera_models.h"
#include "colmap_io/error.h"
#include "colmap_io/image_io.h"
#include "colmap_io/sparse_model_io.h"
#include "colmap_io/stereo_config.h"
#include "colmap_io/workspace.h"

namespace dispmvs::bench {
namespace {

namespace fs = std::filesystem;
using colmap_io::IoError;

constexpr colmap_io::image_t kLeftId = 1;
constexpr colmap_io::image_t kRightId = 2;

void CheckFinite(double value, const char* name) {
  if (!std::isfinite(value)) throw std::invalid_argument(std::string(name) + " must be finite");
}

void CheckPositive(double value, const char* name) {
  if (!(std::isfinite(value) && value > 0)) {
    throw std::invalid_argument(std::string(name) + " must be finite and > 0");
  }
}

Eigen::Matrix3d LeftK(const StereoPairCalibration& c) {
  Eigen::Matrix3d K;
  K << c.focal, 0, c.cx, 0, c.focal, c.cy, 0, 0, 1;
  return K;
}

Eigen::Matrix3d RightK(const StereoPairCalibration& c) {
  Eigen::Matrix3d K = LeftK(c);
  K(0, 2) += c.doffs;
  return K;
}

Eigen::Vector2d Project(const Eigen::Matrix3d& K, const Eigen::Vector3d& camera_point) {
  const Eigen::Vector3d uvw = K * camera_point;
  return {uvw.x() / uvw.z(), uvw.y() / uvw.z()};
}

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string(), "cannot open for reading");
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw IoError(path.string(), "read failed");
  return bytes;
}

void WriteBytes(const std::string& bytes, const fs::path& path) {
  colmap_io::WriteFileAtomically(path, [&](std::ostream& out) {
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  });
}

// "left" + the input's extension, so that the file keeps a name its format
// is recognised by.
std::string ImageName(const std::string& stem, const fs::path& input) {
  return stem + input.extension().string();
}

std::string SizeText(int width, int height) {
  return std::to_string(width) + "x" + std::to_string(height);
}

std::string Number(double value) {
  std::ostringstream out;
  out.precision(12);  // the README is for people; the values are in sparse/ exactly
  out << value;
  return out.str();
}

void WriteReadme(const StereoPairWorkspaceOptions& options, const fs::path& disparity_path,
                 const StereoPairWorkspaceSummary& summary, const fs::path& path) {
  const StereoPairCalibration& c = options.calibration;
  colmap_io::WriteFileAtomically(path, [&](std::ostream& out) {
    out << "Ground truth of a rectified stereo pair (written by dispmvs_stereo_pair_workspace).\n\n"
        << "inputs: left " << options.left_image.filename().string() << ", right "
        << options.right_image.filename().string() << ", disparity "
        << disparity_path.filename().string() << " (" << summary.width << "x" << summary.height
        << ")\n"
        << "calibration (COLMAP convention): f " << Number(c.focal) << ", cx " << Number(c.cx)
        << ", cy " << Number(c.cy) << ", doffs " << Number(c.doffs) << ", baseline "
        << Number(c.baseline) << " (the length unit of the workspace)\n"
        << "right camera cx = cx + doffs; depth z = baseline * f / (d + doffs)\n\n"
        << "depth_maps/" << summary.left_name << ".bin: COLMAP dense array, pixel (col, row) = "
        << "image position (col, row) (COLMAP's dense indexing), the depth of the mean "
           "disparity of the four left pixels around that corner when all are valid and differ "
           "by at most "
        << Number(options.max_disparity_step) << " px; 0 = no ground truth. "
        << summary.gt_pixels << " pixels with ground truth, " << summary.gt_dropped_at_edges
        << " corners dropped at depth edges, depth " << Number(summary.gt_min_depth) << " to "
        << Number(summary.gt_max_depth) << ".\n"
        << "sparse/: " << summary.num_points3D << " points from " << summary.sparse_candidates
        << " candidate pixels (valid disparity, inside the right image, not occluded), "
           "observed in both images at their exact projections.\n";
  });
}

}  // namespace

void StereoPairCalibration::Check() const {
  CheckPositive(focal, "focal");
  CheckFinite(cx, "cx");
  CheckFinite(cy, "cy");
  CheckFinite(doffs, "doffs");
  CheckPositive(baseline, "baseline");
}

bool StereoPairCalibration::IsValidDisparity(double disparity) const {
  return std::isfinite(disparity) && disparity + doffs > 0;
}

void StereoPairWorkspaceOptions::Check() const {
  calibration.Check();
  if (num_sparse_points < 1 || num_sparse_points > 10000000) {
    throw std::invalid_argument("num_sparse_points must be in [1, 10000000]");
  }
  if (!(max_disparity_step > 0)) {
    throw std::invalid_argument("max_disparity_step must be > 0");
  }
}

colmap_io::DenseArray DisparityToDenseDepth(const NpyMatrix& disparity,
                                            const StereoPairCalibration& calibration,
                                            double max_disparity_step,
                                            int64_t* dropped_at_edges) {
  calibration.Check();
  const int width = disparity.cols, height = disparity.rows;
  colmap_io::DenseArray depth(width, height, 1, 0.0f);
  int64_t dropped = 0;
  for (int row = 1; row < height; ++row) {
    for (int col = 1; col < width; ++col) {
      const double around[4] = {disparity.at(row - 1, col - 1), disparity.at(row - 1, col),
                                disparity.at(row, col - 1), disparity.at(row, col)};
      if (!std::all_of(std::begin(around), std::end(around),
                       [&](double d) { return calibration.IsValidDisparity(d); })) {
        continue;
      }
      const auto [low, high] = std::minmax_element(std::begin(around), std::end(around));
      if (*high - *low > max_disparity_step) {
        ++dropped;
        continue;
      }
      const double mean = (around[0] + around[1] + around[2] + around[3]) / 4;
      if (!calibration.IsValidDisparity(mean)) continue;  // cannot happen: a mean of valid ones
      depth.at(row, col) = static_cast<float>(calibration.DepthOfDisparity(mean));
    }
  }
  if (dropped_at_edges != nullptr) *dropped_at_edges = dropped;
  return depth;
}

colmap_io::SparseModel BuildStereoPairModel(const NpyMatrix& disparity,
                                            const StereoPairCalibration& calibration,
                                            const std::string& left_name,
                                            const std::string& right_name, const cv::Mat& rgb_left,
                                            int num_sparse_points, double max_disparity_step,
                                            int64_t* candidates) {
  calibration.Check();
  const int width = disparity.cols, height = disparity.rows;
  if (rgb_left.type() != CV_32FC3 || rgb_left.cols != width || rgb_left.rows != height) {
    throw std::invalid_argument("the left image must be CV_32FC3 of the disparity's size " +
                                SizeText(width, height));
  }
  const Eigen::Matrix3d K_left = LeftK(calibration);
  const Eigen::Matrix3d K_right = RightK(calibration);
  const Eigen::Vector3d right_centre(calibration.baseline, 0, 0);

  colmap_io::SparseModel model;
  const auto add_camera = [&](colmap_io::camera_t id, const Eigen::Matrix3d& K) {
    colmap_io::Camera camera;
    camera.camera_id = id;
    camera.model_id = colmap_io::kPinholeModelId;
    camera.width = static_cast<uint64_t>(width);
    camera.height = static_cast<uint64_t>(height);
    camera.params = {K(0, 0), K(1, 1), K(0, 2), K(1, 2)};
    model.cameras[id] = camera;
  };
  add_camera(1, K_left);
  add_camera(2, K_right);
  const auto add_image = [&](colmap_io::image_t id, const std::string& name,
                             const Eigen::Vector3d& centre) {
    colmap_io::Image image;
    image.image_id = id;
    image.camera_id = id;
    image.name = name;
    const Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    image.SetPose(R, -R * centre);
    model.images[id] = image;
  };
  add_image(kLeftId, left_name, Eigen::Vector3d::Zero());
  add_image(kRightId, right_name, right_centre);

  // Candidates: valid, seen inside the right image and not occluded there.
  // A z-buffer per row: the largest disparity landing on each right pixel.
  std::vector<std::pair<int, int>> chosen_from;  // (row, col), raster order
  std::vector<double> nearest(static_cast<std::size_t>(width));
  const auto right_pixel = [&](int col, double d) {
    return static_cast<int>(std::floor(col + 0.5 - d));  // COLMAP x -> pixel index
  };
  for (int row = 0; row < height; ++row) {
    std::fill(nearest.begin(), nearest.end(), -std::numeric_limits<double>::infinity());
    for (int col = 0; col < width; ++col) {
      const double d = disparity.at(row, col);
      if (!calibration.IsValidDisparity(d)) continue;
      const int x = right_pixel(col, d);
      if (x >= 0 && x < width) nearest[x] = std::max(nearest[x], d);
    }
    for (int col = 0; col < width; ++col) {
      const double d = disparity.at(row, col);
      if (!calibration.IsValidDisparity(d)) continue;
      const int x = right_pixel(col, d);
      if (x < 0 || x >= width) continue;
      if (nearest[x] - d > max_disparity_step) continue;
      chosen_from.emplace_back(row, col);
    }
  }
  if (candidates != nullptr) *candidates = static_cast<int64_t>(chosen_from.size());

  const std::size_t count = chosen_from.size();
  const std::size_t wanted = std::min(count, static_cast<std::size_t>(num_sparse_points));
  colmap_io::point3D_t next_id = 1;
  for (std::size_t i = 0; i < wanted; ++i) {
    // Evenly spaced through the candidates (all of them when few).
    const std::size_t index = count == wanted ? i : (2 * i + 1) * count / (2 * wanted);
    const auto [row, col] = chosen_from[index];
    const double z = calibration.DepthOfDisparity(disparity.at(row, col));
    const Eigen::Vector3d centre_ray = K_left.inverse() * Eigen::Vector3d(col + 0.5, row + 0.5, 1);
    const Eigen::Vector3d world = z * centre_ray;  // the left camera is the world frame
    colmap_io::Point3D point;
    point.point3D_id = next_id++;
    point.xyz = world;
    const cv::Vec3f rgb = rgb_left.at<cv::Vec3f>(row, col);
    for (int k = 0; k < 3; ++k) {
      point.rgb[k] = static_cast<uint8_t>(std::lround(255.0 * std::clamp(rgb[k], 0.0f, 1.0f)));
    }
    point.error = 0;
    // Exact projections (to rounding), as synth/workspace_writer does.
    model.AddObservedPoint(point, {{kLeftId, Project(K_left, world)},
                                   {kRightId, Project(K_right, world - right_centre)}});
  }
  return model;
}

StereoPairWorkspaceSummary WriteStereoPairWorkspace(const fs::path& dir, const NpyMatrix& disparity,
                                                    const fs::path& disparity_path,
                                                    const StereoPairWorkspaceOptions& options) {
  options.Check();
  const StereoPairCalibration& calibration = options.calibration;

  // Inputs first: nothing is written when one is bad.
  const cv::Mat left = colmap_io::ReadImageRgb(options.left_image);
  const cv::Mat right = colmap_io::ReadImageRgb(options.right_image);
  if (left.cols != disparity.cols || left.rows != disparity.rows) {
    throw IoError(disparity_path.string(),
                  "disparity map is " + SizeText(disparity.cols, disparity.rows) +
                      " (cols x rows) but the left image is " + SizeText(left.cols, left.rows));
  }
  if (right.size() != left.size()) {
    throw IoError(options.right_image.string(),
                  "right image is " + SizeText(right.cols, right.rows) + " but the left image is " +
                      SizeText(left.cols, left.rows) + " (a rectified pair has one size)");
  }
  StereoPairWorkspaceSummary summary;
  summary.width = left.cols;
  summary.height = left.rows;
  summary.left_name = ImageName("left", options.left_image);
  summary.right_name = ImageName("right", options.right_image);
  for (const double d : disparity.values) summary.valid_disparities += calibration.IsValidDisparity(d);
  if (summary.valid_disparities == 0) {
    throw IoError(disparity_path.string(),
                  "no valid disparity (finite, with d + doffs > 0) in the map");
  }

  const colmap_io::DenseArray depth = DisparityToDenseDepth(
      disparity, calibration, options.max_disparity_step, &summary.gt_dropped_at_edges);
  summary.gt_min_depth = std::numeric_limits<double>::infinity();
  summary.gt_max_depth = 0;
  for (const float z : depth.values()) {
    if (!(z > 0)) continue;
    ++summary.gt_pixels;
    summary.gt_min_depth = std::min<double>(summary.gt_min_depth, z);
    summary.gt_max_depth = std::max<double>(summary.gt_max_depth, z);
  }
  if (summary.gt_pixels == 0) {
    throw IoError(disparity_path.string(),
                  "no ground-truth depth: no 2x2 block of valid disparities within " +
                      Number(options.max_disparity_step) + " px of each other");
  }
  const colmap_io::SparseModel model =
      BuildStereoPairModel(disparity, calibration, summary.left_name, summary.right_name, left,
                           options.num_sparse_points, options.max_disparity_step,
                           &summary.sparse_candidates);
  summary.num_points3D = static_cast<int64_t>(model.points3D.size());
  if (summary.num_points3D == 0) {
    throw IoError(disparity_path.string(),
                  "no pixel with valid disparity lands inside the right image: no sparse point");
  }

  WriteBytes(ReadBytes(options.left_image), dir / "images" / summary.left_name);
  WriteBytes(ReadBytes(options.right_image), dir / "images" / summary.right_name);
  colmap_io::WriteSparseModelBinary(model, dir / "sparse");
  colmap_io::WriteDenseArray(depth, dir / "ground_truth" / "depth_maps" / (summary.left_name + ".bin"));

  const colmap_io::Workspace workspace(dir);
  workspace.CreateStereoFolders();
  colmap_io::WritePatchMatchConfig(
      {{summary.left_name, colmap_io::SourceSpec::Explicit({summary.right_name})},
       {summary.right_name, colmap_io::SourceSpec::Explicit({summary.left_name})}},
      workspace.PatchMatchConfigPath());
  colmap_io::WriteFusionConfig({summary.left_name, summary.right_name},
                               workspace.FusionConfigPath());
  WriteReadme(options, disparity_path, summary, dir / "ground_truth" / "README.txt");
  return summary;
}

}  // namespace dispmvs::bench
