#include "renderer/adaptive.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "renderer/accumulation.h"
#include "renderer/raytracer_impl.h"

namespace tessera {
namespace {

// The encoding's slope at linear value c, in 8-bit steps per unit of radiance (`srgb`: the sRGB
// curve, else plain); 0 where the value clips or is not a number. The sRGB curve's from a table
// of 4096 steps over [0, 1) (it only weighs the plans; a pow per value made adding a round cost
// a quarter of rendering it).
struct SlopeTable {
  float at[4096];
  SlopeTable() {
    for (int i = 0; i < 4096; ++i) {
      const double c = (i + 0.5) / 4096.0;
      at[i] = float(c <= 0.0031308 ? 12.92 * 255.0 : 255.0 * 1.055 / 2.4 * std::pow(c, 1.0 / 2.4 - 1.0));
    }
  }
};

float slope(float c, bool srgb) {
  static const SlopeTable table;
  if (!(c < 1.0f)) return 0.0f;
  if (!srgb) return 255.0f;
  return table.at[int(std::max(c, 0.0f) * 4096.0f)];
}

}  // namespace

void AdaptiveStill::reset(int32_t width, int32_t height, PacketLayout layout, bool srgb, uint32_t target,
                          const AdaptiveOptions& options) {
  if (width <= 0 || height <= 0 || layout.w <= 0 || layout.h <= 0)
    throw std::invalid_argument("AdaptiveStill: an empty image or packet");
  if (target < 1) throw std::invalid_argument("AdaptiveStill: the target must be at least one sample");
  if (options.uniform < 2) throw std::invalid_argument("AdaptiveStill: at least two uniform samples (a variance needs two)");
  if (!(options.round_cost > 0 && options.round_cost <= 1))
    throw std::invalid_argument("AdaptiveStill: a round's cost must be in (0, 1] of a sample's");
  if (!(options.done_below >= 0) || !std::isfinite(options.done_below))
    throw std::invalid_argument("AdaptiveStill: done_below must be a number >= 0");
  width_ = width;
  height_ = height;
  layout_ = layout;
  const Rect ps = packet_space(width, height, layout);
  pw_ = ps.width();
  ph_ = ps.height();
  srgb_ = srgb;
  target_ = target;
  opt_ = options;
  rounds_ = 0;
  const size_t pixels = size_t(width) * size_t(height);
  sum_.assign(pixels * 3, 0.0f);
  sum_sq_.assign(pixels * 3, 0.0f);
  enc_sum_.assign(pixels * 3, 0);
  enc_sq_.assign(pixels * 3, 0);
  count_.assign(size_t(pw_) * size_t(ph_), 0);
  var_.assign(count_.size(), 0.0);
  encoded_ = Image(width, height);
  cost_.assign(count_.size(), 0.0);
  plan_.assign(count_.size(), 0);
  plan_valid_ = false;
  converged_ = false;
  planned_ = 0;
}

const std::vector<uint32_t>& AdaptiveStill::plan() {
  if (!plan_valid_) make_plan();
  return plan_;
}

void AdaptiveStill::make_plan() {
  plan_valid_ = true;
  const size_t packets = count_.size();
  // Every packet alike until each has `uniform` samples (or the target, if it is lower).
  const uint32_t uniform = std::min(opt_.uniform, target_);
  if (rounds_ < uniform) {
    for (size_t p = 0; p < packets; ++p) plan_[p] = count_[p];
    planned_ = packets;
    return;
  }
  // The largest over the 3x3 packets around: rows, then columns.
  std::vector<double> rowmax(packets), dil(packets);
  for (int32_t py = 0; py < ph_; ++py)
    for (int32_t px = 0; px < pw_; ++px) {
      double m = 0;
      for (int32_t x = std::max(0, px - 1); x <= std::min(pw_ - 1, px + 1); ++x)
        m = std::max(m, var_[size_t(py) * size_t(pw_) + size_t(x)]);
      rowmax[size_t(py) * size_t(pw_) + size_t(px)] = m;
    }
  for (int32_t py = 0; py < ph_; ++py)
    for (int32_t px = 0; px < pw_; ++px) {
      double m = 0;
      for (int32_t y = std::max(0, py - 1); y <= std::min(ph_ - 1, py + 1); ++y)
        m = std::max(m, rowmax[size_t(y) * size_t(pw_) + size_t(px)]);
      dil[size_t(py) * size_t(pw_) + size_t(px)] = m;
    }
  // A packet's cost: its last measured one, else the mean of those measured (else 1 each).
  double known = 0;
  size_t known_n = 0;
  for (double c : cost_)
    if (c > 0) { known += c; ++known_n; }
  const double fallback = known_n ? known / double(known_n) : 1.0;
  struct Candidate {
    double gain;  // error removed per unit of cost by one more sample
    double cost;
    size_t p;
  };
  std::vector<Candidate> cand;
  cand.reserve(packets);
  double whole = 0;  // a whole sample's cost
  for (size_t p = 0; p < packets; ++p) {
    const double c = cost_[p] > 0 ? cost_[p] : fallback;
    whole += c;
    plan_[p] = kSkipPacket;
    const double n = count_[p];
    if (count_[p] >= target_) continue;
    const int32_t px = int32_t(p % size_t(pw_)), py = int32_t(p / size_t(pw_));
    const double values = double((std::min(width_, (px + 1) * layout_.w) - px * layout_.w) *
                                 (std::min(height_, (py + 1) * layout_.h) - py * layout_.h) * 3);
    if (dil[p] / n <= opt_.done_below * values) continue;  // its error is out of sight
    cand.push_back({dil[p] / (n * (n + 1)) / c, c, p});
  }
  planned_ = 0;
  if (cand.empty()) {
    converged_ = true;
    return;
  }
  std::sort(cand.begin(), cand.end(), [](const Candidate& a, const Candidate& b) {
    return a.gain > b.gain || (a.gain == b.gain && a.p < b.p);
  });
  const double budget = opt_.round_cost * whole;
  double spent = 0;
  for (const Candidate& c : cand) {
    if (spent >= budget) break;
    plan_[c.p] = count_[c.p];
    spent += c.cost;
    ++planned_;
  }
}

void AdaptiveStill::add(const std::vector<float>& radiance, const CostMap* cost) {
  if (radiance.size() != size_t(width_) * size_t(height_) * 3)
    throw std::invalid_argument("AdaptiveStill::add: radiance not width x height RGB");
  if (converged_) throw std::logic_error("AdaptiveStill::add: the still is converged (an empty plan)");
  plan();
  tbb::parallel_for(tbb::blocked_range<int32_t>(0, ph_), [&](const tbb::blocked_range<int32_t>& r) {
    for (int32_t py = r.begin(); py != r.end(); ++py)
      for (int32_t px = 0; px < pw_; ++px) {
        const size_t p = size_t(py) * size_t(pw_) + size_t(px);
        if (plan_[p] == kSkipPacket) continue;
        const int32_t x1 = std::min(width_, (px + 1) * layout_.w), y1 = std::min(height_, (py + 1) * layout_.h);
        const double n = ++count_[p];
        const float inv = 1.0f / float(n);  // as Accumulation::average scales its sums
        float var = 0;  // the sum of the values' sample variances, encoded (none below two samples)
        for (int32_t y = py * layout_.h; y < y1; ++y)
          for (int32_t x = px * layout_.w; x < x1; ++x) {
            const size_t pixel = size_t(y) * size_t(width_) + size_t(x);
            for (int c = 0; c < 3; ++c) {
              const size_t i = pixel * 3 + size_t(c);
              const float v = radiance[i];
              sum_[i] += v;
              sum_sq_[i] += v * v;
              const uint32_t e = uint32_t(srgb_ ? raytracer_detail::encode_srgb(v) : raytracer_detail::encode_plain(v));
              enc_sum_[i] += e;
              enc_sq_[i] += e * e;
              const float m = sum_[i] * inv;
              encoded_.rgba[pixel * 4 + size_t(c)] = uint8_t(srgb_ ? raytracer_detail::encode_srgb(m) : raytracer_detail::encode_plain(m));
              // n - 1 times the sample variance (the division is the packet's, below).
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
        var_[p] = n >= 2 ? double(var) / (n - 1) : 0.0;
        if (cost && cost->packets.contains(px, py)) {
          const uint32_t c = cost->at(px, py);
          if (c > 0) cost_[p] = double(c);
        }
      }
  });
  ++rounds_;
  plan_valid_ = false;
}

std::vector<float> AdaptiveStill::mean() const {
  if (rounds_ == 0) return {};
  std::vector<float> out(sum_.size(), 0.0f);
  for (int32_t y = 0; y < height_; ++y)
    for (int32_t x = 0; x < width_; ++x) {
      const uint32_t n = count_[size_t(y / layout_.h) * size_t(pw_) + size_t(x / layout_.w)];
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
  for (int32_t py = 0; py < ph_; ++py)
    for (int32_t px = 0; px < pw_; ++px) {
      const double area = double((std::min(width_, (px + 1) * layout_.w) - px * layout_.w) *
                                 (std::min(height_, (py + 1) * layout_.h) - py * layout_.h));
      s += area * count_[size_t(py) * size_t(pw_) + size_t(px)];
    }
  return s / (double(width_) * double(height_));
}

uint32_t AdaptiveStill::min_samples() const {
  return count_.empty() ? 0 : *std::min_element(count_.begin(), count_.end());
}

}  // namespace tessera
