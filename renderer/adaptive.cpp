#include "renderer/adaptive.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "renderer/accumulation.h"
#include "renderer/raytracer_impl.h"

namespace tessera {
namespace {

// encoding_slope (accumulation.h) in 8-bit steps, squared; the sRGB curve's from a table of
// 4096 steps over [0, 1) (it only weighs the plans; a pow per value made adding a round cost a
// quarter of rendering it). `c`: a mean of values clamped to [0, 1]; at 1 every sample was 1 or
// more and its variance is 0 anyway.
struct SlopeTable {
  float at[4097];
  SlopeTable() {
    for (int i = 0; i < 4096; ++i) {
      const double g = 255.0 * encoding_slope((float(i) + 0.5f) / 4096.0f, true);
      at[i] = float(g * g);
    }
    at[4096] = 0.0f;
  }
};

float slope_sq(float c, bool srgb) {
  static const SlopeTable table;
  if (!srgb) return 255.0f * 255.0f;
  return table.at[int(c * 4096.0f)];
}

// A value as the display sees it: clamped to [0, 1] (NaN: 0).
inline float clamped(float v) { return v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f; }

// One row of a block, `n` values (n / 3 pixels, at most a block's row): each value's mean
// (the sums times `inv`) encoded into `out` (RGBA, opaque), and the sum of the values' variances
// as the display sees them, times n - 1. The row is copied into arrays of a block's row so that
// the loops have a fixed length and compile to vector code.
float block_row(const float* sum, const float* csum, const float* csq, size_t n, float inv, bool srgb, uint8_t* out) {
  constexpr size_t K = size_t(kPlanBlock) * 3;
  alignas(64) float s[K] = {}, cs[K] = {}, cq[K] = {};
  if (n == K) {  // a size known at compile time: moves, not a library call
    std::memcpy(s, sum, sizeof s);
    std::memcpy(cs, csum, sizeof cs);
    std::memcpy(cq, csq, sizeof cq);
  } else {  // the image's last column of blocks
    std::memcpy(s, sum, n * sizeof(float));
    std::memcpy(cs, csum, n * sizeof(float));
    std::memcpy(cq, csq, n * sizeof(float));
  }
  alignas(64) int enc[K];
  alignas(64) float mc[K], d[K];
  if (srgb) {
    for (size_t i = 0; i < K; ++i) enc[i] = raytracer_detail::encode_srgb(s[i] * inv);
  } else {
    for (size_t i = 0; i < K; ++i) enc[i] = raytracer_detail::encode_plain(s[i] * inv);
  }
  for (size_t i = 0; i < K; ++i) {
    mc[i] = cs[i] * inv;
    d[i] = std::max(0.0f, cq[i] - cs[i] * mc[i]);
  }
  float var = 0;
  for (size_t i = 0; i < n; ++i) var += slope_sq(mc[i], srgb) * d[i];
  for (size_t x = 0; x < n / 3; ++x) {
    out[x * 4] = uint8_t(enc[x * 3]);
    out[x * 4 + 1] = uint8_t(enc[x * 3 + 1]);
    out[x * 4 + 2] = uint8_t(enc[x * 3 + 2]);
    out[x * 4 + 3] = 255;
  }
  return var;
}

}  // namespace

namespace adaptive_detail {

size_t take_best(std::vector<Candidate>& cand, double budget) {
  if (cand.empty() || !(budget > 0)) return 0;
  const auto better = [](const Candidate& a, const Candidate& b) {
    return a.gain > b.gain || (a.gain == b.gain && a.block < b.block);
  };
  // In the order of `better` (a strict total order) the round takes candidates while the cost of
  // those before is below the budget: the first k + 1, where k is the first whose cost with
  // those before reaches it (or all of them). A weighted quickselect finds k without sorting:
  // [lo, hi) holds k, every candidate before lo is better than every one from lo on and is
  // taken, and `before` is their cost (below the budget).
  size_t lo = 0, hi = cand.size();
  double before = 0;
  while (hi - lo > 1) {
    const size_t mid = lo + (hi - lo) / 2;
    std::nth_element(cand.begin() + long(lo), cand.begin() + long(mid), cand.begin() + long(hi), better);
    double part = 0;  // [lo, mid): each better than every one from mid on
    for (size_t i = lo; i < mid; ++i) part += cand[i].cost;
    if (before + part >= budget) {
      hi = mid;
    } else {
      before += part;
      lo = mid;
    }
  }
  return lo + 1;
}

}  // namespace adaptive_detail

void AdaptiveStill::reset(int32_t width, int32_t height, bool srgb, uint32_t target, const AdaptiveOptions& options) {
  if (width <= 0 || height <= 0) throw std::invalid_argument("AdaptiveStill: an empty image");
  if (target < 1) throw std::invalid_argument("AdaptiveStill: the target must be at least one sample");
  if (options.uniform < 2) throw std::invalid_argument("AdaptiveStill: at least two uniform samples (a variance needs two)");
  if (!(options.round_cost > 0 && options.round_cost <= 1))
    throw std::invalid_argument("AdaptiveStill: a round's cost must be in (0, 1] of a sample's");
  if (!(options.done_below >= 0) || !std::isfinite(options.done_below))
    throw std::invalid_argument("AdaptiveStill: done_below must be a number >= 0");
  width_ = width;
  height_ = height;
  const Rect blocks = plan_blocks_of({0, 0, width, height});
  bw_ = blocks.width();
  bh_ = blocks.height();
  srgb_ = srgb;
  uniform_ = false;
  target_ = target;
  opt_ = options;
  rounds_ = 0;
  planned_cost_ = 0;
  const size_t values = size_t(width) * size_t(height) * 3;
  sum_.assign(values, 0.0f);
  clamped_sum_.assign(values, 0.0f);
  clamped_sq_.assign(values, 0.0f);
  count_.assign(size_t(bw_) * size_t(bh_), 0);
  var_.assign(count_.size(), 0.0);
  cost_.assign(count_.size(), 0.0);
  round_cost_.assign(count_.size(), 0.0);
  plan_.assign(count_.size(), 0);
  finished_.assign(count_.size(), 0);
  encoded_ = Image(width, height);
  plan_valid_ = false;
  converged_ = false;
  planned_ = 0;
}

uint64_t AdaptiveStill::bytes(int32_t width, int32_t height) {
  const uint64_t pixels = uint64_t(std::max(width, 0)) * uint64_t(std::max(height, 0));
  const Rect b = plan_blocks_of({0, 0, std::max(width, 0), std::max(height, 0)});
  // Three floats per channel, the encoded average; per block its count, variance, two costs,
  // plan entry and finished mark.
  return pixels * (3 * 12 + 4) + uint64_t(b.area()) * (4 + 8 + 8 + 8 + 4 + 1);
}

void AdaptiveStill::set_uniform(bool on) {
  if (on != uniform_) plan_valid_ = false;
  uniform_ = on;
}

const std::vector<uint32_t>& AdaptiveStill::plan() {
  if (!plan_valid_) make_plan();
  return plan_;
}

void AdaptiveStill::make_plan() {
  plan_valid_ = true;
  const size_t blocks = count_.size();
  // Every block alike until each has `uniform` samples (or the target, if it is lower), and
  // while set_uniform holds.
  if (uniform_ || rounds_ < std::min(opt_.uniform, target_)) {
    planned_ = 0;
    planned_cost_ = 0;
    for (size_t b = 0; b < blocks; ++b) {
      plan_[b] = count_[b] < target_ ? count_[b] : kSkipPacket;
      planned_ += plan_[b] != kSkipPacket;
      if (plan_[b] != kSkipPacket) planned_cost_ += cost_[b];
    }
    converged_ = planned_ == 0;
    return;
  }
  // The largest over the 3x3 blocks around: rows, then columns.
  std::vector<double> rowmax(blocks), dil(blocks);
  for (int32_t by = 0; by < bh_; ++by)
    for (int32_t bx = 0; bx < bw_; ++bx) {
      double m = 0;
      for (int32_t x = std::max(0, bx - 1); x <= std::min(bw_ - 1, bx + 1); ++x)
        m = std::max(m, var_[size_t(by) * size_t(bw_) + size_t(x)]);
      rowmax[size_t(by) * size_t(bw_) + size_t(bx)] = m;
    }
  for (int32_t by = 0; by < bh_; ++by)
    for (int32_t bx = 0; bx < bw_; ++bx) {
      double m = 0;
      for (int32_t y = std::max(0, by - 1); y <= std::min(bh_ - 1, by + 1); ++y)
        m = std::max(m, rowmax[size_t(y) * size_t(bw_) + size_t(bx)]);
      dil[size_t(by) * size_t(bw_) + size_t(bx)] = m;
    }
  // A block's cost: its last measured one, else the mean of those measured (else 1 each).
  double known = 0;
  size_t known_n = 0;
  for (double c : cost_)
    if (c > 0) {
      known += c;
      ++known_n;
    }
  const double fallback = known_n ? known / double(known_n) : 1.0;
  using adaptive_detail::Candidate;
  std::vector<Candidate> cand;
  cand.reserve(blocks);
  double whole = 0;  // a whole sample's cost
  for (size_t b = 0; b < blocks; ++b) {
    const double c = cost_[b] > 0 ? cost_[b] : fallback;
    whole += c;
    plan_[b] = kSkipPacket;
    const double n = count_[b];
    if (count_[b] >= target_) continue;
    const int32_t bx = int32_t(b % size_t(bw_)), by = int32_t(b / size_t(bw_));
    const double values = double(block_pixels(bx, by).area() * 3);
    if (dil[b] / n <= opt_.done_below * values) continue;  // its error is out of sight
    cand.push_back({dil[b] / (n * (n + 1)) / c, c, b});
  }
  planned_ = 0;
  planned_cost_ = 0;
  if (cand.empty()) {
    converged_ = true;
    return;
  }
  const size_t taken = adaptive_detail::take_best(cand, opt_.round_cost * whole);
  for (size_t i = 0; i < taken; ++i) {
    plan_[cand[i].block] = count_[cand[i].block];
    planned_cost_ += cand[i].cost;
  }
  planned_ = taken;
}

// Adds the planned blocks' pixels of a tile whose value i (RGB triples, row by row) is value(i).
template <class Value>
void AdaptiveStill::add_values(const Rect& pixels, Value value) {
  if (pixels.empty()) return;
  if (!Rect{0, 0, width_, height_}.contains(pixels)) throw std::invalid_argument("AdaptiveStill::add_tile: a tile outside the image");
  if (converged_) throw std::logic_error("AdaptiveStill::add_tile: the still is converged (an empty plan)");
  plan();
  const size_t tw = size_t(pixels.width());
  const Rect blocks = plan_blocks_of(pixels);  // the blocks the tile touches
  tbb::parallel_for(tbb::blocked_range<int32_t>(blocks.y0, blocks.y1), [&](const tbb::blocked_range<int32_t>& r) {
    for (int32_t by = r.begin(); by != r.end(); ++by)
      for (int32_t bx = blocks.x0; bx < blocks.x1; ++bx) {
        const size_t b = size_t(by) * size_t(bw_) + size_t(bx);
        if (plan_[b] == kSkipPacket) continue;
        const Rect block = block_pixels(bx, by);
        const Rect part = intersect(block, pixels);
        for (int32_t y = part.y0; y < part.y1; ++y) {
          const size_t in = (size_t(y - pixels.y0) * tw + size_t(part.x0 - pixels.x0)) * 3;
          const size_t at = (size_t(y) * size_t(width_) + size_t(part.x0)) * 3;
          float* const sum = &sum_[at];
          float* const csum = &clamped_sum_[at];
          float* const csq = &clamped_sq_[at];
          for (size_t i = 0; i < size_t(part.width()) * 3; ++i) {
            const float v = value(in + i), c = clamped(v);
            sum[i] += v;
            csum[i] += c;
            csq[i] += c * c;
          }
        }
        // The whole block is in this tile: its round is complete, and its sums are still in the
        // cache (end_round finishes the blocks that tiles split).
        if (part == block) {
          if (finished_[b]) throw std::logic_error("AdaptiveStill::add_tile: a block added twice in one round");
          finish_block(b);
          finished_[b] = 1;
        }
      }
  });
}

void AdaptiveStill::add_tile(const float* radiance, const Rect& pixels) {
  add_values(pixels, [radiance](size_t i) { return radiance[i]; });
}

void AdaptiveStill::add_tile_bytes(const std::vector<uint8_t>& radiance, const Rect& pixels) {
  if (radiance.size() != size_t(std::max<int64_t>(0, pixels.area())) * 3 * sizeof(float))
    throw std::invalid_argument("AdaptiveStill::add_tile_bytes: radiance not the tile's RGB float32");
  add_values(pixels, [&radiance](size_t i) {
    float v;
    std::memcpy(&v, radiance.data() + i * sizeof(float), sizeof(float));
    return v;
  });
}

void AdaptiveStill::add_cost(const CostMap& cost, PacketLayout layout) {
  if (layout.w <= 0 || layout.h <= 0 || kPlanBlock % layout.w != 0 || kPlanBlock % layout.h != 0)
    throw std::invalid_argument("AdaptiveStill::add_cost: packets that do not tile a block");
  if (cost.cost.size() != size_t(std::max<int64_t>(0, cost.packets.area())))
    throw std::invalid_argument("AdaptiveStill::add_cost: a cost map not its rectangle's size");
  for (int32_t py = cost.packets.y0; py < cost.packets.y1; ++py)
    for (int32_t px = cost.packets.x0; px < cost.packets.x1; ++px) {
      const int32_t bx = px * layout.w / kPlanBlock, by = py * layout.h / kPlanBlock;
      if (bx < 0 || by < 0 || bx >= bw_ || by >= bh_) continue;
      round_cost_[size_t(by) * size_t(bw_) + size_t(bx)] += double(cost.at(px, py));
    }
}

void AdaptiveStill::end_round() {
  if (converged_) throw std::logic_error("AdaptiveStill::end_round: the still is converged (an empty plan)");
  plan();
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, bh_), [&](const tbb::blocked_range<int32_t>& r) {
    for (int32_t by = r.begin(); by != r.end(); ++by)
      for (int32_t bx = 0; bx < bw_; ++bx) {
        const size_t b = size_t(by) * size_t(bw_) + size_t(bx);
        if (plan_[b] == kSkipPacket) continue;
        if (round_cost_[b] > 0) cost_[b] = round_cost_[b];
        round_cost_[b] = 0;
        if (finished_[b])
          finished_[b] = 0;
        else
          finish_block(b);
      }
  });
  ++rounds_;
  plan_valid_ = false;
}

void AdaptiveStill::finish_block(size_t b) {
  const int32_t bx = int32_t(b % size_t(bw_)), by = int32_t(b / size_t(bw_));
  const Rect block = block_pixels(bx, by);
  const double n = ++count_[b];
  const float inv = 1.0f / float(n);  // as Accumulation::average scales its sums
  float var = 0;  // n - 1 times the sum of the values' sample variances, as the display sees them
  for (int32_t y = block.y0; y < block.y1; ++y) {
    const size_t p0 = size_t(y) * size_t(width_) + size_t(block.x0);
    var += block_row(&sum_[p0 * 3], &clamped_sum_[p0 * 3], &clamped_sq_[p0 * 3], size_t(block.width()) * 3, inv,
                     srgb_, &encoded_.rgba[p0 * 4]);
  }
  var_[b] = n >= 2 ? double(var) / (n - 1) : 0.0;
}

void AdaptiveStill::add(const std::vector<float>& radiance, const CostMap* cost, PacketLayout layout) {
  if (radiance.size() != size_t(width_) * size_t(height_) * 3)
    throw std::invalid_argument("AdaptiveStill::add: radiance not width x height RGB");
  add_tile(radiance.data(), {0, 0, width_, height_});
  if (cost) add_cost(*cost, layout);
  end_round();
}

std::vector<float> AdaptiveStill::mean() const {
  if (rounds_ == 0) return {};
  std::vector<float> out(sum_.size(), 0.0f);
  for (int32_t y = 0; y < height_; ++y)
    for (int32_t x = 0; x < width_; ++x) {
      const uint32_t n = count_[block_of(x, y)];
      if (n == 0) continue;
      const float inv = 1.0f / float(n);
      for (int c = 0; c < 3; ++c) {
        const size_t i = (size_t(y) * size_t(width_) + size_t(x)) * 3 + size_t(c);
        out[i] = sum_[i] * inv;
      }
    }
  return out;
}

Image AdaptiveStill::average() const {
  if (rounds_ == 0) return {};
  return encoded_;
}

double AdaptiveStill::mean_samples() const {
  double s = 0;
  for (int32_t by = 0; by < bh_; ++by)
    for (int32_t bx = 0; bx < bw_; ++bx) {
      s += double(block_pixels(bx, by).area()) * count_[size_t(by) * size_t(bw_) + size_t(bx)];
    }
  return s / (double(width_) * double(height_));
}

uint32_t AdaptiveStill::min_samples() const {
  return count_.empty() ? 0 : *std::min_element(count_.begin(), count_.end());
}

}  // namespace tessera
