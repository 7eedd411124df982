#include "bench/large_workspace.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "colmap_io/atomic_file.h"
#include "colmap_io/camera_models.h"
#include "colmap_io/dense_array.h"
#include "colmap_io/error.h"
#include "colmap_io/sparse_model.h"
#include "colmap_io/sparse_model_io.h"
#include "colmap_io/workspace.h"
#include "dense/workspace_maps.h"

namespace dispmvs::bench {
namespace {

namespace fs = std::filesystem;
using colmap_io::image_t;

constexpr double kPi = 3.14159265358979323846;
// Colour is averaged over kSupersampling^2 rays per pixel, so that the finest
// texture cells (a few pixels wide) do not alias differently in each view.
constexpr int kSupersampling = 2;
// Texture cells on the ground, in scene units (at the default altitude a
// pixel covers about 0.08 units): a fine and a coarse octave.
constexpr double kFineCell = 0.35;
constexpr double kCoarseCell = 1.4;

// One view's geometry, as the sparse model stores it (rotation from the
// written quaternion), so that maps and projections agree with what readers
// get back.
struct ViewGeometry {
  Eigen::Matrix3d R;  // world -> camera
  Eigen::Vector3d t;
  Eigen::Vector3d centre;
};

class PinholeRig {
 public:
  explicit PinholeRig(const LargeWorkspaceOptions& o)
      : width_(o.width),
        height_(o.height),
        focal_(o.focal_per_width * o.width),
        cx_(o.width / 2.0),
        cy_(o.height / 2.0) {}

  int width() const { return width_; }
  int height() const { return height_; }
  std::vector<double> Params() const { return {focal_, focal_, cx_, cy_}; }

  // Camera-frame ray through image position (u, v) (COLMAP convention), with
  // z = 1 so that the ray parameter at a hit is the hit's depth.
  Eigen::Vector3d Ray(double u, double v) const {
    return Eigen::Vector3d((u - cx_) / focal_, (v - cy_) / focal_, 1.0);
  }

  // Image position of camera-frame point p (p.z() > 0).
  Eigen::Vector2d Project(const Eigen::Vector3d& p) const {
    return Eigen::Vector2d(focal_ * p.x() / p.z() + cx_, focal_ * p.y() / p.z() + cy_);
  }

  // COLMAP's image bounds: position (u, v) lies in pixel (floor u, floor v).
  bool InFrame(const Eigen::Vector2d& uv) const {
    return uv.x() >= 0.0 && uv.x() < width_ && uv.y() >= 0.0 && uv.y() < height_;
  }

  // Where the ray through (u, v) meets z = 0; the ray must go down (checked
  // for the frame corners by MeasureFootprint).
  Eigen::Vector3d GroundPoint(const ViewGeometry& view, double u, double v) const {
    const Eigen::Vector3d world_ray = view.R.transpose() * Ray(u, v);
    return view.centre + (-view.centre.z() / world_ray.z()) * world_ray;
  }

 private:
  int width_, height_;
  double focal_, cx_, cy_;
};

// Camera looking down (camera +z towards world -z) turned by `tilt` about the
// world x axis towards +y; camera x is world +x, so image rows run against +y.
Eigen::Matrix3d DownwardRotation(double tilt) {
  const double s = std::sin(tilt), c = std::cos(tilt);
  Eigen::Matrix3d R;
  R.row(0) = Eigen::Vector3d(1, 0, 0).transpose();
  R.row(1) = Eigen::Vector3d(0, -c, -s).transpose();
  R.row(2) = Eigen::Vector3d(0, s, -c).transpose();
  return R;
}

// --- Texture: value noise of the world position, so every view sees the same
// colours at the same ground point.

uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

double LatticeValue(int64_t ix, int64_t iy, uint64_t salt) {
  const uint64_t h = SplitMix64(SplitMix64(static_cast<uint64_t>(ix) ^ (salt << 40)) ^
                                static_cast<uint64_t>(iy));
  return static_cast<double>(h >> 11) * 0x1.0p-53;
}

double SmoothStep(double a) { return a * a * (3.0 - 2.0 * a); }

double ValueNoise(double x, double y, uint64_t salt) {
  const double fx = std::floor(x), fy = std::floor(y);
  const auto ix = static_cast<int64_t>(fx), iy = static_cast<int64_t>(fy);
  const double ax = SmoothStep(x - fx), ay = SmoothStep(y - fy);
  const double top = LatticeValue(ix, iy, salt) * (1 - ax) + LatticeValue(ix + 1, iy, salt) * ax;
  const double bottom =
      LatticeValue(ix, iy + 1, salt) * (1 - ax) + LatticeValue(ix + 1, iy + 1, salt) * ax;
  return top * (1 - ay) + bottom * ay;
}

// RGB in [0, 1] at ground point (x, y).
Eigen::Vector3d GroundColour(double x, double y, uint64_t seed) {
  const double fine_a = ValueNoise(x / kFineCell, y / kFineCell, seed * 4 + 1);
  const double fine_b = ValueNoise(x / kFineCell, y / kFineCell, seed * 4 + 2);
  const double coarse = ValueNoise(x / kCoarseCell, y / kCoarseCell, seed * 4 + 3);
  return Eigen::Vector3d(0.1 + 0.5 * fine_a + 0.35 * coarse, 0.1 + 0.45 * fine_b + 0.4 * coarse,
                         0.1 + 0.3 * fine_a + 0.3 * fine_b + 0.25 * (1.0 - coarse));
}

uint8_t ToByte(double value) {
  return static_cast<uint8_t>(std::lround(std::clamp(value, 0.0, 1.0) * 255.0));
}

// Uniform double in [0, 1) from the raw generator output (std's
// distributions are not specified bit for bit, this is).
double Uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

// --- Which images can see a ground point: every image is listed in the
// cells of a ground grid that its footprint's bounding box touches, so a
// lookup tests a few images, not all of them.
class FootprintIndex {
 public:
  FootprintIndex(double origin_x, double origin_y, double cell_x, double cell_y, int cells_x,
                 int cells_y)
      : origin_x_(origin_x),
        origin_y_(origin_y),
        cell_x_(cell_x),
        cell_y_(cell_y),
        cells_x_(cells_x),
        cells_y_(cells_y),
        cells_(static_cast<std::size_t>(cells_x) * cells_y) {}

  void Insert(int view, double x0, double y0, double x1, double y1) {
    const int c0 = CellX(x0), c1 = CellX(x1), r0 = CellY(y0), r1 = CellY(y1);
    for (int r = r0; r <= r1; ++r) {
      for (int c = c0; c <= c1; ++c) {
        cells_[static_cast<std::size_t>(r) * cells_x_ + c].push_back(view);
      }
    }
  }

  const std::vector<int>& Candidates(double x, double y) const {
    return cells_[static_cast<std::size_t>(CellY(y)) * cells_x_ + CellX(x)];
  }

 private:
  int CellX(double x) const {
    return std::clamp(static_cast<int>(std::floor((x - origin_x_) / cell_x_)), 0, cells_x_ - 1);
  }
  int CellY(double y) const {
    return std::clamp(static_cast<int>(std::floor((y - origin_y_) / cell_y_)), 0, cells_y_ - 1);
  }

  double origin_x_, origin_y_, cell_x_, cell_y_;
  int cells_x_, cells_y_;
  std::vector<std::vector<int>> cells_;
};

std::string ImageName(int index) {
  char name[32];
  std::snprintf(name, sizeof name, "img_%05d.png", index);
  return name;
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

struct Footprint {
  // Bounding box of the ground seen by a view, relative to its centre.
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

// Ground footprint of a view at the origin, and the checks that every ray of
// the frame goes down to the plane.
Footprint MeasureFootprint(const PinholeRig& rig, const ViewGeometry& view) {
  Footprint box{std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
                std::numeric_limits<double>::lowest(), std::numeric_limits<double>::lowest()};
  for (const double u : {0.0, static_cast<double>(rig.width())}) {
    for (const double v : {0.0, static_cast<double>(rig.height())}) {
      if (!((view.R.transpose() * rig.Ray(u, v)).z() < 0)) {
        throw std::invalid_argument(
            "the frame reaches above the horizon: lower --tilt or the field of view");
      }
      const Eigen::Vector3d ground = rig.GroundPoint(view, u, v) - view.centre;
      box.x0 = std::min(box.x0, ground.x());
      box.y0 = std::min(box.y0, ground.y());
      box.x1 = std::max(box.x1, ground.x());
      box.y1 = std::max(box.y1, ground.y());
    }
  }
  return box;
}

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / kPi;
}

struct Layout {
  std::vector<ViewGeometry> views;
  Footprint footprint;
  double spacing_x = 0, spacing_y = 0;
  int num_rows = 0;
};

// Poses on the grid; the spacing comes from the footprint's extent through
// the principal point (along each axis), so neighbours share `overlap` of it.
Layout MakeLayout(const PinholeRig& rig, const LargeWorkspaceOptions& o,
                  colmap_io::SparseModel* model) {
  const Eigen::Matrix3d R = DownwardRotation(o.tilt_deg * kPi / 180.0);
  ViewGeometry origin{R, -R * Eigen::Vector3d(0, 0, o.altitude), Eigen::Vector3d(0, 0, o.altitude)};
  Layout layout;
  layout.footprint = MeasureFootprint(rig, origin);
  const double cx = rig.width() / 2.0, cy = rig.height() / 2.0;
  const double extent_x =
      (rig.GroundPoint(origin, rig.width(), cy) - rig.GroundPoint(origin, 0, cy)).norm();
  const double extent_y =
      (rig.GroundPoint(origin, cx, 0) - rig.GroundPoint(origin, cx, rig.height())).norm();
  layout.spacing_x = (1.0 - o.overlap) * extent_x;
  layout.spacing_y = (1.0 - o.overlap) * extent_y;
  layout.num_rows = (o.num_images + o.images_per_row - 1) / o.images_per_row;

  for (int i = 0; i < o.num_images; ++i) {
    const Eigen::Vector3d centre((i % o.images_per_row) * layout.spacing_x,
                                 (i / o.images_per_row) * layout.spacing_y, o.altitude);
    colmap_io::Image image;
    image.image_id = static_cast<image_t>(i + 1);
    image.camera_id = 1;
    image.name = ImageName(i);
    image.SetPose(R, -R * centre);
    ViewGeometry view;
    view.R = image.RotationMatrix();
    view.t = image.tvec;
    view.centre = image.ProjectionCenter();
    layout.views.push_back(view);
    model->images[image.image_id] = std::move(image);
  }
  return layout;
}

// Sparse points with a uniform density of points_per_image per footprint:
// each image proposes that many points uniformly over its footprint, and a
// point seen by k images is kept with probability 1/k, since k images
// propose it. Points seen by one image only are then dropped.
void AddSparsePoints(const PinholeRig& rig, const Layout& layout, const LargeWorkspaceOptions& o,
                     colmap_io::SparseModel* model, LargeWorkspaceSummary* summary) {
  const Footprint& f = layout.footprint;
  const double last_x = (std::min(o.num_images, o.images_per_row) - 1) * layout.spacing_x;
  const double last_y = (layout.num_rows - 1) * layout.spacing_y;
  const int cells_x = static_cast<int>(std::ceil((last_x + f.x1 - f.x0) / layout.spacing_x)) + 1;
  const int cells_y = static_cast<int>(std::ceil((last_y + f.y1 - f.y0) / layout.spacing_y)) + 1;
  FootprintIndex index(f.x0, f.y0, layout.spacing_x, layout.spacing_y, cells_x, cells_y);
  // Each view's box grown a little: its rotation comes back from a quaternion
  // (last-bit changes), so its frame may reach that far past the box above.
  const double margin = 1e-6 * (layout.spacing_x + layout.spacing_y);
  for (std::size_t i = 0; i < layout.views.size(); ++i) {
    const Eigen::Vector3d& c = layout.views[i].centre;
    index.Insert(static_cast<int>(i), c.x() + f.x0 - margin, c.y() + f.y0 - margin,
                 c.x() + f.x1 + margin, c.y() + f.y1 + margin);
  }

  std::mt19937_64 rng(o.seed);
  std::vector<std::pair<image_t, Eigen::Vector2d>> observations;
  for (std::size_t i = 0; i < layout.views.size(); ++i) {
    const Eigen::Vector3d& c = layout.views[i].centre;
    for (int proposal = 0; proposal < o.points_per_image; ++proposal) {
      Eigen::Vector3d xyz;
      do {  // uniform over the footprint: the bounding box, outside rejected
        xyz = Eigen::Vector3d(c.x() + f.x0 + Uniform(rng) * (f.x1 - f.x0),
                              c.y() + f.y0 + Uniform(rng) * (f.y1 - f.y0), 0.0);
      } while (!rig.InFrame(rig.Project(layout.views[i].R * xyz + layout.views[i].t)));

      observations.clear();
      for (const int candidate : index.Candidates(xyz.x(), xyz.y())) {
        const ViewGeometry& view = layout.views[candidate];
        const Eigen::Vector3d p = view.R * xyz + view.t;
        const Eigen::Vector2d uv = rig.Project(p);
        if (p.z() > 0 && rig.InFrame(uv)) {
          observations.emplace_back(static_cast<image_t>(candidate + 1), uv);
        }
      }
      const double keep = Uniform(rng);  // drawn always, so the stream never depends on k
      if (observations.size() < 2 || keep * observations.size() >= 1.0) continue;
      std::sort(observations.begin(), observations.end(),
                [](const auto& a, const auto& b) { return a.first < b.first; });
      colmap_io::Point3D point;
      point.point3D_id = model->points3D.size() + 1;
      point.xyz = xyz;
      point.error = 0.0;  // exact projections
      const Eigen::Vector3d colour = GroundColour(xyz.x(), xyz.y(), o.seed);
      point.rgb = {ToByte(colour.x()), ToByte(colour.y()), ToByte(colour.z())};
      model->AddObservedPoint(std::move(point), observations);
      summary->num_observations += observations.size();
    }
  }
  summary->num_points3D = model->points3D.size();
}

// Image and exact maps of one view, written at once (nothing is kept).
void RenderView(const PinholeRig& rig, const ViewGeometry& view, const std::string& name,
                uint64_t seed, const colmap_io::Workspace& workspace,
                LargeWorkspaceSummary* summary) {
  const int width = rig.width(), height = rig.height();
  cv::Mat bgr(height, width, CV_8UC3);
  colmap_io::DenseArray depth(width, height, 1);
  colmap_io::DenseArray normal(width, height, 3);
  colmap_io::DenseArray confidence(width, height, 1);
  // The plane's normal in the camera frame, turned to face the camera (every
  // camera is above the plane, so this is the same for all pixels).
  Eigen::Vector3d n = view.R * Eigen::Vector3d(0, 0, 1);
  if (n.dot(view.R * (Eigen::Vector3d::Zero() - view.centre)) > 0) n = -n;
  const Eigen::Matrix3d Rt = view.R.transpose();
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      Eigen::Vector3d colour = Eigen::Vector3d::Zero();
      for (int sy = 0; sy < kSupersampling; ++sy) {
        for (int sx = 0; sx < kSupersampling; ++sx) {
          const Eigen::Vector3d ground = rig.GroundPoint(
              view, col + (sx + 0.5) / kSupersampling, row + (sy + 0.5) / kSupersampling);
          colour += GroundColour(ground.x(), ground.y(), seed);
        }
      }
      colour /= static_cast<double>(kSupersampling * kSupersampling);
      bgr.at<cv::Vec3b>(row, col) =
          cv::Vec3b(ToByte(colour.z()), ToByte(colour.y()), ToByte(colour.x()));

      // COLMAP's dense indexing: map pixel (col, row) is the ray through
      // image position (col, row), not the pixel centre.
      const Eigen::Vector3d world_ray = Rt * rig.Ray(col, row);
      const double z = -view.centre.z() / world_ray.z();
      depth.at(row, col) = static_cast<float>(z);
      for (int c = 0; c < 3; ++c) normal.at(row, col, c) = static_cast<float>(n[c]);
      confidence.at(row, col) = z > 0 ? 1.0f : 0.0f;
      summary->depth_min = std::min(summary->depth_min, z);
      summary->depth_max = std::max(summary->depth_max, z);
    }
  }
  WritePng(bgr, workspace.ImagePath(name));
  dense::WriteMaps(dense::PathsOf(workspace, name, dense::kPhotometricType), depth, normal,
                   confidence);
}

void CreateFolder(const fs::path& path) {
  std::error_code error;
  fs::create_directories(path, error);
  if (error) throw colmap_io::IoError(path.string(), "cannot create: " + error.message());
}

}  // namespace

void LargeWorkspaceOptions::Check() const {
  auto fail = [](const std::string& what) { throw std::invalid_argument(what); };
  if (num_images < 2) fail("images must be 2 or more (a reference needs a source)");
  if (num_images > 99999999) fail("images must be at most 99999999");
  if (width < 8 || width > 65536 || height < 8 || height > 65536) {
    fail("width and height must be in [8, 65536]");
  }
  if (points_per_image < 0) fail("points_per_image must be 0 or more");
  if (images_per_row < 1) fail("images_per_row must be 1 or more");
  if (!(focal_per_width > 0) || !std::isfinite(focal_per_width)) {
    fail("focal_per_width must be > 0");
  }
  if (!(altitude > 0) || !std::isfinite(altitude)) fail("altitude must be > 0");
  if (!(tilt_deg >= 0 && tilt_deg < 80)) fail("tilt_deg must be in [0, 80)");
  if (!(overlap >= 0 && overlap <= 0.95)) fail("overlap must be in [0, 0.95]");
}

LargeWorkspaceSummary WriteLargeWorkspace(const fs::path& dir, const LargeWorkspaceOptions& options,
                                          std::ostream& log) {
  options.Check();
  const PinholeRig rig(options);
  colmap_io::SparseModel model;
  colmap_io::Camera camera;
  camera.camera_id = 1;
  camera.model_id = colmap_io::kPinholeModelId;
  camera.width = static_cast<uint64_t>(options.width);
  camera.height = static_cast<uint64_t>(options.height);
  camera.params = rig.Params();
  model.cameras[camera.camera_id] = camera;

  LargeWorkspaceSummary summary;
  summary.num_images = options.num_images;
  summary.depth_min = std::numeric_limits<double>::max();
  summary.depth_max = 0.0;
  const Layout layout = MakeLayout(rig, options, &model);
  summary.num_rows = layout.num_rows;
  summary.spacing_x = layout.spacing_x;
  summary.spacing_y = layout.spacing_y;
  const ViewGeometry& first = layout.views.front();
  const Eigen::Vector3d target = rig.GroundPoint(first, options.width / 2.0, options.height / 2.0);
  summary.neighbour_angle_x_deg =
      AngleDeg(target - first.centre,
               target - (first.centre + Eigen::Vector3d(layout.spacing_x, 0, 0)));
  summary.neighbour_angle_y_deg =
      AngleDeg(target - first.centre,
               target - (first.centre + Eigen::Vector3d(0, layout.spacing_y, 0)));
  AddSparsePoints(rig, layout, options, &model, &summary);

  // sparse/ is written last: a workspace whose generation was interrupted has
  // no model, so it cannot be mistaken for a complete one.
  CreateFolder(dir / "images");
  CreateFolder(dir / "sparse");
  const colmap_io::Workspace workspace(dir);
  workspace.CreateStereoFolders();
  for (int i = 0; i < options.num_images; ++i) {
    const image_t id = static_cast<image_t>(i + 1);
    RenderView(rig, layout.views[i], model.images.at(id).name, options.seed, workspace, &summary);
    if ((i + 1) % 250 == 0 && i + 1 < options.num_images) {
      log << "rendered " << (i + 1) << " of " << options.num_images << " images\n" << std::flush;
    }
  }
  colmap_io::WriteSparseModelBinary(model, dir / "sparse");
  return summary;
}

}  // namespace dispmvs::bench
