#pragma once
// Tiler actor (paper 6.3): keeps the SAT array of the last rendered frame and answers the
// task list of the next one (one pixel rectangle per rendering node). Messages from one
// sender arrive in order, so SATs of frame f sent before the task request of f+1 are used.
#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"

namespace tessera {

// nodes: the renderer coefficients of the rendering nodes from the next task request on
// (the cluster's membership changed); the SATs already received stay valid.
using tiler_actor =
    caf::typed_actor<caf::reacts_to<sats_atom, SatReport>, caf::replies_to<tasks_atom, TaskRequest>::with<TaskList>,
                     caf::reacts_to<nodes_atom, std::vector<double>>>;

}  // namespace tessera
