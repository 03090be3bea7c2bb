#include "core/math.h"

namespace tessera {

Mat4 Mat4::rotate(const Vec3& axis_in, float angle) {
  Vec3 a = normalize(axis_in);
  Mat4 r;
  if (length(axis_in) == 0) return r;
  float c = std::cos(angle), s = std::sin(angle), t = 1 - c;
  r(0, 0) = t * a.x * a.x + c;       r(0, 1) = t * a.x * a.y - s * a.z; r(0, 2) = t * a.x * a.z + s * a.y;
  r(1, 0) = t * a.x * a.y + s * a.z; r(1, 1) = t * a.y * a.y + c;       r(1, 2) = t * a.y * a.z - s * a.x;
  r(2, 0) = t * a.x * a.z - s * a.y; r(2, 1) = t * a.y * a.z + s * a.x; r(2, 2) = t * a.z * a.z + c;
  return r;
}

Mat4 Mat4::look_at(const Vec3& eye, const Vec3& target, const Vec3& up) {
  Vec3 f = normalize(target - eye);
  Vec3 r = cross(f, up);
  if (length(r) < 1e-12f) r = cross(f, std::fabs(f.y) < 0.9f ? Vec3{0, 1, 0} : Vec3{1, 0, 0});
  r = normalize(r);
  Vec3 u = cross(r, f);
  Mat4 m;
  m(0, 0) = r.x; m(1, 0) = r.y; m(2, 0) = r.z;
  m(0, 1) = u.x; m(1, 1) = u.y; m(2, 1) = u.z;
  m(0, 2) = -f.x; m(1, 2) = -f.y; m(2, 2) = -f.z;
  m(0, 3) = eye.x; m(1, 3) = eye.y; m(2, 3) = eye.z;
  return m;
}

float Mat4::det3() const {
  const Mat4& a = *this;
  return a(0, 0) * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1)) - a(0, 1) * (a(1, 0) * a(2, 2) - a(1, 2) * a(2, 0)) +
         a(0, 2) * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0));
}

Mat4 operator*(const Mat4& a, const Mat4& b) {
  Mat4 r;
  for (int c = 0; c < 4; ++c)
    for (int row = 0; row < 4; ++row) {
      float s = 0;
      for (int k = 0; k < 4; ++k) s += a(row, k) * b(k, c);
      r(row, c) = s;
    }
  return r;
}

Mat4 transpose(const Mat4& a) {
  Mat4 r;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) r(i, j) = a(j, i);
  return r;
}

Mat4 inverse(const Mat4& in) {
  // Gauss-Jordan elimination with partial pivoting, in double precision.
  double a[4][8];
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) {
      a[i][j] = in(i, j);
      a[i][j + 4] = i == j ? 1.0 : 0.0;
    }
  for (int c = 0; c < 4; ++c) {
    int p = c;
    for (int r = c + 1; r < 4; ++r)
      if (std::fabs(a[r][c]) > std::fabs(a[p][c])) p = r;
    if (std::fabs(a[p][c]) < 1e-300) return Mat4{};
    if (p != c)
      for (int j = 0; j < 8; ++j) std::swap(a[p][j], a[c][j]);
    double inv = 1.0 / a[c][c];
    for (int j = 0; j < 8; ++j) a[c][j] *= inv;
    for (int r = 0; r < 4; ++r)
      if (r != c) {
        double f = a[r][c];
        for (int j = 0; j < 8; ++j) a[r][j] -= f * a[c][j];
      }
  }
  Mat4 r;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) r(i, j) = float(a[i][j + 4]);
  return r;
}

}  // namespace tessera
