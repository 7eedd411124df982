#include "model/surface_ncc_rows.h"

#include <algorithm>
#include <cmath>
#include <vector>

// The AVX2 build needs GCC's or Clang's target attributes and x86-64.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define DISPMVS_ROWS_AVX2 1
#include <immintrin.h>
#else
#define DISPMVS_ROWS_AVX2 0
#endif

namespace dispmvs::model {

float PlaneSampler::Sample(int64_t p, bool* inside) const {
  const int64_t hw = h * w;
  const int64_t q = b_per_pixel ? p : 0, b_channel = b_per_pixel ? hw : 1;
  const float inverse_depth = surface[p];
  const float px = a[p] + inverse_depth * b[q];
  const float py = a[hw + p] + inverse_depth * b[b_channel + q];
  const float pz = a[2 * hw + p] + inverse_depth * b[2 * b_channel + q];
  const bool in_front = pz > 0 && inverse_depth > 0;
  // Behind the source the match is taken as pixel (0, 0), as the
  // operations' path does; it does not count, but it is in its
  // neighbours' windows all the same.
  const float inverse_z = in_front ? 1.0f / pz : 0.0f;
  const float x = px * inverse_z, y = py * inverse_z;
  *inside = in_front && std::abs(x - half_w) <= limit_x && std::abs(y - half_h) <= limit_y;
  // Beyond [-1, w) x [-1, h) no pixel of the image is in reach (and NaN or
  // infinite coordinates fail the comparisons).
  if (!(x >= -1.0f && y >= -1.0f && x < static_cast<float>(w) && y < static_cast<float>(h))) return 0.0f;
  // floor by truncation, exact in this range: std::floor is a library call
  // on x86-64's baseline instruction set, twice per sample.
  int64_t x0 = static_cast<int64_t>(x), y0 = static_cast<int64_t>(y);
  x0 -= static_cast<float>(x0) > x;
  y0 -= static_cast<float>(y0) > y;
  const float fx = x - static_cast<float>(x0), fy = y - static_cast<float>(y0);
  if (x0 >= 0 && y0 >= 0 && x0 + 1 < w && y0 + 1 < h) {
    const float* row = source + y0 * w + x0;
    return (1 - fy) * ((1 - fx) * row[0] + fx * row[1]) + fy * ((1 - fx) * row[w] + fx * row[w + 1]);
  }
  const auto at = [&](int64_t yy, int64_t xx) {
    return (xx >= 0 && xx < w && yy >= 0 && yy < h) ? source[yy * w + xx] : 0.0f;
  };
  return (1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1)) +
         fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1));
}

namespace {

// One pixel's NCC and flag from its window's sums of v, v^2 and
// reference * v (both builds' arithmetic, the AVX2 one for the row's last
// w % 8): 0 and false where not wanted.
inline void PixelNcc(double sum_v, double sum_vv, double sum_rv, double inverse_count, float mean, float var,
                     bool inside, bool wanted, float* ncc, bool* ok) {
  if (!wanted) {
    *ncc = 0.0f;
    *ok = false;
    return;
  }
  const float s_mean = static_cast<float>(sum_v * inverse_count);
  const float s_var = std::max(static_cast<float>(sum_vv * inverse_count) - s_mean * s_mean, 0.0f);
  const float covariance = static_cast<float>(sum_rv * inverse_count) - mean * s_mean;
  *ncc = covariance / std::sqrt(std::max(var * s_var, 1e-12f));
  *ok = inside && s_var > 1e-10f;
}

}  // namespace

// Rows [row_begin, row_end) of one source plane in one streaming pass: rows
// are sampled as the window reaches them (from row_begin - r) into a ring of
// 2r + 2 rows, column sums of v, v^2 and reference * v move down with the
// window (in double, so that adding and removing 2r + 1 rows at a time
// leaves no drift), and each output row's window sums are a running sum
// along those columns. Nothing of full size is written but the NCC and the
// flags; ncc and ok point at row_begin's first pixel.
// `needed` (null: every pixel), like ncc from row_begin: the pixels whose NCC
// is wanted; the others get ncc 0, ok false without the arithmetic.
void CorrelateRowsPortable(const PlaneSampler& sampler, const float* reference, const float* reference_mean,
                           const float* reference_var, int64_t r, int64_t row_begin, int64_t row_end, float* ncc,
                           bool* ok, const float* needed) {
  const int64_t h = sampler.h, w = sampler.w;
  const int64_t ring = 2 * r + 2;
  std::vector<float> values(static_cast<size_t>(ring * w));
  std::vector<char> inside(static_cast<size_t>(ring * w));
  std::vector<double> columns(static_cast<size_t>(3 * w), 0.0);
  double* col_v = columns.data();
  double* col_vv = col_v + w;
  double* col_rv = col_vv + w;
  // Adds (sign +1) or removes (-1) row k of the ring to the column sums;
  // sampling it first when it comes in.
  const auto take_row = [&](int64_t k, double sign) {
    float* v = values.data() + (k % ring) * w;
    const float* ref_row = reference + k * w;
    if (sign > 0) {
      char* in = inside.data() + (k % ring) * w;
      for (int64_t j = 0; j < w; ++j) {
        bool is_inside = false;
        v[j] = sampler.Sample(k * w + j, &is_inside);
        in[j] = is_inside;
      }
    }
    for (int64_t j = 0; j < w; ++j) {
      const double value = v[j];
      col_v[j] += sign * value;
      col_vv[j] += sign * static_cast<double>(v[j] * v[j]);
      col_rv[j] += sign * static_cast<double>(ref_row[j] * v[j]);
    }
  };
  // 1 / (window columns inside the image) per column: the window's pixel
  // count is that times the rows', without a division per pixel.
  std::vector<double> inverse_cols(static_cast<size_t>(w));
  for (int64_t j = 0; j < w; ++j) {
    inverse_cols[static_cast<size_t>(j)] =
        1.0 / static_cast<double>(std::min(j + r, w - 1) - std::max<int64_t>(j - r, 0) + 1);
  }
  for (int64_t k = std::max<int64_t>(row_begin - r, 0); k <= std::min(row_begin + r, h - 1); ++k) take_row(k, 1.0);
  for (int64_t i = row_begin; i < row_end; ++i) {
    const int64_t rows = std::min(i + r, h - 1) - std::max<int64_t>(i - r, 0) + 1;
    const double inverse_rows = 1.0 / static_cast<double>(rows);
    const char* in = inside.data() + (i % ring) * w;
    float* ncc_row = ncc + (i - row_begin) * w;
    bool* ok_row = ok + (i - row_begin) * w;
    const float* needed_row = needed ? needed + (i - row_begin) * w : nullptr;
    double s_v = 0, s_vv = 0, s_rv = 0;
    for (int64_t j = 0; j <= std::min(r, w - 1); ++j) {
      s_v += col_v[j];
      s_vv += col_vv[j];
      s_rv += col_rv[j];
    }
    for (int64_t j = 0; j < w; ++j) {
      PixelNcc(s_v, s_vv, s_rv, inverse_rows * inverse_cols[static_cast<size_t>(j)], reference_mean[i * w + j],
               reference_var[i * w + j], in[j] != 0, needed_row == nullptr || needed_row[j] != 0, ncc_row + j,
               ok_row + j);
      if (j + r + 1 < w) {
        s_v += col_v[j + r + 1];
        s_vv += col_vv[j + r + 1];
        s_rv += col_rv[j + r + 1];
      }
      if (j - r >= 0) {
        s_v -= col_v[j - r];
        s_vv -= col_vv[j - r];
        s_rv -= col_rv[j - r];
      }
    }
    if (i + r + 1 < h) take_row(i + r + 1, 1.0);
    if (i - r >= 0) take_row(i - r, -1.0);
  }
}

#if DISPMVS_ROWS_AVX2

namespace {

// Row k's samples and flags, eight pixels at a time: the projection, the
// flags and the bilinear weights as Sample computes them, for pixels whose
// whole 2x2 block lies in the image; the few pixels whose block straddles
// the border (and the row's last w % 8) by Sample.
__attribute__((target("avx2,fma"))) void SampleRowAvx2(const PlaneSampler& s, int64_t k, float* v, char* in) {
  const int64_t w = s.w, hw = s.h * s.w;
  const float* ax = s.a + k * w;
  const float* ay = ax + hw;
  const float* az = ay + hw;
  const float* inverse_depth = s.surface + k * w;
  const int64_t b_stride = s.b_per_pixel ? hw : 1;
  const float* b = s.b_per_pixel ? s.b + k * w : s.b;
  const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.0f), minus_one = _mm256_set1_ps(-1.0f);
  const __m256 width = _mm256_set1_ps(static_cast<float>(w)), height = _mm256_set1_ps(static_cast<float>(s.h));
  const __m256 last_x = _mm256_set1_ps(static_cast<float>(w - 1)), last_y = _mm256_set1_ps(static_cast<float>(s.h - 1));
  const __m256 half_w = _mm256_set1_ps(s.half_w), half_h = _mm256_set1_ps(s.half_h);
  const __m256 limit_x = _mm256_set1_ps(s.limit_x), limit_y = _mm256_set1_ps(s.limit_y);
  const __m256 magnitude = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  const __m256i row_length = _mm256_set1_epi32(static_cast<int>(w));
  int64_t j = 0;
  for (; j + 8 <= w; j += 8) {
    const __m256 d = _mm256_loadu_ps(inverse_depth + j);
    __m256 b_x, b_y, b_z;
    if (s.b_per_pixel) {
      b_x = _mm256_loadu_ps(b + j);
      b_y = _mm256_loadu_ps(b + b_stride + j);
      b_z = _mm256_loadu_ps(b + 2 * b_stride + j);
    } else {
      b_x = _mm256_set1_ps(b[0]);
      b_y = _mm256_set1_ps(b[1]);
      b_z = _mm256_set1_ps(b[2]);
    }
    const __m256 px = _mm256_fmadd_ps(d, b_x, _mm256_loadu_ps(ax + j));
    const __m256 py = _mm256_fmadd_ps(d, b_y, _mm256_loadu_ps(ay + j));
    const __m256 pz = _mm256_fmadd_ps(d, b_z, _mm256_loadu_ps(az + j));
    const __m256 in_front = _mm256_and_ps(_mm256_cmp_ps(pz, zero, _CMP_GT_OQ), _mm256_cmp_ps(d, zero, _CMP_GT_OQ));
    const __m256 inverse_z = _mm256_and_ps(in_front, _mm256_div_ps(one, pz));
    const __m256 x = _mm256_mul_ps(px, inverse_z), y = _mm256_mul_ps(py, inverse_z);
    const __m256 inside = _mm256_and_ps(
        in_front, _mm256_and_ps(_mm256_cmp_ps(_mm256_and_ps(_mm256_sub_ps(x, half_w), magnitude), limit_x, _CMP_LE_OQ),
                                _mm256_cmp_ps(_mm256_and_ps(_mm256_sub_ps(y, half_h), magnitude), limit_y, _CMP_LE_OQ)));
    const int inside_bits = _mm256_movemask_ps(inside);
    for (int lane = 0; lane < 8; ++lane) in[j + lane] = static_cast<char>((inside_bits >> lane) & 1);
    // In reach of some pixel (NaN fails every comparison): [-1, w) x [-1, h).
    const __m256 reach =
        _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(x, minus_one, _CMP_GE_OQ), _mm256_cmp_ps(y, minus_one, _CMP_GE_OQ)),
                      _mm256_and_ps(_mm256_cmp_ps(x, width, _CMP_LT_OQ), _mm256_cmp_ps(y, height, _CMP_LT_OQ)));
    const __m256 x_reach = _mm256_and_ps(reach, x), y_reach = _mm256_and_ps(reach, y);
    const __m256 x0 = _mm256_floor_ps(x_reach), y0 = _mm256_floor_ps(y_reach);
    const __m256 fx = _mm256_sub_ps(x_reach, x0), fy = _mm256_sub_ps(y_reach, y0);
    const __m256 block_inside = _mm256_and_ps(
        reach, _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(x0, zero, _CMP_GE_OQ), _mm256_cmp_ps(y0, zero, _CMP_GE_OQ)),
                             _mm256_and_ps(_mm256_cmp_ps(x0, last_x, _CMP_LT_OQ), _mm256_cmp_ps(y0, last_y, _CMP_LT_OQ))));
    const __m256i offset = _mm256_and_si256(
        _mm256_add_epi32(_mm256_mullo_epi32(_mm256_cvttps_epi32(y0), row_length), _mm256_cvttps_epi32(x0)),
        _mm256_castps_si256(block_inside));
    // The four neighbours by scalar loads from the offsets: on this
    // project's CPU (AMD EPYC) four AVX2 gathers took longer (2.9-3.4 ms
    // against 2.2-2.4 ms for a 640x480 plane).
    alignas(32) int32_t offsets[8];
    alignas(32) float n00[8], n01[8], n10[8], n11[8];
    _mm256_store_si256(reinterpret_cast<__m256i*>(offsets), offset);
    for (int lane = 0; lane < 8; ++lane) {
      const float* corner = s.source + offsets[lane];  // offset 0 where not block_inside
      n00[lane] = corner[0];
      n01[lane] = corner[1];
      n10[lane] = corner[w];
      n11[lane] = corner[w + 1];
    }
    const __m256 v00 = _mm256_and_ps(block_inside, _mm256_load_ps(n00));
    const __m256 v01 = _mm256_and_ps(block_inside, _mm256_load_ps(n01));
    const __m256 v10 = _mm256_and_ps(block_inside, _mm256_load_ps(n10));
    const __m256 v11 = _mm256_and_ps(block_inside, _mm256_load_ps(n11));
    const __m256 gx = _mm256_sub_ps(one, fx), gy = _mm256_sub_ps(one, fy);
    const __m256 top = _mm256_fmadd_ps(fx, v01, _mm256_mul_ps(gx, v00));
    const __m256 bottom = _mm256_fmadd_ps(fx, v11, _mm256_mul_ps(gx, v10));
    _mm256_storeu_ps(v + j, _mm256_fmadd_ps(fy, bottom, _mm256_mul_ps(gy, top)));
    const int straddling = _mm256_movemask_ps(_mm256_andnot_ps(block_inside, reach));
    for (int lane = 0; straddling != 0 && lane < 8; ++lane) {
      bool unused = false;
      if ((straddling >> lane) & 1) v[j + lane] = s.Sample(k * w + j + lane, &unused);
    }
  }
  for (; j < w; ++j) {
    bool is_inside = false;
    v[j] = s.Sample(k * w + j, &is_inside);
    in[j] = is_inside;
  }
}

// Adds (sign +1) or removes (-1) a row's v, v^2 and reference * v to the
// column sums (vector loops in this build).
__attribute__((target("avx2,fma"))) void AccumulateRowAvx2(const float* v, const float* reference_row, double sign,
                                                          int64_t w, double* col_v, double* col_vv, double* col_rv) {
  for (int64_t j = 0; j < w; ++j) {
    const float value = v[j];
    col_v[j] += sign * static_cast<double>(value);
    col_vv[j] += sign * static_cast<double>(value * value);
    col_rv[j] += sign * static_cast<double>(reference_row[j] * value);
  }
}

// The sum of 2r + 1 consecutive doubles from each of four consecutive
// starts: a window's sums for four neighbouring pixels.
__attribute__((target("avx2,fma"))) inline __m256d WindowSum4(const double* first, int64_t r) {
  __m256d sum = _mm256_loadu_pd(first);
  for (int64_t t = 1; t <= 2 * r; ++t) sum = _mm256_add_pd(sum, _mm256_loadu_pd(first + t));
  return sum;
}

// Eight doubles' window sums as eight floats.
__attribute__((target("avx2,fma"))) inline __m256 WindowSum8(const double* first, int64_t r) {
  return _mm256_set_m128(_mm256_cvtpd_ps(WindowSum4(first + 4, r)), _mm256_cvtpd_ps(WindowSum4(first, r)));
}

// One output row: the window sums of v, v^2 and reference * v from the
// padded column sums (first_*[j] is the window's first column for pixel j),
// and the NCC and flags as CorrelateRowsPortable computes them, eight
// pixels at a time (the row's last w % 8 one by one).
__attribute__((target("avx2,fma"))) void WindowNccRowAvx2(const double* first_v, const double* first_vv,
                                                         const double* first_rv, int64_t r, int64_t w,
                                                         float inverse_rows, const float* inverse_cols,
                                                         const float* mean, const float* var, const char* in,
                                                         const float* needed, float* ncc, bool* ok) {
  const __m256 zero = _mm256_setzero_ps(), rows = _mm256_set1_ps(inverse_rows);
  const __m256 floor_product = _mm256_set1_ps(1e-12f), floor_var = _mm256_set1_ps(1e-10f);
  int64_t j = 0;
  for (; j + 8 <= w; j += 8) {
    const __m256 inverse_count = _mm256_mul_ps(rows, _mm256_loadu_ps(inverse_cols + j));
    const __m256 s_mean = _mm256_mul_ps(WindowSum8(first_v + j, r), inverse_count);
    const __m256 s_var = _mm256_max_ps(
        _mm256_fnmadd_ps(s_mean, s_mean, _mm256_mul_ps(WindowSum8(first_vv + j, r), inverse_count)), zero);
    const __m256 covariance =
        _mm256_fnmadd_ps(_mm256_loadu_ps(mean + j), s_mean, _mm256_mul_ps(WindowSum8(first_rv + j, r), inverse_count));
    __m256 value = _mm256_div_ps(
        covariance, _mm256_sqrt_ps(_mm256_max_ps(_mm256_mul_ps(_mm256_loadu_ps(var + j), s_var), floor_product)));
    const __m256i inside_lanes =
        _mm256_cvtepi8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(in + j)));
    __m256 counts = _mm256_and_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(inside_lanes, _mm256_setzero_si256())),
                                  _mm256_cmp_ps(s_var, floor_var, _CMP_GT_OQ));
    if (needed != nullptr) {
      const __m256 wanted = _mm256_cmp_ps(_mm256_loadu_ps(needed + j), zero, _CMP_NEQ_UQ);
      value = _mm256_and_ps(value, wanted);
      counts = _mm256_and_ps(counts, wanted);
    }
    _mm256_storeu_ps(ncc + j, value);
    const int count_bits = _mm256_movemask_ps(counts);
    for (int lane = 0; lane < 8; ++lane) ok[j + lane] = (count_bits >> lane) & 1;
  }
  for (; j < w; ++j) {
    double sum_v = 0, sum_vv = 0, sum_rv = 0;
    for (int64_t t = 0; t <= 2 * r; ++t) {
      sum_v += first_v[j + t];
      sum_vv += first_vv[j + t];
      sum_rv += first_rv[j + t];
    }
    PixelNcc(sum_v, sum_vv, sum_rv, static_cast<double>(inverse_rows * inverse_cols[j]), mean[j], var[j],
             in[j] != 0, needed == nullptr || needed[j] != 0, ncc + j, ok + j);
  }
}

}  // namespace

// As CorrelateRowsPortable, but each output row's window sums are the sums
// of 2r + 1 neighbouring column sums (columns beyond the image hold 0), a
// vector loop instead of the running sum's chain of dependent additions,
// and the NCC of a whole row is computed and then masked by `needed`.
__attribute__((target("avx2,fma"))) void CorrelateRowsAvx2(
    const PlaneSampler& sampler, const float* reference, const float* reference_mean, const float* reference_var,
    int64_t r, int64_t row_begin, int64_t row_end, float* ncc, bool* ok, const float* needed) {
  const int64_t h = sampler.h, w = sampler.w;
  const int64_t ring = 2 * r + 2, padded = w + 2 * r;
  std::vector<float> values(static_cast<size_t>(ring * w));
  std::vector<char> inside(static_cast<size_t>(ring * w));
  std::vector<double> columns(static_cast<size_t>(3 * padded), 0.0);
  double* col_v = columns.data() + r;
  double* col_vv = col_v + padded;
  double* col_rv = col_vv + padded;
  std::vector<float> inverse_cols(static_cast<size_t>(w));
  for (int64_t j = 0; j < w; ++j) {
    inverse_cols[static_cast<size_t>(j)] =
        1.0f / static_cast<float>(std::min(j + r, w - 1) - std::max<int64_t>(j - r, 0) + 1);
  }
  const auto take_row = [&](int64_t k, double sign) {
    float* v = values.data() + (k % ring) * w;
    if (sign > 0) SampleRowAvx2(sampler, k, v, inside.data() + (k % ring) * w);
    AccumulateRowAvx2(v, reference + k * w, sign, w, col_v, col_vv, col_rv);
  };
  for (int64_t k = std::max<int64_t>(row_begin - r, 0); k <= std::min(row_begin + r, h - 1); ++k) take_row(k, 1.0);
  for (int64_t i = row_begin; i < row_end; ++i) {
    const int64_t rows = std::min(i + r, h - 1) - std::max<int64_t>(i - r, 0) + 1;
    const float inverse_rows = 1.0f / static_cast<float>(rows);
    const char* in = inside.data() + (i % ring) * w;
    const float* mean_row = reference_mean + i * w;
    const float* var_row = reference_var + i * w;
    float* ncc_row = ncc + (i - row_begin) * w;
    bool* ok_row = ok + (i - row_begin) * w;
    const float* needed_row = needed ? needed + (i - row_begin) * w : nullptr;
    WindowNccRowAvx2(col_v - r, col_vv - r, col_rv - r, r, w, inverse_rows, inverse_cols.data(), mean_row, var_row,
                     in, needed_row, ncc_row, ok_row);
    if (i + r + 1 < h) take_row(i + r + 1, 1.0);
    if (i - r >= 0) take_row(i - r, -1.0);
  }
}

bool CpuHasAvx2Fma() {
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return has;
}

#else  // no AVX2 build: the portable one

void CorrelateRowsAvx2(const PlaneSampler& sampler, const float* reference, const float* reference_mean,
                       const float* reference_var, int64_t r, int64_t row_begin, int64_t row_end, float* ncc,
                       bool* ok, const float* needed) {
  CorrelateRowsPortable(sampler, reference, reference_mean, reference_var, r, row_begin, row_end, ncc, ok, needed);
}

bool CpuHasAvx2Fma() { return false; }

#endif

// The AVX2 build's pixel offsets are 32-bit (y0 * w + x0 + w + 1 must fit),
// and it reads the 2x2 block at offset 0 for pixels without one, which
// needs a second row.
bool Avx2RowsFit(int64_t h, int64_t w) { return h >= 2 && h * w + w + 1 < (int64_t{1} << 31); }

void CorrelateRows(const PlaneSampler& sampler, const float* reference, const float* reference_mean,
                   const float* reference_var, int64_t r, int64_t row_begin, int64_t row_end, float* ncc, bool* ok,
                   const float* needed) {
  if (CpuHasAvx2Fma() && Avx2RowsFit(sampler.h, sampler.w)) {
    CorrelateRowsAvx2(sampler, reference, reference_mean, reference_var, r, row_begin, row_end, ncc, ok, needed);
  } else {
    CorrelateRowsPortable(sampler, reference, reference_mean, reference_var, r, row_begin, row_end, ncc, ok, needed);
  }
}

}  // namespace dispmvs::model
