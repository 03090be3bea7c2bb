#include "renderer/denoise.h"

#include "renderer/adaptive.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <stdexcept>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "renderer/cpu.h"
#include "renderer/renderer.h"

namespace tessera {
namespace {

using raytracer_detail::cpu_avx2;
using raytracer_detail::cpu_avx512;

static_assert(kDenoiseGuideFloats == kGuideFloats, "denoise.h's guide count is renderer.h's");

// Offsets into one pixel's guides.
constexpr int kNormal = 0, kDistance = 3, kAmbient = 4, kOpen = 7;

constexpr float kB3[5] = {1.0f / 16, 1.0f / 4, 3.0f / 8, 1.0f / 4, 1.0f / 16};
constexpr float kGauss3[3] = {0.25f, 0.5f, 0.25f};
constexpr int kNormalSquarings = 7;  // the normals' weight: their cosine to the power 2^7 = 128 (SVGF's)

// 1 / max(1, |(dx, dy)|) of a tap, for the distance weight.
struct InvDist {
  float v[5][5];
  InvDist() {
    for (int dy = -2; dy <= 2; ++dy)
      for (int dx = -2; dx <= 2; ++dx) v[dy + 2][dx + 2] = 1.0f / std::max(1.0f, std::sqrt(float(dx * dx + dy * dy)));
  }
};
const InvDist kInvDist;

// What one a-trous pass reads (the guides, the values and variances, the weights' scales) and
// writes (the next values and variances).
struct Pass {
  const float *nx, *ny, *nz, *z, *val, *var, *v_scale, *z_scale;
  float *val2, *var2;
  int32_t width, height, step;
};

// What one row of a pass's weight scales reads and writes (scales_row).
struct Scales {
  const float *var, *grad, *z;
  float *v_scale, *z_scale;
  int32_t width, height, step;
  float sigma_value, sigma_distance;
};

// The most pixels interior() filters at once: its sums live on the stack (6 KB), and a span's
// working set (6 arrays on 5 rows, the pixels' own 7 and the sums: about 40 segments of 2 KB)
// stays in the second-level cache. (Whole 1280-pixel rows fit there too; the span's gain was
// not measured apart from the vectorised loops'.)
constexpr int32_t kSpan = 512;

// The pixel loops, once per instruction set (see renderer/denoise_pass.inc). -ffp-contract=off
// for this file (renderer/CMakeLists.txt): no copy fuses a multiply and an add, so all give
// the same bits.
namespace isa_sse {
#include "renderer/denoise_pass.inc"
}  // namespace isa_sse
#if defined(__clang__)
// clang ignores `#pragma GCC target`: one baseline copy (the sanitizer builds), as in raytracer.cpp.
namespace isa_avx2 = isa_sse;
namespace isa_avx512 = isa_sse;
#else
TESSERA_ISA_AVX2_BEGIN
namespace isa_avx2 {
#include "renderer/denoise_pass.inc"
}  // namespace isa_avx2
TESSERA_ISA_END
TESSERA_ISA_AVX512_BEGIN
namespace isa_avx512 {
#include "renderer/denoise_pass.inc"
}  // namespace isa_avx512
TESSERA_ISA_END
#endif

// The copy this CPU runs (the ray tracer's test), or the baseline one (DenoiseOptions).
struct PassCode {
  void (*pass_row)(const Pass&, int32_t);
  void (*scales_row)(const Scales&, int32_t);
};
PassCode pass_code(bool baseline) {
  if (!baseline && cpu_avx512()) return {isa_avx512::pass_row, isa_avx512::scales_row};
  if (!baseline && cpu_avx2()) return {isa_avx2::pass_row, isa_avx2::scales_row};
  return {isa_sse::pass_row, isa_sse::scales_row};
}

template <class Row>
void rows(int32_t height, Row&& row) {
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, height, 8), [&](const tbb::blocked_range<int32_t>& r) {
    for (int32_t y = r.begin(); y != r.end(); ++y) row(y);
  });
}

}  // namespace

void StillAo::reset(int32_t width, int32_t height) {
  width_ = width;
  height_ = height;
  samples_ = 0;
  sum_.assign(size_t(width) * size_t(height), 0.0);
  sum_sq_.assign(size_t(width) * size_t(height), 0.0);
}

void StillAo::add(const std::vector<float>& guides) {
  const size_t pixels = sum_.size();
  if (guides.size() != pixels * kGuideFloats) throw std::invalid_argument("StillAo::add: guides not the still's size");
  for (size_t p = 0; p < pixels; ++p) {
    const double v = guides[p * kGuideFloats + kOpen];
    sum_[p] += v;
    sum_sq_[p] += v * v;
  }
  ++samples_;
}

void StillAo::add_open(const std::vector<float>& open) {
  if (open.size() != sum_.size()) throw std::invalid_argument("StillAo::add_open: open fractions not the still's size");
  for (size_t p = 0; p < open.size(); ++p) {
    const double v = open[p];
    sum_[p] += v;
    sum_sq_[p] += v * v;
  }
  ++samples_;
}

std::vector<float> StillAo::mean() const {
  std::vector<float> m(sum_.size(), 0.0f);
  if (samples_ == 0) return m;
  for (size_t p = 0; p < m.size(); ++p) m[p] = float(sum_[p] / samples_);
  return m;
}

std::vector<float> StillAo::variance_of_mean(const std::vector<float>& guides) const {
  const size_t pixels = sum_.size();
  if (guides.size() != pixels * kGuideFloats) throw std::invalid_argument("StillAo: guides not the still's size");
  std::vector<float> var(pixels, 0.0f);
  if (samples_ == 0) return var;
  const double n = samples_;
  if (samples_ >= kSpatialVarianceBelow) {
    for (size_t p = 0; p < pixels; ++p) {
      const double m = sum_[p] / n;
      var[p] = float(std::max(0.0, (sum_sq_[p] / n - m * m) / (n - 1)));
    }
    return var;
  }
  // Few samples: the spread of the 3x3 neighbourhood's means on the same surface (normals
  // within about 25 degrees, both hits), which holds the mean's noise and the occlusion's own
  // detail; the latter only makes the filter more careful. Rows in parallel.
  rows(height_, [&](int32_t y) {
    for (int32_t x = 0; x < width_; ++x) {
      const size_t p = size_t(y) * size_t(width_) + size_t(x);
      const float* gp = &guides[p * kGuideFloats];
      double s = 0, s2 = 0;
      int k = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int32_t qx = x + dx, qy = y + dy;
          if (qx < 0 || qy < 0 || qx >= width_ || qy >= height_) continue;
          const size_t q = size_t(qy) * size_t(width_) + size_t(qx);
          const float* gq = &guides[q * kGuideFloats];
          const bool same = (gp[kDistance] >= 0) == (gq[kDistance] >= 0) &&
                            gp[0] * gq[0] + gp[1] * gq[1] + gp[2] * gq[2] >= 0.9f;
          if (q != p && !same) continue;
          const double m = sum_[q] / n;
          s += m;
          s2 += m * m;
          ++k;
        }
      const double m = s / k;  // k >= 1: the pixel itself
      var[p] = float(std::max(0.0, s2 / k - m * m));
    }
  });
  return var;
}

std::vector<float> denoise(const std::vector<float>& mean, const std::vector<float>& guides,
                           const std::vector<float>& open_mean, const std::vector<float>& open_variance,
                           int32_t width, int32_t height, const DenoiseOptions& o) {
  const size_t pixels = size_t(std::max(width, 0)) * size_t(std::max(height, 0));
  if (width < 0 || height < 0 || mean.size() != pixels * 3 || guides.size() != pixels * kGuideFloats ||
      open_mean.size() != pixels || open_variance.size() != pixels)
    throw std::invalid_argument("denoise: radiance, guides and open fractions must all be width x height");
  if (o.iterations < 0 || o.iterations > 10 || !(o.sigma_value > 0) || !(o.sigma_distance > 0))
    throw std::invalid_argument("denoise: iterations in 0..10, sigmas > 0");
  if (o.iterations == 0 || pixels == 0) return mean;

  // Structure of arrays: the guides; the open fraction and its variance, filtered pass after
  // pass. Pixels that show no ambient light take no part (z < 0, like misses).
  std::vector<float> nx(pixels), ny(pixels), nz(pixels), z(pixels), grad(pixels, 0.0f);
  std::vector<float> val(open_mean), var(open_variance), val2(pixels), var2(pixels), v_scale(pixels), z_scale(pixels);
  for (size_t p = 0; p < pixels; ++p) {
    const float* g = &guides[p * kGuideFloats];
    const bool shown = g[kDistance] >= 0 && (g[kAmbient] > 0 || g[kAmbient + 1] > 0 || g[kAmbient + 2] > 0);
    nx[p] = g[kNormal], ny[p] = g[kNormal + 1], nz[p] = g[kNormal + 2], z[p] = shown ? g[kDistance] : -1.0f;
  }
  // No pixel shows ambient light (a scene without a sky), or no open fraction is uncertain
  // (AO off, or a still whose samples all agree): nothing to filter.
  if (std::none_of(z.begin(), z.end(), [](float d) { return d >= 0; }) ||
      std::none_of(open_variance.begin(), open_variance.end(), [](float v) { return v > 0; }))
    return mean;
  const size_t W = size_t(width);
  rows(height, [&](int32_t y) {
    for (int32_t x = 0; x < width; ++x) {
      const size_t p = size_t(y) * W + size_t(x);
      if (z[p] < 0) continue;
      float gx = 0, gy = 0;
      if (x + 1 < width && z[p + 1] >= 0) gx = std::fabs(z[p + 1] - z[p]);
      if (x > 0 && z[p - 1] >= 0) gx = std::max(gx, std::fabs(z[p] - z[p - 1]));
      if (y + 1 < height && z[p + W] >= 0) gy = std::fabs(z[p + W] - z[p]);
      if (y > 0 && z[p - W] >= 0) gy = std::max(gy, std::fabs(z[p] - z[p - W]));
      grad[p] = std::max(gx, gy);
    }
  });

  const PassCode code = pass_code(o.baseline);
  for (int it = 0; it < o.iterations; ++it) {
    if (o.stop && o.stop->load(std::memory_order_relaxed)) return {};
    const int32_t step = int32_t(1) << it;
    // The value and distance weights' scales per pixel: the pixel's noise (its variance
    // blurred over 3x3) and its distance gradient over the taps' spacing.
    const Scales scales{var.data(), grad.data(), z.data(), v_scale.data(), z_scale.data(), width, height, step,
                        o.sigma_value, o.sigma_distance};
    rows(height, [&](int32_t y) { code.scales_row(scales, y); });
    const Pass pass{nx.data(), ny.data(), nz.data(), z.data(), val.data(), var.data(), v_scale.data(), z_scale.data(),
                    val2.data(), var2.data(), width, height, step};
    rows(height, [&](int32_t y) { code.pass_row(pass, y); });
    std::swap(val, val2);
    std::swap(var, var2);
  }
  // The radiance with the filtered occlusion instead of the noisy one.
  std::vector<float> out(mean);
  for (size_t p = 0; p < pixels; ++p) {
    if (!(z[p] >= 0)) continue;
    const float d = val[p] - open_mean[p];
    const float* a = &guides[p * kGuideFloats + kAmbient];
    for (int c = 0; c < 3; ++c) out[p * 3 + size_t(c)] = std::max(0.0f, out[p * 3 + size_t(c)] + a[c] * d);
  }
  return out;
}


double estimated_psnr_db(const std::vector<float>& mean, const std::vector<float>& guides,
                         const std::vector<float>& open_variance, int32_t width, int32_t height, bool srgb) {
  const size_t pixels = size_t(std::max(width, 0)) * size_t(std::max(height, 0));
  if (width < 0 || height < 0 || mean.size() != pixels * 3 || guides.size() != pixels * kGuideFloats ||
      open_variance.size() != pixels)
    throw std::invalid_argument("estimated_psnr_db: radiance, guides and variances must all be width x height");
  // Rows in parallel, each row's sum apart, added in row order: the same figure every time.
  std::vector<double> row_sums(size_t(std::max(height, 0)), 0.0);
  const size_t W = size_t(std::max(width, 0));
  rows(height, [&](int32_t y) {
    double row = 0;
    for (size_t p = size_t(y) * W; p < size_t(y + 1) * W; ++p) {
      const float v = open_variance[p];
      if (!(v > 0)) continue;
      const float* a = &guides[p * kGuideFloats + kAmbient];
      for (int c = 0; c < 3; ++c) {
        const double s = encoding_slope(mean[p * 3 + size_t(c)], srgb) * double(a[c]);
        row += s * s * double(v);
      }
    }
    row_sums[size_t(y)] = row;
  });
  double sum = 0;
  for (double r : row_sums) sum += r;
  if (pixels == 0 || !(sum > 0)) return std::numeric_limits<double>::infinity();
  return -10.0 * std::log10(sum / double(pixels * 3));
}

namespace {

// denoise_step for an Accumulation or an AdaptiveStill (mean(), average(), width(), height(), srgb()).
template <class Still>
DenoisedStep step_of(const Still& acc, const std::vector<float>& guides, const StillAo& ao, double below_db,
                     const DenoiseOptions& options) {
  DenoisedStep out;
  const auto stopped = [&] { return options.stop && options.stop->load(std::memory_order_relaxed); };
  if (stopped()) {
    out.stopped = true;
    return out;
  }
  const std::vector<float> mean = acc.mean(), var = ao.variance_of_mean(guides);
  out.estimate_db = estimated_psnr_db(mean, guides, var, acc.width(), acc.height(), acc.srgb());
  out.denoised = out.estimate_db < below_db;
  if (!out.denoised) {
    out.image = acc.average();
    return out;
  }
  const std::vector<float> filtered = denoise(mean, guides, ao.mean(), var, acc.width(), acc.height(), options);
  if (filtered.empty() && stopped()) {
    out.stopped = true;
    return out;
  }
  out.image = Accumulation::encode(filtered, acc.width(), acc.height(), acc.srgb());
  return out;
}

}  // namespace

DenoisedStep denoise_step(const Accumulation& acc, const std::vector<float>& guides, const StillAo& ao,
                          double below_db, const DenoiseOptions& options) {
  return step_of(acc, guides, ao, below_db, options);
}

DenoisedStep denoise_step(const AdaptiveStill& still, const std::vector<float>& guides, const StillAo& ao,
                          double below_db, const DenoiseOptions& options) {
  return step_of(still, guides, ao, below_db, options);
}

}  // namespace tessera
