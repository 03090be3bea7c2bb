#pragma once
// The render scale of interactive frames (issue 18, item 1): while the view changes, each
// frame is rendered at a fraction of the client's resolution (width and height each times the
// scale; the client scales the image up) so that it takes about the budget. A still is then
// rendered and refined at full resolution.
//
// The cost model is the frames themselves: a frame at scale s that took t ms costs t / s^2 per
// unit of full-resolution area (the cost maps' sum, per pixel, scales with the area). The cost
// is smoothed over frames; a frame whose cost is more than twice or less than half the
// smoothed one replaces it at once (a cut, a new object in view), so the scale adapts within a
// frame. When the scene itself changes much (session_actor.cpp: its triangle count more than
// doubles or halves), the model restarts from the smallest scale instead of predicting from a
// different scene. Scales are quantised (steps of 1/32), and the scale changes only when the predicted
// time at the current one is more than 15% off the budget: a resolution change makes the
// next frame's tiling start from an even split (its SATs no longer match), so it should be rare.
//
// Below the smallest scale, interactive frames trade samples for time: levels (interactive_levels)
// step from the page's settings to fewer AO rays per hit and then a shallower depth. A level is
// taken when even the smallest scale would be more than 15% over the budget at the current one
// for two frames in a row (not for one slow frame), and given back when the level above would fit at the smallest scale with 15% to spare. Each
// level has its own smoothed cost, and the cost ratio of neighbouring levels is measured at each
// step between them (guessed until then; smoothed, and kept within 0.35..1), so the cost of the
// level above is predicted from the current view. The still that follows a drag renders the page's settings again.
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tessera {

// One step of the ladder: the AO rays per hit and the depth of an interactive frame.
struct InteractiveSamples {
  uint32_t ao_samples = 0, max_depth = 0;
  bool operator==(const InteractiveSamples& o) const { return ao_samples == o.ao_samples && max_depth == o.max_depth; }
  bool operator!=(const InteractiveSamples& o) const { return !(*this == o); }
};

// The levels for a page's settings: the settings themselves first, then AO rays halved
// (rounded up) down to 1, then the depth down to 2 (one bounce: glass and mirrors still show
// something behind them). Settings with nothing to lower have one level.
std::vector<InteractiveSamples> interactive_levels(uint32_t ao_samples, uint32_t max_depth);

class FrameBudget {
 public:
  static constexpr int kMaxLevels = 8;
  // budget_ms > 0; scales within [min_scale, 1].
  explicit FrameBudget(double budget_ms, double min_scale = 0.25);
  double budget_ms() const { return budget_ms_; }
  // The scale of the next interactive frame.
  double scale() const { return scale_; }
  // Its level (0: the page's settings), below levels().
  int level() const { return level_; }
  int levels() const { return ladder_.empty() ? 1 : int(ladder_.size()); }
  // The samples of the next interactive frame: its level's step of the ladder.
  InteractiveSamples samples() const { return ladder_.at(size_t(level_)); }
  // The levels (interactive_levels(); at most kMaxLevels are kept). The same ladder again changes
  // nothing; a new one (the page changed its settings, or this controller is new) starts again
  // from level 0 at the current scale, and the costs of the lower levels and their ratios are
  // forgotten.
  void set_ladder(std::vector<InteractiveSamples> ladder);
  // A frame rendered at `scale` and `level` took `ms` (its time from start to its pixels being
  // in). The two-argument form: at the current level.
  void observe(double scale, double ms, int level);
  void observe(double scale, double ms) { observe(scale, ms, level_); }
  // The cost model no longer applies: the scene changed under it (a page's scene arrived after
  // frames of an empty one, say), and a frame at the old scale could take many budgets. The
  // next frame renders at the smallest scale and level 0, and its time sets the cost again.
  void restart();
  // The smoothed cost of a full-resolution frame (ms) at the current level, 0 before any
  // observation.
  double full_cost_ms() const { return cost_[size_t(level_)]; }
  // Width and height at `scale` of a w x h frame: at least 1 each, rounded to nearest.
  static void scaled(int32_t w, int32_t h, double scale, int32_t& sw, int32_t& sh);

 private:
  void move_to(int level, double cost);
  double budget_ms_, min_scale_;
  double scale_ = 1.0;
  std::vector<InteractiveSamples> ladder_;  // empty: one level, the page's settings
  int level_ = 0;
  int from_ = -1;  // the level left by the last step, until the first frame at the new one
  int over_ = 0;   // frames in a row at this level over the budget even at the smallest scale
  std::array<double, kMaxLevels> cost_{};   // ms of a frame at scale 1, per level
  std::array<double, kMaxLevels> ratio_{};  // cost_[l] / cost_[l - 1] as measured at a step; 0: not yet
};

}  // namespace tessera
