#pragma once
// Prediction that follows the camera (issue 22 item 1): the previous frame's per-packet cost,
// carried into the next frame's view before the tiler sees it.
//
// The paper predicts frame f from frame f-1's cost maps as if nothing moved. When the camera
// turns or walks, an expensive region (a glass wall, the water) moves across the image and
// the tiling lags one frame behind it. Here every packet of frame f-1 is forward-splatted
// with the new camera: its first-hit point (PacketPoints, from the renderer) is projected into
// frame f's image, and its cost is spread over the (up to four) packets its one-packet
// footprint centred there overlaps, with bilinear weights. A new packet keeps the nearest
// surface that covers at least a quarter of it (a depth test with a 2% margin: an occluder's
// cost is not mixed with the wall it hides; nearer surfaces covering less, an outline crossing
// it, are mixed in by their share). Packets that saw only sky are points at infinity and move
// with the rotation alone. Packets covered by less than a quarter (what the move uncovered,
// the border that came into view) are filled from their filled neighbours, ring by ring; what
// is still empty after that keeps the plain previous-frame cost.
//
// A cut (the new view shares little with the old one: under `min_coverage` of the packets got
// a splat) gives the unprojected map back, so the tiler never works from a mostly invented map.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/cost_map.h"
#include "core/rect.h"
#include "core/scene.h"

namespace tessera {

// The primary rays of a camera at a resolution, as the ray tracer makes them: the ray through
// pixel position (x, y) (pixel centres at +0.5) has direction
//   cz + cx * (2 x / width - 1) * sx_scale + cy * (1 - 2 y / height) * sy_scale.
struct ViewRays {
  Vec3 eye, cx, cy, cz;
  float sx_scale = 1, sy_scale = 1;
  int32_t width = 1, height = 1;
  double inv[9] = {};  // the inverse of the basis (columns cz, cx, cy), row-major
  bool ok = false;     // the basis is invertible (else nothing projects)
  static ViewRays of(const Camera& camera, int32_t width, int32_t height);
  // Pixel position (x, y) of a world point (w = 1) or direction (w = 0); false when it is
  // behind the camera or the view is degenerate. depth: distance along cz (+inf for directions).
  bool project(const float xyzw[4], float& x, float& y, float& depth) const;
  // The ray through pixel position (x, y), with unit coefficient on cz: the point at depth d
  // on it (project's depth) is eye + d * direction.
  Vec3 direction(float x, float y) const;
};

struct ReprojectStats {
  int64_t packets = 0;   // of the new view
  int64_t splatted = 0;  // covered by a quarter of a packet or more of footprints
  int64_t filled = 0;    // filled from neighbours
  int64_t kept = 0;      // nothing near: the previous frame's cost at the same packet
  bool cut = false;      // coverage under min_coverage: the unprojected map was returned
};

// The previous frame's cost map (covering packet space [0, W) x [0, H) of `layout` at the
// view's resolution) carried into `to`. `points` must cover the same packets; where it does
// not (a renderer that gives none), the map comes back unchanged (stats->cut).
// The wire form of a task's PacketPoints (TileResult::depth): one float32 per packet of
// points.packets, row-major, little endian (x86 peers' order, like the radiance): the depth
// of the packet's point along the view direction of the camera that rendered it
// (ViewRays::project), +inf for sky, NaN for nothing known. 4 bytes a packet, not 16: the
// receiver puts each point back on the ray through its packet's centre at that depth, within
// half a packet of where the mean hit projected, which the one-packet footprints blur anyway.
std::vector<uint8_t> encode_depths(const PacketPoints& points, const ViewRays& from);
// Decodes a task's depths over `packets` (packet space of `from`'s resolution in `layout`)
// into `into`, whose rectangle must contain them. False, writing nothing, when the size does
// not match or the rectangle is not inside `into`. Any float value is safe: one that is
// negative, NaN or zero gives w = -1 (nothing known); +inf gives the sky.
bool decode_depths(const uint8_t* data, size_t size, const Rect& packets, const ViewRays& from, PacketLayout layout,
                   PacketPoints& into);

CostMap reproject(const CostMap& cost, const PacketPoints& points, const ViewRays& to, PacketLayout layout,
                  ReprojectStats* stats = nullptr, double min_coverage = 0.5);

// The same at a coarser grain, for large frames: the map is carried in blocks of `block` x
// `block` packets (the cost summed, the points of each block merged into the mean of its surface
// points, else the mean sky direction), and each block's carried cost is spread evenly over its
// packets. About block^2 times less work; the tiler, which cuts at packet boundaries, then sees
// a map that is flat inside each block. block <= 1 is reproject(). stats count blocks.
CostMap reproject_blocks(const CostMap& cost, const PacketPoints& points, const ViewRays& to, PacketLayout layout,
                         int32_t block, ReprojectStats* stats = nullptr, double min_coverage = 0.5);

}  // namespace tessera
