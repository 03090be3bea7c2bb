#pragma once
// Tiler actor (paper 6.3): keeps the SAT array of the last rendered frame and answers the
// task list of the next one (one pixel rectangle per rendering node). Messages from one
// sender arrive in order, so SATs of frame f sent before the task request of f+1 are used.
#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"

namespace tessera {

// Tiler: the task list for a frame, and the SATs of the previous one.
struct TaskRequest {
  uint32_t frame = 0;
  int32_t width = 0, height = 0;
  int32_t packet_w = 4, packet_h = 4;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, TaskRequest& x) {
  return f(caf::meta::type_name("tessera::task_request"), x.frame, x.width, x.height, x.packet_w, x.packet_h);
}

struct TaskList {
  uint32_t frame = 0;
  std::vector<Rect> tasks;  // pixel rectangles, one per rendering node (index = node)
  double tiling_ms = 0;
  bool from_sats = false;   // false: even split (first frame, or the size changed)
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, TaskList& x) {
  return f(caf::meta::type_name("tessera::task_list"), x.frame, x.tasks, x.tiling_ms, x.from_sats);
}

struct SatReport {
  uint32_t frame = 0;
  int32_t width = 0, height = 0;
  int32_t packet_w = 4, packet_h = 4;
  std::vector<std::vector<uint8_t>> sats;  // one serialised SAT per node (empty: missing)
  std::vector<double> perf;                // single-core performance of the node behind each SAT
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, SatReport& x) {
  return f(caf::meta::type_name("tessera::sat_report"), x.frame, x.width, x.height, x.packet_w, x.packet_h, x.sats,
           x.perf);
}

// nodes: the renderer coefficients of the rendering nodes from the next task request on
// (the cluster's membership changed); the SATs already received stay valid.
using tiler_actor =
    caf::typed_actor<caf::reacts_to<sats_atom, SatReport>, caf::replies_to<tasks_atom, TaskRequest>::with<TaskList>,
                     caf::reacts_to<nodes_atom, std::vector<double>>>;

}  // namespace tessera
