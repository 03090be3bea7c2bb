// Session actor (sync channel): one per client. See session_protocol.h.
#include <chrono>
#include <optional>

#include <caf/all.hpp>

#include "actors/node.h"
#include "actors/router.h"
#include "protocol/scene_records.h"
#include "renderer/raytracer.h"
#include "update/scene_update.h"

namespace tessera {
namespace {

using namespace protocol;

struct session_state {
  std::shared_ptr<ClientSink> sink;
  std::shared_ptr<const NodeSettings> settings;
  uint64_t id = 0;
  std::shared_ptr<Scene> scene = std::make_shared<Scene>();
  bool handshake_done = false;
  bool closed = false;
  bool preloaded = false;
  Handshake hs;
  protocol::Settings render;
  PacketLayout layout;
  renderer_actor renderer;
  tiler_actor tiler;
  encoder_actor encoder;
  display_actor display;
  // Frame pipeline.
  std::vector<ClientRecord> cached;  // scene updates that arrived while a frame was rendering
  PendingBytes cached_bytes;         // their buffers and textures count against max_client_bytes
  // This session's part of the node-wide budget (NodeSettings::budget): its scene's buffers
  // and textures plus what the cached updates hold, and, while a message is decoded, what it
  // declares.
  BudgetShare share;
  bool in_flight = false;
  std::optional<uint32_t> pending;   // the latest render request that arrived while rendering
  uint32_t seq = 0, dropped = 0, errors = 0;
  FrameMeta meta;
  // The client's tree (actors/router.h): this node's renderer and its children's workers.
  node_actor node;
  Router router;
  std::vector<NodeInfo> nodes;  // committed flattened list
  RenderBatch batch;            // the frame in flight: its settings and one task per node
  std::vector<size_t> used;     // the entries of `nodes` this client renders on
  bool committed = false;
  double last_rendering_ms = 0;
  uint32_t recovered = 0;       // tasks of lost nodes rendered here in this frame
  std::vector<uint8_t> forward; // accepted scene records not yet sent down the tree
  static inline const char* name = "tessera.session";
};

using self_ptr = session_actor::stateful_pointer<session_state>;

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

void log(self_ptr self, Event e) {
  e.scope = {{"session", self->state.id}};
  node_log(*self->state.settings, std::move(e));
}

// Sends an error record; a fatal one ends the session (and closes the connection).
void fail(self_ptr self, const Error& e) {
  auto& st = self->state;
  if (st.closed) return;
  ErrorReply r = to_reply(e);
  st.errors++;
  st.sink->send(encode(ServerRecord{r}));
  log(self, Event(Ev::error, to_string(e.code))
                .with("fatal", r.fatal)
                .with("record", e.record == kNoRecord ? -1 : int64_t(e.record))
                .with("message", e.message));
  if (r.fatal) {
    st.closed = true;
    st.sink->close(e.message);
    self->quit(caf::exit_reason::user_shutdown);
  }
}

// The session's share of the node budget becomes what it holds now. Never more than it had
// reserved: every update grows the scene by at most the size its message declared.
void settle_budget(self_ptr self) {
  auto& st = self->state;
  st.share.set(scene_bytes(*st.scene) + st.cached_bytes.waiting_bytes());
}

void apply_update(self_ptr self, ClientRecord&& rec, uint32_t index) {
  auto& st = self->state;
  // Children get exactly the records this node accepted (encoded before apply moves them).
  std::vector<uint8_t> one;
  const bool down = st.router.alive_children() > 0;
  if (down) one = encode(rec);
  Status s = apply(*st.scene, std::move(rec), st.settings->limits);
  if (s && down) append_message(st.forward, std::move(one));
  if (!s) {
    Error e = s.error();
    e.record = index;
    fail(self, e);
  }
}

void flush_forward(self_ptr self) {
  auto& st = self->state;
  if (st.forward.empty()) return;
  st.router.forward(self, st.forward, false);
  st.forward.clear();
}

void apply_cached(self_ptr self) {
  auto& st = self->state;
  auto cached = std::move(st.cached);
  st.cached.clear();
  st.cached_bytes.clear();
  for (auto& r : cached) {
    if (st.closed) return;
    apply_update(self, std::move(r), kNoRecord);  // deferred: the record index is no longer meaningful
  }
  flush_forward(self);
  settle_budget(self);
}

void maybe_preload(self_ptr self) {
  auto& st = self->state;
  if (st.preloaded || !st.settings->preload || !st.scene->meshes().empty()) return;
  st.preloaded = true;
  const Scene& pre = *st.settings->preload;
  const int32_t w = st.scene->width(), h = st.scene->height();
  const bool own_camera = st.scene->camera_version() != 0;
  const Camera cam = st.scene->camera();
  *st.scene = pre;
  st.scene->set_resolution(w, h);
  if (own_camera) st.scene->set_camera(cam);
  if (st.router.alive_children() > 0) st.router.forward(self, scene_snapshot_bytes(SceneSnapshot{st.scene}), true);
  settle_budget(self);  // the preloaded scene is the node's own: counted, never refused
  log(self, Event(Ev::preloaded_scene, true).with("triangles", st.scene->triangle_count()));
}

void render_batch(self_ptr self);
void recover(self_ptr self, BatchReply&& r);
void finish_frame(self_ptr self, std::vector<TileResult>&& tiles, std::vector<double>&& perf);

// The committed node list changed: pick the nodes this client may use (the strongest first,
// at most the handshake's max_nodes) and give their coefficients to the tiler.
void on_nodes(self_ptr self, std::vector<NodeInfo> nodes) {
  auto& st = self->state;
  std::vector<size_t> order(nodes.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  auto coef = [&](size_t i) { return double(nodes[i].logical_cores) * nodes[i].single_core_perf; };
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return coef(a) > coef(b); });
  if (st.hs.max_nodes > 0 && order.size() > st.hs.max_nodes) order.resize(st.hs.max_nodes);
  std::sort(order.begin(), order.end());  // keep list order (depth first) for the tiling
  std::vector<double> coefficients;
  for (size_t i : order) coefficients.push_back(std::max(1e-6, coef(i)));
  const bool same = nodes.size() == st.nodes.size() && order == st.used;
  st.nodes = std::move(nodes);
  st.used = std::move(order);
  st.committed = true;
  if (!coefficients.empty()) self->send(st.tiler, nodes_atom::value, std::move(coefficients));
  if (!same || st.seq <= 1)
    log(self, Event(Ev::nodes, nodes_value(st.nodes)).with("used", st.used.size()));
}

void start_frame(self_ptr self, uint32_t client_frame) {
  auto& st = self->state;
  apply_cached(self);
  if (st.closed) return;
  maybe_preload(self);
  st.in_flight = true;
  st.seq++;
  st.meta = FrameMeta{};
  st.meta.seq = st.seq;
  st.meta.client_frame = client_frame;
  st.meta.width = st.scene->width();
  st.meta.height = st.scene->height();
  st.meta.display = uint8_t(st.hs.display);
  st.meta.quality = st.hs.jpeg_quality;
  st.meta.render_start_ns = now_ns();
  st.recovered = 0;
  st.meta.dropped = st.dropped;  // for the display channel's Stats record
  st.meta.scene_bytes = scene_bytes(*st.scene);
  st.meta.triangles = st.scene->triangle_count();
  // Membership changes (lost nodes, nodes that joined) are committed between frames only,
  // without waiting for joins in flight (router.h, commit) once the session has its first
  // list: before that (a render request in the handshake's message), the frame waits, after
  // the handshake's commit, so that the reply still comes first.
  if (!st.committed || st.router.changed || st.router.committing()) {
    const bool first = !st.committed;
    st.router.commit(
        self, st.settings->task_timeout_ms,
        [self](std::vector<NodeInfo> nodes) {
          on_nodes(self, std::move(nodes));
          render_batch(self);
        },
        /*wait_joins=*/first);
    return;
  }
  render_batch(self);
}

// Renders a task on this node's own renderer (also the fallback for tasks of lost nodes).
void render_local(self_ptr self, const RenderTask& t, std::function<void(TileResult&&)> cb) {
  auto& st = self->state;
  if (!st.renderer) {
    st.renderer = spawn_renderer(self->system(), st.layout, st.settings->detached);
    self->link_to(st.renderer);
  }
  SceneSnapshot snap{st.scene};  // read-only until the frame is rendered: updates are cached meanwhile
  self->request(st.renderer, caf::infinite, render_atom::value, snap, t)
      .then([cb](TileResult& r) { cb(std::move(r)); },
            [cb, t](caf::error& e) {
              TileResult r;
              r.frame = t.frame;
              r.pixels = t.pixels;
              r.error = "renderer: " + to_string(e);
              cb(std::move(r));
            });
}

void render_batch(self_ptr self) {
  auto& st = self->state;
  RenderBatch& batch = st.batch;  // this frame's tasks, one per node of st.nodes
  batch = RenderBatch{};
  batch.frame = st.seq;
  batch.width = st.meta.width;
  batch.height = st.meta.height;
  batch.ao_samples = int32_t(st.render.ao_samples);
  batch.max_depth = int32_t(st.render.max_depth);
  batch.renderer = uint8_t(st.hs.renderer);
  // Bounded delay for lost nodes: the configured timeout, or 3x the last frame if longer.
  batch.timeout_ms = std::max<uint32_t>(st.settings->task_timeout_ms, uint32_t(3 * st.last_rendering_ms + 200));
  batch.tasks.assign(st.nodes.size(), Rect{});
  const uint32_t seq = st.seq;
  if (st.used.empty()) {
    // No rendering node at all (a dedicated master whose children are all gone): render the
    // whole frame here rather than show nothing.
    batch.tasks = {Rect{0, 0, st.meta.width, st.meta.height}};
    BatchReply r;
    r.tiles.resize(1);
    r.tiles[0].error = "no rendering node";
    recover(self, std::move(r));
    return;
  }
  TaskRequest req{st.seq, st.meta.width, st.meta.height, st.layout.w, st.layout.h};
  self->request(st.tiler, caf::infinite, tasks_atom::value, req).then([=](TaskList& tl) {
    auto& st = self->state;
    if (!st.in_flight || st.seq != seq) return;
    st.meta.tiling_ms = tl.tiling_ms;
    for (size_t k = 0; k < tl.tasks.size() && k < st.used.size(); ++k) st.batch.tasks[st.used[k]] = tl.tasks[k];
    st.meta.nodes = uint32_t(st.used.size());
    auto local = [self](const RenderTask& t, std::function<void(TileResult&&)> cb) { render_local(self, t, cb); };
    st.router.dispatch(self, st.batch, local, [self, seq](BatchReply&& r) {
      auto& st = self->state;
      if (!st.in_flight || st.seq != seq) return;
      recover(self, std::move(r));
    });
  });
}

// Tasks whose node failed (down, too late, impossible tiles) are rendered here, so the frame
// still completes; the node list is committed again before the next frame.
void recover(self_ptr self, BatchReply&& r) {
  auto& st = self->state;
  const std::vector<Rect>& tasks = st.batch.tasks;
  if (r.changed) st.router.changed = true;
  std::vector<size_t> lost;
  for (size_t i = 0; i < r.tiles.size(); ++i)
    if (!r.tiles[i].error.empty() && !tasks[i].empty()) lost.push_back(i);
  std::vector<double> perf(r.tiles.size(), 1.0);
  for (size_t i = 0; i < r.tiles.size() && i < st.nodes.size(); ++i) perf[i] = st.nodes[i].single_core_perf;
  if (lost.empty()) {
    finish_frame(self, std::move(r.tiles), std::move(perf));
    return;
  }
  std::vector<Json> errors;
  for (size_t i : lost) errors.emplace_back(r.tiles[i].error);
  log(self, Event(Ev::recovering, lost.size())
                .with("frame", st.meta.client_frame)
                .with("errors", Json::array(std::move(errors))));
  st.recovered = uint32_t(lost.size());
  auto tiles = std::make_shared<std::vector<TileResult>>(std::move(r.tiles));
  auto perfs = std::make_shared<std::vector<double>>(std::move(perf));
  auto left = std::make_shared<size_t>(lost.size());
  const uint32_t seq = st.seq;
  for (size_t i : lost) {
    (*perfs)[i] = st.settings->coefficient.single_core_perf;
    render_local(self, task_of(st.batch, tasks[i]), [self, seq, i, tiles, perfs, left](TileResult&& res) {
      (*tiles)[i] = std::move(res);
      if (--*left > 0) return;
      auto& st = self->state;
      if (!st.in_flight || st.seq != seq) return;
      finish_frame(self, std::move(*tiles), std::move(*perfs));
    });
  }
}

void finish_frame(self_ptr self, std::vector<TileResult>&& tiles, std::vector<double>&& perf) {
  auto& st = self->state;
  // The frame is rendered: measurements, SATs to the tiler, pixels to the display channel.
  st.meta.render_end_ns = now_ns();
  std::string error;
  SatReport rep{st.seq, st.meta.width, st.meta.height, st.layout.w, st.layout.h, {}, {}};
  std::vector<TileResult> shown;
  std::vector<Json> per_node;
  double max_norm = 0, sum_norm = 0;
  size_t rendered = 0;
  for (size_t i = 0; i < tiles.size(); ++i) {
    auto& tile = tiles[i];
    if (tile.pixels.empty() && tile.error.empty()) continue;  // a node without a task this frame
    st.meta.kernel_ms += tile.kernel_ms;
    st.meta.rendering_ms = std::max(st.meta.rendering_ms, tile.rendering_ms);
    st.meta.sat_ms = std::max(st.meta.sat_ms, tile.sat_ms);
    if (!tile.error.empty()) error = tile.error;
    if (i < st.nodes.size() && st.node) {  // a cluster node: per-node figures
      const NodeInfo& n = st.nodes[i];
      const double norm = tile.kernel_ms * n.single_core_perf / std::max(1e-9, double(n.logical_cores) * n.single_core_perf);
      max_norm = std::max(max_norm, norm);
      sum_norm += norm;
      ++rendered;
      per_node.push_back(Json::object({{"node", i},
                                       {"kernel_ms", Json::number(tile.kernel_ms)},
                                       {"rendering_ms", Json::number(tile.rendering_ms)},
                                       {"pixels", static_cast<long long>(tile.pixels.area())}}));
    }
    rep.sats.push_back(std::move(tile.sat));
    rep.perf.push_back(i < perf.size() ? perf[i] : 1.0);
    shown.push_back(std::move(tile));
  }
  self->send(st.tiler, sats_atom::value, std::move(rep));
  st.in_flight = false;
  st.last_rendering_ms = st.meta.rendering_ms;
  if (!per_node.empty()) {
    const double balance = rendered && sum_norm > 0 ? max_norm / (sum_norm / double(rendered)) : 1.0;
    log(self, Event(Ev::cluster_frame, st.meta.client_frame)
                  .with("balance", Json::number(balance, 4))
                  .with("recovered", st.recovered)
                  .with("per_node", Json::array(std::move(per_node))));
  }
  if (error.empty()) {
    self->send(st.display, display_atom::value, FrameTiles{st.meta, std::move(shown)});
  } else {
    fail(self, Error{ErrorCode::internal, "frame " + std::to_string(st.meta.client_frame) + ": " + error, kNoRecord});
  }
  if (st.closed) return;
  // Between frames: apply what was cached, then start the remembered render request (the
  // encoder meanwhile encodes the frame just rendered).
  apply_cached(self);
  if (st.pending && !st.closed) {
    uint32_t f = *st.pending;
    st.pending.reset();
    start_frame(self, f);
  }
}

void on_handshake(self_ptr self, const Handshake& h) {
  auto& st = self->state;
  if (h.display == DisplayKind::mjpeg && st.sink->token().empty()) {
    fail(self, Error{ErrorCode::bad_handshake,
                     "display 'mjpeg' needs a session token: connect the WebSocket to /ws?session=TOKEN and "
                     "open /mjpeg/TOKEN",
                     0});
    return;
  }
  st.hs = h;
  if (st.settings->renderer >= 0) st.hs.renderer = RendererKind(st.settings->renderer);  // tessera serve --renderer
  st.handshake_done = true;
  st.scene->set_resolution(h.width, h.height);
  // The reply names the nodes this client gets: commit the tree first (children that are
  // still being opened are waited for, within the task timeout).
  st.router.commit(self, st.settings->task_timeout_ms, [self, h](std::vector<NodeInfo> nodes) {
    on_nodes(self, std::move(nodes));
    auto& st = self->state;
    if (st.closed) return;
    HandshakeReply r;
    r.renderer = st.hs.renderer;
    r.display = h.display;
    r.jpeg_quality = h.jpeg_quality;
    r.nodes = uint32_t(std::max<size_t>(1, st.used.size()));  // with none, this node renders
    r.width = h.width;
    r.height = h.height;
    r.max_message_bytes = st.settings->limits.max_message_bytes;
    r.max_buffer_bytes = st.settings->limits.max_buffer_bytes;
    r.server_version = st.settings->server_version;
    st.sink->send(encode(ServerRecord{r}));
    static const char* displays[] = {"jpeg", "s3tc", "mjpeg"};
    log(self, Event(Ev::handshake, Json::object({{"display", displays[int(h.display)]},
                                                 {"quality", unsigned(h.jpeg_quality)},
                                                 {"width", h.width},
                                                 {"height", h.height},
                                                 {"nodes", r.nodes}})));
  });
}

// The node-wide budget, checked before anything is inflated or decoded: each buffer and
// texture the message declares is reserved from the budget; one that does not fit is
// refused (limit_exceeded, not fatal) and cut out of the message, the others go on. `kept`
// maps the indices of the message that remains to those of the client's. False: nothing is
// left to decode.
bool admit_payloads(self_ptr self, std::vector<uint8_t>& bytes, std::vector<uint32_t>& kept) {
  auto& st = self->state;
  if (!st.settings->budget) return true;
  auto declared = declared_payloads(bytes.data(), bytes.size(), st.settings->limits);
  if (!declared) return true;  // bad framing: the decoder says why
  std::vector<uint32_t> drop;
  for (const DeclaredRecord& d : *declared) {
    if (d.bytes == 0 || st.share.reserve(d.bytes)) continue;
    drop.push_back(d.index);
    const MemoryBudget& b = *st.settings->budget;
    fail(self, Error{ErrorCode::limit_exceeded,
                     "record " + std::to_string(d.index) + ": its " +
                         std::to_string(d.bytes) + " bytes would exceed the node's memory budget (" +
                         std::to_string(b.used()) + " of " + std::to_string(b.limit()) +
                         " bytes in use by all clients); the update is dropped",
                     d.index});
  }
  if (drop.empty()) return true;
  if (drop.size() == declared->size()) return false;
  bytes = without_records(bytes.data(), bytes.size(), *declared, drop);
  for (const DeclaredRecord& d : *declared)
    if (!std::binary_search(drop.begin(), drop.end(), d.index)) kept.push_back(d.index);
  return true;
}

void on_client_records(self_ptr self, std::vector<uint8_t>& bytes, const std::vector<uint32_t>& kept);

void on_client(self_ptr self, std::vector<uint8_t>& bytes) {
  auto& st = self->state;
  if (st.closed) return;
  std::vector<uint32_t> kept;  // empty: every record of the message
  if (admit_payloads(self, bytes, kept)) on_client_records(self, bytes, kept);
  bytes = {};
  if (!st.closed) settle_budget(self);  // gives back what was reserved and not kept
}

void on_client_records(self_ptr self, std::vector<uint8_t>& bytes, const std::vector<uint32_t>& kept) {
  auto& st = self->state;
  auto original = [&](uint32_t i) { return i < kept.size() ? kept[i] : i; };
  auto res = decode_client(bytes.data(), bytes.size(), st.settings->limits);
  bytes = {};  // the decoded records own their data now
  if (!res) {
    Error e = res.error();
    if (e.record != kNoRecord) e.record = original(e.record);
    // Before the handshake, a message that does not decode cannot be one: the session ends.
    if (!st.handshake_done && e.code != ErrorCode::bad_handshake) {
      e.message = "the first message must be a valid handshake: " + std::string(to_string(e.code)) + ": " + e.message;
      e.code = ErrorCode::bad_handshake;
    }
    return fail(self, e);
  }
  auto& recs = res.value();
  if (Status order = check_session_order(st.handshake_done, recs); !order) return fail(self, order.error());
  for (uint32_t i = 0; i < recs.size() && !st.closed; ++i) {
    ClientRecord& rec = recs[i];
    if (auto* h = std::get_if<Handshake>(&rec)) {
      on_handshake(self, *h);
    } else if (auto* s = std::get_if<protocol::Settings>(&rec)) {
      st.render = *s;  // read when the next frame starts
    } else if (auto* rr = std::get_if<RenderRequest>(&rec)) {
      if (!st.in_flight) {
        start_frame(self, rr->frame);
      } else {
        if (st.pending) st.dropped++;  // the older request is merged into this one
        st.pending = rr->frame;
      }
    } else if (st.in_flight) {
      // Waiting updates count against the client's byte limit now: one that would exceed it
      // is refused (as it would be when applied) instead of held until the frame ends.
      if (Status room = st.cached_bytes.admit(*st.scene, rec, st.settings->limits); !room) {
        Error e = room.error();
        e.record = original(i);
        fail(self, e);
        continue;
      }
      st.cached.push_back(std::move(rec));
    } else {
      apply_update(self, std::move(rec), original(i));
    }
  }
  flush_forward(self);
}

void join_children(self_ptr self) {
  auto& st = self->state;
  OpenRequest req{st.id, st.settings->name, st.layout.w, st.layout.h};
  st.router.join_children(self, st.node, req, st.settings->task_timeout_ms, [self] {
    std::vector<std::pair<std::vector<uint8_t>, bool>> out;
    out.emplace_back(scene_snapshot_bytes(SceneSnapshot{self->state.scene}), true);
    return out;
  });
}

session_actor::behavior_type session_impl(self_ptr self, std::shared_ptr<ClientSink> sink,
                                          std::shared_ptr<const NodeSettings> settings, uint64_t id) {
  auto& st = self->state;
  st.sink = std::move(sink);
  st.settings = std::move(settings);
  st.id = id;
  st.layout = st.settings->packet_layout.w > 0 ? st.settings->packet_layout : detect_packet_layout();
  auto& sys = self->system();
  if (st.settings->render) {
    st.renderer = spawn_renderer(sys, st.layout, st.settings->detached);
    self->link_to(st.renderer);
    st.router.self_node = st.settings->info();
  }
  st.tiler = spawn_tiler(sys, {st.settings->coefficient.renderer()});
  st.encoder = spawn_encoder(sys, st.settings->detached);
  st.display = spawn_display(sys, st.sink, st.encoder, st.settings, id);
  self->link_to(st.tiler);
  self->link_to(st.encoder);
  self->link_to(st.display);
  // Linked children end with the session (it always quits with a non-normal reason).
  self->attach_functor([settings = st.settings, id](const caf::error& reason) {
    Event closed(Ev::closed, true);
    closed.scope = {{"session", id}};
    node_log(*settings, std::move(closed));
    schedule_heap_trim();  // its scene, BVH and frames are freed as its linked actors end
  });
  log(self, Event(Ev::opened, true).with("token", st.sink->token()));
  // The client's tree: workers on the children this node is connected to (and, every
  // reconnect period, on children that came back).
  st.router.layout = st.layout;
  st.router.log = [self](Event e) { log(self, std::move(e)); };
  st.router.keepalive_ms = st.settings->reconnect_ms;  // the tick below sends the keep-alives
  st.node = caf::actor_cast<node_actor>(st.settings->node.lock());
  self->set_down_handler([=](caf::down_msg& m) { self->state.router.child_failed(m.source, to_string(m.reason)); });
  if (st.node) {
    join_children(self);
    self->delayed_send(self, std::chrono::milliseconds(st.settings->reconnect_ms), tick_atom::value);
  }
  st.share.attach(st.settings->budget);
  if (st.settings->handshake_timeout_ms > 0)
    self->delayed_send(self, std::chrono::milliseconds(st.settings->handshake_timeout_ms), hs_timeout_atom::value);
  return {
      [=](client_atom, std::vector<uint8_t>& bytes) { on_client(self, bytes); },
      [=](status_atom) -> SessionStatus {
        auto& st = self->state;
        SessionStatus s;
        s.handshake_done = st.handshake_done;
        s.in_flight = st.in_flight;
        s.render_pending = st.pending.has_value();
        s.pending_frame = st.pending.value_or(0);
        s.cached_updates = uint32_t(st.cached.size());
        s.frames_started = st.seq;
        s.dropped = st.dropped;
        s.errors_sent = st.errors;
        s.scene_version = st.scene->version();
        s.triangles = st.scene->triangle_count();
        return s;
      },
      [=](children_atom) -> std::vector<caf::actor> {
        auto& st = self->state;
        std::vector<caf::actor> out;
        if (st.renderer) out.push_back(caf::actor_cast<caf::actor>(st.renderer));
        out.push_back(caf::actor_cast<caf::actor>(st.tiler));
        out.push_back(caf::actor_cast<caf::actor>(st.encoder));
        out.push_back(caf::actor_cast<caf::actor>(st.display));
        for (auto& c : st.router.children)
          if (c.alive) out.push_back(caf::actor_cast<caf::actor>(c.worker));
        return out;
      },
      [=](hs_timeout_atom) {
        auto& st = self->state;
        if (st.handshake_done || st.closed) return;
        fail(self, Error{ErrorCode::bad_handshake,
                         "no handshake within " + std::to_string(st.settings->handshake_timeout_ms) + " ms", kNoRecord});
      },
      [=](tick_atom) {
        self->state.router.keepalive(self);  // the workers below end when these stop (cluster.cpp)
        join_children(self);
        self->delayed_send(self, std::chrono::milliseconds(self->state.settings->reconnect_ms), tick_atom::value);
      },
  };
}

}  // namespace

session_actor spawn_session(caf::actor_system& sys, std::shared_ptr<ClientSink> sink,
                            std::shared_ptr<const NodeSettings> settings, uint64_t session_id) {
  return sys.spawn(session_impl, std::move(sink), std::move(settings), session_id);
}

}  // namespace tessera
