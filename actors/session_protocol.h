#pragma once
// Session actor (the sync channel), one per connected client: owns the client's Scene,
// decodes and validates its messages, applies scene updates (at once when no frame is in
// flight, else cached until the frame is rendered), coalesces render requests, and drives
// tiler -> renderer(s) -> display for each frame.
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
                                       caf::reacts_to<tick_atom>,   // look for children that came back
                                       caf::reacts_to<hs_timeout_atom>>;

}  // namespace tessera
