#pragma once
// Renderer actor: renders one task of a frame from a scene snapshot and returns pixels and
// the serialised SAT of the task's cost map. It is the unit of distribution: a child node
// is later just another (remote) renderer actor with this interface.
//
// Rendering blocks for tens of milliseconds and runs TBB inside, so the actor is spawned
// detached (its own thread) and CAF's scheduler is capped (configs/*.ini).
#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"

namespace tessera {

using renderer_actor = caf::typed_actor<caf::replies_to<render_atom, SceneSnapshot, RenderTask>::with<TileResult>>;

}  // namespace tessera
