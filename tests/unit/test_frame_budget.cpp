// The interactive frames' render scale (lb/frame_budget.h) on a synthetic cost model: a frame
// at scale s costs C * s^2 plus a fixed overhead, with +-10% noise.
#include <catch2/catch.hpp>

#include <cmath>
#include <random>
#include <vector>

#include "lb/frame_budget.h"

using namespace tessera;

namespace {

struct Model {
  double full_ms;          // C: a full-resolution frame
  double overhead_ms = 2;  // per frame, whatever the scale
  std::mt19937 rng{7};
  double frame(double s) {
    std::uniform_real_distribution<double> noise(0.9, 1.1);
    return (full_ms * s * s + overhead_ms) * noise(rng);
  }
};

// Runs n frames; returns their times.
std::vector<double> run(FrameBudget& b, Model& m, int n) {
  std::vector<double> t;
  for (int i = 0; i < n; ++i) {
    const double s = b.scale();
    t.push_back(m.frame(s));
    b.observe(s, t.back());
  }
  return t;
}

size_t within(const std::vector<double>& t, size_t from, double budget, double tol) {
  size_t n = 0;
  for (size_t i = from; i < t.size(); ++i) n += std::abs(t[i] - budget) <= tol * budget;
  return n;
}

}  // namespace

TEST_CASE("Interactive frames settle within 20% of the budget and follow a cost jump", "[budget]") {
  const double budget = 33;
  FrameBudget b(budget);
  Model m{150};  // a full frame takes 4.5x the budget
  auto t = run(b, m, 40);
  // After the first few frames every frame is within +-20% of the budget (noise is +-10%).
  CHECK(within(t, 3, budget, 0.20) == t.size() - 3);
  const double settled = b.scale();
  CHECK(settled < 0.52);
  CHECK(settled > 0.40);
  // The scene gets three times as expensive (a heavy object comes into view).
  m.full_ms = 450;
  auto jump = run(b, m, 20);
  CHECK(jump[0] > 1.5 * budget);  // the frame that shows the jump
  CHECK(within(jump, 1, budget, 0.20) >= jump.size() - 2);  // adapted by the next frame
  CHECK(b.scale() < settled);
  // And back: cheap again, the scale goes up.
  m.full_ms = 150;
  auto back = run(b, m, 20);
  CHECK(within(back, 2, budget, 0.20) >= back.size() - 3);
  CHECK(b.scale() == Approx(settled).margin(1.0 / 32));
}

TEST_CASE("The scale stays steady under noise, and within its bounds", "[budget]") {
  FrameBudget b(33);
  Model m{300};
  run(b, m, 10);
  int changes = 0;
  double last = b.scale();
  for (int i = 0; i < 200; ++i) {
    run(b, m, 1);
    changes += b.scale() != last;
    last = b.scale();
  }
  CHECK(changes <= 10);  // +-10% noise does not move a scale held by 15% hysteresis often
  // A scene cheaper than the budget renders at full resolution.
  FrameBudget cheap(33);
  Model light{10};
  run(cheap, light, 10);
  CHECK(cheap.scale() == 1.0);
  // One that cannot meet it at any scale renders at the smallest.
  FrameBudget heavy(33, 0.25);
  Model huge{100000};
  run(heavy, huge, 10);
  CHECK(heavy.scale() == 0.25);
  // Nonsense measurements teach nothing.
  FrameBudget b2(33);
  b2.observe(0.5, std::nan(""));
  b2.observe(0, 10);
  b2.observe(0.5, -1);
  CHECK(b2.full_cost_ms() == 0);
  CHECK(b2.scale() == 1.0);
  CHECK_THROWS(FrameBudget(0));
  CHECK_THROWS(FrameBudget(33, 0));
}

TEST_CASE("Scaled sizes round to the nearest pixel and never vanish", "[budget]") {
  int32_t w = 0, h = 0;
  FrameBudget::scaled(1280, 720, 0.5, w, h);
  CHECK(w == 640);
  CHECK(h == 360);
  FrameBudget::scaled(3, 1, 0.25, w, h);
  CHECK(w == 1);
  CHECK(h == 1);
}

TEST_CASE("A restart renders the next frame at the smallest scale and learns the cost from it", "[budget]") {
  const double budget = 33;
  FrameBudget b(budget);
  Model cheap{10};  // the empty scene: full resolution is within the budget
  run(b, cheap, 5);
  CHECK(b.scale() == 1.0);
  b.restart();  // the page's scene arrived
  CHECK(b.scale() == 0.25);
  CHECK(b.full_cost_ms() == 0);
  Model heavy{450};
  auto t = run(b, heavy, 10);
  CHECK(t[0] < 2 * budget);  // the first frame of the new scene: small, not 450 ms
  CHECK(within(t, 1, budget, 0.20) >= t.size() - 2);
  CHECK(b.scale() < 0.35);
}
