// SAT and SAT array against brute force (pbrt's SummedAreaTable test style), and the SAT
// wire format's round trip and rejection of bad buffers.
#include <catch2/catch.hpp>

#include <cstring>
#include <random>

#include <tbb/task_arena.h>

#include "lb/sat.h"

using tessera::CostMap;
using tessera::Rect;
using tessera::Sat;
using tessera::SatArray;
using tessera::SatFormatError;

namespace {

CostMap random_map(std::mt19937_64& rng, Rect r, uint32_t max_cost) {
  CostMap m{r, std::vector<uint32_t>(size_t(r.area()))};
  std::uniform_int_distribution<uint32_t> d(0, max_cost);
  for (auto& c : m.cost) c = d(rng);
  return m;
}

uint64_t brute(const CostMap& m, const Rect& q) {
  const Rect r = tessera::intersect(q, m.packets);
  uint64_t s = 0;
  for (int32_t y = r.y0; y < r.y1; ++y)
    for (int32_t x = r.x0; x < r.x1; ++x) s += m.at(x, y);
  return s;
}

Rect random_rect(std::mt19937_64& rng, const Rect& in) {
  std::uniform_int_distribution<int32_t> dx(in.x0, in.x1), dy(in.y0, in.y1);
  int32_t a = dx(rng), b = dx(rng), c = dy(rng), d = dy(rng);
  return {std::min(a, b), std::min(c, d), std::max(a, b), std::max(c, d)};
}

// Random guillotine partition of r into about `parts` rectangles.
void partition(std::mt19937_64& rng, Rect r, int parts, std::vector<Rect>& out) {
  if (parts <= 1 || (r.width() < 2 && r.height() < 2)) {
    out.push_back(r);
    return;
  }
  const bool along_x = r.height() < 2 || (r.width() >= 2 && (rng() & 1));
  const int32_t lo = along_x ? r.x0 : r.y0, hi = along_x ? r.x1 : r.y1;
  const int32_t s = std::uniform_int_distribution<int32_t>(lo + 1, hi - 1)(rng);
  const int left = parts / 2;
  if (along_x) {
    partition(rng, {r.x0, r.y0, s, r.y1}, left, out);
    partition(rng, {s, r.y0, r.x1, r.y1}, parts - left, out);
  } else {
    partition(rng, {r.x0, r.y0, r.x1, s}, left, out);
    partition(rng, {r.x0, s, r.x1, r.y1}, parts - left, out);
  }
}

CostMap sub_map(const CostMap& m, const Rect& r) {
  CostMap s{r, {}};
  s.cost.reserve(size_t(r.area()));
  for (int32_t y = r.y0; y < r.y1; ++y)
    for (int32_t x = r.x0; x < r.x1; ++x) s.cost.push_back(m.at(x, y));
  return s;
}

}  // namespace

TEST_CASE("A SAT answers every rectangle of a small random cost map as a direct sum", "[sat]") {
  std::mt19937_64 rng(1);
  for (int iter = 0; iter < 30; ++iter) {
    std::uniform_int_distribution<int32_t> off(0, 50), ext(1, 11);
    const int32_t x0 = off(rng), y0 = off(rng);
    const Rect r{x0, y0, x0 + ext(rng), y0 + ext(rng)};
    const CostMap m = random_map(rng, r, iter % 2 ? 0xffffffffu : 1000u);
    const Sat s = Sat::from_cost_map(m);
    REQUIRE(s.packets() == r);
    REQUIRE(s.total() == m.total());
    // Every rectangle of the map, plus rectangles reaching outside it.
    for (int32_t ax = r.x0 - 1; ax <= r.x1; ++ax)
      for (int32_t bx = ax; bx <= r.x1 + 1; ++bx)
        for (int32_t ay = r.y0 - 1; ay <= r.y1; ++ay)
          for (int32_t by = ay; by <= r.y1 + 1; ++by) {
            const Rect q{ax, ay, bx, by};
            REQUIRE(s.cost(q) == brute(m, q));
          }
    for (int32_t y = r.y0; y < r.y1; ++y)
      for (int32_t x = r.x0; x < r.x1; ++x) REQUIRE(s.at(x, y) == brute(m, {r.x0, r.y0, x + 1, y + 1}));
  }
}

TEST_CASE("The parallel SAT equals the sequential one on large maps", "[sat]") {
  std::mt19937_64 rng(2);
  tbb::task_arena arena(2);
  for (const Rect r : {Rect{0, 0, 640, 360}, Rect{17, 5, 337, 185}, Rect{3, 0, 4, 40000}, Rect{0, 9, 30000, 10}}) {
    const CostMap m = random_map(rng, r, 0xffffffffu);
    const Sat serial = Sat::from_cost_map_serial(m);
    Sat parallel;
    arena.execute([&] { parallel = Sat::from_cost_map(m); });
    REQUIRE(parallel.packets() == r);
    for (int32_t y = r.y0; y < r.y1; ++y)
      for (int32_t x = r.x0; x < r.x1; ++x) REQUIRE(parallel.at(x, y) == serial.at(x, y));
    REQUIRE(serial.total() == m.total());  // beyond 32 bits: up to 2^32 per packet
    REQUIRE(serial.total() > 0xffffffffull);
    for (int i = 0; i < 2000; ++i) {
      const Rect q = random_rect(rng, r);
      REQUIRE(parallel.cost(q) == brute(m, q));
    }
  }
}

TEST_CASE("Building a SAT rejects a cost map that does not fit its rectangle", "[sat]") {
  CostMap m{{0, 0, 4, 3}, std::vector<uint32_t>(11, 1)};
  REQUIRE_THROWS_AS(Sat::from_cost_map(m), std::invalid_argument);
  m.packets = {-1, 0, 3, 3};
  m.cost.assign(12, 1);
  REQUIRE_THROWS_AS(Sat::from_cost_map(m), std::invalid_argument);
  m.packets = {0, 0, 4, 3};
  REQUIRE(Sat::from_cost_map(m).total() == 12);
  const Sat empty = Sat::from_cost_map(CostMap{{5, 5, 5, 9}, {}});
  REQUIRE(empty.empty());
  REQUIRE(empty.total() == 0);
  REQUIRE(empty.cost({0, 0, 100, 100}) == 0);
}

TEST_CASE("A SAT survives serialisation unchanged", "[sat][serialisation]") {
  std::mt19937_64 rng(3);
  for (const Rect r : {Rect{0, 0, 1, 1}, Rect{12, 7, 45, 19}, Rect{0, 0, 320, 180}}) {
    const CostMap m = random_map(rng, r, 0xffffffffu);
    const Sat s = Sat::from_cost_map(m);
    const std::vector<uint8_t> buf = s.serialize();
    REQUIRE(buf.size() == Sat::kHeaderBytes + size_t(r.area()) * 8);
    REQUIRE(std::memcmp(buf.data(), "TSAT", 4) == 0);
    REQUIRE(buf[8] == uint8_t(r.x0));  // little-endian x0
    const Sat t = Sat::deserialize(buf);
    REQUIRE(t.packets() == r);
    for (int32_t y = r.y0; y < r.y1; ++y)
      for (int32_t x = r.x0; x < r.x1; ++x) REQUIRE(t.at(x, y) == s.at(x, y));
    REQUIRE(t.serialize() == buf);
  }
  const Sat e = Sat::deserialize(Sat().serialize());
  REQUIRE(e.empty());
}

TEST_CASE("Truncated, padded and corrupt SAT buffers are rejected with an error", "[sat][serialisation]") {
  std::mt19937_64 rng(4);
  const CostMap m = random_map(rng, {2, 3, 9, 8}, 1u << 20);
  const std::vector<uint8_t> good = Sat::from_cost_map(m).serialize();
  REQUIRE_NOTHROW(Sat::deserialize(good));

  SECTION("every truncation") {
    for (size_t n = 0; n < good.size(); ++n) REQUIRE_THROWS_AS(Sat::deserialize(good.data(), n), SatFormatError);
  }
  SECTION("a trailing byte") {
    auto b = good;
    b.push_back(0);
    REQUIRE_THROWS_AS(Sat::deserialize(b), SatFormatError);
  }
  SECTION("bad magic, version and header size") {
    for (size_t at : {0u, 4u, 6u}) {
      auto b = good;
      b[at] ^= 0x40;
      REQUIRE_THROWS_AS(Sat::deserialize(b), SatFormatError);
    }
  }
  auto put32 = [](std::vector<uint8_t>& b, size_t at, uint32_t v) {
    for (int i = 0; i < 4; ++i) b[at + size_t(i)] = uint8_t(v >> (8 * i));
  };
  SECTION("impossible rectangles") {
    for (auto [at, v] : std::vector<std::pair<size_t, uint32_t>>{
             {8, 0xffffffffu},   // x0 = -1
             {12, 0x80000000u},  // y0 = INT32_MIN
             {16, 1},            // x1 < x0
             {20, 0x7fffffffu},  // y1 absurd
             {16, 10}}) {        // rectangle no longer matches the count
      auto b = good;
      put32(b, at, v);
      REQUIRE_THROWS_AS(Sat::deserialize(b), SatFormatError);
    }
  }
  SECTION("a count that does not match, or would overflow a size computation") {
    for (uint64_t c : {uint64_t(34), uint64_t(36), uint64_t(1) << 61, ~uint64_t(0)}) {
      auto b = good;
      for (int i = 0; i < 8; ++i) b[24 + size_t(i)] = uint8_t(c >> (8 * i));
      REQUIRE_THROWS_AS(Sat::deserialize(b), SatFormatError);
    }
  }
  SECTION("a corrupt entry") {
    // Raising any one entry by 2^40 implies a packet cost beyond 32 bits at that entry or a
    // negative one at a neighbour.
    for (size_t e = 0; e < size_t(m.packets.area()); ++e) {
      auto b = good;
      b[Sat::kHeaderBytes + e * 8 + 5] ^= 0x01;
      REQUIRE_THROWS_AS(Sat::deserialize(b), SatFormatError);
    }
    // Decreasing the last entry below its neighbours implies a negative cost.
    auto b = good;
    for (int i = 0; i < 8; ++i) b[b.size() - 8 + size_t(i)] = 0;
    REQUIRE_THROWS_AS(Sat::deserialize(b), SatFormatError);
  }
  SECTION("the non-throwing variant reports the error") {
    std::string err;
    REQUIRE_FALSE(Sat::try_deserialize(good.data(), 10, &err).has_value());
    REQUIRE(err.find("truncated") != std::string::npos);
    REQUIRE(Sat::try_deserialize(good.data(), good.size(), &err).has_value());
    REQUIRE_FALSE(Sat::try_deserialize(nullptr, 5, &err).has_value());
  }
  SECTION("random garbage behind a valid header never crashes") {
    for (int i = 0; i < 2000; ++i) {
      auto b = good;
      const int flips = 1 + int(rng() % 4);
      for (int f = 0; f < flips; ++f) b[rng() % b.size()] = uint8_t(rng());
      try {
        const Sat s = Sat::deserialize(b);
        // Accepted: then it must be a consistent SAT of its rectangle.
        REQUIRE(s.total() == s.cost(s.packets()));
      } catch (const SatFormatError&) {
      }
    }
  }
}

TEST_CASE("A SAT array answers every rectangle as a direct sum over per-node SATs", "[sat][sat_array]") {
  std::mt19937_64 rng(5);
  for (int iter = 0; iter < 40; ++iter) {
    const bool small = iter < 20;
    const Rect space{0, 0, small ? 1 + int32_t(rng() % 12) : 160, small ? 1 + int32_t(rng() % 9) : 90};
    const CostMap m = random_map(rng, space, iter % 3 ? 5000u : 0xffffffffu);
    std::vector<Rect> parts;
    partition(rng, space, 1 + int(rng() % 24), parts);
    SatArray array(space);
    std::vector<double> perf_of(size_t(space.area()));
    std::uniform_real_distribution<double> perf(0.5, 3.0);
    for (const Rect& p : parts) {
      const double c = iter % 2 ? perf(rng) : 1.0;
      array.add(Sat::from_cost_map(sub_map(m, p)), c);
      for (int32_t y = p.y0; y < p.y1; ++y)
        for (int32_t x = p.x0; x < p.x1; ++x) perf_of[size_t(y) * space.width() + x] = c;
    }
    array.finalize();
    REQUIRE_FALSE(array.has_missing());
    auto direct = [&](const Rect& q) {
      const Rect r = tessera::intersect(q, space);
      double s = 0;
      for (int32_t y = r.y0; y < r.y1; ++y)
        for (int32_t x = r.x0; x < r.x1; ++x) s += double(m.at(x, y)) * perf_of[size_t(y) * space.width() + x];
      return s;
    };
    auto check = [&](const Rect& q) {
      const double want = direct(q);
      REQUIRE(array.cost(q) == Approx(want).epsilon(1e-12).margin(1e-6));
    };
    if (small) {
      for (int32_t ax = 0; ax <= space.x1; ++ax)
        for (int32_t bx = ax; bx <= space.x1; ++bx)
          for (int32_t ay = 0; ay <= space.y1; ++ay)
            for (int32_t by = ay; by <= space.y1; ++by) check({ax, ay, bx, by});
    } else {
      for (int i = 0; i < 3000; ++i) check(random_rect(rng, space));
    }
    check({-5, -5, space.x1 + 5, space.y1 + 5});
    REQUIRE(array.total() == Approx(direct(space)).epsilon(1e-12));
  }
}

TEST_CASE("A SAT array fills the area of missing SATs with the mean known cost density", "[sat][sat_array]") {
  std::mt19937_64 rng(6);
  for (int iter = 0; iter < 30; ++iter) {
    const Rect space{0, 0, 20 + int32_t(rng() % 40), 10 + int32_t(rng() % 30)};
    const CostMap m = random_map(rng, space, 1000u);
    std::vector<Rect> parts;
    partition(rng, space, 4 + int(rng() % 12), parts);
    SatArray array(space);
    std::vector<char> known(size_t(space.area()), 0);
    double known_cost = 0;
    int64_t known_area = 0;
    for (size_t i = 0; i < parts.size(); ++i) {
      if (i % 3 == 1) continue;  // this node did not report
      const Rect& p = parts[i];
      array.add(Sat::from_cost_map(sub_map(m, p)), 2.0);
      for (int32_t y = p.y0; y < p.y1; ++y)
        for (int32_t x = p.x0; x < p.x1; ++x) {
          known[size_t(y) * space.width() + x] = 1;
          known_cost += 2.0 * m.at(x, y);
        }
      known_area += p.area();
    }
    array.finalize();
    REQUIRE(array.has_missing());
    REQUIRE(array.known_packets() == known_area);
    const double density = known_cost / double(known_area);
    REQUIRE(array.missing_density() == Approx(density));
    for (int i = 0; i < 2000; ++i) {
      const Rect q = random_rect(rng, space);
      double want = 0;
      for (int32_t y = q.y0; y < q.y1; ++y)
        for (int32_t x = q.x0; x < q.x1; ++x)
          want += known[size_t(y) * space.width() + x] ? 2.0 * m.at(x, y) : density;
      REQUIRE(array.cost(q) == Approx(want).epsilon(1e-12).margin(1e-6));
    }
  }
  SECTION("no SAT at all: every packet costs one unit") {
    SatArray none({0, 0, 7, 5});
    none.finalize();
    REQUIRE(none.cost({1, 1, 4, 3}) == 6.0);
    REQUIRE(none.total() == 35.0);
  }
}

TEST_CASE("A SAT array rejects overlapping or outside SATs and bad coefficients", "[sat][sat_array]") {
  const CostMap m{{0, 0, 4, 4}, std::vector<uint32_t>(16, 3)};
  SatArray a({0, 0, 6, 6});
  REQUIRE_THROWS_AS(a.add(Sat::from_cost_map(m), 0.0), std::invalid_argument);
  REQUIRE_THROWS_AS(a.add(Sat::from_cost_map(m), -1.0), std::invalid_argument);
  REQUIRE_THROWS_AS(a.add(Sat::from_cost_map(m), std::nan("")), std::invalid_argument);
  REQUIRE_THROWS_AS(a.add(Sat::from_cost_map(m), HUGE_VAL), std::invalid_argument);
  REQUIRE_THROWS_AS(a.cost({0, 0, 1, 1}), std::logic_error);
  a.add(Sat::from_cost_map(m), 1.0);
  REQUIRE_THROWS_AS(a.add(Sat::from_cost_map(CostMap{{3, 3, 7, 4}, std::vector<uint32_t>(4, 1)})),
                    std::invalid_argument);
  a.add(Sat::from_cost_map(CostMap{{3, 3, 5, 5}, std::vector<uint32_t>(4, 1)}));
  REQUIRE_THROWS_AS(a.finalize(), std::invalid_argument);
}
