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
}  // namespace

FrameBudget::FrameBudget(double budget_ms, double min_scale) : budget_ms_(budget_ms), min_scale_(min_scale) {
  if (!(budget_ms > 0) || !std::isfinite(budget_ms)) throw std::invalid_argument("FrameBudget: budget must be > 0");
  if (!(min_scale > 0) || min_scale > 1) throw std::invalid_argument("FrameBudget: min_scale must be in (0, 1]");
}

void FrameBudget::observe(double scale, double ms) {
  if (!(scale > 0) || !std::isfinite(scale) || !(ms >= 0) || !std::isfinite(ms)) return;  // nothing to learn
  const double cost = ms / (scale * scale);
  if (cost_ <= 0 || cost > kJump * cost_ || cost < cost_ / kJump)
    cost_ = cost;
  else
    cost_ = kSmooth * cost + (1 - kSmooth) * cost_;
  if (cost_ <= 0) {  // free frames: full resolution
    scale_ = 1;
    return;
  }
  const double predicted = cost_ * scale_ * scale_;
  if (std::abs(predicted - budget_ms_) <= kHysteresis * budget_ms_) return;
  double want = std::sqrt(budget_ms_ / cost_);
  want = std::round(want / kStep) * kStep;
  scale_ = std::clamp(want, min_scale_, 1.0);
}

void FrameBudget::restart() {
  cost_ = 0;
  scale_ = min_scale_;
}

void FrameBudget::scaled(int32_t w, int32_t h, double scale, int32_t& sw, int32_t& sh) {
  sw = std::max<int32_t>(1, int32_t(std::lround(double(w) * scale)));
  sh = std::max<int32_t>(1, int32_t(std::lround(double(h) * scale)));
}

}  // namespace tessera
