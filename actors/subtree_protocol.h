#pragma once
// The subtree actor: one interface at every level of the tree (paper 5.2). A subtree is a
// node's own renderer (when the node renders) plus one subtree per child node, opened on that
// child by the node actor (cluster_protocol.h, open). A worker is the subtree a parent opened
// on this node for one session; a master's frame actor (frame_protocol.h) holds one root
// subtree for its whole tree; a hub's subtree renders nothing and only relays.
//
//   update(Payload, reset)               encoded client-protocol scene records
//                                        (protocol/scene_records.h); reset=true replaces the
//                                        whole scene (a node joining a running session). A
//                                        worker applies them to its own scene (at once, or
//                                        after the render in flight) and forwards them to its
//                                        children. Empty and reset=false: the parent's
//                                        adoption notice and keep-alive.
//   update(Payload, reset, last) -> n    one chunk of an update, acknowledged with its size;
//                                        the update is applied at `last`. Parents send big
//                                        updates this way, a window of chunks at a time
//                                        (subtree_state.h, Outbox).
//   render(RenderBatch) -> BatchReply    tasks[i] for entry i of the committed node list: its
//                                        own task on its renderer, the others relayed to the
//                                        children, what comes back checked (checks.h); the
//                                        tasks of a child that is down, too late or lying fail
//                                        with a typed code (TileResult::code). A batch outside
//                                        this node's limits fails every tile (bad_batch).
//   nodes() -> [NodeInfo]                commits membership (dead children out, joined ones in)
//                                        and returns the flattened list that later batches are
//                                        indexed by; requests during a commit wait for it.
//   scene(SceneSnapshot)                 a root only: the scene its own renderer renders from
//                                        now on, which belongs to the session's sync actor
//                                        (session_protocol.h); a worker refuses it.
//   cancel(frame)                        the master abandons frame `frame` (a still's sample
//                                        its client no longer wants): its own task stops early
//                                        (TileResult::cancelled) and the children are told. A
//                                        worker takes it from its parent only, a root from its
//                                        own node only.
//   tick                                 its own periodic work: keep-alives to the children,
//                                        joins of children that (re)connected, and for a
//                                        worker the orphan and parent-silence checks. A tick
//                                        from its parent runs one round now.
//
// Nothing is exchanged during a frame except the batch going down and the tiles coming up;
// rendering nodes never talk to each other.
#include <vector>

#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"
#include "actors/renderer_protocol.h"

namespace tessera {

// One rendering node of a sub-tree, as its parent sees it (paper 5.2: the master gets the
// flattened list of its sub-trees' rendering nodes).
struct NodeInfo {
  std::string name;            // "host:port" of its cluster endpoint, or "local"
  int32_t logical_cores = 1;   // renderer coefficient = logical_cores x single_core_perf
  double single_core_perf = 1;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, NodeInfo& x) {
  return f(caf::meta::type_name("tessera::node_info"), x.name, x.logical_cores, x.single_core_perf);
}

// The tasks of one frame for a sub-tree: tasks[i] is the pixel rectangle of entry i of the
// receiver's flattened node list (as last returned by its nodes query); empty: nothing.
struct RenderBatch {
  uint32_t frame = 0;
  int32_t width = 0, height = 0;
  int32_t ao_samples = 0, max_depth = 4;
  uint32_t timeout_ms = 5000;  // the sender gives up on this batch after this long
  std::vector<Rect> tasks;
  uint8_t renderer = 0;        // protocol::RendererKind of the session
  uint32_t sample = 0, seed = 0;  // RenderTask's: the sample of a progressive still and its seed
  bool radiance = false;          // tiles carry their linear colour (TileResult::radiance)
  bool hit_points = false;        // tiles carry their packets' depths (TileResult::depth)
  uint8_t guides = kNoGuides;     // tiles carry the denoiser's guides (RenderTask::guides)
  // RenderTask's plan of blocks (adaptive refinement), covering the blocks of every task here
  // (a child gets its tasks' part of it); empty: none.
  Rect plan_blocks;
  std::vector<uint32_t> plan;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, RenderBatch& x) {
  return f(caf::meta::type_name("tessera::render_batch"), x.frame, x.width, x.height, x.ao_samples, x.max_depth,
           x.timeout_ms, x.tasks, x.renderer, x.sample, x.seed, x.radiance, x.hit_points, x.guides, x.plan_blocks,
           x.plan);
}

// tiles[i] answers tasks[i] (its code set when that node failed); changed: the sub-tree lost or
// gained nodes, so its parent should ask for the node list again before the next frame.
struct BatchReply {
  std::vector<TileResult> tiles;
  bool changed = false;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, BatchReply& x) {
  return f(caf::meta::type_name("tessera::batch_reply"), x.tiles, x.changed);
}

using subtree_actor = caf::typed_actor<caf::reacts_to<update_atom, Payload, bool>,
                                       caf::replies_to<update_atom, Payload, bool, bool>::with<uint64_t>,
                                       caf::replies_to<render_atom, RenderBatch>::with<BatchReply>,
                                       caf::replies_to<nodes_atom>::with<std::vector<NodeInfo>>,
                                       caf::reacts_to<scene_atom, SceneSnapshot>,
                                       caf::reacts_to<cancel_atom, uint32_t>,
                                       caf::reacts_to<tick_atom>,
                                       caf::replies_to<ping_atom>::with<uint64_t>,
                                       caf::reacts_to<deadline_atom, uint64_t, uint64_t>>;

// Where a root subtree gets the whole scene for a child that joins: the session's sync actor,
// which owns the scene (a worker makes its snapshot from its own scene).
using scene_source_actor = caf::typed_actor<caf::replies_to<snapshot_atom>::with<Payload>>;

}  // namespace tessera
