#include "lb/reproject.h"

#include <algorithm>
#include <cmath>
#include <cstring>
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

Vec3 ViewRays::direction(float x, float y) const {
  const float sx = (2.0f * x / float(width) - 1.0f) * sx_scale, sy = (1.0f - 2.0f * y / float(height)) * sy_scale;
  return {cz.x + cx.x * sx + cy.x * sy, cz.y + cx.y * sx + cy.y * sy, cz.z + cx.z * sx + cy.z * sy};
}

std::vector<uint8_t> encode_depths(const PacketPoints& points, const ViewRays& from) {
  const size_t n = points.xyzw.size() / 4;
  std::vector<uint8_t> out(n * 4);
  for (size_t i = 0; i < n; ++i) {
    const float* p = &points.xyzw[i * 4];
    float d = std::numeric_limits<float>::quiet_NaN(), x, y, depth;
    if (p[3] == 0)
      d = std::numeric_limits<float>::infinity();
    else if (p[3] > 0 && from.project(p, x, y, depth))
      d = depth;
    std::memcpy(&out[i * 4], &d, 4);
  }
  return out;
}

bool decode_depths(const uint8_t* data, size_t size, const Rect& packets, const ViewRays& from, PacketLayout layout,
                   PacketPoints& into) {
  if (packets.empty() || size != size_t(packets.area()) * 4 || !into.packets.contains(packets) ||
      into.xyzw.size() != size_t(into.packets.area()) * 4 || layout.w < 1 || layout.h < 1)
    return false;
  for (int32_t py = packets.y0; py < packets.y1; ++py)
    for (int32_t px = packets.x0; px < packets.x1; ++px) {
      float d;
      std::memcpy(&d, data + (size_t(py - packets.y0) * size_t(packets.width()) + size_t(px - packets.x0)) * 4, 4);
      // The centre of the packet's pixels inside the image (edge packets are cut by it).
      const float x0 = float(px * layout.w), x1 = float(std::min((px + 1) * layout.w, from.width));
      const float y0 = float(py * layout.h), y1 = float(std::min((py + 1) * layout.h, from.height));
      const Vec3 dir = from.direction(0.5f * (x0 + x1), 0.5f * (y0 + y1));
      float* o = &into.xyzw[(size_t(py - into.packets.y0) * size_t(into.packets.width()) + size_t(px - into.packets.x0)) * 4];
      if (d == std::numeric_limits<float>::infinity()) {
        o[0] = dir.x, o[1] = dir.y, o[2] = dir.z, o[3] = 0;
      } else if (d > 0 && d < 3.0e38f) {
        o[0] = from.eye.x + d * dir.x, o[1] = from.eye.y + d * dir.y, o[2] = from.eye.z + d * dir.z, o[3] = 1;
      } else {
        o[0] = o[1] = o[2] = 0, o[3] = -1;
      }
    }
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
  // Where each old packet lands: the new packet whose centre is the footprint's top-left
  // neighbour (i0, j0), the bilinear fractions and the depth. i0 = kNowhere: it lands nowhere.
  constexpr int32_t kNowhere = std::numeric_limits<int32_t>::min();
  struct Landing {
    int32_t i0, j0;
    float fx, fy, depth;
  };
  const Rect& src = cost.packets;
  std::vector<Landing> land(cost.cost.size());
  // ViewRays::project folded into one projective map to packet coordinates, in float: with
  // q = p - eye (a point) or p (a direction), al = A.q, u = U.q / al - 0.5, v = V.q / al - 0.5,
  // one division a packet.
  float A[3], U[3], V[3];
  for (int k = 0; k < 3; ++k) {
    const double al = to.inv[k], be = to.inv[3 + k], ga = to.inv[6 + k];
    A[k] = float(al);
    U[k] = float((be / to.sx_scale + al) * 0.5 * to.width / layout.w);
    V[k] = float((al - ga / to.sy_scale) * 0.5 * to.height / layout.h);
  }
  const float ex = to.eye.x, ey = to.eye.y, ez = to.eye.z;
  for (size_t si = 0; si < land.size(); ++si) {
    Landing& l = land[si];
    l.i0 = kNowhere;
    const float* p = &points.xyzw[si * 4];
    if (!(p[3] >= 0)) continue;
    const float sky = p[3] > 0 ? 1.0f : 0.0f;
    const float qx = p[0] - sky * ex, qy = p[1] - sky * ey, qz = p[2] - sky * ez;
    const float al = A[0] * qx + A[1] * qy + A[2] * qz;
    if (!(al > 1e-9f) || !(al < 3e38f)) continue;  // behind the camera, or not finite
    const float r = 1.0f / al;
    const float u = (U[0] * qx + U[1] * qy + U[2] * qz) * r - 0.5f, v = (V[0] * qx + V[1] * qy + V[2] * qz) * r - 0.5f;
    if (!(u > -2 && v > -2 && u < float(W) + 1 && v < float(H) + 1)) continue;
    l.i0 = int32_t(std::floor(u));
    l.j0 = int32_t(std::floor(v));
    l.fx = u - float(l.i0);
    l.fy = v - float(l.j0);
    l.depth = p[3] > 0 ? al : std::numeric_limits<float>::infinity();
  }
  // Calls f(target, weight) for the (up to four) new packets a landing's footprint overlaps.
  auto targets = [&](const Landing& l, auto&& f) {
    const float wx[2] = {1 - l.fx, l.fx}, wy[2] = {1 - l.fy, l.fy};
    for (int b = 0; b < 2; ++b) {
      const int32_t ty = l.j0 + b;
      if (ty < 0 || ty >= H) continue;
      for (int a = 0; a < 2; ++a) {
        const int32_t tx = l.i0 + a;
        const float w = wx[a] * wy[b];
        if (tx < 0 || tx >= W || !(w > 1e-4f)) continue;
        f(size_t(ty) * size_t(W) + size_t(tx), w);
      }
    }
  };
  std::vector<float> zmin(n, std::numeric_limits<float>::infinity());
  for (const Landing& l : land)
    if (l.i0 != kNowhere)
      targets(l, [&](size_t t, float w) {
        if (w >= 0.25f && l.depth < zmin[t]) zmin[t] = l.depth;
      });
  std::vector<double> sum(n, 0.0);
  std::vector<float> weight(n, 0.0f);
  for (size_t si = 0; si < land.size(); ++si) {
    const Landing& l = land[si];
    if (l.i0 == kNowhere) continue;
    const double c = cost.cost[si];
    targets(l, [&](size_t t, float w) {
      if (!(l.depth <= zmin[t] * 1.02f)) return;  // hidden (sky against sky: inf <= inf)
      sum[t] += double(w) * c;
      weight[t] += w;
    });
  }

  // Known: covered by a quarter of a packet or more of footprints.
  CostMap out{space, std::vector<uint32_t>(n, 0)};
  std::vector<uint8_t> known(n, 0);
  std::vector<size_t> frontier;
  for (size_t i = 0; i < n; ++i)
    if (weight[i] >= 0.25f) {
      out.cost[i] = uint32_t(std::min(sum[i] / double(weight[i]), 4294967295.0) + 0.5);
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
  // Each packet enters a ring at most once (queued): a large unknown area (a worker that gave no
  // depths, a wide disocclusion) costs one pass over it, not a frontier that multiplies.
  std::vector<uint8_t> queued(n, 0);
  for (size_t i = 0; i < n; ++i)
    if (!known[i]) {
      bool edge = false;
      neighbours(i, [&](size_t j) { edge = edge || known[j] == 1; });
      if (edge) {
        frontier.push_back(i);
        queued[i] = 1;
      }
    }
  std::vector<size_t> next;
  std::vector<std::pair<size_t, uint32_t>> ring;
  while (!frontier.empty()) {
    ring.clear();
    for (size_t i : frontier) {  // every one has a known neighbour: it was queued beside one
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
    // Written once the whole ring is computed, so no ring member reads another.
    for (auto& [i, v] : ring) {
      out.cost[i] = v;
      known[i] = 1;
      ++st.filled;
    }
    next.clear();
    for (auto& [i, v] : ring)
      neighbours(i, [&](size_t j) {
        if (!known[j] && !queued[j]) {
          queued[j] = 1;
          next.push_back(j);
        }
      });
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

CostMap reproject_blocks(const CostMap& cost, const PacketPoints& points, const ViewRays& to, PacketLayout layout,
                         int32_t block, ReprojectStats* stats, double min_coverage) {
  if (block <= 1) return reproject(cost, points, to, layout, stats, min_coverage);
  const Rect space = packet_space(to.width, to.height, layout);
  if (cost.packets != space || points.packets != space || points.xyzw.size() != cost.cost.size() * 4 || space.empty()) {
    if (stats) *stats = ReprojectStats{space.area(), 0, 0, 0, true};
    return cost;
  }
  const PacketLayout coarse{layout.w * block, layout.h * block};
  const Rect bspace = packet_space(to.width, to.height, coarse);
  const int32_t W = space.width(), BW = bspace.width();
  CostMap bcost{bspace, std::vector<uint32_t>(size_t(bspace.area()), 0)};
  PacketPoints bpts{bspace, std::vector<float>(size_t(bspace.area()) * 4, 0.0f)};
  std::vector<uint64_t> bsum(size_t(bspace.area()), 0);
  std::vector<int32_t> surf(size_t(bspace.area()), 0), sky(size_t(bspace.area()), 0);
  std::vector<float> dirs(size_t(bspace.area()) * 3, 0.0f);
  for (int32_t py = 0; py < space.y1; ++py)
    for (int32_t px = 0; px < W; ++px) {
      const size_t i = size_t(py) * size_t(W) + size_t(px);
      const size_t b = size_t(py / block) * size_t(BW) + size_t(px / block);
      bsum[b] += cost.cost[i];
      const float* p = &points.xyzw[i * 4];
      if (p[3] > 0) {
        float* o = &bpts.xyzw[b * 4];
        o[0] += p[0], o[1] += p[1], o[2] += p[2];
        ++surf[b];
      } else if (p[3] == 0) {
        dirs[b * 3] += p[0], dirs[b * 3 + 1] += p[1], dirs[b * 3 + 2] += p[2];
        ++sky[b];
      }
    }
  for (size_t b = 0; b < bsum.size(); ++b) {
    bcost.cost[b] = uint32_t(std::min<uint64_t>(bsum[b], 0xffffffffu));  // a block of 16 packets stays far below
    float* o = &bpts.xyzw[b * 4];
    if (surf[b] > 0) {
      const float r = 1.0f / float(surf[b]);
      o[0] *= r, o[1] *= r, o[2] *= r, o[3] = 1;
    } else if (sky[b] > 0) {
      o[0] = dirs[b * 3], o[1] = dirs[b * 3 + 1], o[2] = dirs[b * 3 + 2], o[3] = 0;
    } else {
      o[3] = -1;
    }
  }
  ReprojectStats st;
  const CostMap carried = reproject(bcost, bpts, to, coarse, &st, min_coverage);
  if (stats) *stats = st;
  if (st.cut) return cost;
  // Each block's cost over its packets (edge blocks hold fewer).
  CostMap out{space, std::vector<uint32_t>(cost.cost.size(), 0)};
  for (int32_t by = 0; by < bspace.y1; ++by)
    for (int32_t bx = 0; bx < BW; ++bx) {
      const int32_t x0 = bx * block, y0 = by * block;
      const int32_t x1 = std::min(x0 + block, W), y1 = std::min(y0 + block, space.y1);
      const int32_t n = (x1 - x0) * (y1 - y0);
      if (n <= 0) continue;
      const uint32_t each = uint32_t((uint64_t(carried.cost[size_t(by) * size_t(BW) + size_t(bx)]) + uint64_t(n) / 2) / uint64_t(n));
      for (int32_t y = y0; y < y1; ++y)
        for (int32_t x = x0; x < x1; ++x) out.cost[size_t(y) * size_t(W) + size_t(x)] = each;
    }
  return out;
}

}  // namespace tessera
