#pragma once
// The state of a subtree actor (subtree_protocol.h) and the functions that work on it, shared
// by subtree.cpp (its behaviour, scene and own renderer), subtree_fanout.cpp (updates down in
// windows, batches out and tiles in) and subtree_members.cpp (children that join, fail and are
// committed). Private to those files: everything here runs on the subtree's own thread.
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <caf/all.hpp>

#include "actors/node.h"

namespace tessera {

// What waits to go to one child, in order: scene updates, sent in chunks of at most
// kUpdateChunkBytes with at most kUpdateWindowBytes sent and not yet acknowledged, and the
// batches that must reach the child after them. A small update (a frame's camera) goes as one
// plain message while less than a chunk is unacknowledged; the next acknowledged chunk
// covers it, because a worker takes its messages in order. Without the window a burst of
// uploads went into the CAF connection's write buffers whole, and those buffers keep their
// largest size for as long as the connection lives (docs/results/soak.md).
struct Outbox {
  struct Item {
    std::shared_ptr<const std::vector<uint8_t>> update;  // null: a batch waiting behind updates
    size_t offset = 0;                                   // bytes of `update` already sent
    bool reset = false;
    uint64_t join = 0;                                   // the batch: its join and part
    size_t part = 0;
  };
  std::deque<Item> items;
  uint64_t sent = 0;   // update bytes sent to the child so far
  uint64_t acked = 0;  // of those, the bytes up to the last acknowledged chunk
  uint64_t in_flight() const { return sent - acked; }
};
constexpr size_t kUpdateChunkBytes = size_t(256) << 10;
constexpr size_t kUpdateWindowBytes = size_t(1) << 20;

struct SubtreeChild {
  std::string name;             // the child's cluster address as this node knows it
  subtree_actor actor;          // the worker opened on it
  std::vector<NodeInfo> nodes;  // its flattened list as of the last commit
  bool alive = true;
  bool routed = false;          // part of the committed list (batches are indexed by it)
  Outbox outbox;
  // Slow is not lost. A child whose part of a batch is past its deadline is late: that part is
  // rendered elsewhere, it gets no new tasks until it has answered every batch sent to it and
  // taken every update queued for it, and it is pinged; only a child that does not answer the
  // ping within the task timeout (or goes down) is lost, dropped and opened afresh, which
  // resends the whole scene. Dropping a merely slow child did exactly that on every frame of a
  // large scene on a loaded machine: each new worker was late again building the scene it was
  // sent, so no frame was ever composed by the cluster.
  uint32_t outstanding = 0;     // batches sent and not yet answered
  bool late = false;
  bool probing = false;         // a ping is in flight
};

// One batch in flight: the reply assembled part by part (this node's own task, one part per
// routed child), delivered through the promise when the last part is in.
struct Join {
  struct Part {
    caf::actor_addr child;  // null: this node's own task
    std::string name;
    size_t begin = 0, count = 0;
    bool done = false;
  };
  caf::typed_response_promise<BatchReply> promise;
  RenderBatch batch;  // this node's part of the frame (its tasks: indexed by the node list)
  BatchReply reply;
  std::vector<Part> parts;
  size_t left = 0;
};

struct subtree_state {
  std::shared_ptr<const NodeSettings> settings;
  node_actor node;              // this process's node actor: where the children are found
  OpenRequest req;              // session, master, packet layout, the parent's timeout and keep-alive
  caf::actor_addr parent;
  Json::Members scope;          // who this subtree is in its events
  // --- The scene this node renders ---
  scene_source_actor source;    // a root: the session owns the scene (scene_atom); else none
  std::shared_ptr<Scene> own;   // a worker: built from its parent's updates
  std::shared_ptr<const Scene> scene;  // what the own task renders
  std::vector<std::pair<std::vector<uint8_t>, bool>> cached;  // updates that arrived while rendering
  std::vector<uint8_t> partial; // the chunks of an update received so far
  bool partial_reset = false;
  bool partial_dropped = false; // the update being received went over settings->max_update_bytes
  bool rendering = false;       // the own task is being rendered: updates wait
  std::string broken;           // an update this node could not apply: its tiles would be wrong
  renderer_actor renderer;
  std::shared_ptr<CancelMark> cancel;  // the frames `renderer` abandons (cancel)
  std::optional<NodeInfo> self_node;  // set when this node renders
  // --- Liveness of a worker (tick) ---
  bool adopted = false;         // the parent's adoption notice (an empty update) arrived
  caf::actor_clock::time_point opened_at, last_heard;
  // --- Children ---
  std::vector<SubtreeChild> children;
  bool changed = false;         // membership changed since the last commit
  bool committed = false;       // the first list was committed
  bool committing = false;
  size_t opening = 0;           // link and open requests in flight
  std::set<std::string> joining;
  std::vector<std::pair<caf::typed_response_promise<std::vector<NodeInfo>>, bool>> waiting;  // commits
  std::map<uint64_t, Join> joins;  // batches in flight, by id
  uint64_t next_join = 1;
  static inline const char* name = "tessera.subtree";
};
using subtree_ptr = subtree_actor::stateful_pointer<subtree_state>;

void subtree_log(subtree_ptr self, Event e);

// --- subtree.cpp ---
// The own task of batch `join` (part `part`) on this node's renderer.
void render_own(subtree_ptr self, uint64_t join, size_t part, const RenderTask& task);
// The whole scene for a child that joins, as updates (`done` gets them; a root asks its source).
void scene_snapshot(subtree_ptr self, std::function<void(std::vector<std::pair<std::vector<uint8_t>, bool>>)> done);

// --- subtree_fanout.cpp ---
// The live child whose worker is `who` (nullptr: none).
SubtreeChild* find_child(subtree_state& st, const caf::actor_addr& who);
// The tiles of part `p` failed with `code` (those that have not failed already).
void fail_part(Join& j, const Join::Part& p, protocol::ErrorCode code, const std::string& why);
// An update for one child, sent as its window allows.
void enqueue_update(subtree_ptr self, SubtreeChild& c, std::shared_ptr<const std::vector<uint8_t>> data, bool reset);
// The committed flattened list: this node first (if it renders), then each routed child's.
std::vector<NodeInfo> node_list(const subtree_state& st);
// Sends encoded scene records to every live child (routed or joining), behind what waits for it.
void forward(subtree_ptr self, std::vector<uint8_t> records, bool reset);
// An empty update to every live child: its parent is alive.
void keepalive(subtree_ptr self);
// Splits a batch indexed by node_list() between the own renderer and the children; the reply
// goes to `promise` when every part is in.
void dispatch(subtree_ptr self, RenderBatch batch, caf::typed_response_promise<BatchReply> promise);
// Part `part` of batch `join` is in (its tiles are in the reply).
void finish_part(subtree_ptr self, uint64_t join, size_t part);
// Part `part` of batch `join` reached its deadline: if it is not in, its tiles fail as late and
// its child is late (SubtreeChild::late).
void part_deadline(subtree_ptr self, uint64_t join, size_t part);
// Each late child that has no ping in flight is pinged again (the subtree's tick).
void probe_late(subtree_ptr self);
// --- subtree_members.cpp ---
// Commits membership and delivers the new list; waits behind a commit in flight and, with
// wait_joins, behind the opens in flight (the first list of a subtree should have its children).
void commit(subtree_ptr self, caf::typed_response_promise<std::vector<NodeInfo>> promise, bool wait_joins);
// Opens workers on the children this node is connected to and the subtree does not have yet.
void join_children(subtree_ptr self);
// A child is down or failed a request: its outstanding tasks fail now, it leaves at the next commit.
void child_failed(subtree_ptr self, const caf::actor_addr& who, protocol::ErrorCode code, const std::string& why);

}  // namespace tessera
