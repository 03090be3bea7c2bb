#pragma once
// Summed-area tables of per-packet rendering cost (paper section 6.2) and the SAT array
// that answers the cost of any packet-space rectangle over all rendering nodes (6.3).
//
// Units: a cost map entry is one packet's cost in nanoseconds of a core at the node's
// nominal TSC frequency (cost_map.h). A frame's sum overflows 32 bits, so SAT entries are
// 64-bit: 2^64 ns is 584 years of core time, and a SAT built from 32-bit entries cannot
// overflow for fewer than 2^32 packets.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/cost_map.h"
#include "core/rect.h"

namespace tessera {

// A serialised SAT was truncated, corrupt or claims an impossible rectangle.
struct SatFormatError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// The summed-area table of one task's cost map. at(x, y) is the inclusive prefix sum over
// packets [x0, x] x [y0, y] of the task (absolute packet coordinates), so the bottom-right
// entry is the task's kernel cost. Stored with a zero row and column in front so that
// rectangle queries need no branches.
class Sat {
 public:
  Sat() = default;
  Sat(const Sat& o);
  Sat& operator=(const Sat& o);
  Sat(Sat&&) noexcept = default;
  Sat& operator=(Sat&&) noexcept = default;

  // Builds the SAT of a cost map with TBB in the calling thread's task arena (row prefix
  // sums in parallel over rows, then column sums in parallel over column blocks); with one
  // thread, or a small map, a single sequential pass. Throws std::invalid_argument when
  // cost.size() does not match the rectangle or the rectangle has negative coordinates.
  static Sat from_cost_map(const CostMap& map);
  // The same, always in one sequential pass (reference and 1-thread path).
  static Sat from_cost_map_serial(const CostMap& map);

  const Rect& packets() const { return packets_; }
  bool empty() const { return packets_.empty(); }
  uint64_t total() const { return empty() ? 0 : p(packets_.width(), packets_.height()); }

  // Inclusive prefix sum at absolute packet (x, y); requires packets().contains(x, y).
  uint64_t at(int32_t x, int32_t y) const { return p(x - packets_.x0 + 1, y - packets_.y0 + 1); }
  // Cost of the part of r that lies inside this SAT's rectangle (0 when disjoint).
  uint64_t cost(const Rect& r) const;
  // Cost of r, which must lie inside packets() (empty is fine): four loads, no checks.
  uint64_t cost_inside(const Rect& r) const {
    const int32_t ax = r.x0 - packets_.x0, ay = r.y0 - packets_.y0;
    const int32_t bx = r.x1 - packets_.x0, by = r.y1 - packets_.y0;
    return p(bx, by) - p(ax, by) - p(bx, ay) + p(ax, ay);
  }

  // The padded table itself, for callers that walk it (the tiler's single-SAT path): entry
  // (i, j) at table()[j * stride() + i] is the sum over packets [x0, x0 + i) x [y0, y0 + j),
  // so row 0 and column 0 are zero. Null when empty().
  const uint64_t* table() const { return table_.get(); }
  size_t stride() const { return stride_; }

  // Wire format, little endian: "TSAT", u16 version (1), u16 header bytes (32),
  // i32 x0, y0, x1, y1, u64 count (= width * height), then count u64 inclusive prefix sums
  // in row-major order.
  static constexpr size_t kHeaderBytes = 32;
  std::vector<uint8_t> serialize() const;
  void serialize_into(std::vector<uint8_t>& out) const;  // replaces out's contents
  // Parses and validates a buffer: header, sizes, and that every implied packet cost is in
  // [0, 2^32) (so the table is the SAT of some cost map). Throws SatFormatError.
  static Sat deserialize(const uint8_t* data, size_t size);
  static Sat deserialize(const std::vector<uint8_t>& buf) { return deserialize(buf.data(), buf.size()); }
  // Non-throwing variant for actor code: nullopt and a message in *error on failure.
  static std::optional<Sat> try_deserialize(const uint8_t* data, size_t size, std::string* error) noexcept;

 private:
  Sat(Rect packets);  // allocates an uninitialised padded table with zero row and column
  uint64_t p(int32_t px, int32_t py) const { return table_[size_t(py) * stride_ + size_t(px)]; }

  Rect packets_;
  size_t stride_ = 0;  // width + 1
  std::unique_ptr<uint64_t[]> table_;  // (height + 1) rows of stride_ entries
};

// The SATs of all rendering nodes for one frame. Costs are normalised to the weakest core of
// the cluster: a cost read from a node's SAT is multiplied by that node's single-core
// performance coefficient (paper 6.3: a node twice as fast measures half the time).
//
// Missing SATs: the part of the packet space that no SAT covers (a node that did not report)
// is given the mean normalised cost density of the covered part (total known cost / known
// packets); when nothing is covered or the known cost is zero, every packet of it costs 1 unit
// so the tiler falls back to splitting by area there.
class SatArray {
 public:
  explicit SatArray(Rect packet_space);

  // Adds a node's SAT. Throws std::invalid_argument when the SAT is not inside the packet
  // space or the coefficient is not finite and > 0. Empty SATs are ignored.
  void add(Sat sat, double single_core_perf = 1.0);
  // Sorts by x offset, checks that no two SATs overlap (std::invalid_argument) and computes
  // the missing-area density. Required before cost(); add() after it needs another call.
  void finalize();

  const Rect& packet_space() const { return space_; }
  size_t size() const { return entries_.size(); }
  bool finalized() const { return finalized_; }
  int64_t known_packets() const { return known_area_; }
  bool has_missing() const { return known_area_ < space_.area(); }
  double missing_density() const { return missing_density_; }  // normalised cost per packet
  double total() const { return total_; }                      // normalised cost of the space

  // Normalised cost of r clipped to the packet space: constant time per contributing SAT;
  // a binary search rejects the SATs that start at or beyond r.x1. Requires finalize().
  double cost(const Rect& r) const;

  // The normalised cost of every packet of the space, as one map (rounded to whole units,
  // at most 2^32 - 1): what the reprojection (lb/reproject.h) starts from. Requires finalize().
  CostMap cost_map() const;

  struct Entry {
    Sat sat;
    double perf;  // single-core performance coefficient of the originating node
  };
  const std::vector<Entry>& entries() const { return entries_; }  // sorted by x0 once finalized

 private:
  Rect space_;
  std::vector<Entry> entries_;
  std::vector<int32_t> x0s_;  // entries_[i].sat.packets().x0, for the binary search
  int64_t known_area_ = 0;
  double known_cost_ = 0, missing_density_ = 0, total_ = 0;
  bool finalized_ = false;
};

}  // namespace tessera
