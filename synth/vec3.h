#pragma once
// Small double-precision 3-vector / 3x3-matrix helpers for the scalar side of
// the generator (scene layout, camera rigs). The per-pixel work runs in
// LibTorch; these only describe a handful of objects and cameras, so plain
// doubles keep that code exact and readable without pulling in Eigen (synth/
// builds with LibTorch and the standard library alone).

#include <array>
#include <cmath>

namespace dispmvs::synth {

struct Vec3 {
  double x = 0, y = 0, z = 0;
  double operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
};

inline Vec3 operator+(const Vec3& a, const Vec3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Vec3 operator-(const Vec3& a, const Vec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec3 operator*(double s, const Vec3& a) { return {s * a.x, s * a.y, s * a.z}; }
inline double Dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double Norm(const Vec3& a) { return std::sqrt(Dot(a, a)); }
inline Vec3 Normalized(const Vec3& a) { return (1.0 / Norm(a)) * a; }

// Row-major 3x3 matrix.
struct Mat3 {
  std::array<double, 9> m{1, 0, 0, 0, 1, 0, 0, 0, 1};
  double operator()(int r, int c) const { return m[3 * r + c]; }
  double& operator()(int r, int c) { return m[3 * r + c]; }
  static Mat3 Identity() { return Mat3{}; }
  // The matrix whose rows are r0, r1, r2.
  static Mat3 FromRows(const Vec3& r0, const Vec3& r1, const Vec3& r2) {
    return Mat3{{r0.x, r0.y, r0.z, r1.x, r1.y, r1.z, r2.x, r2.y, r2.z}};
  }
  Vec3 Row(int r) const { return {m[3 * r], m[3 * r + 1], m[3 * r + 2]}; }
  Vec3 Col(int c) const { return {m[c], m[3 + c], m[6 + c]}; }
};

inline Vec3 operator*(const Mat3& a, const Vec3& v) {
  return {Dot(a.Row(0), v), Dot(a.Row(1), v), Dot(a.Row(2), v)};
}
inline Mat3 operator*(const Mat3& a, const Mat3& b) {
  Mat3 out;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out(r, c) = Dot(a.Row(r), b.Col(c));
  return out;
}
inline Mat3 Transposed(const Mat3& a) { return Mat3::FromRows(a.Col(0), a.Col(1), a.Col(2)); }

// Rotation by `angle` radians about the unit vector `axis` (Rodrigues).
inline Mat3 AxisAngle(const Vec3& axis, double angle) {
  const Vec3 k = Normalized(axis);
  const double c = std::cos(angle), s = std::sin(angle), v = 1 - c;
  return Mat3{{c + k.x * k.x * v, k.x * k.y * v - k.z * s, k.x * k.z * v + k.y * s,
               k.y * k.x * v + k.z * s, c + k.y * k.y * v, k.y * k.z * v - k.x * s,
               k.z * k.x * v - k.y * s, k.z * k.y * v + k.x * s, c + k.z * k.z * v}};
}

}  // namespace dispmvs::synth
