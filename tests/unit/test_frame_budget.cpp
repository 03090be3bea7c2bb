// The interactive frames' render scale (lb/frame_budget.h) on a synthetic cost model: a frame
// at scale s costs C * s^2 plus a fixed overhead, with +-10% noise.
#include <catch2/catch.hpp>

#include <algorithm>
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

TEST_CASE("Interactive levels halve the AO rays, then cut the depth to one bounce", "[budget]") {
  using L = std::vector<InteractiveSamples>;
  CHECK(interactive_levels(4, 4) == L{{4, 4}, {2, 4}, {1, 4}, {1, 2}});
  CHECK(interactive_levels(3, 2) == L{{3, 2}, {2, 2}, {1, 2}});
  CHECK(interactive_levels(1, 1) == L{{1, 1}});
  CHECK(interactive_levels(0, 8) == L{{0, 8}, {0, 2}});
  CHECK(interactive_levels(256, 64).size() == size_t(FrameBudget::kMaxLevels));  // 256 .. 2: seven halvings fill it
  CHECK(interactive_levels(256, 64).back() == InteractiveSamples{2, 64});
}

namespace {
// Each level costs a fraction of the level above it (fewer AO rays, then fewer bounces).
struct LevelModel {
  double full_ms;  // level 0 at scale 1
  std::vector<double> factor{1.0, 0.6, 0.4, 0.25};
  std::mt19937 rng{11};
  double frame(double s, int level) {
    std::uniform_real_distribution<double> noise(0.9, 1.1);
    return (full_ms * factor.at(size_t(level)) * s * s + 2) * noise(rng);
  }
};

std::vector<double> run_levels(FrameBudget& b, LevelModel& m, int n, std::vector<int>* levels = nullptr) {
  std::vector<double> t;
  for (int i = 0; i < n; ++i) {
    const double s = b.scale();
    const int l = b.level();
    t.push_back(m.frame(s, l));
    if (levels) levels->push_back(l);
    b.observe(s, t.back(), l);
  }
  return t;
}
}  // namespace

TEST_CASE("A scene too heavy for the smallest scale drops samples to meet the budget, and takes them back", "[budget]") {
  const double budget = 33;
  FrameBudget b(budget, 0.25);
  b.set_ladder(interactive_levels(4, 4));  // 4 levels
  LevelModel m{1000};  // level 0 at the smallest scale: 64 ms, twice the budget
  std::vector<int> levels;
  auto t = run_levels(b, m, 40, &levels);
  CHECK(b.level() == 2);  // level 1 at 0.25 is still 39.5 ms (> 15% over); level 2 fits
  // Two frames in a row over the budget a step (one slow frame is not a reason): level 2 from
  // the fifth frame at the earliest; later here, as level 1 (39.5 ms +-10%) is only just over
  // the 38 ms that calls for a step, and a frame under it starts the count again.
  const size_t at2 = size_t(std::find(levels.begin(), levels.end(), 2) - levels.begin());
  CHECK(at2 >= 4);
  CHECK(at2 <= 12);
  CHECK(within(t, at2 + 2, budget, 0.20) >= t.size() - at2 - 3);
  int steps = 0;  // settled: no back and forth between levels
  for (size_t i = at2 + 1; i < levels.size(); ++i) steps += levels[i] != levels[i - 1];
  CHECK(steps == 0);
  // The view turns to a cheap part of the scene: the samples come back before the resolution.
  m.full_ms = 150;
  levels.clear();
  auto back = run_levels(b, m, 30, &levels);
  CHECK(levels.at(2) == 0);  // two frames to climb two levels
  CHECK(b.level() == 0);
  CHECK(b.scale() > 0.35);
  CHECK(within(back, 5, budget, 0.20) >= back.size() - 6);
  // And heavy again: down the ladder with the measured ratios, not the guess.
  m.full_ms = 1000;
  levels.clear();
  auto heavy = run_levels(b, m, 20, &levels);
  CHECK(b.level() == 2);
  CHECK(within(heavy, 6, budget, 0.20) >= heavy.size() - 7);
}

TEST_CASE("One level is the old behaviour; a new ladder or a restart starts from the page's settings", "[budget]") {
  FrameBudget b(33, 0.25);
  LevelModel m{1000};
  run_levels(b, m, 10);
  CHECK(b.level() == 0);  // no ladder: the smallest scale, over budget
  CHECK(b.scale() == 0.25);
  b.set_ladder(interactive_levels(4, 4));  // 4 levels
  run_levels(b, m, 10);
  CHECK(b.level() == 2);
  b.set_ladder(interactive_levels(2, 2));  // the page lowered its AO rays: a new ladder (2 levels), from its top
  CHECK(b.level() == 0);
  run_levels(b, m, 10);
  CHECK(b.level() == 1);  // the lowest there is
  b.restart();
  CHECK(b.level() == 0);
  CHECK(b.scale() == 0.25);
  // A frame of a level that no longer exists, or nonsense, teaches nothing and moves nothing.
  b.observe(0.25, 500, 3);
  b.observe(0.25, 500, -1);
  CHECK(b.level() == 0);
  CHECK(b.full_cost_ms() == 0);
}

TEST_CASE("One slow frame does not cost a level", "[budget]") {
  const double budget = 33;
  FrameBudget b(budget, 0.25);
  b.set_ladder(interactive_levels(4, 4));  // 4 levels
  LevelModel m{500};  // level 0 fits at a scale above the smallest (500 x 0.0625 + 2 = 33 ms)
  run_levels(b, m, 20);
  REQUIRE(b.level() == 0);
  // A neighbour takes the cores for one frame: five times as long.
  const double s = b.scale();
  b.observe(s, 5 * m.frame(s, 0), 0);
  CHECK(b.level() == 0);  // the scale drops to the smallest, the samples stay
  auto t = run_levels(b, m, 10);
  CHECK(b.level() == 0);
  CHECK(within(t, 2, budget, 0.20) >= t.size() - 3);
}
