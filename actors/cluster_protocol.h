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

// The application identifier of CAF's BASP handshake (the setting middleman.app-identifiers):
// CAF refuses a peer that names another. CAF's default, "generic-caf-app", would tell whoever
// connects which framework this is; this names the program and nothing else. (Over mutual TLS
// no part of the handshake reaches a peer without a certificate of the cluster CA.)
inline constexpr const char* kCafAppIdentifier = "tessera";

// Parent -> node: open a worker for one session on this node's sub-tree.
struct OpenRequest {
  uint64_t session = 0;
  std::string master;        // for log lines
  int32_t packet_w = 4, packet_h = 4;  // the master's packet layout (one packet space per cluster)
  uint32_t timeout_ms = 0;   // how long the parent waits for the reply (0: not said)
  uint32_t keepalive_ms = 0; // the parent sends the worker something (at least an empty update)
                             // this often; a worker that hears nothing for a multiple of it ends
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, OpenRequest& x) {
  return f(caf::meta::type_name("tessera::open_request"), x.session, x.master, x.packet_w, x.packet_h, x.timeout_ms,
           x.keepalive_ms);
}

struct OpenReply {
  caf::actor worker;            // a worker_actor
  std::vector<NodeInfo> nodes;  // its flattened list
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, OpenReply& x) {
  return f(caf::meta::type_name("tessera::open_reply"), x.worker, x.nodes);
}

// A node's live children, for its own workers.
struct ChildLink {
  std::string name;
  caf::actor node;  // a node_actor
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, ChildLink& x) {
  return f(caf::meta::type_name("tessera::child_link"), x.name, x.node);
}

using node_actor = caf::typed_actor<caf::replies_to<open_atom, OpenRequest>::with<OpenReply>,
                                    caf::replies_to<links_atom>::with<std::vector<ChildLink>>,
                                    caf::reacts_to<tick_atom>>;

}  // namespace tessera
