// Session actor (the sync channel): one per client. See session_protocol.h; its frames are
// the frame actor's (frame_actor.cpp), its tree the root subtree's (subtree.cpp).
#include <chrono>
#include <optional>

#include <caf/all.hpp>

#include "actors/errors.h"
#include "actors/node.h"
#include "protocol/scene_records.h"
#include "renderer/raytracer.h"

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
  bool cluster = false;              // this process has a node actor: accepted records go down the tree
  Handshake hs;
  protocol::Settings render;
  PacketLayout layout;
  renderer_actor renderer;
  tiler_actor tiler;
  encoder_actor encoder;
  display_actor display;
  subtree_actor subtree;             // the root of the client's tree
  frame_actor frame;
  std::vector<ClientRecord> cached;  // scene updates that arrived while a frame was rendering
  PendingBytes cached_bytes;         // their buffers and textures count against max_client_bytes
  // This session's part of the node-wide budget (NodeSettings::budget): its scene's buffers
  // and textures plus what the cached updates hold, and, while a message is decoded, what it
  // declares.
  BudgetShare share;
  bool in_flight = false;            // the frame actor renders a frame: the scene is read-only
  std::optional<uint32_t> pending;   // the latest render request that arrived while rendering
  uint32_t seq = 0, dropped = 0, errors = 0;
  std::vector<uint8_t> forward;      // accepted scene records not yet sent down the tree
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
  if (st.cluster) one = encode(rec);
  Status s = apply(*st.scene, std::move(rec), st.settings->limits);
  if (s && st.cluster) append_message(st.forward, std::move(one));
  if (!s) {
    Error e = s.error();
    e.record = index;
    fail(self, e);
  }
}

void flush_forward(self_ptr self) {
  auto& st = self->state;
  if (st.forward.empty()) return;
  self->send(st.subtree, update_atom::value, Payload{std::move(st.forward)}, false);
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
  if (st.cluster) self->send(st.subtree, update_atom::value, Payload{scene_snapshot_bytes(SceneSnapshot{st.scene})}, true);
  settle_budget(self);  // the preloaded scene is the node's own: counted, never refused
  log(self, Event(Ev::preloaded_scene, true).with("triangles", st.scene->triangle_count()));
}

void start_frame(self_ptr self, uint32_t client_frame);

// The frame actor has the frame's tiles (or gave up on it): apply what was cached, then start
// the remembered render request (the encoder meanwhile encodes the frame just rendered).
void frame_done(self_ptr self) {
  auto& st = self->state;
  st.in_flight = false;
  if (st.closed) return;
  apply_cached(self);
  if (st.pending && !st.closed) {
    uint32_t f = *st.pending;
    st.pending.reset();
    start_frame(self, f);
  }
}

void start_frame(self_ptr self, uint32_t client_frame) {
  auto& st = self->state;
  apply_cached(self);
  if (st.closed) return;
  maybe_preload(self);
  st.in_flight = true;
  st.seq++;
  FrameStart fs;
  FrameMeta& m = fs.meta;
  m.seq = st.seq;
  m.client_frame = client_frame;
  m.width = st.scene->width();
  m.height = st.scene->height();
  m.display = uint8_t(st.hs.display);
  m.quality = st.hs.jpeg_quality;
  m.render_start_ns = now_ns();
  m.dropped = st.dropped;  // for the display channel's Stats record
  m.scene_bytes = scene_bytes(*st.scene);
  m.triangles = st.scene->triangle_count();
  fs.scene = SceneSnapshot{st.scene};  // read-only until the frame actor answers: updates are cached meanwhile
  fs.ao_samples = int32_t(st.render.ao_samples);
  fs.max_depth = int32_t(st.render.max_depth);
  fs.renderer = uint8_t(st.hs.renderer);
  self->request(st.frame, caf::infinite, render_atom::value, std::move(fs))
      .then([self](uint32_t) { frame_done(self); },
            [self](caf::error& e) {
              fail(self, Error{ErrorCode::internal, error_message(e), kNoRecord});
              frame_done(self);
            });
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
  // The reply names the nodes this client gets: the tree is committed first (children that
  // are still being opened are waited for, within the task timeout). A render request in the
  // same message asks the frame actor after this, so the reply still comes first.
  self->request(st.frame, caf::infinite, nodes_atom::value, uint32_t(h.max_nodes)).then([self, h](uint32_t nodes) {
    auto& st = self->state;
    if (st.closed) return;
    HandshakeReply r;
    r.renderer = st.hs.renderer;
    r.display = h.display;
    r.jpeg_quality = h.jpeg_quality;
    r.nodes = nodes;
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

session_actor::behavior_type session_impl(self_ptr self, std::shared_ptr<ClientSink> sink,
                                          std::shared_ptr<const NodeSettings> settings, uint64_t id) {
  auto& st = self->state;
  st.sink = std::move(sink);
  st.settings = std::move(settings);
  st.id = id;
  st.layout = st.settings->packet_layout.w > 0 ? st.settings->packet_layout : detect_packet_layout();
  auto& sys = self->system();
  auto node = caf::actor_cast<node_actor>(st.settings->node.lock());
  st.cluster = bool(node);
  if (st.settings->render) st.renderer = spawn_renderer(sys, st.layout, st.settings->detached);
  st.tiler = spawn_tiler(sys, {st.settings->coefficient.renderer()});
  st.encoder = spawn_encoder(sys, st.settings->detached);
  st.display = spawn_display(sys, st.sink, st.encoder, st.settings, id);
  // The client's tree: this node's renderer and workers on the children this node is
  // connected to (and, every reconnect period, on children that came back).
  SubtreeSpec root;
  root.req = OpenRequest{id, st.settings->name, st.layout.w, st.layout.h};
  root.parent = caf::actor_cast<caf::strong_actor_ptr>(self);
  root.renderer = st.renderer;
  root.source = caf::actor_cast<scene_source_actor>(self);
  st.subtree = spawn_subtree(sys, st.settings, node, std::move(root));
  st.frame = spawn_frame(sys, st.settings, id, st.layout, FrameActors{st.subtree, st.renderer, st.tiler, st.display});
  // Linked actors end with the session (it always quits with a non-normal reason).
  if (st.renderer) self->link_to(st.renderer);
  self->link_to(st.tiler);
  self->link_to(st.encoder);
  self->link_to(st.display);
  self->link_to(st.subtree);
  self->link_to(st.frame);
  self->attach_functor([settings = st.settings, id](const caf::error&) {
    Event closed(Ev::closed, true);
    closed.scope = {{"session", id}};
    node_log(*settings, std::move(closed));
    schedule_heap_trim();  // its scene, BVH and frames are freed as its linked actors end
  });
  log(self, Event(Ev::opened, true).with("token", st.sink->token()));
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
        for (caf::actor a : {caf::actor_cast<caf::actor>(st.tiler), caf::actor_cast<caf::actor>(st.encoder),
                             caf::actor_cast<caf::actor>(st.display), caf::actor_cast<caf::actor>(st.frame),
                             caf::actor_cast<caf::actor>(st.subtree)})
          out.push_back(a);
        return out;
      },
      [=](hs_timeout_atom) {
        auto& st = self->state;
        if (st.handshake_done || st.closed) return;
        fail(self, Error{ErrorCode::bad_handshake,
                         "no handshake within " + std::to_string(st.settings->handshake_timeout_ms) + " ms", kNoRecord});
      },
      [=](tick_atom) { self->send(self->state.subtree, tick_atom::value); },
      [=](snapshot_atom) { return Payload{scene_snapshot_bytes(SceneSnapshot{self->state.scene})}; },
  };
}

}  // namespace

session_actor spawn_session(caf::actor_system& sys, std::shared_ptr<ClientSink> sink,
                            std::shared_ptr<const NodeSettings> settings, uint64_t session_id) {
  return sys.spawn(session_impl, std::move(sink), std::move(settings), session_id);
}

}  // namespace tessera
