#pragma once
// Adaptive refinement of a still (issue 18 item 2): after a few samples of every pixel, each
// further round renders only the packets where one more sample lowers the image's error the
// most per unit of time, so the error falls faster than with every pixel sampled alike.
//
// The model: a packet p with n_p samples and per-sample variance v_p (summed over its pixels
// and channels, in units of the encoded 8-bit range) contributes v_p / n_p to the image's
// squared error; one more sample removes v_p / (n_p (n_p + 1)) of it at the packet's cost c_p
// (its last measured time). Each round renders the packets of highest v_p / (n_p (n_p + 1) c_p)
// until their summed cost reaches a fraction of a whole sample's, which spreads the samples
// towards the optimum n_p ~ sqrt(v_p / c_p) round after round (greedy water-filling).
//
// - v_p is each value's sample variance through the slope of the encoding at its mean; where
//   the mean clips (slope 0: an outline against a light source, whose samples do not all clip)
//   it is the variance of the samples encoded one by one. Then the largest over the packet and
//   its 8 neighbours: a packet whose first samples agreed
//   by chance (a thin edge missed by every jittered ray) still gets samples when its
//   neighbours are noisy.
// - Each pixel keeps its own sequence: a packet's next sample is its own count (sampling.h), so
//   skipping rounds leaves no gaps in the low-discrepancy sequence.
// - A packet is done when it reaches the target count, or when its error (v_p / n_p per value)
//   is below `done_below` (an 8-bit step squared, by default a quarter: out of sight). The still is
//   converged when every packet is done.
#include <cstdint>
#include <vector>

#include "core/cost_map.h"
#include "core/image.h"
#include "renderer/renderer.h"

namespace tessera {

struct AdaptiveOptions {
  uint32_t uniform = 4;         // samples of every packet before any is left out (>= 2)
  double round_cost = 0.125;    // a round's cost, as a fraction of a whole sample's (0, 1]
  double done_below = 0.25;     // a packet's error per value (8-bit units squared) counted as none
};

class AdaptiveStill {
 public:
  // An empty still of width x height pixels in packets of `layout`; `srgb`: the renderer's
  // encoding (Environment::linear). `target`: samples per pixel at most (>= 1).
  void reset(int32_t width, int32_t height, PacketLayout layout, bool srgb, uint32_t target,
             const AdaptiveOptions& options = {});
  // The next round's plan for RenderSettings::packet_samples: per packet of the image, the
  // sample it renders, or kSkipPacket. Empty when the still is converged.
  const std::vector<uint32_t>& plan();
  // The round rendered with the last plan: the whole image's radiance (TaskResult::radiance,
  // width * height RGB) and, if measured, its cost map (the packets' costs steer the next plans).
  void add(const std::vector<float>& radiance, const CostMap* cost = nullptr);
  // Each pixel's average, encoded as the renderer encodes a frame (empty before the first round).
  Image average() const;
  std::vector<float> mean() const;
  uint32_t rounds() const { return rounds_; }
  // Samples rendered over all pixels, over the pixel count: the work done in whole samples.
  double mean_samples() const;
  uint32_t min_samples() const;
  bool converged() const { return converged_; }
  int32_t packets_x() const { return pw_; }
  int32_t packets_y() const { return ph_; }
  // The packets the last plan renders.
  size_t planned() const { return planned_; }

 private:
  void make_plan();
  int32_t width_ = 0, height_ = 0, pw_ = 0, ph_ = 0;
  PacketLayout layout_{};
  bool srgb_ = true;
  uint32_t target_ = 1, rounds_ = 0;
  AdaptiveOptions opt_;
  std::vector<float> sum_;                // per pixel and channel (linear radiance)
  std::vector<float> sum_sq_;             // their squares
  // Each sample's value as encoded alone (0..255), summed, and its square summed (exact in
  // integers up to 66,000 samples): the variance where the mean clips.
  std::vector<uint32_t> enc_sum_, enc_sq_;
  std::vector<uint32_t> count_;           // per packet: samples rendered
  std::vector<double> var_;               // per packet: its samples' variance (see above)
  Image encoded_;                         // the average, encoded (kept up to date packet by packet)
  std::vector<double> cost_;              // per packet: last measured cost (ns), 0 unknown
  std::vector<uint32_t> plan_;            // per packet: sample to render, or kSkipPacket
  bool plan_valid_ = false, converged_ = false;
  size_t planned_ = 0;
};

}  // namespace tessera
