#include "lb/reproject.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace tessera {

namespace {

// The inverse of the 3x3 matrix with columns cz, cx, cy (row-major), or false if singular.
bool basis_inverse(const Vec3& cz, const Vec3& cx, const Vec3& cy, double inv[9]) {
  const double a = cz.x, b = cx.x, c = cy.x, d = cz.y, e = cx.y, f = cy.y, g = cz.z, h = cx.z, i = cy.z;
  const double A = e * i - f * h, B = -(d * i - f * g), C = d * h - e * g;
  const double det = a * A + b * B + c * C;
  if (!(std::fabs(det) > 1e-12) || !std::isfinite(det)) return false;
  const double r = 1.0 / det;
  inv[0] = A * r; inv[1] = -(b * i - c * h) * r; inv[2] = (b * f - c * e) * r;
  inv[3] = B * r; inv[4] = (a * i - c * g) * r;  inv[5] = -(a * f - c * d) * r;
  inv[6] = C * r; inv[7] = -(a * h - b * g) * r; inv[8] = (a * e - b * d) * r;
  return true;
}

}  // namespace

ViewRays ViewRays::of(const Camera& camera, int32_t width, int32_t height) {
  // The ray tracer's PrimaryCamera, in world coordinates (no rebasing).
  ViewRays v;
  const float tan_half = std::tan(std::fmin(std::fmax(camera.fov_y, 1e-6f), kPi - 1e-4f) * 0.5f);
  v.eye = camera.to_world.transform_point({0, 0, 0});
  v.cx = camera.to_world.transform_vector({1, 0, 0});
  v.cy = camera.to_world.transform_vector({0, 1, 0});
  v.cz = camera.to_world.transform_vector({0, 0, -1});
  v.width = std::max(width, 1);
  v.height = std::max(height, 1);
  v.sx_scale = tan_half * (float(v.width) / float(v.height));
  v.sy_scale = tan_half;
  v.ok = basis_inverse(v.cz, v.cx, v.cy, v.inv);
  return v;
}

bool ViewRays::project(const float p[4], float& x, float& y, float& depth) const {
  if (!ok) return false;
  double vx = p[0], vy = p[1], vz = p[2];
  if (p[3] > 0) {
    vx -= eye.x;
    vy -= eye.y;
    vz -= eye.z;
  }
  const double al = inv[0] * vx + inv[1] * vy + inv[2] * vz;
  const double be = inv[3] * vx + inv[4] * vy + inv[5] * vz;
  const double ga = inv[6] * vx + inv[7] * vy + inv[8] * vz;
  if (!(al > 1e-9) || !std::isfinite(al)) return false;
  const double sx = be / al / sx_scale, sy = ga / al / sy_scale;
  const double px = (sx + 1) * 0.5 * width, py = (1 - sy) * 0.5 * height;
  if (!(std::fabs(px) < 1e9 && std::fabs(py) < 1e9)) return false;
  x = float(px);
  y = float(py);
  depth = p[3] > 0 ? float(al) : std::numeric_limits<float>::infinity();
  return true;
}

CostMap reproject(const CostMap& cost, const PacketPoints& points, const ViewRays& to, PacketLayout layout,
                  ReprojectStats* stats, double min_coverage) {
  ReprojectStats st;
  const Rect space = packet_space(to.width, to.height, layout);
  st.packets = space.area();
  auto give_back = [&]() {
    st.cut = true;
    if (stats) *stats = st;
    return cost;
  };
  if (points.packets != cost.packets || points.xyzw.size() != cost.cost.size() * 4 || cost.cost.empty() ||
      space.empty())
    return give_back();
  if (!to.ok) return give_back();

  const int32_t W = space.width(), H = space.height();
  const size_t n = size_t(W) * size_t(H);
  // Each old packet's footprint (one packet, centred where its point lands) overlaps up to four
  // new packets, with bilinear weights. The new packet keeps the nearest surface that covers a
  // quarter of it or more; nearer ones below that are mixed in by their share (an outline
  // crossing it), farther ones are hidden.
  struct Splat {
    size_t target;
    float w, depth;
    uint32_t cost;
  };
  std::vector<Splat> splats;
  splats.reserve(cost.cost.size() * 4);
  const Rect& src = cost.packets;
  for (int32_t sy = src.y0; sy < src.y1; ++sy)
    for (int32_t sx = src.x0; sx < src.x1; ++sx) {
      const size_t si = size_t(sy - src.y0) * size_t(src.width()) + size_t(sx - src.x0);
      const float* p = &points.xyzw[si * 4];
      if (!(p[3] >= 0)) continue;
      float x, y, d;
      if (!to.project(p, x, y, d)) continue;
      const float u = x / float(layout.w) - 0.5f, v = y / float(layout.h) - 0.5f;
      if (!(u > -2 && v > -2 && u < float(W) + 1 && v < float(H) + 1)) continue;
      const int32_t i0 = int32_t(std::floor(u)), j0 = int32_t(std::floor(v));
      const float fx = u - float(i0), fy = v - float(j0);
      const float wx[2] = {1 - fx, fx}, wy[2] = {1 - fy, fy};
      for (int b = 0; b < 2; ++b)
        for (int a = 0; a < 2; ++a) {
          const int32_t tx = i0 + a, ty = j0 + b;
          const float w = wx[a] * wy[b];
          if (tx < 0 || ty < 0 || tx >= W || ty >= H || !(w > 1e-4f)) continue;
          splats.push_back({size_t(ty) * size_t(W) + size_t(tx), w, d, cost.cost[si]});
        }
    }
  std::vector<float> zmin(n, std::numeric_limits<float>::infinity());
  for (const Splat& s : splats)
    if (s.w >= 0.25f && s.depth < zmin[s.target]) zmin[s.target] = s.depth;
  std::vector<double> sum(n, 0.0), weight(n, 0.0);
  for (const Splat& s : splats) {
    if (!(s.depth <= zmin[s.target] * 1.02f)) continue;  // hidden (sky against sky: inf <= inf)
    sum[s.target] += double(s.w) * s.cost;
    weight[s.target] += s.w;
  }

  // Known: covered by a quarter of a packet or more of footprints.
  CostMap out{space, std::vector<uint32_t>(n, 0)};
  std::vector<uint8_t> known(n, 0);
  std::vector<size_t> frontier;
  for (size_t i = 0; i < n; ++i)
    if (weight[i] >= 0.25) {
      out.cost[i] = uint32_t(std::llround(std::min(sum[i] / weight[i], 4294967295.0)));
      known[i] = 1;
      ++st.splatted;
    }
  if (double(st.splatted) < min_coverage * double(n)) return give_back();

  // Fill what nothing landed in, ring by ring from the known packets: each new packet gets the
  // mean of its known 8-neighbours as they were when its ring started.
  auto neighbours = [&](size_t i, auto&& f) {
    const int32_t x = int32_t(i % size_t(W)), y = int32_t(i / size_t(W));
    for (int32_t dy = -1; dy <= 1; ++dy)
      for (int32_t dx = -1; dx <= 1; ++dx) {
        if ((dx | dy) == 0) continue;
        const int32_t nx = x + dx, ny = y + dy;
        if (nx >= 0 && ny >= 0 && nx < W && ny < H) f(size_t(ny) * size_t(W) + size_t(nx));
      }
  };
  for (size_t i = 0; i < n; ++i)
    if (!known[i]) {
      bool edge = false;
      neighbours(i, [&](size_t j) { edge = edge || known[j] == 1; });
      if (edge) frontier.push_back(i);
    }
  std::vector<size_t> next;
  std::vector<std::pair<size_t, uint32_t>> ring;
  while (!frontier.empty()) {
    ring.clear();
    for (size_t i : frontier) {
      if (known[i]) continue;
      double s = 0;
      uint32_t c = 0;
      neighbours(i, [&](size_t j) {
        if (known[j] == 1) {
          s += out.cost[j];
          ++c;
        }
      });
      if (c > 0) ring.emplace_back(i, uint32_t(std::llround(s / c)));
    }
    next.clear();
    for (auto& [i, v] : ring) {
      if (known[i]) continue;
      out.cost[i] = v;
      known[i] = 2;  // not read as a neighbour until this ring is done
      ++st.filled;
    }
    for (auto& [i, v] : ring) {
      known[i] = 1;
      neighbours(i, [&](size_t j) {
        if (!known[j]) next.push_back(j);
      });
    }
    frontier.swap(next);
  }
  // Unreachable in a connected image once one packet is known; kept for safety.
  for (size_t i = 0; i < n; ++i)
    if (!known[i]) {
      const int32_t x = int32_t(i % size_t(W)), y = int32_t(i / size_t(W));
      out.cost[i] = src.contains(x, y) ? cost.at(x, y) : 0;
      ++st.kept;
    }
  if (stats) *stats = st;
  return out;
}

}  // namespace tessera
