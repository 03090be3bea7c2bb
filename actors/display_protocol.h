#pragma once
// Display channel actor, one per session: composes the tiles of a frame, has the encoder
// encode it, and sends the Frame record (and MJPEG parts) to the client in frame order.
// Logs one JSON line of per-frame measurements.
#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"
#include "actors/renderer_protocol.h"

namespace tessera {

// Frame actor -> display channel: the tiles of one frame.
struct FrameTiles {
  FrameMeta meta;
  std::vector<TileResult> tiles;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, FrameTiles& x) {
  return f(caf::meta::type_name("tessera::frame_tiles"), x.meta, x.tiles);
}

// tick_atom: the connection has written (or replaced) a frame (ClientSink::on_frame_gone).
using display_actor = caf::typed_actor<caf::reacts_to<display_atom, FrameTiles>, caf::reacts_to<tick_atom>>;

}  // namespace tessera
