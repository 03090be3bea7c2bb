#pragma once
// Per-packet rendering cost of one task (paper section 6.1).
//
// Unit: one cost unit is one nanosecond of a core running at the node's nominal TSC
// frequency: cost = tsc_ticks * 1e6 / tsc_khz. A 32-bit entry overflows only for a
// single packet that takes more than 4.29 s, which no real-time frame comes near; the
// *sum* over a frame does overflow 32 bits (a 1280x720 frame with 8 AO rays costs several
// seconds of core time on one node), so summed-area tables use 64-bit entries (sat.h).
#include <cstdint>
#include <vector>

#include "core/rect.h"

namespace tessera {

struct CostMap {
  Rect packets;                 // the task's rectangle in packet space
  std::vector<uint32_t> cost;   // packets.width() * packets.height(), row-major

  uint32_t at(int32_t px, int32_t py) const {  // absolute packet coordinates
    return cost[size_t(py - packets.y0) * packets.width() + size_t(px - packets.x0)];
  }
  uint64_t total() const {
    uint64_t s = 0;
    for (uint32_t c : cost) s += c;
    return s;
  }
};

// What each packet of a task saw first (for the balancer's reprojection, lb/reproject.h):
// per packet four floats x, y, z, w in world coordinates. w = 1: the mean first-hit point of
// the packet's rays that hit its nearest surface (within 10% of the nearest hit's distance);
// w = 0: none hit, (x, y, z) is the packet's mean ray direction (a point at infinity: the
// sky); w = -1: no valid ray (nothing known).
struct PacketPoints {
  Rect packets;
  std::vector<float> xyzw;  // 4 per packet, row-major like CostMap::cost
};

}  // namespace tessera
