#pragma once
// Encoder actor: JPEG (libjpeg-turbo) or DXT1 (libsquish, TBB over block rows) of a
// composed frame. Runs detached, so the encoding of frame f overlaps the rendering of f+1.
#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"

namespace tessera {

using encoder_actor = caf::typed_actor<caf::replies_to<encode_atom, EncodeJob>::with<EncodedFrame>>;

}  // namespace tessera
