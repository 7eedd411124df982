#include "model/grid_coordinates.h"

namespace dispmvs::model {

torch::Tensor ToGridCoordinate(const torch::Tensor& pixel, int64_t size) {
  torch::Tensor g = (2.0 * pixel + 1.0) / static_cast<double>(size) - 1.0;
  g = torch::where(torch::isfinite(g), g, torch::full_like(g, -3.0));
  return g.clamp(-3.0, 3.0);
}

}  // namespace dispmvs::model
