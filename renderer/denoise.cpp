#include "renderer/denoise.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <stdexcept>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "renderer/renderer.h"

namespace tessera {
namespace {

static_assert(kDenoiseGuideFloats == kGuideFloats, "denoise.h's guide count is renderer.h's");

// Offsets into one pixel's guides.
constexpr int kNormal = 0, kDistance = 3, kAmbient = 4, kOpen = 7;

// exp(-e) for e >= 0 to about 1e-3 relative (a weight, not a result): 2^-(e log2 e) as a
// power of two times a quartic in the fraction. Large e, +inf and NaN give 0. Branch-free
// (selects), so that loops over pixels vectorise.
inline float exp_neg(float e) {
  const float x0 = e * 1.44269504f;
  const bool small = x0 < 126.0f;  // false for large e, +inf and NaN
  const float x = small ? x0 : 0.0f;
  const int32_t i = int32_t(x);  // x >= 0: truncation is the floor
  const float f = x - float(i);
  const float poly = 1.0f + f * (-0.69314718f + f * (0.24022651f + f * (-0.05550411f + f * 0.00961813f)));
  const uint32_t bits = uint32_t(127 - i) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof scale);
  return small ? poly * scale : 0.0f;
}

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

// A tap's weight: the B3 kernel's, times how alike p and q are in normal (their cosine), open
// fraction (dval) and distance (dz) on p's scales. q not taking part (qz < 0) weighs nothing:
// a factor, not a branch, so that interior()'s loop vectorises.
inline float tap_weight(float cosn, float dval, float dz, float v_scale, float z_scale, float kernel, float inv_d,
                        float qz) {
  float wn = cosn > 0.0f ? cosn : 0.0f;
  static_assert(kNormalSquarings == 7, "the squarings below");
  wn *= wn, wn *= wn, wn *= wn, wn *= wn, wn *= wn, wn *= wn, wn *= wn;
  const float e = std::fabs(dval) * v_scale + std::fabs(dz) * z_scale * inv_d;
  return kernel * wn * exp_neg(e) * (qz >= 0 ? 1.0f : 0.0f);
}

// One tap: q's weight for p, added to p's sums.
inline void tap(const Pass& a, size_t p, size_t q, float kernel, float inv_d, float& sv, float& svar, float& sw) {
  const float w = tap_weight(a.nx[p] * a.nx[q] + a.ny[p] * a.ny[q] + a.nz[p] * a.nz[q], a.val[p] - a.val[q],
                             a.z[p] - a.z[q], a.v_scale[p], a.z_scale[p], kernel, inv_d, a.z[q]);
  sv += w * a.val[q];
  svar += w * w * a.var[q];
  sw += w;
}

// The filtered pixel from its sums; one not taking part, or with no weight (guides not
// finite), stays as it is.
inline void put(const Pass& a, size_t p, float sv, float svar, float sw) {
  const bool keep = !(a.z[p] >= 0) || !(sw > 0);
  const float inv = keep ? 0.0f : 1.0f / sw;
  a.val2[p] = keep ? a.val[p] : sv * inv;
  a.var2[p] = keep ? a.var[p] : svar * inv * inv;
}

// Pixels [x0, x1) of row y, all of whose taps lie inside the row's width: tap after tap over
// the whole span, in loops that vectorise (with -fno-trapping-math: renderer/CMakeLists.txt).
// sums: room for 3 (x1 - x0) floats.
void interior(const Pass& a, int32_t y, int32_t x0, int32_t x1, float* sums) {
  const size_t n = size_t(x1 - x0), W = size_t(a.width), row = size_t(y) * W + size_t(x0);
  float* __restrict sv = sums;
  float* __restrict svar = sv + n;
  float* __restrict sw = svar + n;
  std::fill(sums, sums + 3 * n, 0.0f);
  // The span's own pixels (p) as plain pointers, so that the loop below is one the
  // vectoriser reads: every access an affine function of i.
  const float *__restrict pnx = a.nx + row, *__restrict pny = a.ny + row, *__restrict pnz = a.nz + row;
  const float *__restrict pz = a.z + row, *__restrict pval = a.val + row;
  const float *__restrict pvs = a.v_scale + row, *__restrict pzs = a.z_scale + row;
  for (int dy = -2; dy <= 2; ++dy) {
    const int32_t qy = y + dy * a.step;
    if (qy < 0 || qy >= a.height) continue;
    for (int dx = -2; dx <= 2; ++dx) {
      const float kernel = kB3[dx + 2] * kB3[dy + 2], inv_d = kInvDist.v[dy + 2][dx + 2];
      const size_t q0 = size_t(ptrdiff_t(row) + ptrdiff_t(qy - y) * ptrdiff_t(W) + ptrdiff_t(dx) * a.step);
      const float *__restrict qnx = a.nx + q0, *__restrict qny = a.ny + q0, *__restrict qnz = a.nz + q0;
      const float *__restrict qz = a.z + q0, *__restrict qval = a.val + q0, *__restrict qvar = a.var + q0;
      // The pointers only read what the loop never writes (sums is scratch space of its own).
#if defined(__GNUC__) && !defined(__clang__)  // (clang builds are the sanitizer builds, at -O1)
#pragma GCC ivdep
#endif
      for (size_t i = 0; i < n; ++i) {
        const float w = tap_weight(pnx[i] * qnx[i] + pny[i] * qny[i] + pnz[i] * qnz[i], pval[i] - qval[i],
                                   pz[i] - qz[i], pvs[i], pzs[i], kernel, inv_d, qz[i]);
        sv[i] += w * qval[i];
        svar[i] += w * w * qvar[i];
        sw[i] += w;
      }
    }
  }
  for (size_t i = 0; i < n; ++i) put(a, row + i, sv[i], svar[i], sw[i]);
}

// A pixel near the left or right edge, with bounds checks.
void border(const Pass& a, int32_t y, int32_t x) {
  const size_t W = size_t(a.width);
  float v = 0, vv = 0, w = 0;
  for (int dy = -2; dy <= 2; ++dy) {
    const int32_t qy = y + dy * a.step;
    if (qy < 0 || qy >= a.height) continue;
    for (int dx = -2; dx <= 2; ++dx) {
      const int32_t qx = x + dx * a.step;
      if (qx < 0 || qx >= a.width) continue;
      tap(a, size_t(y) * W + size_t(x), size_t(qy) * W + size_t(qx), kB3[dx + 2] * kB3[dy + 2],
          kInvDist.v[dy + 2][dx + 2], v, vv, w);
    }
  }
  put(a, size_t(y) * W + size_t(x), v, vv, w);
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
  // detail; the latter only makes the filter more careful.
  for (int32_t y = 0; y < height_; ++y)
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

  for (int it = 0; it < o.iterations; ++it) {
    const int32_t step = int32_t(1) << it;
    // The value and distance weights' scales per pixel: the pixel's noise (its variance
    // blurred over 3x3) and its distance gradient over the taps' spacing.
    rows(height, [&](int32_t y) {
      for (int32_t x = 0; x < width; ++x) {
        const size_t p = size_t(y) * W + size_t(x);
        float v = 0, vw = 0;
        for (int dy = -1; dy <= 1; ++dy) {
          const int32_t qy = y + dy;
          if (qy < 0 || qy >= height) continue;
          for (int dx = -1; dx <= 1; ++dx) {
            const int32_t qx = x + dx;
            if (qx < 0 || qx >= width) continue;
            const float k = kGauss3[dx + 1] * kGauss3[dy + 1];
            v += k * var[size_t(qy) * W + size_t(qx)];
            vw += k;
          }
        }
        v_scale[p] = 1.0f / (o.sigma_value * std::sqrt(std::max(v / vw, 0.0f)) + 1e-6f);
        z_scale[p] = 1.0f / (o.sigma_distance * grad[p] * float(step) + 1e-3f * std::max(z[p], 0.0f) + 1e-6f);
      }
    });
    const Pass pass{nx.data(), ny.data(), nz.data(), z.data(), val.data(), var.data(), v_scale.data(), z_scale.data(),
                    val2.data(), var2.data(), width, height, step};
    rows(height, [&](int32_t y) {
      // Pixels whose taps all lie inside the row's width: tap after tap over all of them
      // (loops that vectorise); the others one by one, with bounds checks.
      const int32_t x0 = std::min(width, 2 * step), x1 = std::max(x0, width - 2 * step);
      std::vector<float> sums(3 * size_t(x1 - x0));
      interior(pass, y, x0, x1, sums.data());
      for (int32_t x = 0; x < width; x = x + 1 == x0 ? x1 : x + 1) border(pass, y, x);
    });
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
  // The encoding's slope (per unit of linear radiance, in units of the full 8-bit range).
  auto slope = [srgb](float c) -> double {
    if (!(c < 1.0f)) return 0.0;  // clips (or not a number)
    if (!srgb) return 1.0;
    if (c <= 0.0031308f) return 12.92;
    return 1.055 / 2.4 * std::pow(double(c), 1.0 / 2.4 - 1.0);
  };
  double sum = 0;
  for (size_t p = 0; p < pixels; ++p) {
    const float v = open_variance[p];
    if (!(v > 0)) continue;
    const float* a = &guides[p * kGuideFloats + kAmbient];
    for (int c = 0; c < 3; ++c) {
      const double s = slope(mean[p * 3 + size_t(c)]) * double(a[c]);
      sum += s * s * double(v);
    }
  }
  if (pixels == 0 || !(sum > 0)) return std::numeric_limits<double>::infinity();
  return -10.0 * std::log10(sum / double(pixels * 3));
}

DenoisedStep denoise_step(const Accumulation& acc, const std::vector<float>& guides, const StillAo& ao,
                          double below_db, const DenoiseOptions& options) {
  const std::vector<float> mean = acc.mean(), var = ao.variance_of_mean(guides);
  DenoisedStep out;
  out.estimate_db = estimated_psnr_db(mean, guides, var, acc.width(), acc.height(), acc.srgb());
  out.denoised = out.estimate_db < below_db;
  out.image = out.denoised ? Accumulation::encode(denoise(mean, guides, ao.mean(), var, acc.width(), acc.height(), options),
                                                  acc.width(), acc.height(), acc.srgb())
                           : acc.average();
  return out;
}

}  // namespace tessera
