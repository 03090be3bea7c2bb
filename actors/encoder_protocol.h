#pragma once
// Encoder actor, one per session: JPEG (libjpeg-turbo), DXT1 (libsquish, TBB over block rows)
// or H.264 (OpenH264; the session's video stream state lives here) of a composed frame. Runs
// detached, so the encoding of frame f overlaps the rendering of f+1.
#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"

namespace tessera {

// Display -> encoder: a composed image.
struct EncodeJob {
  FrameMeta meta;
  std::vector<uint8_t> rgba;  // width * height * 4
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, EncodeJob& x) {
  return f(caf::meta::type_name("tessera::encode_job"), x.meta, BytesField{x.rgba});
}

// Encoder -> display: the encoded frame. `message` starts with header_bytes of room for the
// protocol header (the display writes it when it knows the pipeline time) followed by the
// payload (JPEG file or DXT1 blocks).
struct EncodedFrame {
  FrameMeta meta;
  std::vector<uint8_t> message;
  uint32_t header_bytes = 0;
  double encode_ms = 0;
  int64_t encode_start_ns = 0, encode_end_ns = 0;
  bool keyframe = false;  // H.264: an IDR access unit
  std::string error;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, EncodedFrame& x) {
  return f(caf::meta::type_name("tessera::encoded_frame"), x.meta, BytesField{x.message}, x.header_bytes, x.encode_ms,
           x.encode_start_ns, x.encode_end_ns, x.keyframe, x.error);
}

using encoder_actor = caf::typed_actor<caf::replies_to<encode_atom, EncodeJob>::with<EncodedFrame>>;

}  // namespace tessera
