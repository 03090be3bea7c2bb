// The tiler against brute force: exact cover, one task per node, and the balance bound.
//
// Balance bound asserted (see docs/load-balancing.md): with C the normalised cost of the
// packet space, S the sum of all coefficients and L the largest normalised cost of one full
// packet row or column of the image, node i with coefficient c_i gets a task of cost C_i with
//     |C_i - c_i C / S| <= (L / 2) * c_i * sum_k 1 / S_k  (+ 1e-9 C for rounding)
// where S_k runs over the coefficient sums of the tiles on the path from the root's child
// down to node i's leaf (S_leaf = c_i). Each split misses its target by at most half of the
// packet line the ideal split falls into. For N homogeneous nodes the right-hand side is
// < 1.14 L, and < L when N is a power of two.
#include <catch2/catch.hpp>

#include <chrono>
#include <cmath>
#include <random>

#include <tbb/task_arena.h>

#include "lb/tiler.h"

using tessera::CostMap;
using tessera::Rect;
using tessera::Sat;
using tessera::SatArray;
using tessera::tile;

namespace {

// Dense normalised per-packet costs of a packet space starting at (0, 0).
struct Field {
  int32_t w = 0, h = 0;
  std::vector<double> v;
  double at(int32_t x, int32_t y) const { return v[size_t(y) * size_t(w) + size_t(x)]; }
  double sum(const Rect& r) const {
    double s = 0;
    for (int32_t y = r.y0; y < r.y1; ++y)
      for (int32_t x = r.x0; x < r.x1; ++x) s += at(x, y);
    return s;
  }
  double max_line() const {
    double m = 0;
    for (int32_t y = 0; y < h; ++y) m = std::max(m, sum({0, y, w, y + 1}));
    for (int32_t x = 0; x < w; ++x) m = std::max(m, sum({x, 0, x + 1, h}));
    return m;
  }
};

enum class Kind { smooth, spiky, zero, hot };

CostMap make_map(std::mt19937_64& rng, Rect space, Kind kind) {
  CostMap m{space, std::vector<uint32_t>(size_t(space.area()), 0)};
  if (kind == Kind::zero) return m;
  if (kind == Kind::hot) {
    m.cost[rng() % m.cost.size()] = 4000000000u;
    return m;
  }
  std::uniform_real_distribution<double> u(0, 1);
  struct Blob {
    double x, y, r, a;
  };
  std::vector<Blob> blobs;
  for (int i = 0; i < 5; ++i)
    blobs.push_back({u(rng) * space.x1, u(rng) * space.y1, (0.05 + 0.3 * u(rng)) * (space.x1 + space.y1), 20000 * u(rng)});
  const double base = 200 + 2000 * u(rng);
  for (int32_t y = 0; y < space.y1; ++y)
    for (int32_t x = 0; x < space.x1; ++x) {
      double c = base * (1 + 0.5 * double(x) / space.x1);
      for (const Blob& b : blobs) {
        const double d2 = ((x - b.x) * (x - b.x) + (y - b.y) * (y - b.y)) / (b.r * b.r);
        c += b.a * std::exp(-d2);
      }
      if (kind == Kind::spiky) {
        c *= 0.5 + u(rng);
        if (u(rng) < 0.01) c += 1e6 * u(rng);  // hot packets: reflections, refraction
      }
      m.cost[size_t(y) * space.x1 + x] = uint32_t(c);
    }
  return m;
}

CostMap sub_map(const CostMap& m, const Rect& r) {
  CostMap s{r, {}};
  for (int32_t y = r.y0; y < r.y1; ++y)
    for (int32_t x = r.x0; x < r.x1; ++x) s.cost.push_back(m.at(x, y));
  return s;
}

// The SAT array of a frame rendered with the given per-node tasks; node i's timings are
// its measured time, i.e. the normalised cost divided by its single-core coefficient, and
// `missing` nodes do not report. Returns the normalised field the array should answer.
Field make_frame(const CostMap& truth, const std::vector<Rect>& tasks, const std::vector<double>& perf,
                 const std::vector<bool>& missing, SatArray& array) {
  const Rect space = truth.packets;
  Field f{space.x1, space.y1, std::vector<double>(size_t(space.area()), -1)};
  double known = 0;
  int64_t known_area = 0;
  for (size_t i = 0; i < tasks.size(); ++i) {
    if (tasks[i].empty() || missing[i]) continue;
    CostMap m = sub_map(truth, tasks[i]);
    for (auto& c : m.cost) c = uint32_t(std::llround(c / perf[i]));
    for (int32_t y = tasks[i].y0; y < tasks[i].y1; ++y)
      for (int32_t x = tasks[i].x0; x < tasks[i].x1; ++x) {
        const double v = double(m.at(x, y)) * perf[i];
        f.v[size_t(y) * f.w + x] = v;
        known += v;
      }
    known_area += tasks[i].area();
    array.add(Sat::from_cost_map(m), perf[i]);
  }
  array.finalize();
  const double density = known_area > 0 && known > 0 ? known / double(known_area) : 1.0;
  for (double& v : f.v)
    if (v < 0) v = density;
  return f;
}

// Every packet in exactly one task, every task inside the space, one task per node.
void require_exact_cover(const std::vector<Rect>& tasks, const Rect& space, size_t nodes) {
  REQUIRE(tasks.size() == nodes);
  std::vector<int> hits(size_t(space.area()), 0);
  for (const Rect& t : tasks) {
    if (t.empty()) continue;
    REQUIRE(space.contains(t));
    for (int32_t y = t.y0; y < t.y1; ++y)
      for (int32_t x = t.x0; x < t.x1; ++x) ++hits[size_t(y - space.y0) * space.width() + size_t(x - space.x0)];
  }
  for (int h : hits) REQUIRE(h == 1);
}

// The tiler's node partition, reimplemented: c_i * sum_k 1/S_k along node i's path.
void path_weights(const std::vector<double>& c, size_t a, size_t b, double acc, std::vector<double>& out) {
  auto sum = [&](size_t p, size_t q) {
    double s = 0;
    for (size_t i = p; i < q; ++i) s += c[i];
    return s;
  };
  const size_t n = b - a;
  if (n == 1) {
    out[a] = c[a] * (acc + 1 / c[a]);
    return;
  }
  size_t m = a + n / 2;
  if (n % 2 && std::fabs(sum(a, m + 1) - sum(m + 1, b)) < std::fabs(sum(a, m) - sum(m, b))) ++m;
  path_weights(c, a, m, m - a > 1 ? acc + 1 / sum(a, m) : acc, out);
  path_weights(c, m, b, b - m > 1 ? acc + 1 / sum(m, b) : acc, out);
}

// Asserts the balance bound; returns the worst |C_i - ideal_i| / L seen.
double require_balanced(const std::vector<Rect>& tasks, const Field& f, const std::vector<double>& coef) {
  const double total = f.sum({0, 0, f.w, f.h}), line = f.max_line();
  double csum = 0;
  for (double c : coef) csum += c;
  std::vector<double> pw(coef.size());
  path_weights(coef, 0, coef.size(), 0, pw);
  double worst = 0;
  for (size_t i = 0; i < tasks.size(); ++i) {
    const double got = f.sum(tasks[i]), ideal = coef[i] / csum * total;
    const double bound = line / 2 * pw[i] + 1e-9 * total;
    INFO("node " << i << " of " << tasks.size() << ": cost " << got << ", ideal " << ideal << ", bound " << bound
                 << ", max line " << line);
    REQUIRE(std::fabs(got - ideal) <= bound);
    if (line > 0) worst = std::max(worst, std::fabs(got - ideal) / line);
  }
  return worst;
}

Field area_field(const Rect& space) {
  return Field{space.x1, space.y1, std::vector<double>(size_t(space.area()), 1.0)};
}

std::vector<double> random_coefficients(std::mt19937_64& rng, size_t n, bool heterogeneous) {
  std::vector<double> c(n, 12.0);
  std::uniform_int_distribution<int> cores(1, 64);
  std::uniform_real_distribution<double> perf(1.0, 3.0);
  if (heterogeneous)
    for (auto& v : c) v = cores(rng) * perf(rng);
  return c;
}

}  // namespace

TEST_CASE("Four equal nodes on uniform cost get the quadrants in depth-first order", "[tiler]") {
  const Rect space{0, 0, 8, 8};
  const auto t = tile(nullptr, space, {1, 1, 1, 1});
  REQUIRE(t[0] == Rect{0, 0, 4, 4});
  REQUIRE(t[1] == Rect{0, 4, 4, 8});
  REQUIRE(t[2] == Rect{4, 0, 8, 4});
  REQUIRE(t[3] == Rect{4, 4, 8, 8});
  // A tall image is cut across y first.
  const auto tall = tile(nullptr, {0, 0, 4, 10}, {1, 1});
  REQUIRE(tall[0] == Rect{0, 0, 4, 5});
  REQUIRE(tall[1] == Rect{0, 5, 4, 10});
}

TEST_CASE("An odd node goes to the side that brings the coefficient sums closest", "[tiler]") {
  const Rect space{0, 0, 12, 12};
  // {1,1,3}: sides {1,1}|{3} (2 vs 3) beat {1}|{1,3} (1 vs 4): the first cut is at 12 * 2/5.
  auto t = tile(nullptr, space, {1, 1, 3});
  REQUIRE(t[2] == Rect{5, 0, 12, 12});
  // {3,1,1}: {3}|{1,1}.
  t = tile(nullptr, space, {3, 1, 1});
  REQUIRE(t[0] == Rect{0, 0, 7, 12});
  // {1,1,1}: a tie keeps the extra node on the second side: {1}|{1,1}.
  t = tile(nullptr, space, {1, 1, 1});
  REQUIRE(t[0] == Rect{0, 0, 4, 12});
}

TEST_CASE("Tilings cover the packet space exactly with one task per node", "[tiler]") {
  std::mt19937_64 rng(11);
  for (int iter = 0; iter < 150; ++iter) {
    const Rect space{0, 0, 1 + int32_t(rng() % 90), 1 + int32_t(rng() % 60)};
    const size_t nodes = iter % 10 == 0 ? 1 + rng() % 3000 : 1 + rng() % 40;
    const auto coef = random_coefficients(rng, nodes, iter % 2);
    const auto kind = Kind(iter % 4);
    const CostMap truth = make_map(rng, space, kind);
    SatArray array(space);
    std::vector<bool> missing(nodes, false);
    for (size_t i = 0; i < nodes; ++i) missing[i] = rng() % 7 == 0;
    const auto prev = tile(nullptr, space, coef);
    require_exact_cover(prev, space, nodes);
    make_frame(truth, prev, std::vector<double>(nodes, 1.0), missing, array);
    require_exact_cover(tile(&array, space, coef), space, nodes);
  }
}

TEST_CASE("Tasks are balanced on smooth and spiky cost maps with homogeneous nodes", "[tiler][stability]") {
  std::mt19937_64 rng(12);
  double worst_pow2 = 0, worst_any = 0;
  for (int iter = 0; iter < 120; ++iter) {
    const Rect space{0, 0, 20 + int32_t(rng() % 140), 10 + int32_t(rng() % 80)};
    const size_t nodes = 1 + rng() % 24;
    const std::vector<double> coef(nodes, 12.0);
    const CostMap truth = make_map(rng, space, iter % 2 ? Kind::spiky : Kind::smooth);
    SatArray array(space);
    const Field f = make_frame(truth, tile(nullptr, space, coef), std::vector<double>(nodes, 1.0),
                               std::vector<bool>(nodes, false), array);
    const auto tasks = tile(&array, space, coef);
    require_exact_cover(tasks, space, nodes);
    const double w = require_balanced(tasks, f, coef);
    worst_any = std::max(worst_any, w);
    if ((nodes & (nodes - 1)) == 0) worst_pow2 = std::max(worst_pow2, w);
  }
  // The closed forms of the bound for homogeneous nodes.
  REQUIRE(worst_pow2 < 1.0);
  REQUIRE(worst_any < 1.14);
}

TEST_CASE("Tasks are balanced with heterogeneous nodes and per-node performance", "[tiler][stability]") {
  std::mt19937_64 rng(13);
  for (int iter = 0; iter < 120; ++iter) {
    const Rect space{0, 0, 20 + int32_t(rng() % 140), 10 + int32_t(rng() % 80)};
    const size_t nodes = 1 + rng() % 24;
    std::vector<tessera::NodeCoefficient> spec(nodes);
    for (auto& n : spec) n = {1 + int32_t(rng() % 32), 1.0 + double(rng() % 2000) / 1000.0};
    const auto coef = tessera::renderer_coefficients(spec);
    std::vector<double> perf(nodes);
    for (size_t i = 0; i < nodes; ++i) perf[i] = spec[i].single_core_perf;
    std::vector<bool> missing(nodes, false);
    if (iter % 3 == 0) missing[rng() % nodes] = true;
    const CostMap truth = make_map(rng, space, iter % 2 ? Kind::spiky : Kind::smooth);
    SatArray array(space);
    // Last frame's tasks came from a different coefficient order, as after a node joined.
    auto shuffled = coef;
    std::shuffle(shuffled.begin(), shuffled.end(), rng);
    const Field f = make_frame(truth, tile(nullptr, space, shuffled), perf, missing, array);
    const auto tasks = tile(&array, space, coef);
    require_exact_cover(tasks, space, nodes);
    require_balanced(tasks, f, coef);
  }
}

TEST_CASE("Without cost data, or with all-zero costs, tasks are split by area", "[tiler]") {
  std::mt19937_64 rng(14);
  for (int iter = 0; iter < 60; ++iter) {
    const Rect space{0, 0, 1 + int32_t(rng() % 100), 1 + int32_t(rng() % 60)};
    const size_t nodes = 1 + rng() % 30;
    const auto coef = random_coefficients(rng, nodes, iter % 2);
    const auto by_area = tile(nullptr, space, coef);
    require_exact_cover(by_area, space, nodes);
    require_balanced(by_area, area_field(space), coef);
    SatArray zero(space);
    make_frame(make_map(rng, space, Kind::zero), by_area, std::vector<double>(nodes, 1.0),
               std::vector<bool>(nodes, false), zero);
    REQUIRE(zero.total() == 0);
    REQUIRE(tile(&zero, space, coef) == by_area);
  }
}

TEST_CASE("One hot packet holding all the cost goes to one task; the others still get area", "[tiler][stability]") {
  std::mt19937_64 rng(15);
  for (int iter = 0; iter < 50; ++iter) {
    const Rect space{0, 0, 16 + int32_t(rng() % 100), 16 + int32_t(rng() % 60)};
    const size_t nodes = 2 + rng() % 16;
    const std::vector<double> coef(nodes, 1.0);
    const CostMap truth = make_map(rng, space, Kind::hot);
    SatArray array(space);
    const Field f = make_frame(truth, tile(nullptr, space, coef), std::vector<double>(nodes, 1.0),
                               std::vector<bool>(nodes, false), array);
    const auto tasks = tile(&array, space, coef);
    require_exact_cover(tasks, space, nodes);
    require_balanced(tasks, f, coef);
    int holders = 0;
    for (const Rect& t : tasks) holders += f.sum(t) > 0;
    REQUIRE(holders == 1);
  }
}

TEST_CASE("More nodes than packets: every packet is one task, the rest are empty", "[tiler]") {
  for (const Rect space : {Rect{0, 0, 3, 2}, Rect{0, 0, 1, 1}, Rect{0, 0, 1, 5}, Rect{0, 0, 7, 1}}) {
    for (size_t nodes : {size_t(7), size_t(10), size_t(64)}) {
      const auto tasks = tile(nullptr, space, std::vector<double>(nodes, 1.0));
      require_exact_cover(tasks, space, nodes);
      size_t non_empty = 0;
      for (const Rect& t : tasks) {
        non_empty += !t.empty();
        if (!t.empty()) REQUIRE(t.area() == 1);
      }
      REQUIRE(non_empty == size_t(std::min<int64_t>(space.area(), int64_t(nodes))));
    }
  }
  REQUIRE(tile(nullptr, {0, 0, 0, 0}, {1, 1}) == std::vector<Rect>{Rect{}, Rect{}});
}

TEST_CASE("One node gets the whole packet space", "[tiler]") {
  const Rect space{0, 0, 640, 360};
  REQUIRE(tile(nullptr, space, {3.5}) == std::vector<Rect>{space});
  SatArray none(space);
  none.finalize();
  REQUIRE(tile(&none, space, {1.0}) == std::vector<Rect>{space});
  // A sub-rectangle of the array's space (a hub tiling its share).
  REQUIRE(tile(&none, Rect{10, 20, 30, 40}, {1.0}) == std::vector<Rect>{Rect{10, 20, 30, 40}});
}

TEST_CASE("A thousand nodes on a 720p frame in 2x2 packets are balanced", "[tiler][stability]") {
  std::mt19937_64 rng(16);
  const Rect space{0, 0, 640, 360};
  const size_t nodes = 1000;
  const std::vector<double> coef(nodes, 1.0);
  const CostMap truth = make_map(rng, space, Kind::spiky);
  SatArray array(space);
  const Field f = make_frame(truth, tile(nullptr, space, std::vector<double>(20, 1.0)), std::vector<double>(20, 1.0),
                             std::vector<bool>(20, false), array);
  const auto tasks = tile(&array, space, coef);
  require_exact_cover(tasks, space, nodes);
  require_balanced(tasks, f, coef);
  for (const Rect& t : tasks) REQUIRE_FALSE(t.empty());
}

TEST_CASE("Coefficient ratios of 1:1000 are honoured", "[tiler][stability]") {
  std::mt19937_64 rng(17);
  const Rect space{0, 0, 320, 180};
  const CostMap truth = make_map(rng, space, Kind::smooth);
  for (const auto& coef : {std::vector<double>{1, 1000}, std::vector<double>{1000, 1},
                           std::vector<double>{1, 1000, 1, 1000, 1}, std::vector<double>{0.001, 1}}) {
    SatArray array(space);
    const Field f = make_frame(truth, tile(nullptr, space, {1, 1}), {1, 1}, {false, false}, array);
    const auto tasks = tile(&array, space, coef);
    require_exact_cover(tasks, space, coef.size());
    require_balanced(tasks, f, coef);
  }
}

TEST_CASE("A one-packet-wide image is cut along its length", "[tiler]") {
  std::mt19937_64 rng(18);
  for (const Rect space : {Rect{0, 0, 1, 360}, Rect{0, 0, 640, 1}}) {
    const CostMap truth = make_map(rng, space, Kind::spiky);
    for (size_t nodes : {size_t(2), size_t(8), size_t(13)}) {
      const std::vector<double> coef(nodes, 1.0);
      SatArray array(space);
      const Field f = make_frame(truth, tile(nullptr, space, coef), coef, std::vector<bool>(nodes, false), array);
      const auto tasks = tile(&array, space, coef);
      require_exact_cover(tasks, space, nodes);
      require_balanced(tasks, f, coef);
      for (const Rect& t : tasks) REQUIRE_FALSE(t.empty());
    }
  }
}

TEST_CASE("Missing SATs count with the mean known cost density", "[tiler][stability]") {
  std::mt19937_64 rng(19);
  const Rect space{0, 0, 160, 90};
  for (int iter = 0; iter < 20; ++iter) {
    const size_t nodes = 4 + rng() % 12;
    const std::vector<double> coef(nodes, 1.0);
    std::vector<bool> missing(nodes, false);
    for (int k = 0; k < 1 + iter % 3; ++k) missing[rng() % nodes] = true;
    SatArray array(space);
    const Field f = make_frame(make_map(rng, space, Kind::smooth), tile(nullptr, space, coef),
                               std::vector<double>(nodes, 1.0), missing, array);
    REQUIRE(array.has_missing());
    const auto tasks = tile(&array, space, coef);
    require_exact_cover(tasks, space, nodes);
    require_balanced(tasks, f, coef);
  }
}

TEST_CASE("Invalid coefficients and inputs are rejected with a clear error", "[tiler]") {
  const Rect space{0, 0, 10, 10};
  REQUIRE_THROWS_AS(tile(nullptr, space, {}), std::invalid_argument);
  for (double bad : {0.0, -1.0, std::nan(""), HUGE_VAL, -HUGE_VAL}) {
    REQUIRE_THROWS_AS(tile(nullptr, space, {1.0, bad}), std::invalid_argument);
    REQUIRE_THROWS_WITH(tile(nullptr, space, {1.0, 1.0, bad}),
                        Catch::Contains("node 2") && Catch::Contains("finite and > 0"));
  }
  REQUIRE_THROWS_AS(tile(nullptr, space, {1e308, 1e308}), std::invalid_argument);
  REQUIRE_THROWS_AS(tessera::renderer_coefficients({{0, 1.0}}), std::invalid_argument);
  REQUIRE_THROWS_AS(tessera::renderer_coefficients({{4, -2.0}}), std::invalid_argument);
  REQUIRE(tessera::renderer_coefficients({{12, 1.5}, {4, 2.0}}) == std::vector<double>{18.0, 8.0});
  SatArray unfinished(space);
  REQUIRE_THROWS_AS(tile(&unfinished, space, {1.0}), std::invalid_argument);
  unfinished.finalize();
  REQUIRE_THROWS_AS(tile(&unfinished, Rect{0, 0, 11, 10}, {1.0}), std::invalid_argument);
}

TEST_CASE("Parallel tiling of 50,000 tasks gives the same tasks as serial tiling", "[tiler]") {
  std::mt19937_64 rng(20);
  const Rect space{0, 0, 640, 360};
  SatArray array(space);
  make_frame(make_map(rng, space, Kind::smooth), {space}, {1.0}, {false}, array);
  const std::vector<double> coef(50000, 1.0);
  tessera::TilerOptions serial;
  serial.parallel_min_nodes = 0;
  tessera::TilerOptions parallel;
  parallel.parallel_min_nodes = 64;
  const auto a = tile(&array, space, coef, serial);
  std::vector<Rect> b;
  tbb::task_arena(2).execute([&] { b = tile(&array, space, coef, parallel); });
  REQUIRE(a == b);
  require_exact_cover(a, space, coef.size());
}

TEST_CASE("One SAT or many SATs of the same cost map give the same tiling", "[tiler]") {
  std::mt19937_64 rng(21);
  const Rect space{0, 0, 200, 120};
  const CostMap truth = make_map(rng, space, Kind::spiky);
  SatArray one(space), many(space);
  make_frame(truth, {space}, {1.0}, {false}, one);
  const std::vector<double> split(17, 1.0);
  make_frame(truth, tile(nullptr, space, split), split, std::vector<bool>(17, false), many);
  REQUIRE(one.total() == many.total());
  for (size_t nodes : {size_t(2), size_t(7), size_t(64), size_t(3000)}) {
    const std::vector<double> coef(nodes, 1.0);
    REQUIRE(tile(&one, space, coef) == tile(&many, space, coef));
  }
}

TEST_CASE("Over a camera-like sequence each node keeps most of its area from frame to frame", "[tiler]") {
  // The cost field drifts by one packet per frame; each frame is tiled from the SATs the nodes
  // measured for the previous frame's tasks, as in the real pipeline.
  std::mt19937_64 rng(22);
  const Rect space{0, 0, 160, 90};
  const size_t nodes = 16;
  const std::vector<double> coef(nodes, 1.0);
  const CostMap base = make_map(rng, {0, 0, 260, 90}, Kind::smooth);
  std::vector<Rect> tasks = tile(nullptr, space, coef);
  double overlap_sum = 0;
  int frames = 0;
  for (int f = 0; f < 40; ++f) {
    CostMap truth{space, {}};
    for (int32_t y = 0; y < 90; ++y)
      for (int32_t x = 0; x < 160; ++x) truth.cost.push_back(base.at(x + f, y));
    SatArray array(space);
    make_frame(truth, tasks, coef, std::vector<bool>(nodes, false), array);
    const auto next = tile(&array, space, coef);
    require_exact_cover(next, space, nodes);
    if (f > 0) {  // frame 0 -> 1 moves from the area split to the cost split
      for (size_t i = 0; i < nodes; ++i)
        overlap_sum += double(tessera::intersect(tasks[i], next[i]).area()) / double(std::max(tasks[i].area(), next[i].area()));
      ++frames;
    }
    tasks = next;
  }
  const double mean_overlap = overlap_sum / (double(frames) * nodes);
  INFO("mean overlap " << mean_overlap);
  REQUIRE(mean_overlap > 0.9);
}
