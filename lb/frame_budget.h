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
#include <cstdint>

namespace tessera {

class FrameBudget {
 public:
  // budget_ms > 0; scales within [min_scale, 1].
  explicit FrameBudget(double budget_ms, double min_scale = 0.25);
  double budget_ms() const { return budget_ms_; }
  // The scale of the next interactive frame.
  double scale() const { return scale_; }
  // A frame rendered at `scale` took `ms` (its time from start to its pixels being in).
  void observe(double scale, double ms);
  // The cost model no longer applies: the scene changed under it (a page's scene arrived after
  // frames of an empty one, say), and a frame at the old scale could take many budgets. The
  // next frame renders at the smallest scale, and its time sets the cost again.
  void restart();
  // The smoothed cost of a full-resolution frame (ms), 0 before any observation.
  double full_cost_ms() const { return cost_; }
  // Width and height at `scale` of a w x h frame: at least 1 each, rounded to nearest.
  static void scaled(int32_t w, int32_t h, double scale, int32_t& sw, int32_t& sh);

 private:
  double budget_ms_, min_scale_;
  double scale_ = 1.0;
  double cost_ = 0;  // ms of a frame at scale 1
};

}  // namespace tessera
