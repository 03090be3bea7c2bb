#pragma once
// Typed errors between actors. protocol::ErrorCode is the one error-code enum of a node, from
// the client protocol's decoder to the renderer's replies; it is registered with CAF as the
// error category "tessera" (register_message_types), the way CAF registers caf::sec, so an
// actor replies with `make_error(ErrorCode::render_failed, why)` and a caf::error carries the
// code across actors and processes. A tile that failed carries the code in TileResult::code.
#include <string>

#include <caf/error.hpp>

#include "actors/subtree_protocol.h"
#include "protocol/protocol.h"

namespace tessera {
namespace protocol {

// A caf::error of the "tessera" category: the code, with the message as its context.
caf::error make_error(ErrorCode code, std::string message);

}  // namespace protocol

inline constexpr caf::atom_value kErrorCategory = caf::atom("tessera");

// The code of an error: ok for none, the code for ours, and for any other error (CAF's
// timeouts, a peer gone) `otherwise`.
protocol::ErrorCode error_code(const caf::error& e, protocol::ErrorCode otherwise);
// The message of an error of ours (its context), or CAF's name and context for others.
std::string error_message(const caf::error& e);

// A tile of task `t` that failed with `code` and `message` (no pixels, no SAT).
TileResult failed_tile(const RenderTask& t, protocol::ErrorCode code, std::string message);
// The same from an actor's error reply; an error not of ours counts as `otherwise`.
TileResult failed_tile(const RenderTask& t, const caf::error& e, protocol::ErrorCode otherwise);

// Every tile of a batch (at most 65536) failed with `code` and `message`.
BatchReply failed_batch(const RenderBatch& b, protocol::ErrorCode code, const std::string& message);

}  // namespace tessera
