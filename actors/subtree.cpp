// The subtree actor (subtree_protocol.h): its behaviour, the scene its own renderer renders,
// and the liveness of a worker. Its children are in subtree_fanout.cpp.
#include <chrono>
#include <limits>
#include <utility>

#include "actors/checks.h"
#include "actors/errors.h"
#include "actors/subtree_state.h"

namespace tessera {

using protocol::ErrorCode;

void subtree_log(subtree_ptr self, Event e) {
  e.scope = self->state.scope;
  node_log(*self->state.settings, std::move(e));
}

namespace {

bool is_root(const subtree_state& st) { return bool(st.source); }

// A message from this subtree's parent (or from anyone, for one without a parent): it is alive.
void heard(subtree_ptr self) {
  auto& st = self->state;
  const auto& sender = self->current_sender();
  if (!st.parent || (sender && sender->address() == st.parent)) st.last_heard = self->clock().now();
}

void apply_update(subtree_ptr self, const std::vector<uint8_t>& bytes, bool reset) {
  auto& st = self->state;
  if (reset) {
    st.own = std::make_shared<Scene>();
    st.scene = st.own;
    st.broken.clear();
  }
  std::string err = apply_records(*st.own, bytes, st.settings->limits);
  if (!err.empty() && st.broken.empty()) {
    st.broken = err;
    subtree_log(self, Event(Ev::update_failed, err));
  }
}

void apply_cached(subtree_ptr self) {
  auto cached = std::move(self->state.cached);
  self->state.cached.clear();
  for (auto& [bytes, reset] : cached) apply_update(self, bytes, reset);
}

// A whole update from the parent: down to the children, and for a worker applied to its own
// scene now or after the render in flight (a root's scene is the session's).
void on_update(subtree_ptr self, std::vector<uint8_t> bytes, bool reset) {
  auto& st = self->state;
  if (is_root(st)) return forward(self, std::move(bytes), reset);
  forward(self, bytes, reset);
  if (st.rendering) st.cached.emplace_back(std::move(bytes), reset);
  else apply_update(self, bytes, reset);
}

// The periodic work: a worker that was never adopted, or whose parent fell silent, ends.
void on_tick(subtree_ptr self) {
  auto& st = self->state;
  const auto now = self->clock().now();
  // An orphan: the open request reached this node after its parent had given up on it (a link
  // that was cut and came back delivers the requests it held), so the reply was dropped and
  // nobody will ever use this worker. The parent's timeout has passed since it was opened; one
  // more is allowed for its adoption notice (an empty update, sent before the scene).
  if (!st.adopted && st.req.timeout_ms > 0 && now - st.opened_at > std::chrono::milliseconds(2 * uint64_t(st.req.timeout_ms))) {
    subtree_log(self, Event(Ev::orphaned, true));
    self->quit(caf::exit_reason::user_shutdown);
    return;
  }
  // A parent that stopped answering (hung, or cut off without the connection noticing) sends
  // no keep-alives: after keepalive_misses of its periods this worker ends.
  const auto silent = now - st.last_heard;
  if (st.req.keepalive_ms > 0 && silent > std::chrono::milliseconds(uint64_t(st.req.keepalive_ms) * st.settings->keepalive_misses)) {
    subtree_log(self, Event(Ev::ended, "parent silent")
                          .with("silent_ms", std::chrono::duration_cast<std::chrono::milliseconds>(silent).count()));
    self->quit(caf::exit_reason::user_shutdown);
    return;
  }
  // Anyone holding this subtree's handle can send it a tick: only its own (delayed_send to
  // itself) keeps the loop going, and only its parent may ask for a round now.
  const bool own = self->current_sender() == self->ctrl();
  const bool from_parent = self->current_sender() && self->current_sender()->address() == st.parent;
  if (!own && !from_parent) return;
  keepalive(self);
  probe_late(self);
  join_children(self);
  if (own) self->delayed_send(self, std::chrono::milliseconds(st.settings->reconnect_ms), tick_atom::value);
}

}  // namespace

void render_own(subtree_ptr self, uint64_t join, size_t part, const RenderTask& t) {
  auto& st = self->state;
  auto deliver = [self, join, part](TileResult&& r) {
    auto& st = self->state;
    auto it = st.joins.find(join);
    if (it == st.joins.end() || it->second.parts[part].done) return;
    TileResult& slot = it->second.reply.tiles[it->second.parts[part].begin];
    if (r.pixels.empty() && !r.failed()) r.pixels = slot.pixels;
    slot = std::move(r);
    finish_part(self, join, part);
  };
  if (!st.broken.empty() || !st.scene)
    return deliver(failed_tile(t, ErrorCode::no_scene, "node " + st.settings->name + " has no valid scene: " +
                                                           (st.broken.empty() ? "none received" : st.broken)));
  if (st.own && (st.own->width() != t.width || st.own->height() != t.height)) st.own->set_resolution(t.width, t.height);
  st.rendering = true;
  self->request(st.renderer, caf::infinite, render_atom::value, SceneSnapshot{st.scene}, t)
      .then(
          [=](TileResult& r) {
            self->state.rendering = false;
            apply_cached(self);
            deliver(std::move(r));
          },
          [=](caf::error& e) {
            self->state.rendering = false;
            apply_cached(self);
            deliver(failed_tile(t, e, ErrorCode::render_failed));
          });
}

void scene_snapshot(subtree_ptr self, std::function<void(std::vector<std::pair<std::vector<uint8_t>, bool>>)> done) {
  auto& st = self->state;
  if (!is_root(st)) {
    std::vector<std::pair<std::vector<uint8_t>, bool>> out;
    out.emplace_back(scene_snapshot_bytes(SceneSnapshot{st.scene}), true);
    for (auto& c : st.cached) out.push_back(c);  // not applied here yet, but already forwarded
    return done(std::move(out));
  }
  // The session's scene: its sync actor makes the snapshot. Records it forwards after
  // answering arrive after the answer, so the child gets each exactly once.
  self->request(st.source, caf::infinite, snapshot_atom::value)
      .then(
          [=](Payload& p) {
            std::vector<std::pair<std::vector<uint8_t>, bool>> out;
            out.emplace_back(std::move(p.bytes), true);
            done(std::move(out));
          },
          [=](caf::error&) { self->quit(caf::exit_reason::user_shutdown); });  // the session is gone
}

namespace {

subtree_actor::behavior_type subtree_impl(subtree_ptr self, std::shared_ptr<const NodeSettings> settings,
                                          node_actor node, SubtreeSpec spec) {
  auto& st = self->state;
  st.settings = std::move(settings);
  st.node = std::move(node);
  st.req = spec.req;
  st.source = spec.source;
  st.renderer = spec.renderer;
  st.cancel = spec.cancel;
  if (is_root(st)) {
    st.scope = {{"session", st.req.session}};
  } else {
    st.scope = {{"node", st.settings->name}, {"session", st.req.session}};
    st.own = std::make_shared<Scene>();
    st.scene = st.own;
  }
  if (st.settings->render) {
    st.self_node = st.settings->info();
    if (!st.renderer) {
      st.cancel = std::make_shared<CancelMark>();
      st.renderer = spawn_renderer(self->system(), {st.req.packet_w, st.req.packet_h}, st.settings->detached, st.cancel);
      self->link_to(st.renderer);
    }
  }
  // Whatever ends this subtree (the session closed, its client left, the parent or the node
  // went down), the render in flight for it stops at its next packet instead of running on
  // for nobody: a maximal frame asked for by a client that then left took the thread for
  // minutes, and held a shutting-down node until it ended.
  self->attach_functor([cancel = st.cancel](const caf::error&) {
    if (cancel) cancel->raise(std::numeric_limits<uint32_t>::max());
  });
  if (spec.parent) {
    st.parent = caf::actor_cast<caf::actor_addr>(spec.parent);
    self->monitor(spec.parent);
  }
  if (st.node) self->monitor(st.node);  // the node shuts down: its workers go with it
  st.opened_at = st.last_heard = self->clock().now();
  self->set_down_handler([=](caf::down_msg& m) {
    auto& st = self->state;
    const bool from_parent = m.source == st.parent;
    if (from_parent || (st.node && m.source == st.node.address())) {
      // The session ended (or the parent worker did), its connection to this node broke, or
      // this node is shutting down.
      subtree_log(self, Event(Ev::ended, from_parent ? "parent down" : "node down").with("reason", to_string(m.reason)));
      self->quit(caf::exit_reason::user_shutdown);
      return;
    }
    child_failed(self, m.source, ErrorCode::node_lost, to_string(m.reason));
  });
  join_children(self);
  // A root without a node has no children to look after; a worker checks its parent.
  if (st.node || !is_root(st)) self->delayed_send(self, std::chrono::milliseconds(st.settings->reconnect_ms), tick_atom::value);
  return {
      [=](update_atom, Payload& payload, bool reset) {
        heard(self);
        self->state.adopted = true;
        if (payload.bytes.empty() && !reset) return;  // the parent's adoption notice or keep-alive
        on_update(self, std::move(payload.bytes), reset);
      },
      [=](update_atom, Payload& chunk, bool reset, bool last) -> uint64_t {
        auto& st = self->state;
        heard(self);
        st.adopted = true;
        const uint64_t n = chunk.bytes.size();
        if (st.partial.empty() && !st.partial_dropped) st.partial_reset = reset;
        if (st.partial_dropped || st.partial.size() + n > st.settings->max_update_bytes) {
          if (!st.partial_dropped) {
            st.broken = "a scene update over " + std::to_string(st.settings->max_update_bytes) + " bytes";
            subtree_log(self, Event(Ev::update_failed, st.broken));
          }
          st.partial_dropped = true;
          st.partial = {};
        } else {
          st.partial.insert(st.partial.end(), chunk.bytes.begin(), chunk.bytes.end());
        }
        if (last) {
          if (!st.partial_dropped) on_update(self, std::exchange(st.partial, {}), st.partial_reset);
          st.partial_dropped = false;
        }
        return n;
      },
      [=](render_atom, RenderBatch& batch) -> caf::result<BatchReply> {
        heard(self);
        // Checked like a client's requests on this node: a bad batch fails every tile and the
        // subtree serves on.
        if (std::string bad = check_batch(batch, self->state.settings->limits); !bad.empty()) {
          subtree_log(self, Event(Ev::bad_batch, bad));
          return failed_batch(batch, ErrorCode::bad_batch, "node " + self->state.settings->name + " refused the batch: " + bad);
        }
        auto rp = self->make_response_promise<BatchReply>();
        dispatch(self, std::move(batch), rp);
        return rp;
      },
      [=](nodes_atom) -> caf::result<std::vector<NodeInfo>> {
        heard(self);
        auto& st = self->state;
        // Nothing changed since the last commit: the same list, at once.
        if (st.committed && !st.changed && !st.committing) return node_list(st);
        auto rp = self->make_response_promise<std::vector<NodeInfo>>();
        // The first list (the open reply, the session's handshake) waits for the children
        // being opened; later commits do not (subtree_fanout.cpp, commit).
        commit(self, rp, /*wait_joins=*/!st.committed);
        return rp;
      },
      [=](scene_atom, SceneSnapshot& snap) {
        auto& st = self->state;
        if (is_root(st) && self->current_sender() && self->current_sender()->node() == self->node()) {
          st.scene = std::move(snap.scene);
          return;
        }
        subtree_log(self, Event(Ev::update_failed, "a scene message from a peer (a worker's scene comes from its parent's updates)"));
      },
      // The session abandons frame `frame` (a still's sample its client no longer wants): the
      // own renderer stops its task early and the children are told. From the parent only (a
      // worker), or from this node (a root: the session's frame actor); older frames stay
      // abandoned, so a late or repeated notice changes nothing.
      [=](cancel_atom, uint32_t frame) {
        auto& st = self->state;
        const caf::strong_actor_ptr& from = self->current_sender();
        if (!from || (is_root(st) ? from->node() != self->node() : from->address() != st.parent)) return;
        if (!is_root(st)) heard(self);
        if (st.cancel) st.cancel->raise(frame);
        for (auto& c : st.children)
          if (c.alive) self->send(c.actor, cancel_atom::value, frame);
      },
      [=](tick_atom) { on_tick(self); },
      // A parent asks whether this subtree, late with a batch, is still there: the batches in
      // flight here.
      [=](ping_atom) -> uint64_t {
        heard(self);
        return uint64_t(self->state.joins.size());
      },
      [=](deadline_atom, uint64_t join, uint64_t part) {
        if (self->current_sender() != self->ctrl()) return;  // only its own timers
        part_deadline(self, join, size_t(part));
      },
  };
}

}  // namespace

subtree_actor spawn_subtree(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings, node_actor node,
                            SubtreeSpec spec) {
  return sys.spawn(subtree_impl, std::move(settings), std::move(node), std::move(spec));
}

subtree_actor spawn_worker(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings, node_actor node,
                           OpenRequest request, caf::strong_actor_ptr parent) {
  SubtreeSpec spec;
  spec.req = std::move(request);
  spec.parent = std::move(parent);
  return spawn_subtree(sys, std::move(settings), std::move(node), std::move(spec));
}

}  // namespace tessera
