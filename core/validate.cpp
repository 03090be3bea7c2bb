#include "core/validate.h"

#include <cmath>
#include <cstdio>
#include <limits>

namespace tessera {
namespace {

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

}  // namespace

TransformFigures transform_figures(const Mat4& m) {
  TransformFigures f;
  double a[3][3];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) a[r][c] = double(m(r, c));
  // Float inputs are at most 3.4e38 and at least 1.4e-45 in magnitude, so the products of
  // three below neither overflow nor underflow in double.
  double adj[3][3];  // adjugate: A^-1 = adj / det
  adj[0][0] = a[1][1] * a[2][2] - a[1][2] * a[2][1];
  adj[0][1] = a[0][2] * a[2][1] - a[0][1] * a[2][2];
  adj[0][2] = a[0][1] * a[1][2] - a[0][2] * a[1][1];
  adj[1][0] = a[1][2] * a[2][0] - a[1][0] * a[2][2];
  adj[1][1] = a[0][0] * a[2][2] - a[0][2] * a[2][0];
  adj[1][2] = a[0][2] * a[1][0] - a[0][0] * a[1][2];
  adj[2][0] = a[1][0] * a[2][1] - a[1][1] * a[2][0];
  adj[2][1] = a[0][1] * a[2][0] - a[0][0] * a[2][1];
  adj[2][2] = a[0][0] * a[1][1] - a[0][1] * a[1][0];
  f.det = a[0][0] * adj[0][0] + a[0][1] * adj[1][0] + a[0][2] * adj[2][0];
  double adj_norm = 0;
  for (int r = 0; r < 3; ++r) {
    double row = 0, row_adj = 0;
    for (int c = 0; c < 3; ++c) {
      row += std::fabs(a[r][c]);
      row_adj += std::fabs(adj[r][c]);
    }
    f.norm = std::fmax(f.norm, row);
    adj_norm = std::fmax(adj_norm, row_adj);
  }
  const double inf = std::numeric_limits<double>::infinity();
  f.norm_inverse = f.det != 0 ? adj_norm / std::fabs(f.det) : inf;
  f.condition = f.det != 0 ? f.norm * f.norm_inverse : inf;
  for (int r = 0; r < 3; ++r) f.max_translation = std::fmax(f.max_translation, std::fabs(double(m(r, 3))));
  return f;
}

std::string check_transform(const Mat4& m, const TransformLimits& lim) {
  if (!m.finite()) return "holds NaN or Inf";
  return check_transform(transform_figures(m), lim);
}

std::string check_transform(const TransformFigures& f, const TransformLimits& lim) {
  if (f.norm > lim.max_norm)
    return "scale too large: the upper 3x3's norm (max row sum) is " + num(f.norm) + ", at most " + num(lim.max_norm);
  if (f.max_translation > lim.max_translation)
    return "translation " + num(f.max_translation) + " beyond " + num(lim.max_translation);
  if (f.det == 0) return "the upper 3x3 is singular (determinant 0)";
  if (f.norm_inverse > lim.max_inverse_norm)
    return "nearly singular: the inverse's norm is " + num(f.norm_inverse) + ", at most " + num(lim.max_inverse_norm) +
           " (a scale below " + num(1.0 / lim.max_inverse_norm) + ")";
  if (f.condition > lim.max_condition)
    return "ill-conditioned: condition number " + num(f.condition) + ", at most " + num(lim.max_condition);
  return {};
}

std::string check_camera(const Camera& c) {
  std::string why = check_transform(c.to_world, kCameraLimits);
  if (!why.empty()) return "to_world: " + why;
  if (!(c.fov_y > 0 && c.fov_y < kPi)) return "fov_y " + num(c.fov_y) + " outside (0, pi)";
  return {};
}

std::string check_point(const Vec3& p) {
  if (!finite(p)) return "is not finite";
  const double m = std::fmax(std::fabs(p.x), std::fmax(std::fabs(p.y), std::fabs(p.z)));
  if (m > kWorldLimit) return "component " + num(m) + " beyond the world limit " + num(kWorldLimit);
  return {};
}

std::string check_direction(const Vec3& d) {
  if (!finite(d)) return "is not finite";
  const Vec3 n = normalize(d);
  const float l = length(n);
  if (!(std::fabs(l - 1.0f) < kUnitTolerance)) return "cannot be normalised (zero, or too large or small for float)";
  return {};
}

std::string check_world_extent(const TransformFigures& f, float max_abs_vertex) {
  const double extent = f.norm * double(max_abs_vertex) + f.max_translation;
  if (!(extent <= kWorldLimit))
    return "places vertices up to " + num(extent) + " from the origin, beyond the world limit " + num(kWorldLimit);
  return {};
}

}  // namespace tessera
