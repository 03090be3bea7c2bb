#pragma once
// Session actor (the sync channel), one per connected client: decodes and validates the
// client's messages, owns its Scene, applies scene updates (at once when no frame is in
// flight, else cached until the frame is rendered) and forwards the accepted ones down the
// tree (its root subtree), coalesces render requests, and asks its frame actor
// (frame_protocol.h) for one frame at a time. It spawns and links the session's other actors.
//
//   client(bytes)            a message from the client (net/server.cpp)
//   status -> SessionStatus  for tests and monitoring
//   children -> [actor]      renderer (when this node renders), tiler, encoder, display,
//                            frame actor, root subtree
//   tick                     a round of keep-alives and joins in the tree now
//   snapshot -> Payload      the whole scene as records, for a child that joins (the root
//                            subtree asks: scene_source_actor)
#include <cstdint>
#include <vector>

#include <caf/actor.hpp>
#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"

namespace tessera {

// A session's state, for tests and monitoring.
struct SessionStatus {
  bool handshake_done = false;
  bool in_flight = false;        // a frame is being rendered (scene updates are cached)
  bool render_pending = false;   // a render request waits for the frame in flight
  uint32_t pending_frame = 0;
  uint32_t cached_updates = 0;
  uint32_t frames_started = 0;
  uint32_t dropped = 0;          // render requests merged into a later one
  uint32_t errors_sent = 0;
  uint64_t scene_version = 0;
  uint64_t triangles = 0;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, SessionStatus& x) {
  return f(caf::meta::type_name("tessera::session_status"), x.handshake_done, x.in_flight, x.render_pending,
           x.pending_frame, x.cached_updates, x.frames_started, x.dropped, x.errors_sent, x.scene_version,
           x.triangles);
}

// The handshake timeout (NodeSettings::handshake_timeout_ms), sent by the session to itself.
using hs_timeout_atom = caf::atom_constant<caf::atom("hstimeout")>;
// The still after interactive frames, due (NodeSettings::still_delay_ms), sent by the session to
// itself with the still's seed: a still replaced meanwhile ignores it.
using still_atom = caf::atom_constant<caf::atom("still")>;
// Errors not reported yet (session_state::unreported_errors) are due, sent by the session to
// itself when the rate limit held back their summary.
using unreported_atom = caf::atom_constant<caf::atom("unreport")>;

using session_actor = caf::typed_actor<caf::reacts_to<client_atom, std::vector<uint8_t>>,
                                       caf::replies_to<status_atom>::with<SessionStatus>,
                                       // renderer, tiler, encoder, display, workers (tests, monitoring)
                                       caf::replies_to<children_atom>::with<std::vector<caf::actor>>,
                                       caf::reacts_to<tick_atom>,
                                       caf::reacts_to<hs_timeout_atom>,
                                       caf::reacts_to<still_atom, uint32_t>,
                                       caf::reacts_to<unreported_atom>,
                                       caf::replies_to<snapshot_atom>::with<Payload>>;

}  // namespace tessera
