#include "codecs/dxt1.h"

#include <squish.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstring>

namespace tessera {

size_t dxt1_size(int width, int height) {
  if (width <= 0 || height <= 0) return 0;
  return size_t((width + 3) / 4) * size_t((height + 3) / 4) * 8;
}

void dxt1_encode(const uint8_t* rgba, int width, int height, Dxt1Fit fit, uint8_t* blocks) {
  if (width <= 0 || height <= 0) return;
  const int bw = (width + 3) / 4, bh = (height + 3) / 4;
  const int flags = squish::kDxt1 | (fit == Dxt1Fit::cluster ? squish::kColourClusterFit : squish::kColourRangeFit);
  tbb::parallel_for(tbb::blocked_range<int>(0, bh), [&](const tbb::blocked_range<int>& rows) {
    uint8_t texels[64];
    for (int by = rows.begin(); by != rows.end(); ++by) {
      uint8_t* dst = blocks + size_t(by) * bw * 8;
      for (int bx = 0; bx < bw; ++bx, dst += 8) {
        // Gather the 4x4 block; texels beyond the image repeat the last column/row and are
        // masked out of the fit.
        int mask = 0;
        for (int y = 0; y < 4; ++y) {
          int sy = std::min(by * 4 + y, height - 1);
          for (int x = 0; x < 4; ++x) {
            int sx = std::min(bx * 4 + x, width - 1);
            std::memcpy(texels + (y * 4 + x) * 4, rgba + (size_t(sy) * width + sx) * 4, 4);
            texels[(y * 4 + x) * 4 + 3] = 255;
            if (bx * 4 + x < width && by * 4 + y < height) mask |= 1 << (y * 4 + x);
          }
        }
        squish::CompressMasked(texels, mask, dst, flags);
      }
    }
  });
}

void dxt1_encode(const Image& img, Dxt1Fit fit, std::vector<uint8_t>& out, size_t offset) {
  out.resize(offset + dxt1_size(img.width, img.height));
  dxt1_encode(img.rgba.data(), img.width, img.height, fit, out.data() + offset);
}

namespace {
struct Rgb {
  int r, g, b;
};
Rgb expand565(unsigned v) {
  int r = (v >> 11) & 31, g = (v >> 5) & 63, b = v & 31;
  return {(r << 3) | (r >> 2), (g << 2) | (g >> 4), (b << 3) | (b >> 2)};
}
}  // namespace

Image dxt1_decode(const uint8_t* blocks, int width, int height, bool transparent_black) {
  Image img(std::max(width, 0), std::max(height, 0));
  if (width <= 0 || height <= 0) return img;
  const int bw = (width + 3) / 4, bh = (height + 3) / 4;
  for (int by = 0; by < bh; ++by)
    for (int bx = 0; bx < bw; ++bx) {
      const uint8_t* b = blocks + (size_t(by) * bw + bx) * 8;
      unsigned c0 = b[0] | (b[1] << 8), c1 = b[2] | (b[3] << 8);
      uint32_t idx = uint32_t(b[4]) | (uint32_t(b[5]) << 8) | (uint32_t(b[6]) << 16) | (uint32_t(b[7]) << 24);
      Rgb p[4];
      int alpha[4] = {255, 255, 255, 255};
      p[0] = expand565(c0);
      p[1] = expand565(c1);
      if (c0 > c1) {
        p[2] = {(2 * p[0].r + p[1].r) / 3, (2 * p[0].g + p[1].g) / 3, (2 * p[0].b + p[1].b) / 3};
        p[3] = {(p[0].r + 2 * p[1].r) / 3, (p[0].g + 2 * p[1].g) / 3, (p[0].b + 2 * p[1].b) / 3};
      } else {
        p[2] = {(p[0].r + p[1].r) / 2, (p[0].g + p[1].g) / 2, (p[0].b + p[1].b) / 2};
        p[3] = {0, 0, 0};
        if (transparent_black) alpha[3] = 0;
      }
      for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 4; ++x) {
          int px = bx * 4 + x, py = by * 4 + y;
          if (px >= width || py >= height) continue;
          int i = (idx >> (2 * (y * 4 + x))) & 3;
          uint8_t* d = img.pixel(px, py);
          d[0] = uint8_t(p[i].r);
          d[1] = uint8_t(p[i].g);
          d[2] = uint8_t(p[i].b);
          d[3] = uint8_t(alpha[i]);
        }
    }
  return img;
}

}  // namespace tessera
