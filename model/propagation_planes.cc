#include "model/propagation_planes.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

#include "model/window_mean.h"

namespace dispmvs::model {
namespace {

void CheckMap(const torch::Tensor& t, const torch::Tensor& like, const char* function, const char* name) {
  if (!t.defined() || t.dim() != 4 || t.size(1) != 1 || (like.defined() && t.sizes() != like.sizes())) {
    throw std::invalid_argument(std::string(function) + ": " + name + " must be [B,1,H,W]" +
                                (like.defined() ? " like w" : ""));
  }
}

void CheckSlopeInputs(const torch::Tensor& w, const torch::Tensor& usable, int64_t radius) {
  CheckMap(w, torch::Tensor(), "LeastSquaresSlopes", "w");
  CheckMap(usable, w, "LeastSquaresSlopes", "usable");
  if (radius < 1) throw std::invalid_argument("LeastSquaresSlopes: radius must be >= 1");
}

void CheckPlaneInputs(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy) {
  CheckMap(w, torch::Tensor(), "PlaneFromNeighbour", "w");
  CheckMap(gx, w, "PlaneFromNeighbour", "gx");
  CheckMap(gy, w, "PlaneFromNeighbour", "gy");
}

bool CpuFloat(const torch::Tensor& t) { return t.device().is_cpu() && t.scalar_type() == torch::kFloat32; }

// The fit's loop takes a CPU float map and a CPU bool mask.
bool CpuFloatMaps(const torch::Tensor& w, const torch::Tensor& usable) {
  return CpuFloat(w) && usable.device().is_cpu() && usable.scalar_type() == torch::kBool;
}

// Rows per task of the slope fit: each band sums its first window afresh
// (2r + 1 rows), so a fixed size keeps results independent of the thread
// count, and 64 rows keep that start-up small at the radii used.
constexpr int64_t kBandRows = 64;

// The slopes (and, where value is not null, the plane at each pixel) of one
// band of rows of one map. Per column, the sums over the
// window's rows of m, m y, m y^2, m w and m w y (m: usable) move down with
// the output row; along the row, nine running sums over the window's
// columns give the moments. Coordinates are centred on the image, as in
// the operations' version; in double, the centred moments keep their
// digits (and the sums of m, x and y, integers, are exact).
void FitBand(const float* w, const bool* usable, int64_t h, int64_t width, int64_t radius, int64_t row_begin,
             int64_t row_end, float* gx, float* gy, float* value) {
  const double half_w = 0.5 * static_cast<double>(width - 1), half_h = 0.5 * static_cast<double>(h - 1);
  std::vector<double> m_sum(width, 0.0), my_sum(width, 0.0), myy_sum(width, 0.0), mw_sum(width, 0.0),
      mwy_sum(width, 0.0);
  const auto add_row = [&](int64_t row, double sign) {
    const double y = static_cast<double>(row) - half_h;
    const float* w_row = w + row * width;
    const bool* m_row = usable + row * width;
    for (int64_t j = 0; j < width; ++j) {
      if (!m_row[j]) continue;
      const double value = static_cast<double>(w_row[j]);
      m_sum[j] += sign;
      my_sum[j] += sign * y;
      myy_sum[j] += sign * y * y;
      mw_sum[j] += sign * value;
      mwy_sum[j] += sign * value * y;
    }
  };
  for (int64_t row = std::max<int64_t>(0, row_begin - radius); row <= std::min(h - 1, row_begin + radius); ++row) {
    add_row(row, 1.0);
  }
  for (int64_t i = row_begin; i < row_end; ++i) {
    const int64_t rows_inside = std::min(h - 1, i + radius) - std::max<int64_t>(0, i - radius) + 1;
    // s0 = sum m, sx = sum m x, sy, sxx, sxy, syy, sw = sum m w, swx, swy.
    double s0 = 0, sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0, sw = 0, swx = 0, swy = 0;
    const auto add_column = [&](int64_t j, double sign) {
      const double x = static_cast<double>(j) - half_w;
      const double m = sign * m_sum[j], my = sign * my_sum[j], mw = sign * mw_sum[j];
      s0 += m;
      sx += m * x;
      sy += my;
      sxx += m * x * x;
      sxy += my * x;
      syy += sign * myy_sum[j];
      sw += mw;
      swx += mw * x;
      swy += sign * mwy_sum[j];
    };
    for (int64_t j = 0; j <= std::min(width - 1, radius); ++j) add_column(j, 1.0);
    float* gx_row = gx + i * width;
    float* gy_row = gy + i * width;
    float* value_row = value != nullptr ? value + i * width : nullptr;
    const double y_here = static_cast<double>(i) - half_h;
    for (int64_t j = 0; j < width; ++j) {
      const int64_t cols_inside = std::min(width - 1, j + radius) - std::max<int64_t>(0, j - radius) + 1;
      float slope_x = 0.0f, slope_y = 0.0f, plane_here = 0.0f;
      // More than a quarter of the window inside the image usable (s0 is an
      // exact integer).
      if (4.0 * s0 > static_cast<double>(rows_inside * cols_inside)) {
        const double mx = sx / s0, my = sy / s0, mean_w = sw / s0;
        const double cxx = sxx / s0 - mx * mx, cxy = sxy / s0 - mx * my, cyy = syy / s0 - my * my;
        const double cxw = swx / s0 - mx * mean_w, cyw = swy / s0 - my * mean_w;
        const double det = cxx * cyy - cxy * cxy;
        if (det > 1e-3) {
          const double fit_x = (cyy * cxw - cxy * cyw) / det, fit_y = (cxx * cyw - cxy * cxw) / det;
          slope_x = static_cast<float>(fit_x);
          slope_y = static_cast<float>(fit_y);
          // The plane through the centroid (mx, my, mean_w), at this pixel.
          const double x_here = static_cast<double>(j) - half_w;
          plane_here = static_cast<float>(mean_w + fit_x * (x_here - mx) + fit_y * (y_here - my));
        }
      }
      gx_row[j] = slope_x;
      gy_row[j] = slope_y;
      if (value_row != nullptr) value_row[j] = plane_here;
      if (j + radius + 1 < width) add_column(j + radius + 1, 1.0);
      if (j - radius >= 0) add_column(j - radius, -1.0);
    }
    if (i + 1 < row_end) {
      if (i + radius + 1 < h) add_row(i + radius + 1, 1.0);
      if (i - radius >= 0) add_row(i - radius, -1.0);
    }
  }
}

// The fit of every window on CPU float maps; the planes' values only when
// asked for (propagation needs the slopes alone).
LeastSquaresPlane LeastSquaresPlanesCpu(const torch::Tensor& w_in, const torch::Tensor& usable_in, int64_t radius,
                                        bool with_value) {
  const torch::Tensor w = w_in.contiguous(), usable = usable_in.contiguous();
  const int64_t batch = w.size(0), h = w.size(2), width = w.size(3), hw = h * width;
  const int64_t bands = (h + kBandRows - 1) / kBandRows;
  LeastSquaresPlane plane;
  plane.gx = torch::empty_like(w);
  plane.gy = torch::empty_like(w);
  if (with_value) plane.value = torch::empty_like(w);
  const float* w_p = w.data_ptr<float>();
  const bool* m_p = usable.data_ptr<bool>();
  float* gx_p = plane.gx.data_ptr<float>();
  float* gy_p = plane.gy.data_ptr<float>();
  float* value_p = with_value ? plane.value.data_ptr<float>() : nullptr;
  at::parallel_for(0, batch * bands, 1, [&](int64_t begin, int64_t end) {
    for (int64_t task = begin; task < end; ++task) {
      const int64_t item = task / bands, row_begin = (task % bands) * kBandRows;
      FitBand(w_p + item * hw, m_p + item * hw, h, width, radius, row_begin, std::min(row_begin + kBandRows, h),
              gx_p + item * hw, gy_p + item * hw, value_p != nullptr ? value_p + item * hw : nullptr);
    }
  });
  return plane;
}

// t shifted so that out(y, x) = t(y + dy, x + dx), zero where that is outside.
torch::Tensor Shifted(const torch::Tensor& t, int64_t dx, int64_t dy) {
  const int64_t h = t.size(2), w = t.size(3);
  torch::Tensor out = torch::zeros_like(t);
  if (std::abs(dx) >= w || std::abs(dy) >= h) return out;
  out.narrow(3, std::max<int64_t>(0, -dx), w - std::abs(dx))
      .narrow(2, std::max<int64_t>(0, -dy), h - std::abs(dy))
      .copy_(t.narrow(3, std::max<int64_t>(0, dx), w - std::abs(dx))
                 .narrow(2, std::max<int64_t>(0, dy), h - std::abs(dy)));
  return out;
}

torch::Tensor PlaneFromNeighbourCpu(const torch::Tensor& w_in, const torch::Tensor& gx_in,
                                    const torch::Tensor& gy_in, int64_t dx, int64_t dy) {
  const torch::Tensor w = w_in.contiguous(), gx = gx_in.contiguous(), gy = gy_in.contiguous();
  const int64_t batch = w.size(0), h = w.size(2), width = w.size(3), hw = h * width;
  torch::Tensor out = torch::zeros_like(w);
  const float fdx = static_cast<float>(dx), fdy = static_cast<float>(dy);
  const float* w_p = w.data_ptr<float>();
  const float* gx_p = gx.data_ptr<float>();
  const float* gy_p = gy.data_ptr<float>();
  float* out_p = out.data_ptr<float>();
  // Output rows and columns whose neighbour lies inside the image.
  const int64_t y_begin = std::max<int64_t>(0, -dy), y_end = std::min(h, h - dy);
  const int64_t x_begin = std::max<int64_t>(0, -dx), x_end = std::min(width, width - dx);
  if (y_begin >= y_end || x_begin >= x_end) return out;
  at::parallel_for(0, batch * (y_end - y_begin), 16, [&](int64_t begin, int64_t end) {
    for (int64_t task = begin; task < end; ++task) {
      const int64_t item = task / (y_end - y_begin), y = y_begin + task % (y_end - y_begin);
      const int64_t from = item * hw + (y + dy) * width + dx;  // + x: the neighbour of (x, y)
      float* out_row = out_p + item * hw + y * width;
      for (int64_t x = x_begin; x < x_end; ++x) {
        const float value = w_p[from + x];
        // As the operations round: (w - gx dx) - gy dy, each in float.
        const float plane = (value - gx_p[from + x] * fdx) - gy_p[from + x] * fdy;
        out_row[x] = value > 0.0f && plane > 0.0f ? plane : 0.0f;
      }
    }
  });
  return out;
}

// LeastSquaresPlanesByOps on checked inputs.
LeastSquaresPlane PlanesByOps(const torch::Tensor& w, const torch::Tensor& usable, int64_t radius) {
  const int64_t h = w.size(2), wd = w.size(3);
  const torch::Tensor m = usable.to(w.scalar_type());
  const torch::Tensor x =
      (torch::arange(wd, w.options()) - 0.5 * static_cast<double>(wd - 1)).view({1, 1, 1, wd}).expand_as(w);
  const torch::Tensor y =
      (torch::arange(h, w.options()) - 0.5 * static_cast<double>(h - 1)).view({1, 1, h, 1}).expand_as(w);
  const torch::Tensor mw = m * w;
  const torch::Tensor sums =
      WindowMean(torch::cat({m, m * x, m * y, m * x * x, m * x * y, m * y * y, mw, mw * x, mw * y}, 1), radius);
  const auto c = [&](int64_t i) { return sums.narrow(1, i, 1); };
  const torch::Tensor count = c(0).clamp_min(1e-6);
  const torch::Tensor mx = c(1) / count, my = c(2) / count, mean_w = c(6) / count;
  const torch::Tensor cxx = c(3) / count - mx * mx, cxy = c(4) / count - mx * my, cyy = c(5) / count - my * my;
  const torch::Tensor cxw = c(7) / count - mx * mean_w, cyw = c(8) / count - my * mean_w;
  const torch::Tensor det = cxx * cyy - cxy * cxy;
  const torch::Tensor ok = (c(0) > 0.25) & (det > 1e-3);
  const torch::Tensor safe = torch::where(ok, det, torch::ones_like(det));
  LeastSquaresPlane plane;
  plane.gx = torch::where(ok, (cyy * cxw - cxy * cyw) / safe, torch::zeros_like(w));
  plane.gy = torch::where(ok, (cxx * cyw - cxy * cxw) / safe, torch::zeros_like(w));
  plane.value = torch::where(ok, mean_w + plane.gx * (x - mx) + plane.gy * (y - my), torch::zeros_like(w));
  return plane;
}

// PlaneFromNeighbourByOps on checked inputs.
torch::Tensor PlaneByOps(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy, int64_t dx,
                         int64_t dy) {
  // Computed at the neighbour, then shifted once: a third of the passes of
  // shifting the depth and both slopes.
  const torch::Tensor plane = w - gx * static_cast<double>(dx) - gy * static_cast<double>(dy);
  return Shifted(torch::where((w > 0) & (plane > 0), plane, torch::zeros_like(plane)), dx, dy);
}

}  // namespace

std::pair<torch::Tensor, torch::Tensor> LeastSquaresSlopesByOps(const torch::Tensor& w,
                                                                const torch::Tensor& usable, int64_t radius) {
  CheckSlopeInputs(w, usable, radius);
  const LeastSquaresPlane plane = PlanesByOps(w, usable, radius);
  return {plane.gx, plane.gy};
}

std::pair<torch::Tensor, torch::Tensor> LeastSquaresSlopes(const torch::Tensor& w, const torch::Tensor& usable,
                                                           int64_t radius) {
  CheckSlopeInputs(w, usable, radius);
  const LeastSquaresPlane plane =
      CpuFloatMaps(w, usable) ? LeastSquaresPlanesCpu(w, usable, radius, false) : PlanesByOps(w, usable, radius);
  return {plane.gx, plane.gy};
}

LeastSquaresPlane LeastSquaresPlanesByOps(const torch::Tensor& w, const torch::Tensor& usable, int64_t radius) {
  CheckSlopeInputs(w, usable, radius);
  return PlanesByOps(w, usable, radius);
}

LeastSquaresPlane LeastSquaresPlanes(const torch::Tensor& w, const torch::Tensor& usable, int64_t radius) {
  CheckSlopeInputs(w, usable, radius);
  return CpuFloatMaps(w, usable) ? LeastSquaresPlanesCpu(w, usable, radius, true) : PlanesByOps(w, usable, radius);
}

torch::Tensor PlaneFromNeighbourByOps(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                                      int64_t dx, int64_t dy) {
  CheckPlaneInputs(w, gx, gy);
  return PlaneByOps(w, gx, gy, dx, dy);
}

torch::Tensor PlaneFromNeighbour(const torch::Tensor& w, const torch::Tensor& gx, const torch::Tensor& gy,
                                 int64_t dx, int64_t dy) {
  CheckPlaneInputs(w, gx, gy);
  if (CpuFloat(w) && CpuFloat(gx) && CpuFloat(gy)) return PlaneFromNeighbourCpu(w, gx, gy, dx, dy);
  return PlaneByOps(w, gx, gy, dx, dy);
}

}  // namespace dispmvs::model
