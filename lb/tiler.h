#pragma once
// Static load balancing: the tiling of packet space into one task per rendering node for
// the next frame, from the SAT array of the previous frame (paper section 6.3).
#include <cstdint>
#include <vector>

#include "core/rect.h"
#include "lb/sat.h"

namespace tessera {

// What the cluster operator states about a node (paper 6.3): its logical cores and the
// single-core performance relative to the weakest cores of the cluster (>= 1 by convention,
// any finite value > 0 accepted). The single-core coefficient also goes with the node's SAT
// into SatArray::add, which normalises the node's measured costs with it.
struct NodeCoefficient {
  int32_t logical_cores = 1;
  double single_core_perf = 1.0;
  // Renderer coefficient: logical cores x single-core performance coefficient.
  double renderer() const { return double(logical_cores) * single_core_perf; }
};

// Renderer coefficients of a list of nodes; throws std::invalid_argument when a node has
// fewer than one core or a performance coefficient that is not finite and > 0.
std::vector<double> renderer_coefficients(const std::vector<NodeCoefficient>& nodes);

struct TilerOptions {
  // Recurse into the two halves of a split in parallel (TBB, calling thread's arena) while a
  // tile holds at least this many nodes; 0 disables parallel tiling.
  int32_t parallel_min_nodes = 1024;
};

// Splits packet_space into coefficients.size() tasks; result[i] is node i's task.
//
// The tile holding all nodes is split recursively; the first split cuts across the longer
// axis of packet_space (x on ties) and the axis alternates on each level, except that a
// tile one packet thick is always cut across its other axis. A tile's nodes (a contiguous
// range of node indices) are halved; with an odd count the extra node goes to the side that
// brings the two sides' coefficient sums closest (the second side on ties). The split line is
// found by binary search so that the first side's normalised cost is as close as possible to
// (its coefficient sum / the tile's sum) x the tile's cost; its error is at most half the cost
// of the packet line (row or column of the tile) the ideal split falls into. Leaves are
// assigned in depth-first order, so node i keeps roughly the same area from frame to frame.
//
// Costs come from sats (normalised, missing area filled as SatArray documents). With no
// SAT array (first frame), or where a tile's cost is zero, tiles are split by area instead.
// Tasks cover packet_space exactly, without overlap. A task is empty (Rect{}) when there are
// more nodes than packets, or when a single packet line at a tile's border costs more than
// twice a side's share (the nearest split is then the border).
//
// Throws std::invalid_argument when coefficients is empty or holds a value that is not
// finite and > 0, when sats is not finalized, or packet_space is not inside its space.
std::vector<Rect> tile(const SatArray* sats, Rect packet_space, const std::vector<double>& coefficients,
                       const TilerOptions& options = {});

}  // namespace tessera
