#pragma once
// The average of a still's progressive samples (renderer/sampling.h). Samples are averaged as
// linear radiance (TaskResult::radiance, asked for with RenderSettings::radiance) and encoded
// once, as the renderer encodes a frame: averaging the 8-bit encoded values instead would
// converge to the mean of the sRGB curve over the noise, which depends on how noisy each
// sample is (one AO ray or four), not to the image.
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/image.h"

namespace tessera {

// The slope of the renderer's encoding (Accumulation::encode) at linear value c, per unit of
// radiance, in units of the full 8-bit range (`srgb`: the sRGB curve, else plain); 0 where the
// value clips or is not a number: noise of variance v at c is about slope^2 v once encoded.
inline double encoding_slope(float c, bool srgb) {
  if (!(c < 1.0f)) return 0.0;
  if (!srgb) return 1.0;
  if (c <= 0.0031308f) return 12.92;
  return 1.055 / 2.4 * double(std::pow(c, 1.0f / 2.4f - 1.0f));
}

class Accumulation {
 public:
  // An empty average of width x height pixels; `srgb`: encode on the sRGB curve
  // (Environment::linear), else plainly, as the renderer does.
  void reset(int32_t width, int32_t height, bool srgb);
  // A tile of the current sample at (x, y): width * height RGB triples, row by row. It must fit.
  void add(const std::vector<float>& radiance, int32_t width, int32_t height, int32_t x, int32_t y);
  void end_sample() { ++samples_; }
  uint32_t samples() const { return samples_; }
  int32_t width() const { return width_; }
  int32_t height() const { return height_; }
  // The memory a width x height average holds.
  static uint64_t bytes(int32_t width, int32_t height) { return uint64_t(width) * uint64_t(height) * 3 * sizeof(float); }
  // The average, encoded (opaque alpha); an empty image before the first sample. With one
  // sample it is exactly the frame the renderer encoded.
  Image average() const;
  // The average as linear radiance (width * height RGB); empty before the first sample.
  std::vector<float> mean() const;
  // Linear radiance (width * height RGB) encoded as the renderer encodes a frame.
  static Image encode(const std::vector<float>& rgb, int32_t width, int32_t height, bool srgb);
  bool srgb() const { return srgb_; }

 private:
  template <class Value>
  void add_tile(size_t values, int32_t width, int32_t height, int32_t x, int32_t y, Value value);
  int32_t width_ = 0, height_ = 0;
  bool srgb_ = true;
  uint32_t samples_ = 0;
  std::vector<float> sum_;  // RGB per pixel (float: 12 bytes a pixel; 4096 samples of values
                            // near 1 keep a relative error near 1e-6, far below 8 bits)
};

}  // namespace tessera
