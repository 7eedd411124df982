#include "fusion/point_fusion.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <utility>
#include <stdexcept>
#include <string>

#include "fusion/input_checks.h"
#include "fusion/view_cache.h"

namespace dispmvs::fusion {

void FusionOptions::Check() const {
  consistency.Check();
  if (!(max_normal_error >= 0 && max_normal_error <= 180)) {
    throw std::invalid_argument("max_normal_error must be in [0, 180] degrees, got " +
                                std::to_string(max_normal_error));
  }
  if (max_num_pixels < 1) {
    throw std::invalid_argument("max_num_pixels must be >= 1, got " + std::to_string(max_num_pixels));
  }
  if (max_num_pixels < consistency.min_consistent_views + 1) {
    throw std::invalid_argument("max_num_pixels (" + std::to_string(max_num_pixels) +
                                ") must be at least min_consistent_views + 1 (" +
                                std::to_string(consistency.min_consistent_views + 1) +
                                "): a point holds the reference pixel and the pixels it must agree with");
  }
  if (max_traversal_depth < 1) {
    throw std::invalid_argument("max_traversal_depth must be >= 1, got " + std::to_string(max_traversal_depth));
  }
  if (check_num_images < 1) {
    throw std::invalid_argument("check_num_images must be >= 1, got " + std::to_string(check_num_images));
  }
  if (bounding_box) {
    const BoundingBox& box = *bounding_box;
    if (!box.min.allFinite() || !box.max.allFinite() || !(box.min.array() <= box.max.array()).all()) {
      throw std::invalid_argument("bounding_box corners must be finite with min <= max");
    }
  }
}

namespace {

void ValidateView(const FusionView& view, std::size_t index, std::size_t num_views) {
  const std::string what = "FusePoints: view " + std::to_string(index);
  ValidateDepthView(view.geometry, what);
  if (!view.normals.empty()) {
    internal::CheckMap(view.normals, 3, what + " normals");
    internal::CheckSameSize(view.normals, view.geometry.depth, what + " normals");
  }
  if (!view.image.empty()) {
    if (view.image.type() != CV_8UC3 && view.image.type() != CV_32FC3) {
      throw std::invalid_argument(what + ": image must be CV_8UC3 or CV_32FC3 RGB");
    }
    if (view.image.cols != view.geometry.depth.width() ||
        view.image.rows != view.geometry.depth.height()) {
      throw std::invalid_argument(what + ": image is " + std::to_string(view.image.cols) + "x" +
                                  std::to_string(view.image.rows) + ", the depth map " +
                                  std::to_string(view.geometry.depth.width()) + "x" +
                                  std::to_string(view.geometry.depth.height()));
    }
  }
  if (view.min_consistent_views < -1 || view.min_consistent_views > kMaxSourceViews) {
    throw std::invalid_argument(what + ": min_consistent_views must be in [-1, " +
                                std::to_string(kMaxSourceViews) + "], got " +
                                std::to_string(view.min_consistent_views));
  }
  if (view.source_views.size() > static_cast<std::size_t>(kMaxSourceViews)) {
    throw std::invalid_argument(what + ": " + std::to_string(view.source_views.size()) +
                                " source views, at most " + std::to_string(kMaxSourceViews));
  }
  for (std::size_t i = 0; i < view.source_views.size(); ++i) {
    const int source = view.source_views[i];
    if (source < 0 || static_cast<std::size_t>(source) >= num_views) {
      throw std::invalid_argument(what + ": source view index " + std::to_string(source) +
                                  " out of range");
    }
    if (static_cast<std::size_t>(source) == index) {
      throw std::invalid_argument(what + ": lists itself as a source view");
    }
    if (std::find(view.source_views.begin(), view.source_views.begin() + i, source) !=
        view.source_views.begin() + i) {
      throw std::invalid_argument(what + ": source view " + std::to_string(source) +
                                  " listed twice");
    }
  }
}

// Per-view constants for turning pixels into world points and normals.
struct ViewFrame {
  Eigen::Matrix3d K_inv;
  Eigen::Matrix3d R_transpose;  // camera-to-world rotation
  Eigen::Vector3d centre;       // camera centre in the world, -R^T t

  explicit ViewFrame(const DepthView& view)
      : K_inv(view.K.inverse()), R_transpose(view.R.transpose()),
        centre(-view.R.transpose() * view.t) {}

  Eigen::Vector3d WorldPoint(int row, int col, double depth) const {
    return R_transpose * (depth * (K_inv * Eigen::Vector3d(col, row, 1.0))) + centre;
  }
};

// The unit world-frame normal of a view's pixel; nullopt where the view has
// no normals or the pixel's is zero (unknown) or not finite.
std::optional<Eigen::Vector3d> WorldNormal(const FusionView& view, const ViewFrame& frame, int row,
                                           int col) {
  if (view.normals.empty()) return std::nullopt;
  const int width = view.geometry.depth.width();
  const std::size_t index = static_cast<std::size_t>(row) * width + col;
  const std::size_t plane = static_cast<std::size_t>(width) * view.geometry.depth.height();
  const float* n = view.normals.data();
  const Eigen::Vector3d camera_normal(n[index], n[plane + index], n[2 * plane + index]);
  const double norm = camera_normal.norm();
  if (!(norm > 1e-6) || !std::isfinite(norm)) return std::nullopt;
  return frame.R_transpose * (camera_normal / norm);
}

// Sums of the per-pixel contributions to one point.
struct Accumulator {
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  int num_points = 0;
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  Eigen::Vector3d rgb = Eigen::Vector3d::Zero();  // in [0, 1]
  int num_colours = 0;
  std::array<uint32_t, kMaxSourceViews + 1> visibility{};
  int num_visibility = 0;

  void Add(const FusionView& view, const ViewFrame& frame, int row, int col, double depth) {
    xyz += frame.WorldPoint(row, col, depth);
    ++num_points;
    visibility[num_visibility++] = view.vis_index;
    // Zero (unknown) and non-finite normals are skipped.
    if (const auto world_normal = WorldNormal(view, frame, row, col)) normal += *world_normal;
    if (!view.image.empty()) {
      if (view.image.type() == CV_8UC3) {
        const cv::Vec3b& c = view.image.at<cv::Vec3b>(row, col);
        rgb += Eigen::Vector3d(c[0], c[1], c[2]) / 255.0;
      } else {
        const cv::Vec3f& c = view.image.at<cv::Vec3f>(row, col);
        rgb += Eigen::Vector3d(c[0], c[1], c[2]);
      }
      ++num_colours;
    }
  }

  FusedPoint Finish() {
    FusedPoint point;
    point.xyz = (xyz / num_points).cast<float>();
    const double normal_norm = normal.norm();
    // Opposite normals can cancel; such a point has no reliable normal.
    if (normal_norm > 1e-6) point.normal = (normal / normal_norm).cast<float>();
    if (num_colours > 0) {
      for (int c = 0; c < 3; ++c) {
        const double value = std::clamp(rgb[c] / num_colours, 0.0, 1.0);
        point.rgb[c] = static_cast<uint8_t>(std::lround(value * 255.0));
      }
    }
    std::sort(visibility.begin(), visibility.begin() + num_visibility);
    const auto end = std::unique(visibility.begin(), visibility.begin() + num_visibility);
    point.visibility.assign(visibility.begin(), end);
    return point;
  }
};

// Per pixel of `reference`, whether the geometric filter with `rule` keeps
// it against `sources` (FilterDepthMap), needing `min_consistent` of them.
std::vector<uint8_t> SupportedReferencePixels(
    const FusionView& reference,
    const std::vector<std::pair<int, std::shared_ptr<const FusionView>>>& sources,
    const GeometricFilterOptions& rule, int min_consistent) {
  std::vector<const DepthView*> geometries;
  geometries.reserve(sources.size());
  for (const auto& source : sources) geometries.push_back(&source.second->geometry);
  GeometricFilterOptions reference_rule = rule;
  reference_rule.min_consistent_views = min_consistent;
  const GeometricFilterResult kept = FilterDepthMap(reference.geometry, geometries, reference_rule);
  std::vector<uint8_t> supported(kept.depth.size());
  for (std::size_t i = 0; i < supported.size(); ++i) supported[i] = kept.depth.data()[i] > 0.0f;
  return supported;
}

}  // namespace

std::vector<FusedPoint> FusePoints(const std::vector<FusionView>& views,
                                   const FusionOptions& options, FusionStats* stats) {
  // The caller holds every view already: the cache only lends them out. Each
  // view is checked when first lent (every view is, as a reference in turn).
  FusionViewCache cache(
      [&views](int index) {
        return std::shared_ptr<const FusionView>(&views[static_cast<std::size_t>(index)],
                                                 [](const FusionView*) {});
      },
      std::numeric_limits<std::size_t>::max());
  return FusePoints(static_cast<int>(views.size()), &cache, options, stats);
}

std::vector<FusedPoint> FusePoints(int num_views, FusionViewCache* cache,
                                   const FusionOptions& options, FusionStats* stats) {
  std::vector<FusedPoint> points;
  FusePoints(
      num_views, cache, options, [&points](FusedPoint&& point) { points.push_back(std::move(point)); },
      stats);
  return points;
}

std::vector<int> LastUses(const std::vector<std::vector<int>>& sources) {
  std::vector<int> last(sources.size());
  for (std::size_t v = 0; v < sources.size(); ++v) {
    last[v] = std::max(last[v], static_cast<int>(v));
    for (int source : sources[v]) {
      if (source >= 0 && static_cast<std::size_t>(source) < last.size()) {
        last[static_cast<std::size_t>(source)] =
            std::max(last[static_cast<std::size_t>(source)], static_cast<int>(v));
      }
    }
  }
  return last;
}

void FusePoints(int num_views, FusionViewCache* cache, const FusionOptions& options,
                const PointSink& emit, FusionStats* stats, const std::vector<int>& last_use) {
  options.Check();
  const auto count = static_cast<std::size_t>(std::max(num_views, 0));
  if (!last_use.empty() && last_use.size() != count) {
    throw std::invalid_argument("FusePoints: last_use must have one entry per view");
  }
  // Views to free after each reference.
  std::vector<std::vector<std::size_t>> released_after(count);
  for (std::size_t v = 0; v < last_use.size(); ++v) {
    const int last = last_use[v];
    if (last >= 0 && static_cast<std::size_t>(last) < count) {
      released_after[static_cast<std::size_t>(last)].push_back(v);
    }
  }
  std::vector<bool> released(count, false);
  // Per-view state that outlives the cached maps: what has been consumed
  // (one byte per pixel, made when the view is first loaded) and the frame.
  std::vector<std::vector<uint8_t>> consumed(count);
  std::vector<std::optional<ViewFrame>> frames(count);
  auto get = [&](int index) {
    const auto i = static_cast<std::size_t>(index);
    if (i < count && released[i]) {
      throw std::logic_error("FusePoints: view " + std::to_string(index) +
                             " used after its last use");
    }
    std::shared_ptr<const FusionView> view = cache->Get(index);
    if (view != nullptr && !frames[i]) {
      ValidateView(*view, i, count);
      frames[i].emplace(view->geometry);
      consumed[i].assign(view->geometry.depth.size(), 0u);
    }
    return view;
  };
  if (stats != nullptr) {
    stats->points_per_view.assign(count, 0);
    stats->consumed_pixels_per_view.assign(count, 0);
  }

  // Frees the masks of the views whose last use was reference v.
  auto release = [&](std::size_t v) {
    for (std::size_t done : released_after[v]) {
      std::vector<uint8_t>().swap(consumed[done]);
      released[done] = true;
    }
  };

  std::vector<PairConsistency> pairs;
  std::vector<std::pair<int, std::shared_ptr<const FusionView>>> sources;
  std::array<PairConsistency::Match, kMaxSourceViews> matches;
  std::array<bool, kMaxSourceViews> agrees{};
  const GeometricFilterOptions& rule = options.consistency;
  const double min_cos_normal = std::cos(options.max_normal_error * M_PI / 180.0);
  const bool tests_normals = options.max_normal_error < 180;
  const int max_pixels = options.max_traversal_depth == 1 ? 1 : options.max_num_pixels;
  for (std::size_t v = 0; v < count; ++v) {
    const std::shared_ptr<const FusionView> reference_view = get(static_cast<int>(v));
    if (reference_view == nullptr) {  // left out
      release(v);
      continue;
    }
    const FusionView& reference = *reference_view;
    const ViewFrame& reference_frame = *frames[v];
    const int min_consistent = reference.min_consistent_views >= 0
                                   ? reference.min_consistent_views
                                   : rule.min_consistent_views;
    // Sources that cannot be loaded are left out, as if not listed.
    sources.clear();
    pairs.clear();
    for (int source : reference.source_views) {
      if (static_cast<int>(sources.size()) >= options.check_num_images) break;
      std::shared_ptr<const FusionView> view = get(source);
      if (view == nullptr) continue;
      pairs.emplace_back(reference.geometry, view->geometry, rule);
      sources.emplace_back(source, std::move(view));
    }
    const int width = reference.geometry.depth.width();
    const int height = reference.geometry.depth.height();
    const float* depth = reference.geometry.depth.data();
    // With the support rule, a point starts only at a pixel the geometric
    // filter keeps, so that the cloud and the geometric maps give the same
    // verdict (the filter sees neither the box nor the pixels already
    // consumed).
    const std::vector<uint8_t> supported =
        rule.min_support > 0 ? SupportedReferencePixels(reference, sources, rule, min_consistent)
                             : std::vector<uint8_t>();
    for (int row = 0; row < height; ++row) {
      for (int col = 0; col < width; ++col) {
        const std::size_t index = static_cast<std::size_t>(row) * width + col;
        if (!HasUsableDepth(reference.geometry, row, col, rule.min_confidence)) continue;
        if (!supported.empty() && !supported[index]) continue;
        if (consumed[v][index]) {
          if (stats != nullptr) ++stats->consumed_pixels_per_view[v];
          continue;
        }
        if (options.bounding_box &&
            !options.bounding_box->Contains(reference_frame.WorldPoint(row, col, depth[index]))) {
          continue;
        }
        const std::optional<Eigen::Vector3d> reference_normal =
            tests_normals ? WorldNormal(reference, reference_frame, row, col) : std::nullopt;
        int agreeing = 0;
        for (std::size_t s = 0; s < pairs.size(); ++s) {
          PairConsistency::Match& match = matches[s];
          agrees[s] = pairs[s].Check(row, col, depth[index], &match);
          if (agrees[s] && (options.bounding_box || reference_normal)) {
            const FusionView& source_view = *sources[s].second;
            const ViewFrame& source_frame = *frames[static_cast<std::size_t>(sources[s].first)];
            if (options.bounding_box &&
                !options.bounding_box->Contains(source_frame.WorldPoint(match.row, match.col, match.depth))) {
              agrees[s] = false;
            } else if (reference_normal) {
              const auto source_normal = WorldNormal(source_view, source_frame, match.row, match.col);
              if (source_normal && reference_normal->dot(*source_normal) < min_cos_normal) agrees[s] = false;
            }
          }
          agreeing += agrees[s] ? 1 : 0;
        }
        if (agreeing < min_consistent) continue;

        Accumulator sum;
        sum.Add(reference, reference_frame, row, col, depth[index]);
        consumed[v][index] = 1;
        for (std::size_t s = 0; s < pairs.size() && sum.num_points < max_pixels; ++s) {
          if (!agrees[s]) continue;
          const auto source = static_cast<std::size_t>(sources[s].first);
          const FusionView& source_view = *sources[s].second;
          const PairConsistency::Match& match = matches[s];
          sum.Add(source_view, *frames[source], match.row, match.col, match.depth);
          consumed[source][static_cast<std::size_t>(match.row) * source_view.geometry.depth.width() +
                           match.col] = 1;
        }
        emit(sum.Finish());
        if (stats != nullptr) ++stats->points_per_view[v];
      }
    }
    release(v);
  }
}

}  // namespace dispmvs::fusion
