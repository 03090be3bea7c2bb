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

// encoding_slope (accumulation.h) in 8-bit steps, the sRGB curve's from a table of 4096 steps
// over [0, 1) (it only weighs the plans; a pow per value made adding a round cost a quarter of
// rendering it).
struct SlopeTable {
  float at[4096];
  SlopeTable() {
    for (int i = 0; i < 4096; ++i) at[i] = float(255.0 * encoding_slope((float(i) + 0.5f) / 4096.0f, true));
  }
};

float slope(float c, bool srgb) {
  static const SlopeTable table;
  if (!(c < 1.0f)) return 0.0f;
  if (!srgb) return 255.0f;
  return table.at[int(std::max(c, 0.0f) * 4096.0f)];
}

}  // namespace

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
  const size_t values = size_t(width) * size_t(height) * 3;
  sum_.assign(values, 0.0f);
  sum_sq_.assign(values, 0.0f);
  enc_sum_.assign(values, 0);
  enc_sq_.assign(values, 0);
  count_.assign(size_t(bw_) * size_t(bh_), 0);
  var_.assign(count_.size(), 0.0);
  cost_.assign(count_.size(), 0.0);
  round_cost_.assign(count_.size(), 0.0);
  plan_.assign(count_.size(), 0);
  encoded_ = Image(width, height);
  plan_valid_ = false;
  converged_ = false;
  planned_ = 0;
}

uint64_t AdaptiveStill::bytes(int32_t width, int32_t height) {
  const uint64_t pixels = uint64_t(std::max(width, 0)) * uint64_t(std::max(height, 0));
  const Rect b = plan_blocks_of({0, 0, std::max(width, 0), std::max(height, 0)});
  // Four 4-byte values per channel, the encoded average; per block its count, variance, two
  // costs and plan entry.
  return pixels * (3 * 16 + 4) + uint64_t(b.area()) * (4 + 8 + 8 + 8 + 4);
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
    for (size_t b = 0; b < blocks; ++b) {
      plan_[b] = count_[b] < target_ ? count_[b] : kSkipPacket;
      planned_ += plan_[b] != kSkipPacket;
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
  struct Candidate {
    double gain;  // error removed per unit of cost by one more sample
    double cost;
    size_t b;
  };
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
    const double values = double((std::min(width_, (bx + 1) * kPlanBlock) - bx * kPlanBlock) *
                                 (std::min(height_, (by + 1) * kPlanBlock) - by * kPlanBlock) * 3);
    if (dil[b] / n <= opt_.done_below * values) continue;  // its error is out of sight
    cand.push_back({dil[b] / (n * (n + 1)) / c, c, b});
  }
  planned_ = 0;
  if (cand.empty()) {
    converged_ = true;
    return;
  }
  const auto better = [](const Candidate& a, const Candidate& b) { return a.gain > b.gain || (a.gain == b.gain && a.b < b.b); };
  const double budget = opt_.round_cost * whole;
  // Only the best ones are taken: order the first twice as many as the budget buys at the
  // candidates' mean cost (all of them when that is not enough).
  double cand_cost = 0;
  for (const Candidate& c : cand) cand_cost += c.cost;
  const size_t want = size_t(std::min<double>(double(cand.size()), 2.0 * budget / (cand_cost / double(cand.size())) + 64));
  std::nth_element(cand.begin(), cand.begin() + long(want) - 1, cand.end(), better);
  std::sort(cand.begin(), cand.begin() + long(want), better);
  double head = 0;
  for (size_t i = 0; i < want; ++i) head += cand[i].cost;
  if (head < budget) std::sort(cand.begin(), cand.end(), better);
  double spent = 0;
  for (const Candidate& c : cand) {
    if (spent >= budget) break;
    plan_[c.b] = count_[c.b];
    spent += c.cost;
    ++planned_;
  }
}

// Adds the planned blocks' pixels of a tile whose value i (RGB triples, row by row) is value(i).
template <class Value>
void AdaptiveStill::add_values(const Rect& pixels, Value value) {
  if (pixels.empty()) return;
  if (!Rect{0, 0, width_, height_}.contains(pixels)) throw std::invalid_argument("AdaptiveStill::add_tile: a tile outside the image");
  if (converged_) throw std::logic_error("AdaptiveStill::add_tile: the still is converged (an empty plan)");
  plan();
  const size_t tw = size_t(pixels.width());
  tbb::parallel_for(tbb::blocked_range<int32_t>(pixels.y0, pixels.y1, 8), [&](const tbb::blocked_range<int32_t>& r) {
    for (int32_t y = r.begin(); y != r.end(); ++y)
      // Block by block along the row: a skipped block's pixels are passed over at once.
      for (int32_t bx = pixels.x0 / kPlanBlock; bx * kPlanBlock < pixels.x1; ++bx) {
        if (plan_[block_of(bx * kPlanBlock, y)] == kSkipPacket) continue;
        const int32_t x0 = std::max(pixels.x0, bx * kPlanBlock), x1 = std::min(pixels.x1, (bx + 1) * kPlanBlock);
        const size_t in = (size_t(y - pixels.y0) * tw + size_t(x0 - pixels.x0)) * 3;
        const size_t at = (size_t(y) * size_t(width_) + size_t(x0)) * 3;
        for (size_t i = 0; i < size_t(x1 - x0) * 3; ++i) {
          const float v = value(in + i);
          sum_[at + i] += v;
          sum_sq_[at + i] += v * v;
          const uint32_t e = uint32_t(srgb_ ? raytracer_detail::encode_srgb(v) : raytracer_detail::encode_plain(v));
          enc_sum_[at + i] += e;
          enc_sq_[at + i] += e * e;
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
        const int32_t x1 = std::min(width_, (bx + 1) * kPlanBlock), y1 = std::min(height_, (by + 1) * kPlanBlock);
        const double n = ++count_[b];
        const float inv = 1.0f / float(n);  // as Accumulation::average scales its sums
        float var = 0;  // n - 1 times the sum of the values' sample variances, encoded
        for (int32_t y = by * kPlanBlock; y < y1; ++y)
          for (int32_t x = bx * kPlanBlock; x < x1; ++x) {
            const size_t pixel = size_t(y) * size_t(width_) + size_t(x);
            for (int c = 0; c < 3; ++c) {
              const size_t i = pixel * 3 + size_t(c);
              const float m = sum_[i] * inv;
              encoded_.rgba[pixel * 4 + size_t(c)] =
                  uint8_t(srgb_ ? raytracer_detail::encode_srgb(m) : raytracer_detail::encode_plain(m));
              const float g = slope(m, srgb_);
              if (g > 0) {
                var += g * g * std::max(0.0f, sum_sq_[i] - sum_[i] * m);
              } else {
                const float s1 = float(enc_sum_[i]);
                var += std::max(0.0f, float(enc_sq_[i]) - s1 * s1 * inv);
              }
            }
            encoded_.rgba[pixel * 4 + 3] = 255;
          }
        var_[b] = n >= 2 ? double(var) / (n - 1) : 0.0;
      }
  });
  ++rounds_;
  plan_valid_ = false;
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
      const double area = double((std::min(width_, (bx + 1) * kPlanBlock) - bx * kPlanBlock) *
                                 (std::min(height_, (by + 1) * kPlanBlock) - by * kPlanBlock));
      s += area * count_[size_t(by) * size_t(bw_) + size_t(bx)];
    }
  return s / (double(width_) * double(height_));
}

uint32_t AdaptiveStill::min_samples() const {
  return count_.empty() ? 0 : *std::min_element(count_.begin(), count_.end());
}

}  // namespace tessera
