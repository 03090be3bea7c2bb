#pragma once
// Adaptive refinement of a still (issue 18 item 2): after a few samples of every pixel, each
// further round renders only the blocks (kPlanBlock x kPlanBlock pixels) where one more sample
// lowers the image's error the most per unit of time, so the error falls faster than with every
// pixel sampled alike.
//
// The model: a block b with n_b samples and per-sample variance v_b (summed over its pixels
// and channels, in units of the encoded 8-bit range) contributes v_b / n_b to the image's
// squared error; one more sample removes v_b / (n_b (n_b + 1)) of it at the block's cost c_b
// (its last measured time). Each round renders the blocks of highest v_b / (n_b (n_b + 1) c_b)
// until their summed cost reaches a fraction of a whole sample's, which spreads the samples
// towards the optimum n_b ~ sqrt(v_b / c_b) round after round (greedy water-filling).
//
// - v_b is the sample variance of each value as the display sees it, clamped to [0, 1], through
//   the slope of the encoding at the clamped values' mean. Where the mean clips (an outline
//   against a light source) the samples below 1 still count; a firefly far above 1 counts as 1.
//   Then the largest over the block and its 8 neighbours: a block whose first samples agreed by
//   chance (a thin edge missed by every jittered ray) still gets samples when its neighbours are
//   noisy.
// - Each pixel keeps its own sequence: a block's next sample is its own count (sampling.h), so
//   skipping rounds leaves no gaps in the low-discrepancy sequence.
// - A block is done when it reaches the target count, or when its error (v_b / n_b per value)
//   is below `done_below` (in 8-bit steps squared; a quarter by default: out of sight). The still
//   is converged when every block is done.
//
// A round's tiles may come from several renderers (add_tile, add_cost, then end_round); a tile
// boundary may cross a block when the renderers' packets are smaller than a block: each part of
// the block is rendered with the block's sample, and the block counts one sample at end_round.
// A block that one tile holds whole is finished as that tile is added, while its sums are in
// the cache.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/cost_map.h"
#include "core/image.h"
#include "renderer/renderer.h"

namespace tessera {

namespace adaptive_detail {
struct Candidate {
  double gain;  // error removed per unit of cost by one more sample
  double cost;
  size_t block;
};
// The plan's choice: reorders `cand` so that its first k are the best ones (highest gain; equal
// gains by lower block) and returns k, the fewest whose cost reaches `budget` (all of them when
// none does; none for a budget of 0 or less). The order within the first k and after is
// unspecified. Linear time on average.
size_t take_best(std::vector<Candidate>& cand, double budget);
}  // namespace adaptive_detail

struct AdaptiveOptions {
  uint32_t uniform = 4;         // samples of every block before any is left out (>= 2)
  double round_cost = 0.125;    // a round's cost, as a fraction of a whole sample's (0, 1]
  double done_below = 0.25;     // a block's error per value (8-bit steps squared) counted as none
};

class AdaptiveStill {
 public:
  // An empty still of width x height pixels; `srgb`: the renderer's encoding
  // (Environment::linear). `target`: samples per pixel at most (>= 1).
  void reset(int32_t width, int32_t height, bool srgb, uint32_t target, const AdaptiveOptions& options = {});
  // The next round's plan for RenderSettings::block_samples (plan_blocks: the whole image's
  // blocks, blocks()): per block, the sample it renders, or kSkipPacket. All kSkipPacket when the
  // still is converged.
  const std::vector<uint32_t>& plan();
  Rect blocks() const { return {0, 0, bw_, bh_}; }
  // While set, every block not at the target renders each round, as in the uniform rounds (a
  // still being denoised needs every pixel's sample). The next plan follows it.
  void set_uniform(bool on);
  // One renderer's part of the round planned last: `radiance`, the linear RGB of `pixels`
  // (row by row, 3 floats a pixel); only the planned blocks' pixels are taken.
  void add_tile(const float* radiance, const Rect& pixels);
  // The same from the float32 bytes a tile carries between nodes (TileResult::radiance).
  void add_tile_bytes(const std::vector<uint8_t>& radiance, const Rect& pixels);
  // Its cost map (packets of `layout`, which must tile a block), where measured: the blocks'
  // costs steer the next plans.
  void add_cost(const CostMap& cost, PacketLayout layout);
  // The round is complete: each planned block counts one more sample.
  void end_round();
  // The whole round at once: the image's radiance (width * height RGB) and its cost map.
  void add(const std::vector<float>& radiance, const CostMap* cost = nullptr, PacketLayout layout = {4, 4});
  // Each pixel's average, encoded as the renderer encodes a frame (empty before the first round).
  Image average() const;
  // The same as linear radiance (width * height RGB; empty before the first round).
  std::vector<float> mean() const;
  uint32_t rounds() const { return rounds_; }
  // Samples rendered over all pixels, over the pixel count: the work done in whole samples.
  double mean_samples() const;
  uint32_t min_samples() const;
  bool converged() const { return converged_; }
  int32_t width() const { return width_; }
  int32_t height() const { return height_; }
  bool srgb() const { return srgb_; }
  // The blocks the last plan renders.
  size_t planned() const { return planned_; }
  // What the last plan's blocks cost when last measured (the cost map's units, ns; 0 for blocks
  // not measured yet): what the round is expected to cost.
  double planned_cost() const { return planned_cost_; }
  // The memory a width x height still holds.
  static uint64_t bytes(int32_t width, int32_t height);

 private:
  void make_plan();
  // Counts block b's sample of this round and derives its pixels' average and its variance.
  void finish_block(size_t b);
  template <class Value>
  void add_values(const Rect& pixels, Value value);
  size_t block_of(int32_t x, int32_t y) const { return size_t(y / kPlanBlock) * size_t(bw_) + size_t(x / kPlanBlock); }
  // Block (bx, by)'s pixels, clipped to the image.
  Rect block_pixels(int32_t bx, int32_t by) const {
    return packets_to_pixels({bx, by, bx + 1, by + 1}, {kPlanBlock, kPlanBlock}, width_, height_);
  }
  int32_t width_ = 0, height_ = 0, bw_ = 0, bh_ = 0;
  bool srgb_ = true, uniform_ = false;
  uint32_t target_ = 1, rounds_ = 0;
  AdaptiveOptions opt_;
  std::vector<float> sum_;                // per pixel and channel (linear radiance)
  // The same clamped to [0, 1], and their squares: the variance the display sees.
  std::vector<float> clamped_sum_, clamped_sq_;
  std::vector<uint32_t> count_;           // per block: samples rendered
  std::vector<double> var_;               // per block: its samples' variance (see above)
  std::vector<double> cost_;              // per block: last measured cost (ns), 0 unknown
  std::vector<double> round_cost_;        // per block: this round's cost so far
  std::vector<uint32_t> plan_;            // per block: sample to render, or kSkipPacket
  std::vector<uint8_t> finished_;         // per block: its round finished by a tile that held all of it
  Image encoded_;                         // the average, encoded (kept up to date block by block)
  bool plan_valid_ = false, converged_ = false;
  size_t planned_ = 0;
  double planned_cost_ = 0;
};

}  // namespace tessera
