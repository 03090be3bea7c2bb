// Session actor (sync channel): one per client. See session_protocol.h.
#include <chrono>
#include <optional>

#include <caf/all.hpp>

#include "actors/node.h"
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
  Handshake hs;
  protocol::Settings render;
  PacketLayout layout;
  renderer_actor renderer;
  tiler_actor tiler;
  encoder_actor encoder;
  display_actor display;
  // Frame pipeline.
  std::vector<ClientRecord> cached;  // scene updates that arrived while a frame was rendering
  bool in_flight = false;
  std::optional<uint32_t> pending;   // the latest render request that arrived while rendering
  uint32_t seq = 0, dropped = 0, errors = 0;
  FrameMeta meta;
  size_t expected = 0;
  std::vector<TileResult> tiles;
  static inline const char* name = "tessera.session";
};

using self_ptr = session_actor::stateful_pointer<session_state>;

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

std::string json_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '"' || c == '\\') o += '\\', o += c;
    else if (static_cast<unsigned char>(c) < 0x20) o += ' ';
    else o += c;
  }
  return o;
}

void log(self_ptr self, const std::string& what) {
  node_log(*self->state.settings, "{\"session\": " + std::to_string(self->state.id) + ", " + what + "}");
}

// Sends an error record; a fatal one ends the session (and closes the connection).
void fail(self_ptr self, const Error& e) {
  auto& st = self->state;
  if (st.closed) return;
  ErrorReply r = to_reply(e);
  st.errors++;
  st.sink->send(encode(ServerRecord{r}));
  log(self, std::string("\"error\": \"") + to_string(e.code) + "\", \"fatal\": " + (r.fatal ? "true" : "false") +
                ", \"record\": " + std::to_string(int64_t(e.record == kNoRecord ? -1 : int64_t(e.record))) +
                ", \"message\": \"" + json_escape(e.message) + "\"");
  if (r.fatal) {
    st.closed = true;
    st.sink->close(e.message);
    self->quit(caf::exit_reason::user_shutdown);
  }
}

void apply_update(self_ptr self, ClientRecord&& rec, uint32_t index) {
  auto& st = self->state;
  Status s = apply(*st.scene, std::move(rec), st.settings->limits);
  if (!s) {
    Error e = s.error();
    e.record = index;
    fail(self, e);
  }
}

void apply_cached(self_ptr self) {
  auto& st = self->state;
  auto cached = std::move(st.cached);
  st.cached.clear();
  for (auto& r : cached) {
    if (st.closed) return;
    apply_update(self, std::move(r), kNoRecord);  // deferred: the record index is no longer meaningful
  }
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
  log(self, "\"preloaded_scene\": true, \"triangles\": " + std::to_string(st.scene->triangle_count()));
}

void on_tile(self_ptr self, TileResult&& t);

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
  st.tiles.clear();
  TaskRequest req{st.seq, st.meta.width, st.meta.height, st.layout.w, st.layout.h};
  RenderTask base;
  base.frame = st.seq;
  base.width = st.meta.width;
  base.height = st.meta.height;
  base.ao_samples = int32_t(st.render.ao_samples);
  base.max_depth = int32_t(st.render.max_depth);
  base.renderer = uint8_t(st.hs.renderer);
  SceneSnapshot snap{st.scene};  // read-only until the frame is rendered: updates are cached meanwhile
  self->request(st.tiler, caf::infinite, tasks_atom::value, req).then([=](TaskList& tl) {
    auto& st = self->state;
    st.meta.tiling_ms = tl.tiling_ms;
    st.meta.nodes = uint32_t(tl.tasks.size());
    st.expected = tl.tasks.size();
    for (const Rect& r : tl.tasks) {
      RenderTask t = base;
      t.pixels = r;
      self->request(st.renderer, caf::infinite, render_atom::value, snap, t).then([=](TileResult& tr) {
        on_tile(self, std::move(tr));
      });
    }
  });
}

void on_tile(self_ptr self, TileResult&& t) {
  auto& st = self->state;
  if (!st.in_flight || t.frame != st.seq) return;
  st.tiles.push_back(std::move(t));
  if (st.tiles.size() < st.expected) return;
  // The frame is rendered: measurements, SATs to the tiler, pixels to the display channel.
  st.meta.render_end_ns = now_ns();
  std::string error;
  SatReport rep{st.seq, st.meta.width, st.meta.height, st.layout.w, st.layout.h, {}};
  for (auto& tile : st.tiles) {
    st.meta.kernel_ms += tile.kernel_ms;
    st.meta.rendering_ms = std::max(st.meta.rendering_ms, tile.rendering_ms);
    st.meta.sat_ms = std::max(st.meta.sat_ms, tile.sat_ms);
    if (!tile.error.empty()) error = tile.error;
    rep.sats.push_back(std::move(tile.sat));
  }
  self->send(st.tiler, sats_atom::value, std::move(rep));
  st.in_flight = false;
  if (error.empty()) {
    self->send(st.display, display_atom::value, FrameTiles{st.meta, std::move(st.tiles)});
  } else {
    fail(self, Error{ErrorCode::internal, "frame " + std::to_string(st.meta.client_frame) + ": " + error, kNoRecord});
  }
  st.tiles.clear();
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
  HandshakeReply r;
  r.renderer = st.hs.renderer;
  r.display = h.display;
  r.jpeg_quality = h.jpeg_quality;
  r.nodes = 1;  // single node: this node renders every frame
  r.width = h.width;
  r.height = h.height;
  r.max_message_bytes = st.settings->limits.max_message_bytes;
  r.max_buffer_bytes = st.settings->limits.max_buffer_bytes;
  r.server_version = st.settings->server_version;
  st.sink->send(encode(ServerRecord{r}));
  static const char* displays[] = {"jpeg", "s3tc", "mjpeg"};
  log(self, std::string("\"handshake\": {\"display\": \"") + displays[int(h.display)] + "\", \"quality\": " +
                std::to_string(h.jpeg_quality) + ", \"width\": " + std::to_string(h.width) +
                ", \"height\": " + std::to_string(h.height) + "}");
}

void on_client(self_ptr self, std::vector<uint8_t>& bytes) {
  auto& st = self->state;
  if (st.closed) return;
  auto res = decode_client(bytes.data(), bytes.size(), st.settings->limits);
  bytes = {};  // the decoded records own their data now
  if (!res) return fail(self, res.error());
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
      st.cached.push_back(std::move(rec));
    } else {
      apply_update(self, std::move(rec), i);
    }
  }
}

session_actor::behavior_type session_impl(self_ptr self, std::shared_ptr<ClientSink> sink,
                                          std::shared_ptr<const NodeSettings> settings, uint64_t id) {
  auto& st = self->state;
  st.sink = std::move(sink);
  st.settings = std::move(settings);
  st.id = id;
  st.layout = st.settings->packet_layout.w > 0 ? st.settings->packet_layout : detect_packet_layout();
  auto& sys = self->system();
  st.renderer = spawn_renderer(sys, st.layout, st.settings->detached);
  st.tiler = spawn_tiler(sys, {st.settings->coefficient.renderer()});
  st.encoder = spawn_encoder(sys, st.settings->detached);
  st.display = spawn_display(sys, st.sink, st.encoder, st.settings, id);
  self->link_to(st.renderer);
  self->link_to(st.tiler);
  self->link_to(st.encoder);
  self->link_to(st.display);
  // Linked children end with the session (it always quits with a non-normal reason).
  self->attach_functor([settings = st.settings, id](const caf::error& reason) {
    node_log(*settings, "{\"session\": " + std::to_string(id) + ", \"closed\": true}");
  });
  log(self, "\"opened\": true, \"token\": \"" + json_escape(st.sink->token()) + "\"");
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
        return {caf::actor_cast<caf::actor>(st.renderer), caf::actor_cast<caf::actor>(st.tiler),
                caf::actor_cast<caf::actor>(st.encoder), caf::actor_cast<caf::actor>(st.display)};
      },
  };
}

}  // namespace

session_actor spawn_session(caf::actor_system& sys, std::shared_ptr<ClientSink> sink,
                            std::shared_ptr<const NodeSettings> settings, uint64_t session_id) {
  return sys.spawn(session_impl, std::move(sink), std::move(settings), session_id);
}

}  // namespace tessera
