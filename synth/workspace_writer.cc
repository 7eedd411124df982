#include "synth/workspace_writer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <system_error>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "colmap_io/atomic_file.h"
#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"
#include "colmap_io/ply.h"
#include "colmap_io/sparse_model.h"
#include "colmap_io/sparse_model_io.h"
#include "colmap_io/stereo_config.h"
#include "colmap_io/workspace.h"
#include "synth/raycast.h"
#include "synth/rng.h"

namespace dispmvs::synth {
namespace {

namespace fs = std::filesystem;
using colmap_io::image_t;

// Random stream of the sparse point sample, apart from the generator's own
// streams (generator.cc) so that it never changes the scene of a seed.
constexpr uint64_t kSparseSampleStream = 0x5350415253450001ull;

// One view in COLMAP's terms, everything metric.
struct ViewGeometry {
  std::string name;
  Eigen::Matrix3d K;  // COLMAP convention
  Eigen::Matrix3d R;  // world -> camera
  Eigen::Vector3d t;
};

// What a view contributes besides its image: the ground truth in COLMAP's
// dense indexing and the 8-bit image written to disk.
struct ViewData {
  ViewGeometry geometry;
  colmap_io::DenseArray depth;          // metric camera z, 0 = no surface
  std::vector<Eigen::Vector3f> normal;  // world normal per ground-truth sample (row-major)
  cv::Mat rgb;                          // CV_8UC3, RGB order
};

ViewGeometry MakeGeometry(const PinholeCamera& camera, double scale, int index) {
  ViewGeometry view;
  char name[32];
  std::snprintf(name, sizeof(name), "view_%02d.png", index);
  view.name = name;
  view.K << camera.fx, 0, camera.cx + 0.5, 0, camera.fy, camera.cy + 0.5, 0, 0, 1;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) view.R(r, c) = camera.rotation(r, c);
    view.t[r] = scale * camera.translation[r];
  }
  return view;
}

// Ground truth sampled where COLMAP's dense stage reads it: depth pixel
// (col, row) is image position (col, row) in COLMAP's convention, pixel index
// (col - 0.5, row - 0.5). Cast in double precision so that the only rounding
// is the final float32 of the dense array.
void CastGroundTruth(const SynthScene& scene, const SynthConfig& config, int index, ViewData* view) {
  const int64_t height = config.height, width = config.width;
  const auto doubles = torch::TensorOptions().dtype(torch::kDouble);
  const torch::Tensor cols = torch::arange(width, doubles) - 0.5;
  const torch::Tensor rows = torch::arange(height, doubles) - 0.5;
  const std::vector<torch::Tensor> grid = torch::meshgrid({rows, cols}, "ij");
  const torch::Tensor xy = torch::stack({grid[1].reshape({-1}), grid[0].reshape({-1})}, 1);
  RaycastOptions options;
  options.dtype = torch::kDouble;
  options.march_steps = config.march_steps;
  options.bisection_steps = config.bisection_steps;
  const RayHits hits = CastPixels(scene.scene, scene.cameras[static_cast<size_t>(index)], xy, options);
  const torch::Tensor depth = (hits.depth * scene.scale).contiguous();
  const torch::Tensor normal = hits.normal.contiguous();
  const auto depth_a = depth.accessor<double, 1>();
  const auto normal_a = normal.accessor<double, 2>();

  view->depth = colmap_io::DenseArray(static_cast<int>(width), static_cast<int>(height), 1);
  view->normal.resize(static_cast<size_t>(height * width));
  for (int64_t i = 0; i < height * width; ++i) {
    view->depth.data()[i] = static_cast<float>(depth_a[i]);
    view->normal[static_cast<size_t>(i)] = Eigen::Vector3f(
        static_cast<float>(normal_a[i][0]), static_cast<float>(normal_a[i][1]), static_cast<float>(normal_a[i][2]));
  }
}

// COLMAP's normal map of the ground truth: camera-frame unit normals facing
// the camera, 3 channels, 0 where there is no surface.
colmap_io::DenseArray CameraFrameNormals(const ViewData& view) {
  const int width = view.depth.width(), height = view.depth.height();
  colmap_io::DenseArray normals(width, height, 3);
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      if (!(view.depth.at(row, col) > 0)) continue;
      const Eigen::Vector3d world = view.normal[static_cast<size_t>(row) * width + col].cast<double>();
      const Eigen::Vector3d camera = view.geometry.R * world;
      for (int c = 0; c < 3; ++c) normals.at(row, col, c) = static_cast<float>(camera[c]);
    }
  }
  return normals;
}

// [3,H,W] in [0,1] -> 8-bit RGB, round to nearest.
cv::Mat ToRgb8(const torch::Tensor& image) {
  const torch::Tensor bytes =
      (image.to(torch::kCPU, torch::kDouble).clamp(0, 1) * 255.0).round().to(torch::kByte).permute({1, 2, 0}).contiguous();
  cv::Mat rgb(static_cast<int>(bytes.size(0)), static_cast<int>(bytes.size(1)), CV_8UC3);
  std::memcpy(rgb.data, bytes.data_ptr<uint8_t>(), static_cast<size_t>(bytes.numel()));
  return rgb;
}

void WritePng(const cv::Mat& rgb, const fs::path& path) {
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  std::vector<uint8_t> bytes;
  if (!cv::imencode(".png", bgr, bytes)) throw colmap_io::IoError(path.string(), "PNG encoding failed");
  colmap_io::WriteFileAtomically(path, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  });
}

// Colour at ground-truth sample (col, row), which lies on the corner shared by
// image pixels (col-1..col, row-1..row): the rounded mean of those inside.
std::array<uint8_t, 3> ColourAtSample(const cv::Mat& rgb, int col, int row) {
  int sum[3] = {0, 0, 0}, count = 0;
  for (int r = std::max(row - 1, 0); r <= std::min(row, rgb.rows - 1); ++r) {
    for (int c = std::max(col - 1, 0); c <= std::min(col, rgb.cols - 1); ++c) {
      const cv::Vec3b& p = rgb.at<cv::Vec3b>(r, c);
      for (int k = 0; k < 3; ++k) sum[k] += p[k];
      ++count;
    }
  }
  std::array<uint8_t, 3> out{};
  for (int k = 0; k < 3; ++k) out[k] = static_cast<uint8_t>((sum[k] + count / 2) / count);
  return out;
}

Eigen::Vector3d BackProject(const ViewData& view, int col, int row) {
  const double depth = view.depth.at(row, col);
  const Eigen::Vector3d camera_point = depth * (view.geometry.K.inverse() * Eigen::Vector3d(col, row, 1.0));
  return view.geometry.R.transpose() * (camera_point - view.geometry.t);
}

// Where `view` sees `world` if it does: inside the ground truth's sample grid,
// and the bilinear interpolation of the four surrounding samples (all on a
// surface) equals the point's depth within `tolerance` (relative).
std::optional<Eigen::Vector2d> Observe(const ViewData& view, const Eigen::Vector3d& world, double tolerance) {
  const Eigen::Vector3d p = view.geometry.R * world + view.geometry.t;
  if (!(p.z() > 0)) return std::nullopt;
  const Eigen::Vector3d uvw = view.geometry.K * p;
  const double u = uvw.x() / uvw.z(), v = uvw.y() / uvw.z();
  const int width = view.depth.width(), height = view.depth.height();
  if (!(u >= 0 && u <= width - 1 && v >= 0 && v <= height - 1)) return std::nullopt;
  const int c0 = std::min(static_cast<int>(std::floor(u)), width - 2);
  const int r0 = std::min(static_cast<int>(std::floor(v)), height - 2);
  const double a = u - c0, b = v - r0;
  const double d00 = view.depth.at(r0, c0), d01 = view.depth.at(r0, c0 + 1);
  const double d10 = view.depth.at(r0 + 1, c0), d11 = view.depth.at(r0 + 1, c0 + 1);
  if (!(d00 > 0 && d01 > 0 && d10 > 0 && d11 > 0)) return std::nullopt;
  const double interpolated = (1 - b) * ((1 - a) * d00 + a * d01) + b * ((1 - a) * d10 + a * d11);
  if (std::abs(interpolated - p.z()) > tolerance * p.z()) return std::nullopt;
  return Eigen::Vector2d(u, v);
}

colmap_io::SparseModel BuildSparseModel(const std::vector<ViewData>& views, const SynthWorkspaceOptions& options,
                                        uint64_t seed) {
  colmap_io::SparseModel model;
  for (size_t i = 0; i < views.size(); ++i) {
    const ViewGeometry& g = views[i].geometry;
    colmap_io::Camera camera;
    camera.camera_id = static_cast<colmap_io::camera_t>(i + 1);
    camera.model_id = 1;  // PINHOLE
    camera.width = static_cast<uint64_t>(views[i].depth.width());
    camera.height = static_cast<uint64_t>(views[i].depth.height());
    camera.params = {g.K(0, 0), g.K(1, 1), g.K(0, 2), g.K(1, 2)};
    model.cameras[camera.camera_id] = camera;

    colmap_io::Image image;
    image.image_id = static_cast<image_t>(i + 1);
    image.SetPose(g.R, g.t);
    image.camera_id = camera.camera_id;
    image.name = g.name;
    model.images[image.image_id] = image;
  }

  Rng rng = Rng(seed).Fork(kSparseSampleStream);
  for (size_t source = 0; source < views.size(); ++source) {
    const ViewData& view = views[source];
    const int width = view.depth.width(), height = view.depth.height();
    // Square cells, about sparse_points_per_view of them.
    const double cell = std::max(1.0, std::sqrt(static_cast<double>(width) * height / options.sparse_points_per_view));
    const int cells_x = std::max(1, static_cast<int>(std::lround(width / cell)));
    const int cells_y = std::max(1, static_cast<int>(std::lround(height / cell)));
    for (int cy = 0; cy < cells_y; ++cy) {
      for (int cx = 0; cx < cells_x; ++cx) {
        const int col0 = cx * width / cells_x, col1 = (cx + 1) * width / cells_x;
        const int row0 = cy * height / cells_y, row1 = (cy + 1) * height / cells_y;
        const int col = static_cast<int>(rng.Int(col0, std::max(col0, col1 - 1)));
        const int row = static_cast<int>(rng.Int(row0, std::max(row0, row1 - 1)));
        if (!(view.depth.at(row, col) > 0)) continue;  // sky
        const Eigen::Vector3d world = BackProject(view, col, row);

        std::vector<std::pair<image_t, Eigen::Vector2d>> observations;
        for (size_t other = 0; other < views.size(); ++other) {
          if (other == source) {
            // Exactly at a ground-truth sample; project anyway so that the
            // stored position is the point's projection to the last bit.
            const Eigen::Vector3d uvw = view.geometry.K * (view.geometry.R * world + view.geometry.t);
            observations.emplace_back(static_cast<image_t>(other + 1),
                                      Eigen::Vector2d(uvw.x() / uvw.z(), uvw.y() / uvw.z()));
          } else if (const auto xy = Observe(views[other], world, options.visibility_tolerance)) {
            observations.emplace_back(static_cast<image_t>(other + 1), *xy);
          }
        }
        if (observations.size() < 2) continue;  // SfM only keeps triangulated points

        colmap_io::Point3D point;
        point.point3D_id = model.points3D.size() + 1;
        point.xyz = world;
        point.error = 0.0;  // exact projections
        point.rgb = ColourAtSample(view.rgb, col, row);
        model.AddObservedPoint(point, observations);
      }
    }
  }
  return model;
}

std::vector<colmap_io::PlyPoint> GroundTruthCloud(const std::vector<ViewData>& views, int stride) {
  std::vector<colmap_io::PlyPoint> points;
  for (const ViewData& view : views) {
    for (int row = 0; row < view.depth.height(); row += stride) {
      for (int col = 0; col < view.depth.width(); col += stride) {
        if (!(view.depth.at(row, col) > 0)) continue;
        colmap_io::PlyPoint point;
        const Eigen::Vector3f xyz = BackProject(view, col, row).cast<float>();
        const Eigen::Vector3f& n = view.normal[static_cast<size_t>(row) * view.depth.width() + col];
        point.xyz = {xyz.x(), xyz.y(), xyz.z()};
        point.normal = {n.x(), n.y(), n.z()};
        point.rgb = ColourAtSample(view.rgb, col, row);
        points.push_back(point);
      }
    }
  }
  return points;
}

void WriteReadme(const SynthScene& scene, uint64_t seed, const SynthWorkspaceOptions& options, const fs::path& path) {
  colmap_io::WriteFileAtomically(path, [&](std::ostream& out) {
    out << "Exact ground truth of this synthetic workspace (dispmvs_synth).\n"
           "rig: " << RigName(scene.rig) << "\nseed: " << seed << "\nmetric scale: " << scene.scale << "\n\n"
           "depth_maps/NAME.bin: camera-frame z depth, 1 channel, 0 = no surface, as a\n"
           "COLMAP dense array (WIDTH&HEIGHT&CHANNELS& + float32).\n"
           "normal_maps/NAME.bin: unit normals in the camera frame, 3 channels, facing the\n"
           "camera (COLMAP's convention), 0 = no surface; same sampling as the depth.\n"
           "Sampling: colmap-dense. Pixel (col, row) holds the ray through image position\n"
           "(col, row) in the sparse model's convention (top-left pixel centre at 0.5, 0.5),\n"
           "the indexing of COLMAP's PatchMatch and stereo_fusion, so stereo_fusion of these\n"
           "maps reproduces the surfaces exactly. The images are rendered at pixel centres.\n"
           "points.ply: world points of one depth sample in " << options.ply_stride << " along the rows and\n"
           "the columns of every view, with the ray caster's unit normals (facing that view) and\n"
           "the mean colour of the image pixels around the sample; COLMAP's fused.ply layout.\n"
           "sparse/: every point is observed at its exact projection by each view whose\n"
           "ground-truth depth, interpolated bilinearly, agrees within a relative "
        << options.visibility_tolerance << ".\n";
  });
}

}  // namespace

void SynthWorkspaceOptions::Check() const {
  config.Check();
  if (sparse_points_per_view < 1 || sparse_points_per_view > 100000) {
    throw std::invalid_argument("sparse_points_per_view must be in [1, 100000]");
  }
  if (!(visibility_tolerance > 0 && visibility_tolerance < 0.1)) {
    throw std::invalid_argument("visibility_tolerance must be in (0, 0.1)");
  }
  if (ply_stride < 1 || ply_stride > 64) throw std::invalid_argument("ply_stride must be in [1, 64]");
}

SynthConfig ConfigForRig(const std::string& rig, SynthConfig config) {
  if (rig == "random") return config;
  config.p_table = config.p_walkthrough = config.p_turntable = config.p_outdoor = 0;
  if (rig == RigName(RigKind::kTable)) {
    config.p_table = 1;
  } else if (rig == RigName(RigKind::kWalkThrough)) {
    config.p_walkthrough = 1;
  } else if (rig == RigName(RigKind::kTurntable)) {
    config.p_turntable = 1;
  } else if (rig == RigName(RigKind::kOutdoor)) {
    config.p_outdoor = 1;
  } else {
    throw std::invalid_argument("unknown rig '" + rig + "' (expected table, walkthrough, turntable, outdoor or random)");
  }
  return config;
}

uint64_t SceneSeed(uint64_t base_seed, int scene_index) {
  return Rng(base_seed).Fork(static_cast<uint64_t>(scene_index) + 1).NextU64();
}

std::string SceneFolderName(int scene_index) {
  char name[32];
  std::snprintf(name, sizeof(name), "scene_%03d", scene_index);
  return name;
}

SynthWorkspaceSummary WriteSynthWorkspace(const fs::path& dir, const SynthWorkspaceOptions& options, uint64_t seed) {
  options.Check();
  const SynthConfig& config = options.config;
  const SynthScene scene = DrawScene(config, seed);
  const SynthSample sample = RenderSample(scene, config, torch::kCPU);

  std::vector<ViewData> views(scene.cameras.size());
  for (size_t i = 0; i < views.size(); ++i) {
    const int index = static_cast<int>(i);
    views[i].geometry = MakeGeometry(scene.cameras[i], scene.scale, index);
    CastGroundTruth(scene, config, index, &views[i]);
    views[i].rgb = ToRgb8(sample.images[index]);
    WritePng(views[i].rgb, dir / "images" / views[i].geometry.name);
    colmap_io::WriteDenseArray(views[i].depth, dir / "ground_truth" / "depth_maps" / (views[i].geometry.name + ".bin"));
    colmap_io::WriteDenseArray(CameraFrameNormals(views[i]),
                               dir / "ground_truth" / "normal_maps" / (views[i].geometry.name + ".bin"));
  }

  const colmap_io::SparseModel model = BuildSparseModel(views, options, seed);
  colmap_io::WriteSparseModelBinary(model, dir / "sparse");

  const std::vector<colmap_io::PlyPoint> cloud = GroundTruthCloud(views, options.ply_stride);
  colmap_io::WritePlyPoints(cloud, dir / "ground_truth" / "points.ply");

  const colmap_io::Workspace workspace(dir);
  workspace.CreateStereoFolders();
  std::vector<colmap_io::PatchMatchEntry> entries;
  std::vector<std::string> names;
  for (const ViewData& view : views) {
    entries.push_back({view.geometry.name, colmap_io::SourceSpec::Auto(views.size() - 1)});
    names.push_back(view.geometry.name);
  }
  colmap_io::WritePatchMatchConfig(entries, workspace.PatchMatchConfigPath());
  colmap_io::WriteFusionConfig(names, workspace.FusionConfigPath());
  WriteReadme(scene, seed, options, dir / "ground_truth" / "README.txt");

  SynthWorkspaceSummary summary;
  summary.num_images = views.size();
  summary.num_points3D = model.points3D.size();
  for (const auto& [id, point] : model.points3D) summary.num_observations += point.track.size();
  summary.num_ground_truth_points = cloud.size();
  summary.rig = RigName(scene.rig);
  summary.scale = scene.scale;
  return summary;
}

SynthDatasetSummary WriteSynthDataset(const fs::path& output_dir, int num_scenes, uint64_t base_seed,
                                      const SynthWorkspaceOptions& options, std::ostream* log) {
  if (num_scenes < 1 || num_scenes > 1000000) throw std::invalid_argument("num_scenes must be in [1, 1000000]");
  options.Check();
  std::error_code error;
  fs::create_directories(output_dir, error);
  if (error) throw colmap_io::IoError(output_dir.string(), "cannot create: " + error.message());

  SynthDatasetSummary summary;
  for (int i = 0; i < num_scenes; ++i) {
    const fs::path final_dir = output_dir / SceneFolderName(i);
    if (fs::is_directory(final_dir)) {  // only ever created by the rename below
      ++summary.skipped;
      if (log) *log << final_dir.string() << ": exists, skipped\n";
      continue;
    }
    const fs::path temp_dir = output_dir / (SceneFolderName(i) + ".tmp");
    fs::remove_all(temp_dir, error);
    if (error) throw colmap_io::IoError(temp_dir.string(), "cannot remove: " + error.message());
    const SynthWorkspaceSummary scene = WriteSynthWorkspace(temp_dir, options, SceneSeed(base_seed, i));
    fs::rename(temp_dir, final_dir, error);
    if (error) throw colmap_io::IoError(final_dir.string(), "cannot rename the finished scene into place: " + error.message());
    ++summary.written;
    if (log) {
      *log << final_dir.string() << ": " << scene.rig << ", scale " << scene.scale << ", " << scene.num_images
           << " images, " << scene.num_points3D << " sparse points (" << scene.num_observations << " observations), "
           << scene.num_ground_truth_points << " ground-truth points\n";
    }
  }
  return summary;
}

}  // namespace dispmvs::synth
