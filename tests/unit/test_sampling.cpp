// Progressive samples (renderer/sampling.h) and their average (core/image.h Accumulation):
// the sequence is a stratified net under every per-pixel shift, its error on an analytic
// integrand falls much faster than independent random samples', jittered samples anti-alias
// an edge to its exact coverage, and averaged AO is unbiased against many AO rays at once.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <vector>

#include "renderer/accumulation.h"
#include "renderer/raytracer.h"
#include "renderer/raytracer_impl.h"
#include "renderer/sampling.h"
#include "scene_builders.h"

using namespace tessera;
using namespace tessera::testing;

namespace {

constexpr float kDeg = kPi / 180.0f;

// RMS error over 256 pixels (seeds) of the N-point estimate of the integral of f over the unit
// square, with points from `point(i, seed)`.
template <class F, class P>
double rms_error(F f, double exact, uint32_t n, P point) {
  double sum = 0;
  for (uint32_t seed = 0; seed < 256; ++seed) {
    double est = 0;
    for (uint32_t i = 0; i < n; ++i) {
      const sampling::Point q = point(i, sampling::mix(seed * 7919u + 1u));
      est += f(q.u, q.v);
    }
    est /= n;
    sum += (est - exact) * (est - exact);
  }
  return std::sqrt(sum / 256);
}

}  // namespace

TEST_CASE("sampling: sobol1 and shifted give the bits of their definitions", "[sampling]") {
  // The second dimension from its direction numbers, one set bit of i at a time, and a point
  // as Owen-scrambled Sobol dimensions of an Owen-scrambled index, spelled out.
  auto sobol1_loop = [](uint32_t i) {
    uint32_t r = 0;
    for (uint32_t v = 1u << 31; i; i >>= 1, v ^= v >> 1)
      if (i & 1) r ^= v;
    return r;
  };
  auto shifted_spelled = [&](uint32_t i, uint32_t seed, uint32_t salt) {
    const uint32_t key = sampling::mix(seed ^ salt);
    const uint32_t index = sampling::owen(i, key);
    const uint32_t a = sampling::owen(sampling::sobol0(index), sampling::mix(key ^ 0x5BD1E995u));
    const uint32_t b = sampling::owen(sobol1_loop(index), sampling::mix(key ^ 0x1B873593u));
    return sampling::Point{float(a >> 8) * 5.9604644775390625e-08f, float(b >> 8) * 5.9604644775390625e-08f};
  };
  for (uint32_t i = 0; i < 4096; ++i) REQUIRE(sampling::sobol1(i) == sobol1_loop(i));
  std::mt19937 rng(11);
  for (int n = 0; n < 200000; ++n) {
    const uint32_t i = rng();
    REQUIRE(sampling::sobol1(i) == sobol1_loop(i));
  }
  for (int n = 0; n < 20000; ++n) {
    const uint32_t i = rng() & 0xFFFFu, seed = rng(), salt = rng();
    const sampling::Point p = sampling::shifted(i, seed, salt), q = shifted_spelled(i, seed, salt);
    REQUIRE(p.u == q.u);
    REQUIRE(p.v == q.v);
  }
}

TEST_CASE("sampling: the AO azimuth's sine and cosine of a turn are within float rounding", "[sampling]") {
  // Every 2^-20 of the turn and the ends of its quarters: against double precision.
  double worst = 0;
  auto check = [&](float u) {
    float s, c;
    raytracer_detail::sincos_turn(u, s, c);
    const double phi = 2.0 * 3.14159265358979323846 * double(u);
    worst = std::max({worst, std::fabs(double(s) - std::sin(phi)), std::fabs(double(c) - std::cos(phi))});
  };
  for (uint32_t i = 0; i < (1u << 20); ++i) check(float(i) * (1.0f / 1048576.0f));
  for (float u : {0.0f, 0.125f, 0.25f, 0.375f, 0.5f, 0.625f, 0.75f, 0.875f, 0.99999994f}) check(u);
  INFO("largest error " << worst);
  CHECK(worst < 3e-7);
}

TEST_CASE("sampling: every 2^k consecutive points form a (0,k,2)-net under any per-pixel shift", "[sampling]") {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    const uint32_t seed = rng(), salt = rng();
    for (int k : {2, 4, 6, 8}) {
      const uint32_t n = 1u << k;
      for (uint32_t block : {0u, 1u, 5u}) {  // the points from block * 2^k on (AO uses blocks of S)
        for (int a = 0; a <= k; ++a) {
          // Elementary intervals of 2^-a by 2^-(k-a): each holds exactly one point.
          std::set<uint32_t> cells;
          for (uint32_t i = block * n; i < (block + 1) * n; ++i) {
            const sampling::Point q = sampling::shifted(i, seed, salt);
            REQUIRE(q.u >= 0.0f);
            REQUIRE(q.u < 1.0f);
            REQUIRE(q.v >= 0.0f);
            REQUIRE(q.v < 1.0f);
            const uint32_t cu = uint32_t(q.u * float(1u << a)), cv = uint32_t(q.v * float(1u << (k - a)));
            cells.insert(cu << 16 | cv);
          }
          INFO("k " << k << " a " << a << " block " << block);
          CHECK(cells.size() == n);
        }
      }
    }
  }
}

TEST_CASE("sampling: the error on smooth and discontinuous integrands falls far faster than random sampling's", "[sampling]") {
  auto smooth = [](float u, float v) { return double(u) * double(v) + std::sin(3.0 * u); };
  const double smooth_exact = 0.25 + (1.0 - std::cos(3.0)) / 3.0;
  auto disc = [](float u, float v) { return double(u) * u + double(v) * v < 1.0 ? 1.0 : 0.0; };
  const double disc_exact = kPi / 4.0;
  auto sobol = [](uint32_t i, uint32_t seed) { return sampling::shifted(i, seed, 0x1234u); };
  auto random = [](uint32_t i, uint32_t seed) {
    const uint32_t a = sampling::mix(seed ^ sampling::mix(i * 2u + 1u)), b = sampling::mix(a ^ 0x9E3779B9u);
    return sampling::Point{float(a >> 8) * (1.0f / 16777216.0f), float(b >> 8) * (1.0f / 16777216.0f)};
  };
  for (uint32_t n : {64u, 1024u}) {
    const double s_lds = rms_error(smooth, smooth_exact, n, sobol), s_mc = rms_error(smooth, smooth_exact, n, random);
    const double d_lds = rms_error(disc, disc_exact, n, sobol), d_mc = rms_error(disc, disc_exact, n, random);
    INFO("n " << n << ": smooth " << s_lds << " vs random " << s_mc << "; disc " << d_lds << " vs random " << d_mc);
    // Random sampling's RMS error is sigma / sqrt(n); a shifted (0,2)-sequence's falls like
    // n^-1 (smooth; n^-3/2 in theory for scrambled nets) and n^-3/4 (a curved edge).
    CHECK(s_lds < s_mc / 4);
    CHECK(d_lds < d_mc / 2);
  }
  // The rate: 16x the points cut the smooth error by well over sqrt(16) = 4.
  CHECK(rms_error(smooth, smooth_exact, 1024, sobol) < rms_error(smooth, smooth_exact, 64, sobol) / 8);
}

TEST_CASE("Accumulation: averages radiance tile by tile, encodes as the renderer does, refuses a tile outside", "[sampling]") {
  Accumulation acc;
  acc.reset(4, 2, /*srgb=*/false);
  CHECK(acc.average().rgba.empty());
  std::vector<float> one(4 * 2 * 3, 1.0f), zero(4 * 2 * 3, 0.0f), half(2 * 2 * 3, 0.4f), over(4 * 2 * 3, 3.0f);
  acc.add(one, 4, 2, 0, 0);
  acc.end_sample();
  acc.add(zero, 4, 2, 0, 0);
  acc.end_sample();
  Image avg = acc.average();
  REQUIRE(avg.width == 4);
  CHECK(int(avg.pixel(1, 1)[0]) == 128);  // 0.5 * 255 = 127.5 rounds up
  CHECK(int(avg.pixel(1, 1)[3]) == 255);
  acc.add(half, 2, 2, 0, 0);  // a sample in two tiles
  acc.add(half, 2, 2, 2, 0);
  acc.end_sample();
  CHECK(acc.samples() == 3);
  CHECK(int(acc.average().pixel(3, 0)[1]) == 119);  // (1 + 0 + 0.4) / 3 * 255 = 119.0
  CHECK_THROWS(acc.add(half, 2, 2, 3, 0));
  CHECK_THROWS(acc.add(half, 4, 2, 0, 0));  // not the size it claims
  // Radiance is averaged before it is clamped: a bright sample lifts its neighbours' average.
  Accumulation hot;
  hot.reset(4, 2, false);
  hot.add(over, 4, 2, 0, 0);
  hot.end_sample();
  for (int i = 0; i < 3; ++i) {
    hot.add(zero, 4, 2, 0, 0);
    hot.end_sample();
  }
  CHECK(int(hot.average().pixel(0, 0)[0]) == 191);  // 3 / 4 * 255 = 191.25, not 255 / 4
}

namespace {

Image progressive(RayTracer& rt, const Scene& scene, RenderSettings s, uint32_t samples) {
  Accumulation acc;
  acc.reset(scene.width(), scene.height(), scene.environment().linear);
  TaskResult r;
  s.radiance = true;
  for (uint32_t i = 0; i < samples; ++i) {
    s.sample = i;
    rt.render({0, 0, scene.width(), scene.height()}, s, r);
    acc.add(r.radiance, scene.width(), scene.height(), 0, 0);
    acc.end_sample();
  }
  return acc.average();
}

}  // namespace

TEST_CASE("progressive samples: sample 0 is the fixed frame, and jitter anti-aliases an edge to its coverage", "[sampling][raytracer]") {
  // A white quad covering world x < 0 in front of a black background, seen head on: with an
  // odd width the edge runs down the middle of pixel column 16.
  Scene scene;
  const int W = 33, H = 9;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0, 0, 0}, {1, 1, 1}));
  Material m = matte({1, 1, 1});
  scene.set_material(1, m);
  add_object(scene, 100, quad({-50, -50, 0}, {50, 0, 0}, {0, 100, 0}), 1);
  scene.set_camera(look({0, 0, 10}, {0, 0, 0}, 30 * kDeg));
  RayTracer rt;
  RenderSettings s = no_ao();
  const Image fixed = render_full(rt, scene, s);
  Image one = progressive(rt, scene, s, 1);
  CHECK(one.rgba == fixed.rgba);
  Image avg = progressive(rt, scene, s, 64);
  for (int y = 0; y < H; ++y) {
    CHECK(px(avg, 14, y).r == 255);
    CHECK(px(avg, 18, y).r == 0);
    // Coverage 1/2: 64 stratified positions put about 32 on each side (one stratum of 64 is
    // the centre, on the edge).
    CHECK(std::abs(px(avg, 16, y).r - 128) <= 6);
  }
}

TEST_CASE("progressive samples: averaged AO (1 ray per sample) is unbiased against 256 AO rays at once, plain and sRGB",
          "[sampling][raytracer]") {
  // A floor and a wall meeting at a corner under a sky: the occlusion varies over the image.
  // On the sRGB curve the average must be taken before encoding: the mean of encoded one-ray
  // samples (each either lit or occluded) is far from the encoded mean (issue 18).
  for (bool linear : {false, true}) {
    Scene scene;
    const int W = 48, H = 32;
    scene.set_resolution(W, H);
    Environment env = plain_env({0, 0, 0}, {0.6f, 0.6f, 0.6f});
    env.linear = linear;
    scene.set_environment(env);
    scene.set_material(1, diffuse({1, 1, 1}));
    add_object(scene, 100, quad({-20, 0, 20}, {40, 0, 0}, {0, 0, -40}), 1);
    add_object(scene, 200, quad({-20, 0, 0}, {40, 0, 0}, {0, 20, 0}), 1);
    scene.set_camera(look({0, 2, 4}, {0, 0.5f, 0}, 60 * kDeg));
    RayTracer rt;
    RenderSettings many = no_ao();
    many.ao_samples = 256;
    many.ao_distance = 2;
    const Image ref = render_full(rt, scene, many);
    RenderSettings one = many;
    one.ao_samples = 1;
    const Image avg = progressive(rt, scene, one, 256);
    const Image single = progressive(rt, scene, one, 1);
    double bias = 0;
    for (size_t i = 0; i < ref.rgba.size(); i += 4) bias += double(avg.rgba[i]) - double(ref.rgba[i]);
    bias /= double(W * H);
    const double psnr_avg = compare(avg, ref).psnr, psnr_single = compare(single, ref).psnr;
    INFO((linear ? "sRGB" : "plain") << ": mean difference " << bias << " levels; PSNR 256 samples " << psnr_avg
                                     << " dB, 1 sample " << psnr_single << " dB");
    CHECK(std::abs(bias) < 1.0);
    CHECK(psnr_avg > 34);
    CHECK(psnr_avg > psnr_single + 15);
  }
}
