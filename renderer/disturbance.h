#pragma once
// Cost maps that ignore disturbances (docs/load-balancing.md, "Disturbed packets").
//
// A packet's cost is the TSC time from the previous packet's end to its own end, so when the
// OS preempts the rendering thread, or an interrupt lands, during a packet, its cost includes
// the stall, and the next frame's tiling is steered by it. The kernel times sub-blocks of
// kSubBlockPackets packets twice: by the TSC (wall time, the sum of their costs) and by the
// thread's CPU clock (CLOCK_THREAD_CPUTIME_ID, one read per sub-block). Time that passes on
// the wall but not on the thread's CPU clock is time the thread was not running.
//
// 1. A sub-block is disturbed when wall - cpu > disturbance_threshold_ns(wall).
// 2. locate_disturbed marks the packets of a disturbed sub-block that absorbed the gap.
// 3. replace_disturbed gives every marked packet a prediction from undisturbed neighbours
//    of the same task; every other packet keeps its measured cost exactly.
#include <cstddef>
#include <cstdint>
#include <ctime>
#include <vector>

#include "core/cost_map.h"

namespace tessera {

// Packets per timed sub-block (in the block's row-major order; a block's last sub-block may
// be shorter). At a few microseconds per packet, one clock read per 32 packets is well under
// 1% of the kernel, and the read is kept out of every packet's timing window.
constexpr int kSubBlockPackets = 32;

// A sub-block whose wall time exceeds its CPU time by more than this is disturbed:
// max(50 us, 10% of the sub-block's wall time). The 10% covers the TSC frequency estimate
// (tsc_khz) and clock granularity; 50 us is far above the clock reads' own cost, far below a
// scheduler time slice (ms), so what it catches are preemptions and long interrupts.
inline uint64_t disturbance_threshold_ns(uint64_t wall_ns) {
  const uint64_t tenth = wall_ns / 10;
  return tenth > 50000 ? tenth : 50000;
}

// The calling thread's CPU time in ns (a system call: ~0.1-1 us).
inline uint64_t thread_cpu_ns() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return uint64_t(ts.tv_sec) * 1000000000u + uint64_t(ts.tv_nsec);
}

// Marks (marks[idx[k]] = 1) the packets of one disturbed sub-block that absorbed a gap of
// gap_ns: cost[idx[k]], k < n, are the sub-block's packet costs. Reference: the median of the
// sub-block's costs. Packets are taken in decreasing excess over it while the excess is at
// least gap/4, until the excess taken explains 90% of the gap; when what was taken explains
// less than half the gap (no packet stands out: the stall was spread out), every packet of
// the sub-block is marked. Returns the number of packets newly marked.
uint32_t locate_disturbed(const uint32_t* cost, const size_t* idx, int n, uint64_t gap_ns, uint8_t* marks);

struct DisturbanceStats {
  uint32_t packets = 0;     // packets whose cost was replaced
  uint64_t removed_ns = 0;  // sum over them of (measured - replacement), clamped at 0 each
};

// Replaces the cost of every packet with marks[i] == kDisturbed (marks: one byte per packet of
// map, row-major) by the median of its undisturbed neighbours in the task: the 3x3 window (up
// to 8), widened to 5x5, 7x7 and 9x9 while it holds fewer than 3 undisturbed packets; with none
// even then, the median of all undisturbed packets of the task. Replacements are computed from
// measured costs only (never from another replacement). Packets marked kNotRendered (skipped by
// an adaptive round's plan: cost 0) are neither replaced nor used. When no packet is left to
// predict from, nothing is changed. Unmarked packets keep their cost exactly.
constexpr uint8_t kDisturbed = 1, kNotRendered = 2;
DisturbanceStats replace_disturbed(CostMap& map, const std::vector<uint8_t>& marks);

}  // namespace tessera
