#include "lb/tiler.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include <tbb/parallel_invoke.h>

namespace tessera {
namespace {

enum class Axis { x, y };

// The first side of t cut at line s along axis.
Rect first_side(const Rect& t, Axis axis, int32_t s) {
  return axis == Axis::x ? Rect{t.x0, t.y0, s, t.y1} : Rect{t.x0, t.y0, t.x1, s};
}
Rect second_side(const Rect& t, Axis axis, int32_t s) {
  return axis == Axis::x ? Rect{s, t.y0, t.x1, t.y1} : Rect{t.x0, s, t.x1, t.y1};
}

// Weights of the SAT array in general: normalised costs as doubles, each first side asked of
// SatArray::cost (or the area).
struct ArrayWeights {
  using W = double;
  const SatArray* sats;
  W weight(const Rect& r, bool by_area) const { return by_area ? double(r.area()) : sats->cost(r); }
  static double value(W w, bool) { return w; }
  W area(const Rect& r) const { return double(r.area()); }
  W second(W, W, const Rect& second, bool by_area) const { return weight(second, by_area); }
  template <class F>
  void with_line(const Rect& t, Axis axis, bool by_area, F&& f) const {
    f([&](int32_t s) { return weight(first_side(t, axis, s), by_area); });
  }
};

// One SAT covering the whole array (the common case of one node's map, and 50,000-task
// tilings): integer weights read straight from the padded table. A split's first side
// along x is (row y1 - row y0) at column s less the same at the tile's left edge, two loads
// per probe with the tile's rows fixed; the second side is the tile's weight less the first
// (exact in integers), so no query at all. Doubles are the generic path's exactly (perf x
// cost), so both paths give the same tiling.
struct SingleWeights {
  using W = uint64_t;
  const uint64_t* table;
  size_t stride;
  int32_t ox, oy;
  double perf;
  uint64_t at(int32_t x, int32_t y) const { return table[size_t(y - oy) * stride + size_t(x - ox)]; }
  W weight(const Rect& r, bool by_area) const {
    if (by_area) return uint64_t(r.area());
    return at(r.x1, r.y1) - at(r.x0, r.y1) - at(r.x1, r.y0) + at(r.x0, r.y0);
  }
  // Through int64: the same double for every weight below 2^63 ns (292 years of core time),
  // and a single instruction where the unsigned conversion takes a branch and several.
  double value(W w, bool by_area) const {
    const double d = double(int64_t(w));
    return by_area ? d : perf * d;
  }
  W area(const Rect& r) const { return uint64_t(r.area()); }
  static W second(W total, W first, const Rect&, bool) { return total - first; }
  template <class F>
  void with_line(const Rect& t, Axis axis, bool by_area, F&& f) const {
    if (by_area) {
      const uint64_t thick = uint64_t(axis == Axis::x ? t.height() : t.width());
      const int32_t lo = axis == Axis::x ? t.x0 : t.y0;
      f([=](int32_t s) { return uint64_t(s - lo) * thick; });
    } else if (axis == Axis::x) {
      const uint64_t* r0 = table + size_t(t.y0 - oy) * stride;  // rows y0 and y1, indexed by s - ox
      const uint64_t* r1 = table + size_t(t.y1 - oy) * stride;
      const int32_t o = ox;
      const uint64_t edge = r1[t.x0 - o] - r0[t.x0 - o];
      f([=](int32_t s) { return (r1[s - o] - r0[s - o]) - edge; });
    } else {
      const uint64_t* c0 = table + size_t(t.x0 - ox);  // columns x0 and x1, indexed by (s - oy) x stride
      const uint64_t* c1 = table + size_t(t.x1 - ox);
      const size_t st = stride;
      const int32_t o = oy;
      const uint64_t edge = c1[size_t(t.y0 - o) * st] - c0[size_t(t.y0 - o) * st];
      f([=](int32_t s) { return (c1[size_t(s - o) * st] - c0[size_t(s - o) * st]) - edge; });
    }
  }
};

template <class Weights>
struct Tiler {
  using W = typename Weights::W;
  Weights wts;
  const std::vector<double>* prefix;  // prefix[i] = sum of the coefficients of nodes [0, i)
  Rect* out;
  int32_t parallel_min_nodes;

  struct Split {
    Rect first, second;
    int32_t m;
    W w_first, w_second;
    Axis next;
    bool by_area;
  };

  // Tiles [a, b) over t: in parallel while it holds parallel_min_nodes nodes, then serially.
  // (Two functions so that the serial recursion, which makes nearly all the calls, carries
  // no TBB task frame.)
  void run(const Rect& t, int32_t a, int32_t b, Axis axis, W t_w, bool by_area) const {
    if (!(parallel_min_nodes > 0 && b - a >= parallel_min_nodes)) return serial(t, a, b, axis, t_w, by_area);
    if (leaf(t, a, b)) return;
    const Split sp = split(t, a, b, axis, t_w, by_area);
    tbb::parallel_invoke([&] { run(sp.first, a, sp.m, sp.next, sp.w_first, sp.by_area); },
                         [&] { run(sp.second, sp.m, b, sp.next, sp.w_second, sp.by_area); });
  }
  void serial(const Rect& t, int32_t a, int32_t b, Axis axis, W t_w, bool by_area) const {
    if (leaf(t, a, b)) return;
    const Split sp = split(t, a, b, axis, t_w, by_area);
    // Half of all tiles hold one node: written here rather than by a call.
    if (sp.m - a == 1) out[a] = sp.first.empty() ? Rect{} : sp.first;
    else serial(sp.first, a, sp.m, sp.next, sp.w_first, sp.by_area);
    if (b - sp.m == 1) out[sp.m] = sp.second.empty() ? Rect{} : sp.second;
    else serial(sp.second, sp.m, b, sp.next, sp.w_second, sp.by_area);
  }
  // An empty tile or a single node: the tasks are written, nothing to split.
  bool leaf(const Rect& t, int32_t a, int32_t b) const {
    if (t.empty()) {
      for (int32_t i = a; i < b; ++i) out[i] = Rect{};
      return true;
    }
    if (b - a == 1) {
      out[a] = t;
      return true;
    }
    return false;
  }

  // One split of t (not empty, at least two nodes [a, b)).
  Split split(const Rect& t, int32_t a, int32_t b, Axis axis, W t_w, bool by_area) const {
    const int32_t n = b - a;
    // A zero-cost tile (and everything in it) is split by area.
    if (!by_area && !(wts.value(t_w, false) > 0)) {
      by_area = true;
      t_w = wts.area(t);
    }
    const double t_weight = wts.value(t_w, by_area);
    // Halve the nodes; an odd extra node goes where the coefficient sums come closest.
    const std::vector<double>& pre = *prefix;
    int32_t m = a + n / 2;
    if (n % 2 == 1) {
      const int32_t m2 = m + 1;
      const double d1 = std::fabs((pre[m] - pre[a]) - (pre[b] - pre[m]));
      const double d2 = std::fabs((pre[m2] - pre[a]) - (pre[b] - pre[m2]));
      if (d2 < d1) m = m2;
    }
    const double left_coef = pre[m] - pre[a], all_coef = pre[b] - pre[a];
    const double frac = left_coef / all_coef;
    // A tile one packet thick is cut across its other axis.
    if (axis == Axis::x && t.width() < 2 && t.height() >= 2) axis = Axis::y;
    if (axis == Axis::y && t.height() < 2 && t.width() >= 2) axis = Axis::x;
    const int32_t lo0 = axis == Axis::x ? t.x0 : t.y0, hi0 = axis == Axis::x ? t.x1 : t.y1;

    // The first line s with weight(first side) >= target, then the nearer of s and s - 1. The
    // first side's weight w(s) is monotone in s, 0 at lo0 and t_weight at hi0. Bisection with
    // the invariant w(lo) < target <= w(hi): when it ends, hi - lo = 1 and both weights the
    // split needs are known, none asked twice. (Interpolating the guess from the bracket's
    // weights was measured slower: docs/load-balancing.md.)
    const double target = frac * t_weight;
    int32_t s = lo0;
    W w_first{};
    if (target > 0) {
      int32_t lo = lo0, hi = hi0;
      W wlo{}, whi = t_w;
      wts.with_line(t, axis, by_area, [&](auto&& w_of) {
        while (hi - lo > 1) {
          const int32_t mid = lo + (hi - lo) / 2;
          const W wm = w_of(mid);
          if (wts.value(wm, by_area) >= target) {
            hi = mid;
            whi = wm;
          } else {
            lo = mid;
            wlo = wm;
          }
        }
      });
      s = hi;
      w_first = whi;
      const double w_prev = wts.value(wlo, by_area), w_s = wts.value(whi, by_area);
      const double d_prev = target - w_prev, d_s = w_s - target;
      bool take_prev = d_prev < d_s;
      if (d_prev == d_s) {
        // Tie: keep both sides non-empty, else stay nearer the area-proportional line.
        const bool s_inner = s > lo0 && s < hi0, prev_inner = s - 1 > lo0;
        const double area_line = lo0 + frac * double(hi0 - lo0);
        take_prev = prev_inner != s_inner ? prev_inner : std::fabs(s - 1 - area_line) < std::fabs(s - area_line);
      }
      if (take_prev) {
        --s;
        w_first = wlo;
      }
    }
    const Rect first = first_side(t, axis, s), second = second_side(t, axis, s);
    const W w_second = s == lo0 ? t_w : wts.second(t_w, w_first, second, by_area);
    return Split{first, second, m, w_first, w_second, axis == Axis::x ? Axis::y : Axis::x, by_area};
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
  std::vector<double> prefix(coefficients.size() + 1);
  prefix[0] = 0;
  for (size_t i = 0; i < coefficients.size(); ++i) {
    const double c = coefficients[i];
    if (!(std::isfinite(c) && c > 0)) {
      std::ostringstream os;
      os << "tile: renderer coefficient of node " << i << " is " << c << " (must be finite and > 0)";
      throw std::invalid_argument(os.str());
    }
    prefix[i + 1] = prefix[i] + c;
  }
  if (!std::isfinite(prefix.back())) throw std::invalid_argument("tile: the sum of the coefficients overflows");
  if (packet_space.x1 < packet_space.x0 || packet_space.y1 < packet_space.y0)
    throw std::invalid_argument("tile: invalid packet space rectangle");
  if (sats) {
    if (!sats->finalized()) throw std::invalid_argument("tile: SatArray::finalize() was not called");
    if (!sats->packet_space().contains(packet_space))
      throw std::invalid_argument("tile: packet space is not inside the SAT array's packet space");
  }
  std::vector<Rect> out(coefficients.size());
  const int32_t n = int32_t(coefficients.size());
  const Axis first = packet_space.height() > packet_space.width() ? Axis::y : Axis::x;
  if (sats && sats->size() == 1 && !sats->has_missing()) {
    const auto& e = sats->entries()[0];
    const Rect& p = e.sat.packets();
    Tiler<SingleWeights> t{SingleWeights{e.sat.table(), e.sat.stride(), p.x0, p.y0, e.perf}, &prefix, out.data(),
                           options.parallel_min_nodes};
    t.run(packet_space, 0, n, first, t.wts.weight(packet_space, false), false);
  } else {
    Tiler<ArrayWeights> t{ArrayWeights{sats}, &prefix, out.data(), options.parallel_min_nodes};
    const bool by_area = sats == nullptr;
    t.run(packet_space, 0, n, first, by_area ? double(packet_space.area()) : sats->cost(packet_space), by_area);
  }
  return out;
}

}  // namespace tessera
