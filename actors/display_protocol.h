#pragma once
// Display channel actor, one per session: composes the tiles of a frame, has the encoder
// encode it, and sends the Frame record (and MJPEG parts) to the client in frame order.
// Logs one JSON line of per-frame measurements.
#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"

namespace tessera {

using display_actor = caf::typed_actor<caf::reacts_to<display_atom, FrameTiles>>;

}  // namespace tessera
