#include "lb/frame_budget.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tessera {

namespace {
constexpr double kStep = 1.0 / 32;     // scales are multiples of this
constexpr double kSmooth = 0.5;        // weight of the newest frame in the smoothed cost
constexpr double kJump = 2.0;          // a cost this far off the smoothed one replaces it
constexpr double kHysteresis = 0.15;   // keep the scale while its predicted time is this close
constexpr double kLevelGuess = 0.6;    // cost of a level over the one above it, until measured
// A measured ratio is kept within these: one frame's time swings by 2x on a busy machine, and a
// ratio taken from such a frame would otherwise pin the ladder (a level that looks 5x cheaper
// than the one above never gives its samples back). Halving the AO rays keeps the primary,
// shadow and secondary rays, so a level never costs less than about a third of the one above.
constexpr double kMinRatio = 0.35, kMaxRatio = 1.0;

double quantised(double scale) { return std::round(scale / kStep) * kStep; }
}  // namespace

std::vector<InteractiveSamples> interactive_levels(uint32_t ao_samples, uint32_t max_depth) {
  std::vector<InteractiveSamples> levels{{ao_samples, max_depth}};
  InteractiveSamples s{ao_samples, max_depth};
  while (s.ao_samples > 1 && int(levels.size()) < FrameBudget::kMaxLevels) {
    s.ao_samples = (s.ao_samples + 1) / 2;
    levels.push_back(s);
  }
  if (s.max_depth > 2 && int(levels.size()) < FrameBudget::kMaxLevels) {
    s.max_depth = 2;
    levels.push_back(s);
  }
  return levels;
}

FrameBudget::FrameBudget(double budget_ms, double min_scale) : budget_ms_(budget_ms), min_scale_(min_scale) {
  if (!(budget_ms > 0) || !std::isfinite(budget_ms)) throw std::invalid_argument("FrameBudget: budget must be > 0");
  if (!(min_scale > 0) || min_scale > 1) throw std::invalid_argument("FrameBudget: min_scale must be in (0, 1]");
}

void FrameBudget::set_ladder(std::vector<InteractiveSamples> ladder) {
  if (ladder.size() > size_t(kMaxLevels)) ladder.resize(size_t(kMaxLevels));
  if (ladder == ladder_) return;
  ladder_ = std::move(ladder);
  for (int l = 1; l < kMaxLevels; ++l) cost_[size_t(l)] = ratio_[size_t(l)] = 0;
  level_ = 0;
  from_ = -1;
  over_ = 0;
}

void FrameBudget::move_to(int level, double cost) {
  from_ = level_;
  over_ = 0;
  level_ = level;
  scale_ = cost > 0 ? std::clamp(quantised(std::sqrt(budget_ms_ / cost)), min_scale_, 1.0) : 1.0;
}

void FrameBudget::observe(double scale, double ms, int level) {
  if (!(scale > 0) || !std::isfinite(scale) || !(ms >= 0) || !std::isfinite(ms)) return;  // nothing to learn
  if (level < 0 || level >= levels()) return;  // a frame of a ladder that is gone
  const double cost = ms / (scale * scale);
  double& c = cost_[size_t(level)];
  if (c <= 0 || cost > kJump * c || cost < c / kJump)
    c = cost;
  else
    c = kSmooth * cost + (1 - kSmooth) * c;
  if (level != level_) return;  // learnt; the decision is the current level's
  const double min2 = min_scale_ * min_scale_;
  // Frames in a row whose own cost is over the budget at the smallest scale: a level is given up
  // on the second, not on one slow frame (a busy neighbour, the BVH build of a new object).
  over_ = cost * min2 > (1 + kHysteresis) * budget_ms_ ? over_ + 1 : 0;
  if (from_ >= 0) {  // the first frame after a step: the ratio of the two levels' costs
    const int hi = std::max(from_, level_), lo = std::min(from_, level_);
    if (cost_[size_t(lo)] > 0 && cost_[size_t(hi)] > 0) {
      const double r = std::clamp(cost_[size_t(hi)] / cost_[size_t(lo)], kMinRatio, kMaxRatio);
      double& kept = ratio_[size_t(hi)];
      kept = kept > 0 ? kSmooth * r + (1 - kSmooth) * kept : r;  // smoothed over the steps between the two
    }
    from_ = -1;
  }
  // Back up a level when it would fit at the smallest scale with room to spare.
  if (level_ > 0) {
    const double r = ratio_[size_t(level_)] > 0 ? ratio_[size_t(level_)] : kLevelGuess;
    const double up = c / r;
    if (up * min2 <= (1 - kHysteresis) * budget_ms_) {
      move_to(level_ - 1, up);
      return;
    }
  }
  if (c <= 0) {  // free frames: full resolution
    scale_ = 1;
    return;
  }
  const double predicted = c * scale_ * scale_;
  if (std::abs(predicted - budget_ms_) <= kHysteresis * budget_ms_) return;
  // Down a level when even the smallest scale is well over the budget, for the second frame.
  if (over_ >= 2 && c * min2 > (1 + kHysteresis) * budget_ms_ && level_ + 1 < levels()) {
    const double r = ratio_[size_t(level_ + 1)] > 0 ? ratio_[size_t(level_ + 1)] : kLevelGuess;
    move_to(level_ + 1, c * r);
    return;
  }
  scale_ = std::clamp(quantised(std::sqrt(budget_ms_ / c)), min_scale_, 1.0);
}

void FrameBudget::restart() {
  cost_.fill(0);
  ratio_.fill(0);
  level_ = 0;
  from_ = -1;
  over_ = 0;
  scale_ = min_scale_;
}

void FrameBudget::scaled(int32_t w, int32_t h, double scale, int32_t& sw, int32_t& sh) {
  sw = std::max<int32_t>(1, int32_t(std::lround(double(w) * scale)));
  sh = std::max<int32_t>(1, int32_t(std::lround(double(h) * scale)));
}

}  // namespace tessera
