#include "lb/tiler.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include <tbb/parallel_invoke.h>

namespace tessera {
namespace {

enum class Axis { x, y };

struct Tiler {
  const SatArray* sats;
  const Sat* single = nullptr;  // the only SAT when it covers the whole array: no search, no fill
  double single_perf = 1.0;
  std::vector<double> prefix;  // prefix[i] = sum of the coefficients of nodes [0, i)
  Rect* out;
  int32_t parallel_min_nodes;

  double weight(const Rect& r, bool by_area) const {
    if (by_area) return double(r.area());
    if (single) return single_perf * double(single->cost_inside(r));
    return sats->cost(r);
  }

  // The first side of t cut at line s along axis.
  static Rect first_side(const Rect& t, Axis axis, int32_t s) {
    return axis == Axis::x ? Rect{t.x0, t.y0, s, t.y1} : Rect{t.x0, t.y0, t.x1, s};
  }
  static Rect second_side(const Rect& t, Axis axis, int32_t s) {
    return axis == Axis::x ? Rect{s, t.y0, t.x1, t.y1} : Rect{t.x0, s, t.x1, t.y1};
  }

  // The first s in [lo0, hi0] with w(s) >= target, where w(s) = weight(first_side(t, axis, s))
  // is monotone, w(lo0) = 0 and w(hi0) = t_weight >= target; *w_s = w(s) and, for s > lo0,
  // *w_before = w(s - 1).
  int32_t find_line(const Rect& t, Axis axis, int32_t lo0, int32_t hi0, double target, double t_weight, bool by_area,
                    double& w_s, double& w_before) const {
    if (!(target > 0)) {  // w(lo0) = 0 already reaches it
      w_s = 0;
      return lo0;
    }
    // Bisection with the invariant w(lo) < target <= w(hi): when it ends, hi - lo = 1 and both
    // weights the split needs are known, none asked twice. (Interpolating the guess from the
    // bracket's weights was measured slower: docs/load-balancing.md.)
    int32_t lo = lo0, hi = hi0;
    double wlo = 0, whi = t_weight;
    while (hi - lo > 1) {
      const int32_t mid = lo + (hi - lo) / 2;
      const double wm = weight(first_side(t, axis, mid), by_area);
      if (wm >= target) {
        hi = mid;
        whi = wm;
      } else {
        lo = mid;
        wlo = wm;
      }
    }
    w_s = whi;
    w_before = wlo;
    return hi;
  }

  void run(const Rect& t, int32_t a, int32_t b, Axis axis, double t_weight, bool by_area) const {
    const int32_t n = b - a;
    if (t.empty()) {
      for (int32_t i = a; i < b; ++i) out[i] = Rect{};
      return;
    }
    if (n == 1) {
      out[a] = t;
      return;
    }
    // A zero-cost tile (and everything in it) is split by area.
    if (!by_area && !(t_weight > 0)) {
      by_area = true;
      t_weight = double(t.area());
    }
    // Halve the nodes; an odd extra node goes where the coefficient sums come closest.
    int32_t m = a + n / 2;
    if (n % 2 == 1) {
      const int32_t m2 = m + 1;
      const double d1 = std::fabs((prefix[m] - prefix[a]) - (prefix[b] - prefix[m]));
      const double d2 = std::fabs((prefix[m2] - prefix[a]) - (prefix[b] - prefix[m2]));
      if (d2 < d1) m = m2;
    }
    const double left_coef = prefix[m] - prefix[a], all_coef = prefix[b] - prefix[a];
    const double frac = left_coef / all_coef;
    // A tile one packet thick is cut across its other axis.
    if (axis == Axis::x && t.width() < 2 && t.height() >= 2) axis = Axis::y;
    if (axis == Axis::y && t.height() < 2 && t.width() >= 2) axis = Axis::x;
    const int32_t lo0 = axis == Axis::x ? t.x0 : t.y0, hi0 = axis == Axis::x ? t.x1 : t.y1;

    // The first line s with weight(first side) >= target, then the nearer of s and s - 1. The
    // first side's weight is monotone in s, 0 at lo0 and t_weight at hi0.
    const double target = frac * t_weight;
    double w_first = 0, w_prev = 0;
    int32_t s = find_line(t, axis, lo0, hi0, target, t_weight, by_area, w_first, w_prev);
    if (s > lo0) {
      const double d_prev = target - w_prev, d_s = w_first - target;
      bool take_prev = d_prev < d_s;
      if (d_prev == d_s) {
        // Tie: keep both sides non-empty, else stay nearer the area-proportional line.
        const bool s_inner = s > lo0 && s < hi0, prev_inner = s - 1 > lo0;
        const double area_line = lo0 + frac * double(hi0 - lo0);
        take_prev = prev_inner != s_inner ? prev_inner : std::fabs(s - 1 - area_line) < std::fabs(s - area_line);
      }
      if (take_prev) {
        --s;
        w_first = w_prev;
      }
    }
    const Rect first = first_side(t, axis, s), second = second_side(t, axis, s);
    const double w_second = s == lo0 ? t_weight : weight(second, by_area);
    const Axis next = axis == Axis::x ? Axis::y : Axis::x;
    if (parallel_min_nodes > 0 && n >= parallel_min_nodes) {
      tbb::parallel_invoke([&] { run(first, a, m, next, w_first, by_area); },
                           [&] { run(second, m, b, next, w_second, by_area); });
    } else {
      run(first, a, m, next, w_first, by_area);
      run(second, m, b, next, w_second, by_area);
    }
  }
};

}  // namespace

std::vector<double> renderer_coefficients(const std::vector<NodeCoefficient>& nodes) {
  std::vector<double> c;
  c.reserve(nodes.size());
  for (size_t i = 0; i < nodes.size(); ++i) {
    const NodeCoefficient& n = nodes[i];
    if (n.logical_cores < 1 || !(std::isfinite(n.single_core_perf) && n.single_core_perf > 0)) {
      std::ostringstream os;
      os << "renderer_coefficients: node " << i << " has " << n.logical_cores
         << " logical cores and single-core performance coefficient " << n.single_core_perf
         << " (need >= 1 core and a finite coefficient > 0)";
      throw std::invalid_argument(os.str());
    }
    c.push_back(n.renderer());
  }
  return c;
}

std::vector<Rect> tile(const SatArray* sats, Rect packet_space, const std::vector<double>& coefficients,
                       const TilerOptions& options) {
  if (coefficients.empty()) throw std::invalid_argument("tile: no nodes (empty coefficient list)");
  if (coefficients.size() > size_t(INT32_MAX - 1)) throw std::invalid_argument("tile: too many nodes");
  Tiler t;
  t.prefix.resize(coefficients.size() + 1);
  t.prefix[0] = 0;
  for (size_t i = 0; i < coefficients.size(); ++i) {
    const double c = coefficients[i];
    if (!(std::isfinite(c) && c > 0)) {
      std::ostringstream os;
      os << "tile: renderer coefficient of node " << i << " is " << c << " (must be finite and > 0)";
      throw std::invalid_argument(os.str());
    }
    t.prefix[i + 1] = t.prefix[i] + c;
  }
  if (!std::isfinite(t.prefix.back())) throw std::invalid_argument("tile: the sum of the coefficients overflows");
  if (packet_space.x1 < packet_space.x0 || packet_space.y1 < packet_space.y0)
    throw std::invalid_argument("tile: invalid packet space rectangle");
  if (sats) {
    if (!sats->finalized()) throw std::invalid_argument("tile: SatArray::finalize() was not called");
    if (!sats->packet_space().contains(packet_space))
      throw std::invalid_argument("tile: packet space is not inside the SAT array's packet space");
  }
  std::vector<Rect> out(coefficients.size());
  t.sats = sats;
  if (sats && sats->size() == 1 && !sats->has_missing()) {
    t.single = &sats->entries()[0].sat;
    t.single_perf = sats->entries()[0].perf;
  }
  t.out = out.data();
  t.parallel_min_nodes = options.parallel_min_nodes;
  const bool by_area = sats == nullptr;
  const double w = by_area ? double(packet_space.area()) : sats->cost(packet_space);
  const Axis first = packet_space.height() > packet_space.width() ? Axis::y : Axis::x;
  t.run(packet_space, 0, int32_t(coefficients.size()), first, w, by_area);
  return out;
}

}  // namespace tessera
