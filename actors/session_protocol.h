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

// The handshake timeout (NodeSettings::handshake_timeout_ms), sent by the session to itself.
using hs_timeout_atom = caf::atom_constant<caf::atom("hstimeout")>;

using session_actor = caf::typed_actor<caf::reacts_to<client_atom, std::vector<uint8_t>>,
                                       caf::replies_to<status_atom>::with<SessionStatus>,
                                       // renderer, tiler, encoder, display, workers (tests, monitoring)
                                       caf::replies_to<children_atom>::with<std::vector<caf::actor>>,
                                       caf::reacts_to<tick_atom>,
                                       caf::reacts_to<hs_timeout_atom>,
                                       caf::replies_to<snapshot_atom>::with<Payload>>;

}  // namespace tessera
