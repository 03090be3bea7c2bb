#pragma once
// The node actor (paper 5.2): nodes form a tree over CAF's middleman, and every node
// publishes one node actor on its cluster port.
//
//   node_actor (one per process, published)
//     open(OpenRequest) -> OpenReply   a worker: a subtree (subtree_protocol.h) for one session
//                  on this node's sub-tree, with its flattened node list (renderer
//                  coefficients of every rendering node below, this node first if it renders).
//                  Recursive: the worker opens workers on the node's children. The request
//                  says how long the parent waits (OpenRequest::timeout_ms): a worker that is
//                  not adopted within twice that was opened after its parent gave up (a cut
//                  link delivering what it held) and ends itself ("orphaned"). A worker lives
//                  as long as its session: it watches the actor that opened it (down: the
//                  session ended or the connection broke), and the parent sends it an empty
//                  update every OpenRequest::keepalive_ms; silent for
//                  NodeSettings::keepalive_misses periods, it ends. A node refuses malformed
//                  opens and opens beyond NodeSettings::max_workers (check_open, checks.h).
//     links -> [ChildLink]   the children this node is connected to now (its workers use it to
//                  notice children that came back)
#include <vector>

#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>

#include "actors/messages.h"
#include "actors/subtree_protocol.h"

namespace tessera {

using node_actor = caf::typed_actor<caf::replies_to<open_atom, OpenRequest>::with<OpenReply>,
                                    caf::replies_to<links_atom>::with<std::vector<ChildLink>>,
                                    caf::reacts_to<tick_atom>>;

}  // namespace tessera
