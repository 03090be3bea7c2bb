#include "renderer/accumulation.h"

#include <algorithm>
#include <stdexcept>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "renderer/raytracer_impl.h"

namespace tessera {

void Accumulation::reset(int32_t width, int32_t height, bool srgb) {
  width_ = width;
  height_ = height;
  srgb_ = srgb;
  samples_ = 0;
  sum_.assign(size_t(width) * size_t(height) * 3, 0.0f);
}

// Adds a tile whose i-th value `value(i)` gives (RGB triples, row by row).
template <class Value>
void Accumulation::add_tile(size_t values, int32_t width, int32_t height, int32_t x, int32_t y, Value value) {
  if (x < 0 || y < 0 || width < 0 || height < 0 || x + width > width_ || y + height > height_ ||
      values != size_t(width) * size_t(height) * 3)
    throw std::invalid_argument("Accumulation: a tile outside the frame, or not its size");
  for (int32_t ty = 0; ty < height; ++ty) {
    const size_t row = size_t(ty) * size_t(width) * 3;
    float* dst = &sum_[(size_t(y + ty) * size_t(width_) + size_t(x)) * 3];
    for (size_t i = 0; i < size_t(width) * 3; ++i) dst[i] += value(row + i);
  }
}

void Accumulation::add(const std::vector<float>& radiance, int32_t width, int32_t height, int32_t x, int32_t y) {
  add_tile(radiance.size(), width, height, x, y, [&](size_t i) { return radiance[i]; });
}

std::vector<float> Accumulation::mean() const {
  if (samples_ == 0) return {};
  std::vector<float> out(sum_.size());
  const float inv = 1.0f / float(samples_);
  for (size_t i = 0; i < sum_.size(); ++i) out[i] = sum_[i] * inv;  // one sample: exactly the renderer's value
  return out;
}

namespace {

// width x height pixels whose RGB value i is value(i), encoded as the renderer encodes a frame.
// Rows in parallel (TBB, the calling arena): every refined frame of a still goes through here.
// The values are encoded in runs of contiguous values, one loop per encoding (vector code), and
// then spread into RGBA; encoding each value where it lands in RGBA, with the encoding chosen
// per value, was scalar: 10 ms a 1280x720 frame on one thread.
template <bool Srgb, class Value>
void encode_rows(Image& out, size_t begin, size_t end, Value value) {
  constexpr size_t kRun = 256;  // pixels
  alignas(64) uint8_t codes[kRun * 3];
  uint8_t* __restrict dst = out.rgba.data();
  for (size_t p0 = begin; p0 < end; p0 += kRun) {
    const size_t n = std::min(kRun, end - p0);
    for (size_t i = 0; i < n * 3; ++i) {
      const float v = value(p0 * 3 + i);
      codes[i] = uint8_t(Srgb ? raytracer_detail::encode_srgb(v) : raytracer_detail::encode_plain(v));
    }
    for (size_t k = 0; k < n; ++k) {
      dst[(p0 + k) * 4] = codes[k * 3];
      dst[(p0 + k) * 4 + 1] = codes[k * 3 + 1];
      dst[(p0 + k) * 4 + 2] = codes[k * 3 + 2];
      dst[(p0 + k) * 4 + 3] = 255;
    }
  }
}

template <class Value>
Image encode_values(int32_t width, int32_t height, bool srgb, Value value) {
  Image out(width, height);
  const size_t W = size_t(std::max(width, 0));
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, std::max(height, 0), 16), [&](const tbb::blocked_range<int32_t>& r) {
    const size_t begin = size_t(r.begin()) * W, end = size_t(r.end()) * W;
    if (srgb)
      encode_rows<true>(out, begin, end, value);
    else
      encode_rows<false>(out, begin, end, value);
  });
  return out;
}

}  // namespace

Image Accumulation::encode(const std::vector<float>& rgb, int32_t width, int32_t height, bool srgb) {
  if (width < 0 || height < 0 || rgb.size() != size_t(width) * size_t(height) * 3)
    throw std::invalid_argument("Accumulation::encode: radiance not width x height RGB");
  return encode_values(width, height, srgb, [&](size_t i) { return rgb[i]; });
}

// Encoded straight from the sums (no mean() copy: this runs for every refined frame).
Image Accumulation::average() const {
  if (samples_ == 0) return {};
  const float inv = 1.0f / float(samples_);
  return encode_values(width_, height_, srgb_, [&](size_t i) { return sum_[i] * inv; });
}

}  // namespace tessera
