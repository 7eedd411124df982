#include "examples/example_workspace.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "colmap_io/atomic_file.h"
#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"
#include "colmap_io/sparse_model.h"
#include "colmap_io/sparse_model_io.h"
#include "colmap_io/stereo_config.h"
#include "colmap_io/workspace.h"
#include "examples/example_scene.h"

namespace dispmvs::examples {
namespace {

namespace fs = std::filesystem;
using colmap_io::image_t;

constexpr double kPi = 3.14159265358979323846;

// Camera rig: one PINHOLE camera shared by all views.
constexpr int kWidth = 320;
constexpr int kHeight = 240;
constexpr double kFocal = 280.0;
constexpr double kCx = kWidth / 2.0;
constexpr double kCy = kHeight / 2.0;
constexpr int kNumViews = 7;
constexpr double kArcRadius = 3.6;
constexpr double kArcHeight = 2.8;
constexpr double kFirstAzimuthDeg = -60.0;
constexpr double kAzimuthStepDeg = 20.0;
constexpr std::size_t kAutoSources = 4;

// Colour is averaged over kSupersampling^2 rays per pixel (anti-aliasing the
// finest texture octaves); depth and normals come from the centre ray.
constexpr int kSupersampling = 2;

constexpr int kNumCandidatePoints = 4000;
constexpr double kGroundSampleFraction = 0.55;
constexpr double kGroundSampleHalfSize = 2.5;
constexpr double kFaceMargin = 0.03;  // fraction of a face kept clear of its edges

struct View {
  std::string name;
  Eigen::Matrix3d R;  // world -> camera
  Eigen::Vector3d t;
  Eigen::Vector3d centre;
  // Per pixel, from the centre ray: the surface hit (-1: sky), as used by the
  // visibility test of sparse points.
  std::vector<int> surface_at_pixel;
};

// Camera looking from `centre` at `target` with world +z up in the image.
View MakeView(const std::string& name, const Eigen::Vector3d& centre,
              const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - centre).normalized();
  const Eigen::Vector3d down(0, 0, -1);
  const Eigen::Vector3d x = down.cross(z).normalized();  // camera x = y cross z
  const Eigen::Vector3d y = z.cross(x);
  View view;
  view.name = name;
  view.R.row(0) = x.transpose();
  view.R.row(1) = y.transpose();
  view.R.row(2) = z.transpose();
  view.centre = centre;
  view.t = -view.R * centre;
  return view;
}

std::vector<View> MakeViews() {
  std::vector<View> views;
  const Eigen::Vector3d target(0.1, 0.0, 0.35);
  for (int i = 0; i < kNumViews; ++i) {
    const double azimuth = (kFirstAzimuthDeg + kAzimuthStepDeg * i) * kPi / 180.0;
    const Eigen::Vector3d centre(kArcRadius * std::sin(azimuth), -kArcRadius * std::cos(azimuth),
                                 kArcHeight);
    char name[32];
    std::snprintf(name, sizeof(name), "view_%02d.png", i);
    views.push_back(MakeView(name, centre, target));
  }
  return views;
}

// World direction of the ray through image position (u, v) (COLMAP pixel
// convention), scaled so that its camera-frame z component is 1: the ray
// parameter at a hit is then the hit's depth.
Eigen::Vector3d RayDirection(const View& view, double u, double v) {
  const Eigen::Vector3d camera_ray((u - kCx) / kFocal, (v - kCy) / kFocal, 1.0);
  return view.R.transpose() * camera_ray;
}

uint8_t ToByte(double linear) {
  const double encoded = std::pow(std::clamp(linear, 0.0, 1.0), 1.0 / 2.2);  // display gamma
  return static_cast<uint8_t>(std::lround(encoded * 255.0));
}

struct RenderedView {
  cv::Mat bgr;  // CV_8UC3
  colmap_io::DenseArray depth;
  colmap_io::DenseArray normals;
};

// Where ground-truth pixel (col, row) is sampled, as an offset added to both
// indices.
double SampleOffset(GroundTruthSampling sampling) {
  return sampling == GroundTruthSampling::kPixelCentres ? 0.5 : 0.0;
}

RenderedView Render(const ExampleScene& scene, double sample_offset, View* view) {
  RenderedView out;
  out.bgr = cv::Mat(kHeight, kWidth, CV_8UC3);
  out.depth = colmap_io::DenseArray(kWidth, kHeight, 1);
  out.normals = colmap_io::DenseArray(kWidth, kHeight, 3);
  view->surface_at_pixel.assign(static_cast<std::size_t>(kWidth) * kHeight, -1);
  for (int row = 0; row < kHeight; ++row) {
    for (int col = 0; col < kWidth; ++col) {
      Eigen::Vector3d colour = Eigen::Vector3d::Zero();
      for (int sy = 0; sy < kSupersampling; ++sy) {
        for (int sx = 0; sx < kSupersampling; ++sx) {
          const double u = col + (sx + 0.5) / kSupersampling;
          const double v = row + (sy + 0.5) / kSupersampling;
          const auto hit = scene.Cast(view->centre, RayDirection(*view, u, v));
          colour += hit ? scene.Shade(*hit) : ExampleScene::SkyColour();
        }
      }
      colour /= static_cast<double>(kSupersampling * kSupersampling);
      out.bgr.at<cv::Vec3b>(row, col) =
          cv::Vec3b(ToByte(colour.z()), ToByte(colour.y()), ToByte(colour.x()));

      const auto hit = scene.Cast(
          view->centre, RayDirection(*view, col + sample_offset, row + sample_offset));
      if (!hit) continue;  // sky: depth 0, normal 0
      out.depth.at(row, col) = static_cast<float>(hit->t);
      const Eigen::Vector3d normal = view->R * hit->normal;
      for (int c = 0; c < 3; ++c) out.normals.at(row, col, c) = static_cast<float>(normal[c]);
      view->surface_at_pixel[static_cast<std::size_t>(row) * kWidth + col] =
          static_cast<int>(hit->surface);
    }
  }
  return out;
}

// Uniform double in [0, 1) from the raw generator output (std's
// distributions are not specified bit for bit, this is).
double Uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

struct SurfaceSample {
  Eigen::Vector3d xyz;
  Surface surface;
};

SurfaceSample SampleSurface(const ExampleScene& scene, std::mt19937_64& rng) {
  if (Uniform(rng) < kGroundSampleFraction) {
    const double x = (2.0 * Uniform(rng) - 1.0) * kGroundSampleHalfSize;
    const double y = (2.0 * Uniform(rng) - 1.0) * kGroundSampleHalfSize;
    return {Eigen::Vector3d(x, y, 0.0), Surface::kGround};
  }
  static constexpr std::array<Surface, 5> kVisibleFaces = {
      Surface::kBoxPlusX, Surface::kBoxMinusX, Surface::kBoxPlusY, Surface::kBoxMinusY,
      Surface::kBoxTop};
  double total_area = 0.0;
  for (const Surface face : kVisibleFaces) total_area += scene.FaceArea(face);
  double pick = Uniform(rng) * total_area;
  Surface face = kVisibleFaces.back();
  for (const Surface candidate : kVisibleFaces) {
    if (pick < scene.FaceArea(candidate)) {
      face = candidate;
      break;
    }
    pick -= scene.FaceArea(candidate);
  }
  const double a = kFaceMargin + (1.0 - 2.0 * kFaceMargin) * Uniform(rng);
  const double b = kFaceMargin + (1.0 - 2.0 * kFaceMargin) * Uniform(rng);
  return {scene.BoxFacePoint(face, a, b), face};
}

// Where `view` observes `sample`, if it does: in front of the camera, at least
// a pixel inside the image, not occluded (the ray towards it first hits it),
// and with the four ground-truth samples around the projection on the same
// face.
std::optional<Eigen::Vector2d> Observe(const ExampleScene& scene, const View& view,
                                       double sample_offset, const SurfaceSample& sample) {
  const Eigen::Vector3d p = view.R * sample.xyz + view.t;
  if (p.z() <= 0.0) return std::nullopt;
  const double u = kFocal * p.x() / p.z() + kCx;
  const double v = kFocal * p.y() / p.z() + kCy;
  if (!(u >= 1.0 && u <= kWidth - 1.0 && v >= 1.0 && v <= kHeight - 1.0)) return std::nullopt;
  const auto hit = scene.Cast(view.centre, sample.xyz - view.centre);
  if (!hit || hit->surface != sample.surface || std::abs(hit->t - 1.0) > 1e-9) {
    return std::nullopt;
  }
  const int col0 = static_cast<int>(std::floor(u - sample_offset));
  const int row0 = static_cast<int>(std::floor(v - sample_offset));
  for (int row = row0; row <= row0 + 1; ++row) {
    for (int col = col0; col <= col0 + 1; ++col) {
      const int surface = view.surface_at_pixel[static_cast<std::size_t>(row) * kWidth + col];
      if (surface != static_cast<int>(sample.surface)) return std::nullopt;
    }
  }
  return Eigen::Vector2d(u, v);
}

void WritePng(const cv::Mat& bgr, const fs::path& path) {
  std::vector<uint8_t> bytes;
  if (!cv::imencode(".png", bgr, bytes)) {
    throw colmap_io::IoError(path.string(), "PNG encoding failed");
  }
  colmap_io::WriteFileAtomically(path, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
  });
}

void WriteGroundTruthReadme(GroundTruthSampling sampling, const fs::path& path) {
  colmap_io::WriteFileAtomically(path, [&](std::ostream& out) {
    out << "Exact ground truth of this synthetic workspace (dispmvs_make_example).\n"
           "depth_maps/NAME.bin: z depth in the camera frame, 1 channel, 0 = no surface.\n"
           "normal_maps/NAME.bin: unit normals in the camera frame, 3 channels, facing\n"
           "the camera. Both are COLMAP dense arrays (WIDTH&HEIGHT&CHANNELS& + float32).\n";
    if (sampling == GroundTruthSampling::kPixelCentres) {
      out << "Sampling: pixel-centres. Pixel (col, row) holds the ray through image\n"
             "position (col + 0.5, row + 0.5) in the sparse model's convention.\n";
    } else {
      out << "Sampling: colmap-dense. Pixel (col, row) holds the ray through image\n"
             "position (col, row), the indexing of COLMAP's PatchMatch and stereo_fusion.\n";
    }
  });
}

}  // namespace

ExampleWorkspaceSummary WriteExampleWorkspace(const fs::path& dir,
                                              const ExampleWorkspaceOptions& options) {
  const ExampleScene scene(options.seed);
  const double sample_offset = SampleOffset(options.sampling);
  std::vector<View> views = MakeViews();

  colmap_io::SparseModel model;
  colmap_io::Camera camera;
  camera.camera_id = 1;
  camera.model_id = 1;  // PINHOLE
  camera.width = kWidth;
  camera.height = kHeight;
  camera.params = {kFocal, kFocal, kCx, kCy};
  model.cameras[camera.camera_id] = camera;

  std::error_code error;
  fs::create_directories(dir / "images", error);
  if (error) {
    throw colmap_io::IoError((dir / "images").string(), "cannot create: " + error.message());
  }

  for (std::size_t i = 0; i < views.size(); ++i) {
    View& view = views[i];
    const RenderedView rendered = Render(scene, sample_offset, &view);
    WritePng(rendered.bgr, dir / "images" / view.name);
    colmap_io::WriteDenseArray(rendered.depth,
                               dir / "ground_truth" / "depth_maps" / (view.name + ".bin"));
    colmap_io::WriteDenseArray(rendered.normals,
                               dir / "ground_truth" / "normal_maps" / (view.name + ".bin"));

    colmap_io::Image image;
    image.image_id = static_cast<image_t>(i + 1);
    image.SetPose(view.R, view.t);
    image.camera_id = camera.camera_id;
    image.name = view.name;
    model.images[image.image_id] = image;
  }

  std::mt19937_64 rng(options.seed);
  ExampleWorkspaceSummary summary;
  summary.num_images = views.size();
  for (int candidate = 0; candidate < kNumCandidatePoints; ++candidate) {
    const SurfaceSample sample = SampleSurface(scene, rng);
    std::vector<std::pair<image_t, Eigen::Vector2d>> observations;
    for (std::size_t i = 0; i < views.size(); ++i) {
      if (const auto xy = Observe(scene, views[i], sample_offset, sample)) {
        observations.emplace_back(static_cast<image_t>(i + 1), *xy);
      }
    }
    if (observations.size() < 2) continue;  // SfM only keeps triangulated points

    colmap_io::Point3D point;
    point.point3D_id = model.points3D.size() + 1;
    point.xyz = sample.xyz;
    point.error = 0.0;  // exact projections
    // Shading is view independent: any observing view gives the colour.
    const View& first_view = views[observations.front().first - 1];
    const Eigen::Vector3d colour =
        scene.Shade(*scene.Cast(first_view.centre, sample.xyz - first_view.centre));
    point.rgb = {ToByte(colour.x()), ToByte(colour.y()), ToByte(colour.z())};
    model.AddObservedPoint(point, observations);
    summary.num_observations += observations.size();
  }
  summary.num_points3D = model.points3D.size();

  colmap_io::WriteSparseModelBinary(model, dir / "sparse");

  const colmap_io::Workspace workspace(dir);
  workspace.CreateStereoFolders();
  std::vector<colmap_io::PatchMatchEntry> entries;
  std::vector<std::string> names;
  for (const View& view : views) {
    entries.push_back({view.name, colmap_io::SourceSpec::Auto(kAutoSources)});
    names.push_back(view.name);
  }
  colmap_io::WritePatchMatchConfig(entries, workspace.PatchMatchConfigPath());
  colmap_io::WriteFusionConfig(names, workspace.FusionConfigPath());
  WriteGroundTruthReadme(options.sampling, dir / "ground_truth" / "README.txt");
  return summary;
}

}  // namespace dispmvs::examples
