#include "examples/surface_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "examples/example_scene.h"

namespace dispmvs::examples {

std::vector<double> SortedSurfaceDistances(const std::vector<Eigen::Vector3d>& points,
                                           const colmap_io::SparseModel& model) {
  const ExampleScene scene(/*seed=*/0);  // the geometry does not depend on the seed
  std::vector<double> distances;
  distances.reserve(points.size());
  for (const Eigen::Vector3d& x : points) {
    double best = std::numeric_limits<double>::infinity();
    for (const auto& [image_id, image] : model.images) {
      const Eigen::Vector3d centre = image.ProjectionCenter();
      const auto hit = scene.Cast(centre, x - centre);
      if (hit) best = std::min(best, std::abs(hit->t - 1.0) * (x - centre).norm());
    }
    distances.push_back(best);
  }
  std::sort(distances.begin(), distances.end());
  return distances;
}

}  // namespace dispmvs::examples
