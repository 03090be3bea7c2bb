#pragma once
// The cluster protocols (paper 5.2): nodes form a tree over CAF's middleman; every node
// publishes one node actor on its cluster port; a session's master opens one worker per node
// of its sub-tree, and the workers relay scene updates down and tiles up.
//
//   node_actor   (one per process, published)
//     open      -> a worker for one session on this node's sub-tree, with its flattened
//                  node list (renderer coefficients of every rendering node below, this node
//                  first if it renders); recursive: the worker opens workers on the children.
//                  The request says how long the parent waits (OpenRequest::timeout_ms): a
//                  worker that gets no update within twice that was opened after its parent
//                  gave up (a cut link delivering what it held) and ends itself ("orphaned").
//                  A worker lives as long as its session: it watches the actor that opened
//                  it (down: the session ended or the connection broke), and the parent sends
//                  it an empty update every OpenRequest::keepalive_ms; silent for
//                  NodeSettings::keepalive_misses periods, it ends. A node refuses malformed
//                  opens and opens beyond NodeSettings::max_workers (check_open, router.h).
//     links     -> the children this node is connected to now (used by its own workers to
//                  notice children that came back)
//   worker_actor (one per session per node)
//     update    -> encoded client-protocol scene records (protocol/scene_records.h); reset=true
//                  replaces the whole scene (a node that joins a running session). Applied at
//                  once, or cached while this node renders, and forwarded to the children.
//                  Empty and reset=false: the parent adopted this worker (its first message).
//     update chunk -> (bytes, reset, last): a piece of one update, acknowledged with its size
//                  when the worker takes it; the worker applies the update at `last`. Parents
//                  send updates this way, a window of chunks at a time (Outbox, router.h), so
//                  no burst of uploads piles up in a connection's buffers; a small update
//                  (a frame's camera) goes as one plain update while less than a chunk is
//                  unacknowledged.
//     render    -> BatchReply: renders its own task, relays the others, validates what the
//                  children return, fails the tasks of a child that is down or too late. A
//                  batch outside this node's limits fails every tile (check_batch, router.h).
//     nodes     -> commits membership changes (dead children out, rejoined children in) and
//                  returns the flattened list that the next batches are indexed by.
//
// Nothing is exchanged during a frame except the batch going down and the tiles coming up;
// rendering nodes never talk to each other.
#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"

namespace tessera {

using worker_actor = caf::typed_actor<caf::reacts_to<update_atom, Payload, bool>,
                                      caf::replies_to<update_atom, Payload, bool, bool>::with<uint64_t>,
                                      caf::replies_to<render_atom, RenderBatch>::with<BatchReply>,
                                      caf::replies_to<nodes_atom>::with<std::vector<NodeInfo>>,
                                      caf::reacts_to<tick_atom>>;

using node_actor = caf::typed_actor<caf::replies_to<open_atom, OpenRequest>::with<OpenReply>,
                                    caf::replies_to<links_atom>::with<std::vector<ChildLink>>,
                                    caf::reacts_to<tick_atom>>;

}  // namespace tessera
