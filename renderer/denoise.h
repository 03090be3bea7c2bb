#pragma once
// An edge-avoiding denoiser for the average of a still's first samples (issue 18 item 3): the
// spatial filter of SVGF (Schied et al. 2017), itself the edge-avoiding a-trous wavelet filter
// of Dammertz et al. 2010 with its value weight scaled by each pixel's estimated noise.
//
// What it filters: the only noise in our images is ambient occlusion's (and the sub-pixel
// jitter that anti-aliases edges, which averaging converges). So it filters the fraction of
// each pixel's AO rays that were open, at the primary hit (TaskResult::guides), and puts the
// difference back through the ambient light the pixel would show unoccluded. Reflections,
// refractions, textures and direct light are left exactly as rendered: no guide can blur them.
//
// - Five passes of a 5x5 B3-spline kernel, 1, 2, 4, 8 and 16 pixels apart (a 125x125
//   footprint), each tap weighted by how alike the two pixels' normals (their cosine to the
//   power 128), distances and open fractions are.
// - The open fraction's weight is measured against the noise of the pixel's mean: its samples'
//   variance over their count (StillAo), from the 3x3 neighbourhood's spread while there are
//   fewer than kSpatialVarianceBelow samples. Where the samples agree the filter keeps the
//   edges of the occlusion, and it smooths less as samples accumulate.
#include <atomic>
#include <cstdint>
#include <vector>

#include "renderer/accumulation.h"

namespace tessera {

constexpr int kDenoiseGuideFloats = 8;  // renderer.h's kGuideFloats (checked in denoise.cpp)
// The plain average's estimated PSNR (estimated_psnr_db) below which a refining still is
// denoised by default. The estimate reads 2-3 dB low on our low-discrepancy samples, and the
// denoised frame stays ahead of the plain one up to there (docs/renderer.md, "In the node"):
// past it the noise is out of sight, and handing over to the plain average costs little.
constexpr double kDenoiseBelowDb = 40.0;

struct DenoiseOptions {
  int iterations = 5;           // a-trous passes (tap spacing 1, 2, 4, ...); 0 returns the input
  float sigma_value = 4.0f;     // open-fraction distance, in standard deviations of the mean
  float sigma_distance = 1.0f;  // distance difference, in units of the local distance gradient
  bool baseline = false;        // the SSE2 copy of the pixel loops whatever the CPU (every copy
                                // gives the same bits: tests compare them)
  // Read before each pass: once raised, denoise() returns an empty vector and denoise_step a
  // step with `stopped` and no image (a still whose frame was abandoned).
  const std::atomic<bool>* stop = nullptr;
};

// A still's AO open fractions at its primary hits, per pixel, over its samples.
class StillAo {
 public:
  // Below this many samples the variance of a pixel's mean is estimated from its neighbours.
  static constexpr uint32_t kSpatialVarianceBelow = 4;
  void reset(int32_t width, int32_t height);
  // One sample's guides (TaskResult::guides).
  void add(const std::vector<float>& guides);
  // One sample's open fractions alone, one float a pixel (what a still's later samples carry
  // between nodes: their normals, distances and ambient light are the first sample's).
  void add_open(const std::vector<float>& open);
  uint32_t samples() const { return samples_; }
  std::vector<float> mean() const;
  // The variance of each pixel's mean; `guides` (the first sample's) tell which neighbours
  // lie on the same surface for the spatial estimate.
  std::vector<float> variance_of_mean(const std::vector<float>& guides) const;

 private:
  int32_t width_ = 0, height_ = 0;
  uint32_t samples_ = 0;
  std::vector<double> sum_, sum_sq_;
};

// Denoises `mean` (width * height RGB linear radiance, the average of a still's samples) with
// the still's first guides and its open fractions' mean and variance of the mean (StillAo);
// multi-threaded with TBB in the calling arena. Pixels whose primary ray missed, or that show
// no ambient light, come back as they are. Throws std::invalid_argument on sizes that do not
// match or options out of range.
std::vector<float> denoise(const std::vector<float>& mean, const std::vector<float>& guides,
                           const std::vector<float>& open_mean, const std::vector<float>& open_variance,
                           int32_t width, int32_t height, const DenoiseOptions& options = {});

// The PSNR (dB, of the 8-bit encoded image, as `tessera quality` measures it) that the plain
// average `mean` is estimated to have against the converged still, from its AO noise alone: per
// pixel and channel, the unoccluded ambient light squared times the open fraction's variance of
// the mean (StillAo), through the slope of the encoding at the mean (`srgb`: the sRGB curve,
// else plain; 0 where the value clips). It leaves out the aliasing that later samples still
// average away, so it is an upper bound of the true PSNR while AO dominates. +infinity when no
// pixel is noisy. Throws std::invalid_argument on sizes that do not match.
double estimated_psnr_db(const std::vector<float>& mean, const std::vector<float>& guides,
                         const std::vector<float>& open_variance, int32_t width, int32_t height, bool srgb);

// While a still is denoised, the steps shown: each of its first 4 samples, then each with a
// quarter more samples than the last one shown (`last_shown`), and its last (`target`). A
// denoising costs a third to a whole sample (docs/renderer.md); the samples between are
// averaged and not shown, so the still converges nearly as fast as a plain one, and each
// frame shown is better than the one before.
inline bool shown_while_denoising(uint32_t samples, uint32_t last_shown, uint32_t target) {
  const uint32_t step = last_shown / 4 > 1 ? last_shown / 4 : 1;
  return samples <= 4 || samples >= target || samples >= last_shown + step;
}

// One shown step of a still being denoised, by the node's rule (actors/frame_actor.cpp): the
// plain average's estimated PSNR and, below `below_db`, the average denoised with the still's
// first guides and open fractions, else the plain average; encoded as the renderer encodes.
struct DenoisedStep {
  Image image;
  double estimate_db = 0;
  bool denoised = false;
  bool stopped = false;  // DenoiseOptions::stop was raised: no image
};
DenoisedStep denoise_step(const Accumulation& acc, const std::vector<float>& guides, const StillAo& ao,
                          double below_db, const DenoiseOptions& options = {});
// The same for a still refined adaptively (renderer/adaptive.h), while its rounds are uniform.
class AdaptiveStill;
DenoisedStep denoise_step(const AdaptiveStill& still, const std::vector<float>& guides, const StillAo& ao,
                          double below_db, const DenoiseOptions& options = {});

// What a still being denoised holds beside its average, per pixel: the first sample's guides
// and the open fractions' sums and sums of squares (StillAo).
inline uint64_t denoise_bytes(int32_t width, int32_t height) {
  return uint64_t(width) * uint64_t(height) * (kDenoiseGuideFloats * sizeof(float) + 2 * sizeof(double));
}

}  // namespace tessera
