// The denoiser of a still's few-sample average (renderer/denoise.h): the ray tracer's guides
// describe its radiance exactly (the rest of a pixel is free of AO noise), the filter lowers
// the noise of flat occlusion without bleeding across surfaces, leaves what is not noisy as it
// is, and a denoised 4-sample still is closer to the converged one than the plain average.
#include <catch2/catch.hpp>

#include <atomic>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "renderer/accumulation.h"
#include "renderer/denoise.h"
#include "renderer/raytracer.h"
#include "scene_builders.h"

using namespace tessera;
using namespace tessera::testing;

namespace {

constexpr float kDeg = kPi / 180.0f;

// A floor and a low wall meeting at a corner under a sky (ambient 0.6) and a directional
// light; the image's top rows see the sky. White diffuse surfaces: the unoccluded ambient a
// pixel shows is the sky's ambient itself.
Scene corner(int W, int H) {
  Scene scene;
  scene.set_resolution(W, H);
  scene.set_environment(plain_env({0.1f, 0.2f, 0.3f}, {0.6f, 0.6f, 0.6f}));
  scene.set_material(1, diffuse({1, 1, 1}));
  add_object(scene, 100, quad({-20, 0, 20}, {40, 0, 0}, {0, 0, -40}), 1);
  add_object(scene, 200, quad({-20, 0, 0}, {40, 0, 0}, {0, 1.5f, 0}), 1);
  scene.set_light(1, directional({0.3f, -1, -0.5f}, 0.5f));
  scene.set_camera(look({0, 2, 4}, {0, 0.5f, 0}, 60 * kDeg));
  return scene;
}

// A ray tracer synced with the corner scene at W x H, and settings for a still's samples
// (AO rays 2 units long, linear radiance, no cost map).
struct Corner {
  Scene scene;
  RayTracer rt;
  RenderSettings s = no_ao();
  Corner(int W, int H) : scene(corner(W, H)) {
    std::vector<std::string> warnings;
    rt.sync(scene, warnings);
    s.ao_distance = 2;
    s.radiance = true;
    s.cost_map = false;
  }
};

const float* guide(const TaskResult& r, int32_t x, int32_t y) {
  return &r.guides[(size_t(y) * size_t(r.pixels.width()) + size_t(x)) * kGuideFloats];
}

// Per-pixel noisy means of open fractions: each pixel's N samples are open with probability
// truth(x, y) (a seeded coin per sample), written as guides of one sample each into `ao`.
template <class Truth>
void noisy_samples(StillAo& ao, std::vector<float>& first_guides, int W, int H, int N, Truth truth,
                   const std::vector<float>& normals) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0, 1);
  ao.reset(W, H);
  for (int s = 0; s < N; ++s) {
    std::vector<float> g(size_t(W) * H * kGuideFloats, 0.0f);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        float* o = &g[(size_t(y) * W + x) * kGuideFloats];
        const size_t p = size_t(y) * W + x;
        o[0] = normals[p * 3], o[1] = normals[p * 3 + 1], o[2] = normals[p * 3 + 2];
        o[3] = 5.0f;                   // distance: one flat depth
        o[4] = o[5] = o[6] = 1.0f;     // unoccluded ambient: 1, so radiance = open fraction
        o[7] = u(rng) < truth(x, y) ? 1.0f : 0.0f;
      }
    if (s == 0) first_guides = g;
    ao.add(g);
  }
}

std::vector<float> radiance_of(const std::vector<float>& open) {
  std::vector<float> rgb(open.size() * 3);
  for (size_t p = 0; p < open.size(); ++p) rgb[p * 3] = rgb[p * 3 + 1] = rgb[p * 3 + 2] = open[p];
  return rgb;
}

}  // namespace

TEST_CASE("guides: normal, distance, unoccluded ambient and open fraction describe the radiance", "[denoise][raytracer]") {
  const int W = 48, H = 32;
  Corner setup(W, H);
  RayTracer& rt = setup.rt;
  RenderSettings& s = setup.s;
  s.ao_samples = 4;
  s.guides = true;
  TaskResult a, b;
  rt.render({0, 0, W, H}, s, a);
  s.frame = 99;  // another AO pattern at the same pixel centres
  rt.render({0, 0, W, H}, s, b);
  REQUIRE(a.guides.size() == size_t(W) * H * kGuideFloats);
  int hits = 0, misses = 0, open_differs = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float* g = guide(a, x, y);
      const float* gb = guide(b, x, y);
      const size_t p = (size_t(y) * W + x) * 3;
      if (g[3] < 0) {  // a miss: the sky
        ++misses;
        CHECK(g[0] == 0.0f);
        CHECK(g[4] == 0.0f);
        CHECK(g[7] == 1.0f);
        continue;
      }
      ++hits;
      const float len = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
      CHECK(len == Approx(1.0f).margin(1e-4));
      CHECK((std::fabs(g[1] - 1.0f) < 1e-3f || std::fabs(g[2] - 1.0f) < 1e-3f));  // the floor or the wall
      CHECK(g[3] > 1.0f);
      CHECK(g[3] < 60.0f);
      for (int c = 0; c < 3; ++c) CHECK(g[4 + c] == Approx(0.6f).margin(1e-5));
      CHECK(g[7] >= 0.0f);
      CHECK(g[7] <= 1.0f);
      open_differs += g[7] != gb[7];
      // What is not ambient x open is the same whatever the AO rays did.
      for (int c = 0; c < 3; ++c) {
        const float rest_a = a.radiance[p + size_t(c)] - g[4 + c] * g[7];
        const float rest_b = b.radiance[p + size_t(c)] - gb[4 + c] * gb[7];
        CHECK(rest_a == Approx(rest_b).margin(1e-5));
      }
    }
  CHECK(hits > W * H / 2);
  CHECK(misses > 0);
  CHECK(open_differs > 0);  // the AO noise is there to filter
}

TEST_CASE("denoise: the noise of flat occlusion falls and does not bleed across surfaces", "[denoise]") {
  const int W = 64, H = 48, N = 4;
  // Left half faces +z with 80% open, right half faces +x with 20% open.
  std::vector<float> normals(size_t(W) * H * 3, 0.0f);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) normals[(size_t(y) * W + x) * 3 + (x < W / 2 ? 2 : 0)] = 1.0f;
  auto truth = [&](int x, int) { return x < W / 2 ? 0.8f : 0.2f; };
  StillAo ao;
  std::vector<float> guides;
  noisy_samples(ao, guides, W, H, N, truth, normals);
  const std::vector<float> mean = ao.mean();
  const std::vector<float> out = denoise(radiance_of(mean), guides, mean, ao.variance_of_mean(guides), W, H);
  double err_in = 0, err_out = 0;
  double edge_left = 0, edge_right = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const size_t p = size_t(y) * W + x;
      const double t = truth(x, y);
      err_in += (mean[p] - t) * (mean[p] - t);
      err_out += (out[p * 3] - t) * (out[p * 3] - t);
      if (x == W / 2 - 1) edge_left += out[p * 3];
      if (x == W / 2) edge_right += out[p * 3];
    }
  const double rms_in = std::sqrt(err_in / (W * H)), rms_out = std::sqrt(err_out / (W * H));
  INFO("RMS error of the open fraction: " << rms_in << " averaged, " << rms_out << " denoised");
  CHECK(rms_in > 0.1);
  CHECK(rms_out < rms_in / 3);
  // The columns either side of the edge keep their own surface's value.
  CHECK(edge_left / H == Approx(0.8).margin(0.06));
  CHECK(edge_right / H == Approx(0.2).margin(0.06));
}

TEST_CASE("denoise: what is not noisy comes back as it is", "[denoise]") {
  const int W = 40, H = 30;
  std::vector<float> normals(size_t(W) * H * 3, 0.0f);
  for (size_t p = 0; p < size_t(W) * H; ++p) normals[p * 3 + 2] = 1.0f;
  // Every sample the same: zero variance, a sharp pattern of occlusion.
  auto pattern = [](int x, int y) { return (x / 3 + y / 5) % 2 ? 1.0f : 0.0f; };
  StillAo ao;
  std::vector<float> guides;
  noisy_samples(ao, guides, W, H, 5, pattern, normals);
  std::vector<float> mean = ao.mean(), var = ao.variance_of_mean(guides);
  for (float v : var) REQUIRE(v == 0.0f);
  std::vector<float> rgb = radiance_of(mean);
  // A pixel with no ambient light and a miss keep their radiance whatever the filter does.
  auto at = [&](int x, int y) { return size_t(y) * W + x; };
  guides[at(5, 5) * kGuideFloats + 4] = guides[at(5, 5) * kGuideFloats + 5] = guides[at(5, 5) * kGuideFloats + 6] = 0;
  rgb[at(5, 5) * 3] = 0.123f;
  guides[at(9, 9) * kGuideFloats + 3] = -1;
  rgb[at(9, 9) * 3 + 1] = 0.456f;
  const std::vector<float> out = denoise(rgb, guides, mean, var, W, H);
  REQUIRE(out.size() == rgb.size());
  for (size_t i = 0; i < rgb.size(); ++i) CHECK(out[i] == Approx(rgb[i]).margin(1e-5));
  // No passes: the input itself.
  DenoiseOptions none;
  none.iterations = 0;
  CHECK(denoise(rgb, guides, mean, var, W, H, none) == rgb);
}

TEST_CASE("denoise: the AVX2 and AVX-512 copies of the pixel loops give the SSE2 copy's bits", "[denoise]") {
  // Wider than two of interior()'s spans (512 pixels), with surfaces of three normals, misses,
  // pixels without ambient light and depth steps, after 3 samples (the neighbours' variance).
  const int W = 1100, H = 37;
  std::vector<float> normals(size_t(W) * H * 3, 0.0f);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) normals[(size_t(y) * W + x) * 3 + size_t((x / 97 + y / 11) % 3)] = 1.0f;
  StillAo ao;
  std::vector<float> guides;
  noisy_samples(ao, guides, W, H, 3, [](int x, int y) { return 0.2f + 0.6f * float((x * 7 + y * 3) % 17) / 16.0f; },
                normals);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      float* g = &guides[(size_t(y) * W + x) * kGuideFloats];
      g[3] = (x + 2 * y) % 53 == 0 ? -1.0f : 2.0f + 0.01f * float(x % 300) + (x > 640 ? 3.0f : 0.0f);
      if ((x * 5 + y) % 41 == 0) g[4] = g[5] = g[6] = 0.0f;
    }
  const std::vector<float> mean = ao.mean(), var = ao.variance_of_mean(guides), rgb = radiance_of(mean);
  DenoiseOptions baseline;
  baseline.baseline = true;
  const std::vector<float> wide = denoise(rgb, guides, mean, var, W, H), sse = denoise(rgb, guides, mean, var, W, H, baseline);
  REQUIRE(wide.size() == sse.size());
  CHECK(std::memcmp(wide.data(), sse.data(), wide.size() * sizeof(float)) == 0);
  // And the filter did something here (the comparison is not of two copies of the input).
  CHECK(wide != rgb);
}

TEST_CASE("denoise and StillAo refuse inputs of the wrong size or options out of range", "[denoise]") {
  const int W = 8, H = 4;
  const size_t n = size_t(W) * H;
  std::vector<float> rgb(n * 3, 0.5f), guides(n * kGuideFloats, 0.0f), open(n, 1.0f), var(n, 0.0f);
  CHECK_NOTHROW(denoise(rgb, guides, open, var, W, H));
  CHECK_THROWS_AS(denoise(std::vector<float>(n * 3 - 1), guides, open, var, W, H), std::invalid_argument);
  CHECK_THROWS_AS(denoise(rgb, std::vector<float>(n * 7), open, var, W, H), std::invalid_argument);
  CHECK_THROWS_AS(denoise(rgb, guides, std::vector<float>(n + 1), var, W, H), std::invalid_argument);
  CHECK_THROWS_AS(denoise(rgb, guides, open, var, W + 1, H), std::invalid_argument);
  DenoiseOptions bad;
  bad.iterations = 11;
  CHECK_THROWS_AS(denoise(rgb, guides, open, var, W, H, bad), std::invalid_argument);
  bad = {};
  bad.sigma_value = 0;
  CHECK_THROWS_AS(denoise(rgb, guides, open, var, W, H, bad), std::invalid_argument);
  StillAo ao;
  ao.reset(W, H);
  CHECK_THROWS_AS(ao.add(std::vector<float>(n * kGuideFloats - 1)), std::invalid_argument);
  CHECK_THROWS_AS(ao.variance_of_mean(std::vector<float>(3)), std::invalid_argument);
}

TEST_CASE("StillAo: the variance of the mean, from the samples or (few samples) from the neighbours", "[denoise]") {
  const int W = 3, H = 3;
  StillAo ao;
  ao.reset(W, H);
  std::vector<float> g(size_t(W) * H * kGuideFloats, 0.0f);
  for (size_t p = 0; p < size_t(W) * H; ++p) g[p * kGuideFloats + 2] = 1, g[p * kGuideFloats + 3] = 1;
  // One sample: the centre's 3x3 neighbourhood holds four 1s and five 0s.
  for (size_t p = 0; p < size_t(W) * H; ++p) g[p * kGuideFloats + 7] = p % 2 ? 1.0f : 0.0f;
  ao.add(g);
  const double m = 4.0 / 9;
  CHECK(ao.variance_of_mean(g)[4] == Approx(m - m * m).epsilon(1e-5));
  // Four samples of the centre: 0, 1, 1, 1 -> sample variance 0.25, of the mean 0.0625.
  for (float v : {1.0f, 1.0f, 1.0f}) {
    g[4 * kGuideFloats + 7] = v;
    ao.add(g);
  }
  REQUIRE(ao.samples() == StillAo::kSpatialVarianceBelow);
  CHECK(ao.mean()[4] == Approx(0.75f));
  CHECK(ao.variance_of_mean(g)[4] == Approx(0.0625f).epsilon(1e-5));
}

TEST_CASE("denoise: a 4-sample still comes closer to the converged one than its plain average", "[denoise][raytracer]") {
  const int W = 96, H = 64;
  Corner setup(W, H);
  RayTracer& rt = setup.rt;
  const RenderSettings& s = setup.s;
  auto still = [&](int ao_rays, uint32_t samples, uint32_t frame, StillAo* ao, std::vector<float>* first) {
    Accumulation acc;
    acc.reset(W, H, false);
    RenderSettings t = s;
    t.ao_samples = ao_rays;
    t.frame = frame;
    t.guides = ao != nullptr;
    if (ao) ao->reset(W, H);
    TaskResult r;
    for (uint32_t i = 0; i < samples; ++i) {
      t.sample = i;
      rt.render({0, 0, W, H}, t, r);
      acc.add(r.radiance, W, H, 0, 0);
      acc.end_sample();
      if (!ao) continue;
      if (i == 0) *first = r.guides;
      ao->add(r.guides);
    }
    return acc;
  };
  const Image ref = still(4, 128, 12345, nullptr, nullptr).average();
  StillAo ao;
  std::vector<float> first;
  const Accumulation acc = still(1, 4, 1, &ao, &first);
  const Image plain = acc.average();
  const Image denoised =
      Accumulation::encode(denoise(acc.mean(), first, ao.mean(), ao.variance_of_mean(first), W, H), W, H, false);
  const double db_plain = compare(plain, ref).psnr, db_denoised = compare(denoised, ref).psnr;
  INFO("PSNR against 128 samples: 4 samples " << db_plain << " dB, denoised " << db_denoised << " dB");
  CHECK(db_denoised > db_plain + 3);

  // The frame actor's step, with a stop flag (raised when the still's frame is abandoned):
  // lowered, the same bits; raised, nothing filtered and no image.
  std::atomic<bool> stop{false};
  DenoiseOptions o;
  o.stop = &stop;
  const DenoisedStep go = denoise_step(acc, first, ao, 99.0, o);
  CHECK(!go.stopped);
  CHECK(go.denoised);
  CHECK(go.image.rgba == denoised.rgba);
  stop = true;
  CHECK(denoise(acc.mean(), first, ao.mean(), ao.variance_of_mean(first), W, H, o).empty());
  const DenoisedStep halted = denoise_step(acc, first, ao, 99.0, o);
  CHECK(halted.stopped);
  CHECK(halted.image.rgba.empty());
}

TEST_CASE("StillAo::add_open adds what add adds of the same sample", "[denoise]") {
  const int W = 16, H = 8;
  std::vector<float> normals(size_t(W) * H * 3, 0.0f);
  for (size_t p = 0; p < size_t(W) * H; ++p) normals[p * 3 + 2] = 1.0f;
  StillAo all, open_only;
  std::vector<float> first;
  noisy_samples(all, first, W, H, 6, [](int x, int) { return 0.1f + 0.05f * float(x); }, normals);
  // The same samples again (the same seed), the first with all its guides, the rest alone.
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0, 1);
  open_only.reset(W, H);
  for (int s = 0; s < 6; ++s) {
    std::vector<float> open(size_t(W) * H);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) open[size_t(y) * W + x] = u(rng) < 0.1f + 0.05f * float(x) ? 1.0f : 0.0f;
    if (s == 0) {
      std::vector<float> g = first;
      for (size_t p = 0; p < open.size(); ++p) g[p * kGuideFloats + 7] = open[p];
      open_only.add(g);
    } else {
      open_only.add_open(open);
    }
  }
  CHECK(open_only.samples() == all.samples());
  CHECK(open_only.mean() == all.mean());
  CHECK(open_only.variance_of_mean(first) == all.variance_of_mean(first));
  CHECK_THROWS_AS(open_only.add_open(std::vector<float>(size_t(W) * H - 1)), std::invalid_argument);
}

TEST_CASE("estimated_psnr_db: the plain average's PSNR from its AO noise", "[denoise]") {
  const int W = 32, H = 16;
  const size_t pixels = size_t(W) * H;
  std::vector<float> guides(pixels * kGuideFloats, 0.0f), mean(pixels * 3, 0.5f), var(pixels, 0.01f);
  for (size_t p = 0; p < pixels; ++p) {
    guides[p * kGuideFloats + 2] = 1.0f;
    guides[p * kGuideFloats + 3] = 5.0f;
    for (int c = 0; c < 3; ++c) guides[p * kGuideFloats + 4 + size_t(c)] = 0.5f;
  }
  SECTION("plain encoding: ambient^2 x variance is the error's MSE") {
    // 0.5^2 x 0.01 = 0.0025 in every pixel and channel: 10 log10(1 / 0.0025) = 26.02 dB.
    CHECK(estimated_psnr_db(mean, guides, var, W, H, false) == Approx(26.0206).margin(1e-3));
    // Half the pixels noise-free: half the MSE, 3 dB more.
    for (size_t p = 0; p < pixels / 2; ++p) var[p] = 0.0f;
    CHECK(estimated_psnr_db(mean, guides, var, W, H, false) == Approx(26.0206 + 3.0103).margin(1e-3));
    // Pixels that show no ambient light (misses, unlit) or clip at white add nothing.
    for (size_t p = pixels / 2; p < pixels; ++p) mean[p * 3] = mean[p * 3 + 1] = mean[p * 3 + 2] = 1.5f;
    CHECK(std::isinf(estimated_psnr_db(mean, guides, var, W, H, false)));
  }
  SECTION("sRGB: through the curve's slope at the mean") {
    // The slope of the sRGB encoding at 0.5, from the encoding itself: 8-bit steps over a span.
    Image lo = Accumulation::encode(std::vector<float>(3, 0.45f), 1, 1, true);
    Image hi = Accumulation::encode(std::vector<float>(3, 0.55f), 1, 1, true);
    const double slope = double(hi.rgba[0] - lo.rgba[0]) / 255.0 / 0.1;
    const double want = -10 * std::log10(slope * slope * 0.25 * 0.01);
    CHECK(estimated_psnr_db(mean, guides, var, W, H, true) == Approx(want).margin(0.15));
  }
  SECTION("no noise: +infinity; sizes must match") {
    std::fill(var.begin(), var.end(), 0.0f);
    CHECK(std::isinf(estimated_psnr_db(mean, guides, var, W, H, true)));
    CHECK_THROWS_AS(estimated_psnr_db(mean, guides, std::vector<float>(pixels - 1), W, H, true), std::invalid_argument);
  }
}

TEST_CASE("estimated_psnr_db matches the measured PSNR of independent samples' average", "[denoise]") {
  // Independent coin flips per sample (no low-discrepancy sequence, which converges faster
  // than this estimate assumes): the estimate from the samples' own variance meets the error
  // of their average against the truth.
  const int W = 96, H = 64;
  std::vector<float> normals(size_t(W) * H * 3, 0.0f);
  for (size_t p = 0; p < size_t(W) * H; ++p) normals[p * 3 + 2] = 1.0f;
  auto truth = [](int x, int y) { return 0.2f + 0.6f * float((x / 8 + y / 8) % 2); };
  for (int N : {8, 32}) {
    StillAo ao;
    std::vector<float> first;
    noisy_samples(ao, first, W, H, N, truth, normals);
    const std::vector<float> mean = radiance_of(ao.mean());  // ambient 1: radiance = open fraction
    double mse = 0;
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const double d = mean[(size_t(y) * W + x) * 3] - truth(x, y);
        mse += d * d;
      }
    const double measured = -10 * std::log10(mse / (double(W) * H));
    const double estimate = estimated_psnr_db(mean, first, ao.variance_of_mean(first), W, H, false);
    INFO("N = " << N << ": measured " << measured << " dB, estimated " << estimate << " dB");
    CHECK(std::fabs(estimate - measured) < 0.5);
  }
}
