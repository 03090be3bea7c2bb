// Adaptive refinement of a still (renderer/adaptive.h): the plans, the averages and when it stops.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <vector>

#include "renderer/accumulation.h"
#include "renderer/adaptive.h"
#include "renderer/raytracer.h"
#include "scene_builders.h"

using namespace tessera;
using namespace tessera::testing;

namespace {

constexpr int W = 64, H = 32;
constexpr PacketLayout kLayout{4, 4};  // 16 x 8 packets

// A synthetic still: the left half a constant grey, the right half noisy around a grey (the
// noise of an AO estimate: each sample one of two values), drawn from a seeded generator.
struct Synthetic {
  std::mt19937 rng{7};
  float constant = 0.25f, lo = 0.05f, hi = 0.45f;  // the noisy half's mean is 0.25 too
  std::vector<float> sample() {
    std::vector<float> out(size_t(W) * H * 3);
    std::bernoulli_distribution coin(0.5);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const float v = x < W / 2 ? constant : (coin(rng) ? hi : lo);
        for (int c = 0; c < 3; ++c) out[(size_t(y) * W + size_t(x)) * 3 + size_t(c)] = v;
      }
    return out;
  }
};

}  // namespace

TEST_CASE("adaptive: every packet alike at first, then only where the samples disagree", "[adaptive]") {
  AdaptiveStill still;
  AdaptiveOptions o;
  o.uniform = 4;
  o.round_cost = 0.25;
  still.reset(W, H, false, 64, o);
  REQUIRE(still.blocks() == Rect{0, 0, 16, 8});
  Synthetic syn;
  for (uint32_t r = 0; r < 4; ++r) {
    const std::vector<uint32_t>& plan = still.plan();
    for (uint32_t k : plan) CHECK(k == r);  // each packet's next sample is its own count
    still.add(syn.sample());
  }
  CHECK(still.min_samples() == 4);
  // From now on the constant half is left out, except for the column next to the noisy half
  // (the plans look at each packet's neighbours too), and a round costs a quarter of a sample.
  for (int r = 0; r < 20; ++r) {
    const std::vector<uint32_t>& plan = still.plan();
    REQUIRE_FALSE(still.converged());
    CHECK(still.planned() == size_t(128 / 4));
    for (int py = 0; py < 8; ++py)
      for (int px = 0; px < 7; ++px) CHECK(plan[size_t(py) * 16 + size_t(px)] == kSkipPacket);
    still.add(syn.sample());
  }
  // The samples went to the noisy half, spread evenly over it.
  const std::vector<float> mean = still.mean();
  CHECK(still.mean_samples() > 4.0);
  CHECK(still.mean_samples() == Approx(4.0 + 20 * 0.25).epsilon(1e-9));
  // Each pixel's average is its own samples' mean: exact on the constant half, and on the
  // noisy half within a few standard errors of 0.25 (each sample 0.25 +- 0.2).
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float m = mean[(size_t(y) * W + size_t(x)) * 3];
      if (x < W / 2) {
        CHECK(m == 0.25f);
      } else {
        CHECK(std::fabs(m - 0.25f) < 0.2f);
      }
    }
  double noisy = 0;
  for (int y = 0; y < H; ++y)
    for (int x = W / 2; x < W; ++x) noisy += mean[(size_t(y) * W + size_t(x)) * 3];
  CHECK(noisy / (H * W / 2) == Approx(0.25).margin(0.01));  // unbiased over the half
}

TEST_CASE("adaptive: the plans follow the cost: of two equally noisy halves the cheaper one gets more samples",
          "[adaptive]") {
  AdaptiveStill still;
  AdaptiveOptions o;
  o.round_cost = 0.25;
  still.reset(W, H, false, 1000, o);
  std::mt19937 rng(3);
  std::bernoulli_distribution coin(0.5);
  CostMap cost;
  cost.packets = {0, 0, 16, 8};
  cost.cost.resize(128);
  for (int py = 0; py < 8; ++py)
    for (int px = 0; px < 16; ++px) cost.cost[size_t(py) * 16 + size_t(px)] = px < 8 ? 1000 : 4000;
  for (int r = 0; r < 60; ++r) {
    std::vector<float> rad(size_t(W) * H * 3);
    for (float& v : rad) v = coin(rng) ? 0.45f : 0.05f;
    still.plan();
    still.add(rad, &cost, kLayout);
  }
  // The optimum is n ~ sqrt(v / c): the cheap half about twice the samples of the dear one.
  // Away from the column where the halves meet (its plans see both), each planned packet's
  // next sample is its count.
  std::vector<uint32_t> counts_cheap, counts_dear;
  for (int r = 0; r < 10; ++r) {
    const std::vector<uint32_t>& p = still.plan();
    for (int py = 0; py < 8; ++py) {
      if (p[size_t(py) * 16 + 2] != kSkipPacket) counts_cheap.push_back(p[size_t(py) * 16 + 2]);
      if (p[size_t(py) * 16 + 13] != kSkipPacket) counts_dear.push_back(p[size_t(py) * 16 + 13]);
    }
    std::vector<float> rad(size_t(W) * H * 3);
    for (float& v : rad) v = coin(rng) ? 0.45f : 0.05f;
    still.add(rad, &cost, kLayout);
  }
  REQUIRE_FALSE(counts_cheap.empty());
  REQUIRE_FALSE(counts_dear.empty());
  double mc = 0, md = 0;
  for (uint32_t c : counts_cheap) mc += c;
  for (uint32_t c : counts_dear) md += c;
  mc /= double(counts_cheap.size());
  md /= double(counts_dear.size());
  CHECK(mc / md == Approx(2.0).epsilon(0.25));
}

TEST_CASE("adaptive: a still without noise is converged after its uniform samples, and the target caps every packet",
          "[adaptive]") {
  AdaptiveStill still;
  still.reset(W, H, true, 64);
  const std::vector<float> grey(size_t(W) * H * 3, 0.3f);
  for (int r = 0; r < 4; ++r) {
    REQUIRE_FALSE(still.converged());
    still.plan();
    still.add(grey);
  }
  CHECK(still.plan().size() == 128);
  CHECK(still.converged());
  CHECK(still.planned() == 0);
  CHECK_THROWS_AS(still.add(grey), std::logic_error);

  // Noise everywhere, a target of 6: rounds until every packet has 6, then converged.
  AdaptiveStill capped;
  capped.reset(W, H, true, 6);
  Synthetic syn;
  int rounds = 0;
  while (!capped.converged() && rounds < 1000) {
    capped.plan();
    if (capped.converged()) break;
    capped.add(syn.sample());
    ++rounds;
  }
  CHECK(capped.converged());
  CHECK(capped.min_samples() == 4);
  // The noisy half at 6, the quiet one at 4 but for its column next to the noisy half (its
  // plans see the neighbours), also at 6: (64 x 6 + 8 x 6 + 56 x 4) / 128.
  CHECK(capped.mean_samples() == Approx(5.125));
}

TEST_CASE("adaptive: an outline against a light that clips keeps its samples (the mean clips, the samples do not)",
          "[adaptive]") {
  // Every pixel's samples: a light five times white or a dark frame, at random: the mean clips
  // nearly always, so the encoding's slope at the mean is 0, but the average is not settled.
  AdaptiveStill still;
  AdaptiveOptions o;
  o.round_cost = 1;
  still.reset(W, H, true, 64, o);
  std::mt19937 rng(11);
  std::bernoulli_distribution coin(0.75);
  for (int r = 0; r < 8; ++r) {
    std::vector<float> rad(size_t(W) * H * 3);
    for (float& v : rad) v = coin(rng) ? 5.0f : 0.01f;
    still.plan();
    still.add(rad);
  }
  CHECK_FALSE(still.converged());
  CHECK(still.planned() > 64);
  // A light that clips in every sample: settled at once.
  AdaptiveStill lit;
  lit.reset(W, H, true, 64, o);
  const std::vector<float> bright(size_t(W) * H * 3, 5.0f);
  for (int r = 0; r < 4; ++r) {
    lit.plan();
    lit.add(bright);
  }
  lit.plan();
  CHECK(lit.converged());
}

TEST_CASE("adaptive: with every packet in every round the average is Accumulation's, byte for byte", "[adaptive]") {
  AdaptiveStill still;
  AdaptiveOptions o;
  o.round_cost = 1;
  o.done_below = 0;
  still.reset(W, H, true, 64, o);
  Accumulation acc;
  acc.reset(W, H, true);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.2f);
  for (int r = 0; r < 6; ++r) {
    std::vector<float> rad(size_t(W) * H * 3);
    for (float& v : rad) v = u(rng);
    const std::vector<uint32_t>& plan = still.plan();
    for (uint32_t k : plan) REQUIRE(k == uint32_t(r));
    still.add(rad);
    acc.add(rad, W, H, 0, 0);
    acc.end_sample();
    CHECK(still.average().rgba == acc.average().rgba);
  }
}

TEST_CASE("adaptive: a round in tiles that split blocks counts each block once, and set_uniform plans every block",
          "[adaptive]") {
  AdaptiveStill whole, tiled;
  AdaptiveOptions o;
  o.round_cost = 0.25;
  whole.reset(W, H, true, 64, o);
  tiled.reset(W, H, true, 64, o);
  Synthetic syn;
  for (int r = 0; r < 10; ++r) {
    const std::vector<float> rad = syn.sample();
    REQUIRE(whole.plan() == tiled.plan());
    whole.add(rad);
    // Two renderers' tiles, split at row 6 (inside the second row of blocks), then the round.
    std::vector<float> top(rad.begin(), rad.begin() + 6 * W * 3), bottom(rad.begin() + 6 * W * 3, rad.end());
    tiled.add_tile(bottom.data(), Rect{0, 6, W, H});
    tiled.add_tile(top.data(), Rect{0, 0, W, 6});
    tiled.end_round();
    CHECK(tiled.average().rgba == whole.average().rgba);
    CHECK(tiled.mean_samples() == whole.mean_samples());
  }
  CHECK(tiled.planned() < 128);  // adaptive by now
  tiled.set_uniform(true);
  for (uint32_t k : tiled.plan()) CHECK(k != kSkipPacket);
  CHECK(tiled.planned() == 128);
  tiled.set_uniform(false);
  tiled.plan();
  CHECK(tiled.planned() < 128);
}

TEST_CASE("adaptive: bad settings and sizes are refused", "[adaptive]") {
  AdaptiveStill still;
  CHECK_THROWS_AS(still.reset(0, H, true, 4), std::invalid_argument);
  CHECK_THROWS_AS(still.reset(W, H, true, 0), std::invalid_argument);
  AdaptiveOptions o;
  o.uniform = 1;
  CHECK_THROWS_AS(still.reset(W, H, true, 4, o), std::invalid_argument);
  o = {};
  o.round_cost = 0;
  CHECK_THROWS_AS(still.reset(W, H, true, 4, o), std::invalid_argument);
  o.round_cost = std::nan("");
  CHECK_THROWS_AS(still.reset(W, H, true, 4, o), std::invalid_argument);
  o = {};
  o.done_below = -1;
  CHECK_THROWS_AS(still.reset(W, H, true, 4, o), std::invalid_argument);
  still.reset(W, H, true, 4);
  CHECK(still.average().rgba.empty());
  CHECK_THROWS_AS(still.add(std::vector<float>(10)), std::invalid_argument);
  CHECK_THROWS_AS(still.add_tile(nullptr, Rect{60, 0, 70, 4}), std::invalid_argument);  // outside the image
  CostMap odd;
  odd.packets = {0, 0, 2, 2};
  odd.cost.assign(4, 1);
  CHECK_THROWS_AS(still.add_cost(odd, PacketLayout{8, 2}), std::invalid_argument);  // wider than a block
  odd.cost.assign(3, 1);
  CHECK_THROWS_AS(still.add_cost(odd, PacketLayout{4, 4}), std::invalid_argument);  // not its size
}

// The renderer and the plans together: a still of a real scene refined adaptively converges to
// the uniformly refined one.
TEST_CASE("adaptive: a rendered still refined adaptively approaches the plain average of many samples",
          "[adaptive]") {
  const int w = 48, h = 32;
  Scene scene;
  scene.set_resolution(w, h);
  scene.set_environment(plain_env({0.2f, 0.3f, 0.5f}, {0.6f, 0.6f, 0.6f}));
  scene.set_material(1, diffuse({0.8f, 0.8f, 0.8f}));
  add_object(scene, 100, box({-1, 0, -1}, {1, 1, 1}), 1);
  add_object(scene, 200, quad({-5, 0, -5}, {10, 0, 0}, {0, 0, 10}), 1);
  scene.set_camera(look({2.5f, 2.0f, 3.5f}, {0, 0.4f, 0}, 0.9f));
  RayTracer rt(PacketLayout{4, 4});
  std::vector<std::string> warnings;
  rt.sync(scene, warnings);
  RenderSettings s;
  s.ao_samples = 1;
  s.ao_distance = 2;
  s.radiance = true;
  s.frame = 1;
  // The reference: 256 plain samples.
  Accumulation ref;
  ref.reset(w, h, true);
  TaskResult r;
  for (uint32_t k = 0; k < 256; ++k) {
    s.sample = k;
    rt.render({0, 0, w, h}, s, r);
    ref.add(r.radiance, w, h, 0, 0);
    ref.end_sample();
  }
  const Image want = ref.average();
  AdaptiveStill still;
  AdaptiveOptions o;
  o.round_cost = 0.25;
  still.reset(w, h, true, 64, o);
  double first_db = 0;
  for (int round = 0; round < 60 && !still.converged(); ++round) {
    s.block_samples = still.plan().data();
    s.plan_blocks = still.blocks();
    if (still.converged()) break;
    rt.render({0, 0, w, h}, s, r);
    // Every packet at one cost: the measured map follows the machine's load (a preempted packet
    // looks dear), and which blocks this case refines must depend on the noise alone (the cost's
    // part is the case above with two halves).
    CostMap even = r.cost;
    std::fill(even.cost.begin(), even.cost.end(), 1000u);
    still.add(r.radiance, &even, rt.packet_layout());
    if (round == 3) first_db = compare(still.average(), want).psnr;
  }
  const double db = compare(still.average(), want).psnr;
  CHECK(db > first_db + 6);  // it kept refining where it mattered
  CHECK(db > 33);
  CHECK(still.mean_samples() < 40);  // and left the quiet packets alone
}

TEST_CASE("adaptive: the plan takes the best blocks until the budget as a sort would (equal gains included)",
          "[adaptive]") {
  std::mt19937 rng(5);
  for (int trial = 0; trial < 400; ++trial) {
    const size_t n = size_t(std::uniform_int_distribution<int>(1, 300)(rng));
    std::vector<adaptive_detail::Candidate> cand;
    double total = 0;
    for (size_t i = 0; i < n; ++i) {
      // Few distinct gains, so that many are equal and the block decides.
      const double gain = std::uniform_int_distribution<int>(0, trial % 2 ? 3 : 1000)(rng);
      const double cost = std::uniform_real_distribution<double>(0.5, 2.0)(rng);
      cand.push_back({gain, cost, size_t(std::uniform_int_distribution<int>(0, 100000)(rng)) * 1000 + i});
      total += cost;
    }
    const double budget = total * std::uniform_real_distribution<double>(-0.05, 1.1)(rng);
    // The reference: sorted, then taken while the cost before is below the budget.
    std::vector<adaptive_detail::Candidate> sorted = cand;
    std::sort(sorted.begin(), sorted.end(), [](const auto& a, const auto& b) {
      return a.gain > b.gain || (a.gain == b.gain && a.block < b.block);
    });
    std::vector<size_t> want;
    double spent = 0;
    for (const auto& c : sorted) {
      if (!(budget > 0) || spent >= budget) break;
      want.push_back(c.block);
      spent += c.cost;
    }
    const size_t k = adaptive_detail::take_best(cand, budget);
    std::vector<size_t> got;
    for (size_t i = 0; i < k; ++i) got.push_back(cand[i].block);
    std::sort(want.begin(), want.end());
    std::sort(got.begin(), got.end());
    INFO("trial " << trial << ", " << n << " candidates, budget " << budget << " of " << total);
    REQUIRE(got == want);
  }
}

TEST_CASE("adaptive: tiles of an image whose edge blocks stick out give the whole image's rounds; a block added twice is refused",
          "[adaptive]") {
  constexpr int w = 30, h = 18;  // the last column and row of blocks hold 2 pixels
  AdaptiveStill whole, tiled;
  AdaptiveOptions o;
  o.round_cost = 0.3;
  whole.reset(w, h, true, 32, o);
  tiled.reset(w, h, true, 32, o);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.0f, 1.5f);
  // Four tiles, split inside blocks (column 13, row 6) and on their edges (column 28).
  const Rect tiles[] = {{0, 0, 13, 6}, {13, 0, w, 6}, {0, 6, 28, h}, {28, 6, w, h}};
  for (int r = 0; r < 12; ++r) {
    std::vector<float> rad(size_t(w) * h * 3);
    for (size_t i = 0; i < rad.size(); ++i) rad[i] = (i / 3) % 7 < 3 ? u(rng) : 0.2f;
    REQUIRE(whole.plan() == tiled.plan());
    whole.add(rad);
    for (const Rect& t : tiles) {
      std::vector<float> part;
      for (int y = t.y0; y < t.y1; ++y)
        part.insert(part.end(), rad.begin() + (y * w + t.x0) * 3, rad.begin() + (y * w + t.x1) * 3);
      tiled.add_tile(part.data(), t);
    }
    tiled.end_round();
    REQUIRE(tiled.average().rgba == whole.average().rgba);
    REQUIRE(tiled.mean() == whole.mean());
  }
  CHECK(tiled.planned() < size_t(plan_blocks_of({0, 0, w, h}).area()));  // adaptive by now
  // The same whole block twice in one round.
  AdaptiveStill twice;
  twice.reset(w, h, true, 32, o);
  const std::vector<float> grey(size_t(w) * h * 3, 0.5f);
  twice.add_tile(grey.data(), {0, 0, w, h});
  CHECK_THROWS_AS(twice.add_tile(grey.data(), {0, 0, w, h}), std::logic_error);
}

TEST_CASE("adaptive: radiance at the largest value a tile may carry keeps the plans finite", "[adaptive]") {
  // check_tile lets a peer's radiance up to 3e38 through; two such samples overflow a float sum.
  AdaptiveStill still;
  AdaptiveOptions o;
  o.round_cost = 0.5;
  still.reset(W, H, true, 64, o);
  std::mt19937 rng(9);
  std::bernoulli_distribution coin(0.5);
  for (int r = 0; r < 12 && !still.converged(); ++r) {
    std::vector<float> rad(size_t(W) * H * 3, 0.25f);
    for (int y = 0; y < H; ++y)
      for (int x = W / 2; x < W; ++x)
        for (int c = 0; c < 3; ++c) rad[(size_t(y) * W + size_t(x)) * 3 + size_t(c)] = coin(rng) ? 3.0e38f : 0.0f;
    still.plan();
    still.add(rad);
  }
  // The noisy half clips or is black: as the display sees it, each value varies between 0 and 1.
  REQUIRE_FALSE(still.converged());
  const std::vector<uint32_t>& plan = still.plan();
  size_t right = 0, left = 0;
  for (int by = 0; by < H / kPlanBlock; ++by)
    for (int bx = 0; bx < W / kPlanBlock; ++bx)
      if (plan[size_t(by) * (W / kPlanBlock) + size_t(bx)] != kSkipPacket) ++(bx >= W / kPlanBlock / 2 ? right : left);
  CHECK(right > 0);
  CHECK(left <= size_t(H / kPlanBlock));  // the constant half: at most the column beside the noise
  const Image avg = still.average();
  for (int y = 0; y < H; ++y) {
    CHECK(int(avg.pixel(1, y)[0]) == int(avg.pixel(2, y)[0]));  // the constant half is one grey
    const int v = avg.pixel(W - 1, y)[0];
    CHECK((v == 0 || v == 255));
  }
}
