#pragma once
// The frame actor, one per session: runs each frame through tiler -> subtree -> recovery ->
// display. The session's sync actor (session_protocol.h) owns the scene and asks for frames.
//
//   nodes(max_nodes) -> n          commits the session's tree (its root subtree) and picks the
//                                  nodes this client renders on (the strongest first, at most
//                                  max_nodes, 0: all); n of them (at least 1: with none, this
//                                  node renders). Sent once, for the handshake's reply.
//   render(FrameStart) -> more     one frame: the root subtree's node list (committed again
//                                  when its membership changed), the tiler's tasks from the
//                                  previous frame's SATs, the scene to the root subtree and the
//                                  batch through it, the tasks of lost nodes rendered here, the
//                                  SATs to the tiler and the tiles to the display. Answers when
//                                  the tiles went to the display (the encoder then encodes this
//                                  frame while the next one renders), or with a typed error
//                                  (actors/errors.h) when the frame cannot be shown. `more`: 0
//                                  when it was a refining still's last round (converged: every
//                                  block at the target, or refined adaptively, its error out of
//                                  sight; FrameMeta::converged), else 1.
//   cancel(seq)                    the session abandons frame `seq`, a still's sample in flight
//                                  (its client asked for a new frame): the root subtree and its
//                                  renderers are told, the tasks stop early, and the frame is
//                                  answered without being averaged, shown or given to the tiler
//                                  (a sample that was complete by then goes on as usual). Other
//                                  frames are never abandoned.
#include <cstdint>

#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/display_protocol.h"
#include "actors/messages.h"
#include "actors/renderer_protocol.h"
#include "actors/subtree_protocol.h"
#include "actors/tiler_protocol.h"

namespace tessera {

// Sync actor -> frame actor (frame_protocol.h): render one frame. `meta` has the session's
// figures as of the frame's start; `scene` is read-only until the frame actor answers.
struct FrameStart {
  FrameMeta meta;
  SceneSnapshot scene;
  int32_t ao_samples = 0, max_depth = 4;
  uint8_t renderer = 0;  // protocol::RendererKind
  // A progressive still (renderer/adaptive.h): `refine` renders with radiance and averages
  // it in the frame actor; `sample` 0 starts a new average, k > 0 adds the k-th round (a
  // sample of every pixel, or refined adaptively, of the blocks its plan picks).
  // `seed`: the frame number that seeds the still's sample pattern (its first frame).
  bool refine = false;
  uint32_t sample = 0, seed = 0;
  // With refine: the samples the still refines to (its last is always shown), and whether it
  // is denoised (renderer/denoise.h; a scene with a sky and AO, NodeSettings::denoise_below_db).
  uint32_t target = 0;
  bool denoise = false;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, FrameStart& x) {
  return f(caf::meta::type_name("tessera::frame_start"), x.meta, x.scene, x.ao_samples, x.max_depth, x.renderer, x.refine,
           x.sample, x.seed, x.target, x.denoise);
}

using frame_actor = caf::typed_actor<caf::replies_to<nodes_atom, uint32_t>::with<uint32_t>,
                                     caf::replies_to<render_atom, FrameStart>::with<uint32_t>,
                                     caf::reacts_to<cancel_atom, uint32_t>>;

// The actors a frame actor drives; the session spawns and links them all.
struct FrameActors {
  subtree_actor subtree;    // the root of the session's tree
  renderer_actor renderer;  // this node's renderer (none on a node that does not render: one is
                            // spawned when a lost node's tasks must be rendered here)
  tiler_actor tiler;
  display_actor display;
};

}  // namespace tessera
