#pragma once
// Tiler actor (paper 6.3): keeps the SAT array of the last rendered frame and answers the
// task list of the next one (one pixel rectangle per rendering node). Messages from one
// sender arrive in order, so SATs of frame f sent before the task request of f+1 are used.
#include <algorithm>
#include <cmath>

#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"

namespace tessera {

// A camera as the tiler's messages carry it: the 16 floats of Camera::to_world, then fov_y.
// Empty: no camera (the tiler does not reproject).
inline std::vector<float> pack_camera(const Camera& c) {
  std::vector<float> v(c.to_world.m.begin(), c.to_world.m.end());
  v.push_back(c.fov_y);
  return v;
}
inline bool unpack_camera(const std::vector<float>& v, Camera& c) {
  if (v.size() != 17) return false;
  for (float x : v)
    if (!std::isfinite(x)) return false;
  std::copy(v.begin(), v.begin() + 16, c.to_world.m.begin());
  c.fov_y = v[16];
  return true;
}

// Tiler: the task list for a frame, and the SATs of the previous one.
struct TaskRequest {
  uint32_t frame = 0;
  int32_t width = 0, height = 0;
  int32_t packet_w = 4, packet_h = 4;
  // This frame's camera (pack_camera): with the last report's depths, the last frame's cost is
  // reprojected into it (lb/reproject.h). Empty: the previous frame's map as it is (the paper).
  std::vector<float> camera;
  // A round of a still refined adaptively (renderer/adaptive.h), which renders part of the
  // image: tiled from the last such round's SATs, else from the last whole frame's.
  bool partial = false;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, TaskRequest& x) {
  return f(caf::meta::type_name("tessera::task_request"), x.frame, x.width, x.height, x.packet_w, x.packet_h,
           x.camera, x.partial);
}

// Which prediction a task list was tiled from.
enum class Predictor : uint8_t {
  area = 0,         // no usable SATs (first frame, the size changed): an even split
  previous = 1,     // the previous frame's SATs as they are (the paper)
  reprojected = 2,  // the previous frame's cost carried into this frame's camera
  cut = 3,          // reprojection found a cut (too little of the view shared): the previous SATs
};
inline const char* to_string(Predictor p) {
  switch (p) {
    case Predictor::area: return "area";
    case Predictor::previous: return "previous_frame";
    case Predictor::reprojected: return "reprojected";
    case Predictor::cut: return "cut";
  }
  return "?";
}

struct TaskList {
  uint32_t frame = 0;
  std::vector<Rect> tasks;  // pixel rectangles, one per rendering node (index = node)
  double tiling_ms = 0;     // the reprojection included
  bool from_sats = false;   // false: even split (first frame, or the size changed)
  uint8_t predictor = 0;    // Predictor
  double reproject_ms = 0;  // of tiling_ms: carrying the cost into the new camera (wall clock)
  double reproject_cpu_ms = 0;  // the same in the tiler thread's CPU time (without preemption)
  int64_t filled = 0;       // reprojection: packets filled from their neighbours
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, TaskList& x) {
  return f(caf::meta::type_name("tessera::task_list"), x.frame, x.tasks, x.tiling_ms, x.from_sats, x.predictor,
           x.reproject_ms, x.reproject_cpu_ms, x.filled);
}

struct SatReport {
  uint32_t frame = 0;
  int32_t width = 0, height = 0;
  int32_t packet_w = 4, packet_h = 4;
  std::vector<std::vector<uint8_t>> sats;  // one serialised SAT per node (empty: missing)
  std::vector<double> perf;                // single-core performance of the node behind each SAT
  // Per SAT, its packets' depths (TileResult::depth; empty: none), and the camera they were
  // rendered with (pack_camera; empty: none): what the next frame's reprojection starts from.
  std::vector<std::vector<uint8_t>> depths;
  std::vector<float> camera;
  // The SATs of a partial round (TaskRequest::partial): they steer the next partial round only,
  // and the last whole frame's stay for the frames after the still.
  bool partial = false;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, SatReport& x) {
  return f(caf::meta::type_name("tessera::sat_report"), x.frame, x.width, x.height, x.packet_w, x.packet_h, x.sats,
           x.perf, x.depths, x.camera, x.partial);
}

// nodes: the renderer coefficients of the rendering nodes from the next task request on
// (the cluster's membership changed); the SATs already received stay valid.
using tiler_actor =
    caf::typed_actor<caf::reacts_to<sats_atom, SatReport>, caf::replies_to<tasks_atom, TaskRequest>::with<TaskList>,
                     caf::reacts_to<nodes_atom, std::vector<double>>>;

}  // namespace tessera
