#pragma once
// Half-open integer rectangles, used both in pixel space and in packet space.
#include <algorithm>
#include <cstdint>

namespace tessera {

struct Rect {
  int32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // [x0, x1) x [y0, y1)

  constexpr int32_t width() const { return x1 > x0 ? x1 - x0 : 0; }
  constexpr int32_t height() const { return y1 > y0 ? y1 - y0 : 0; }
  constexpr int64_t area() const { return int64_t(width()) * height(); }
  constexpr bool empty() const { return width() == 0 || height() == 0; }
  constexpr bool contains(int32_t x, int32_t y) const { return x >= x0 && x < x1 && y >= y0 && y < y1; }
  constexpr bool contains(const Rect& r) const {
    return r.empty() || (r.x0 >= x0 && r.x1 <= x1 && r.y0 >= y0 && r.y1 <= y1);
  }
  friend constexpr bool operator==(const Rect& a, const Rect& b) {
    return a.x0 == b.x0 && a.y0 == b.y0 && a.x1 == b.x1 && a.y1 == b.y1;
  }
  friend constexpr bool operator!=(const Rect& a, const Rect& b) { return !(a == b); }
};

inline Rect intersect(const Rect& a, const Rect& b) {
  Rect r{std::max(a.x0, b.x0), std::max(a.y0, b.y0), std::min(a.x1, b.x1), std::min(a.y1, b.y1)};
  if (r.x1 < r.x0) r.x1 = r.x0;
  if (r.y1 < r.y0) r.y1 = r.y0;
  return r;
}

// Plan blocks (adaptive refinement, renderer/adaptive.h): kPlanBlock x kPlanBlock pixels, a
// unit every packet layout tiles. The blocks (in block coordinates, x0 = first pixel / kPlanBlock)
// that the pixels `r` touch:
constexpr int32_t kPlanBlock = 4;
inline Rect plan_blocks_of(const Rect& r) {
  return r.empty() ? Rect{} : Rect{r.x0 / kPlanBlock, r.y0 / kPlanBlock, (r.x1 + kPlanBlock - 1) / kPlanBlock,
                                   (r.y1 + kPlanBlock - 1) / kPlanBlock};
}

// The pixel footprint of one ray packet (2x2, 4x2 or 4x4, chosen from the CPU at run time).
struct PacketLayout {
  int32_t w = 4, h = 4;
  int32_t size() const { return w * h; }
};

// Packet space: packet (px, py) covers pixels [px*w, px*w+w) x [py*h, py*h+h), clipped to
// the image. An image of W x H pixels has ceil(W/w) x ceil(H/h) packets.
inline Rect packet_space(int32_t width, int32_t height, PacketLayout p) {
  return {0, 0, (width + p.w - 1) / p.w, (height + p.h - 1) / p.h};
}
inline Rect packets_to_pixels(const Rect& packets, PacketLayout p, int32_t width, int32_t height) {
  return intersect({packets.x0 * p.w, packets.y0 * p.h, packets.x1 * p.w, packets.y1 * p.h},
                   {0, 0, width, height});
}
// The packets a pixel rectangle touches (its edges rounded out to whole packets).
inline Rect pixels_to_packets(const Rect& pixels, PacketLayout p) {
  return {pixels.x0 / p.w, pixels.y0 / p.h, (pixels.x1 + p.w - 1) / p.w, (pixels.y1 + p.h - 1) / p.h};
}

}  // namespace tessera
