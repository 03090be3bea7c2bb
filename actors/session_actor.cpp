// Session actor (the sync channel): one per client. See session_protocol.h; its frames are
// the frame actor's (frame_actor.cpp), its tree the root subtree's (subtree.cpp), its input
// session_input.cpp.
#include <chrono>

#include "actors/errors.h"
#include "actors/session_state.h"
#include "protocol/scene_records.h"
#include "renderer/adaptive.h"
#include "renderer/denoise.h"
#include "renderer/embree_device.h"
#include "renderer/raytracer.h"
#include "update/scene_update.h"

namespace tessera {
namespace session {


void log(self_ptr self, Event e) {
  e.scope = {{"session", self->state.id}};
  node_log(*self->state.settings, std::move(e));
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
  st.showing_preload = true;
  st.scene->set_resolution(w, h);
  if (own_camera) st.scene->set_camera(cam);
  if (st.cluster) self->send(st.subtree, update_atom::value, Payload{scene_snapshot_bytes(SceneSnapshot{st.scene})}, true);
  settle_budget(self);  // the preloaded scene is the node's own: counted, never refused
  log(self, Event(Ev::preloaded_scene, true).with("triangles", st.scene->triangle_count()));
}

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
  } else if (st.still.active && st.still.after_scaled && st.settings->still_delay_ms > 0) {
    // After an interactive frame: the still's first sample waits a moment for the next request.
    self->delayed_send(self, std::chrono::milliseconds(st.settings->still_delay_ms), still_atom::value, st.still.seed);
  } else if (st.still.active && (st.still.after_scaled || st.still.more)) {
    start_frame(self, st.still.client_frame, true);  // nothing changed: the next sample
  } else if (st.still.active) {
    st.still.active = false;  // converged: idle until the client asks again
    log(self, Event(Ev::converged, st.still.client_frame).with("samples", st.still.samples));
  }
}

void start_frame(self_ptr self, uint32_t client_frame, bool refine) {
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
  // Whether the still refines: the client wants more than one sample, the ray tracer renders
  // it (the rasterizer has nothing to add), and the scene has triangles (a scene without any, a
  // page's frames before its scene has come, is its uniform background, exact at one sample).
  const auto refinable = [&] {
    return st.still.target > 1 && st.hs.renderer == RendererKind::raytracer && st.frame_triangles > 0;
  };
  st.frame_scale = 1;
  st.frame_level = 0;
  if (!refine) {
    // A requested frame starts a new still, refined when refinable(). Within a frame budget it
    // is rendered at the scale that keeps it there, and the still follows it at full resolution
    // unasked (not for an empty scene: its background is the same at any scale).
    st.still = {};
    st.still.target = st.refine.value_or(st.settings->refine_samples);
    st.frame_triangles = st.scene->triangle_count();
    if (st.budget && st.budget_triangles) {
      // A scene that has grown or shrunk this much is not the one the cost model measured
      // (the page's scene after frames of an empty one): start again from the smallest scale,
      // rather than render a full frame that takes many budgets.
      constexpr uint64_t kMinChange = 10000;
      const uint64_t was = *st.budget_triangles, now = st.frame_triangles;
      if (now > 2 * was + kMinChange || 2 * now + kMinChange < was) st.budget->restart();
    }
    if (st.budget) {
      // The ray tracer's samples only: the rasterizer takes neither AO rays nor a depth.
      // A new ladder (the page's settings changed, or a budget record replaced the controller)
      // starts from the settings' own level.
      st.budget->set_ladder(st.hs.renderer == RendererKind::raytracer
                                ? interactive_levels(st.render.ao_samples, st.render.max_depth)
                                : std::vector<InteractiveSamples>{{st.render.ao_samples, st.render.max_depth}});
      st.frame_scale = st.budget->scale();
      st.frame_level = st.budget->level();
    }
    // A frame below the page's samples is never the still's sample 0, even at full resolution.
    st.still.after_scaled = st.reduced_frame() && st.frame_triangles > 0;
    st.still.active = st.still.after_scaled || refinable();
    st.still.client_frame = client_frame;
    st.still.seed = st.seq;
  } else if (st.still.after_scaled) {
    st.still.after_scaled = false;  // the still's sample 0, at full resolution, seeds it
    st.still.seed = st.seq;
  }
  if (st.budget || st.scene->width() != st.full_w || st.scene->height() != st.full_h) {
    int32_t w = st.full_w, h = st.full_h;
    if (st.frame_scale < 1) FrameBudget::scaled(st.full_w, st.full_h, st.frame_scale, w, h);
    set_resolution(self, w, h);
    if (st.closed) return;
  }
  fs.refine = !st.reduced_frame() && refinable();
  // Denoised while the plain average is noisy (renderer/denoise.h): only AO under a sky is
  // noise the filter knows.
  fs.denoise = fs.refine && st.settings->denoise_below_db > 0 && st.render.ao_samples > 0 &&
               ineffective_settings(*st.scene, int(st.render.ao_samples), false).empty();
  fs.target = st.still.target;
  if (fs.refine) {
    // The still's average (and what its denoising holds) is held by the frame actor while it
    // refines: it counts against the node's memory budget like the scene; a still it cannot
    // hold is not refined.
    uint64_t need = AdaptiveStill::bytes(st.scene->width(), st.scene->height());
    if (fs.denoise) need += denoise_bytes(st.scene->width(), st.scene->height());
    if (need > st.acc_bytes && !st.share.reserve(need - st.acc_bytes)) {
      fs.refine = false;
      st.still.active = st.still.after_scaled = false;
      fail(self, Error{ErrorCode::limit_exceeded,
                       "refining a " + std::to_string(st.scene->width()) + "x" + std::to_string(st.scene->height()) +
                           " still needs " + std::to_string(need) +
                           " bytes, which would exceed the node's memory budget; the frame is not refined",
                       kNoRecord});
      if (st.closed) return;
    } else {
      st.acc_bytes = need;
    }
  }
  fs.sample = refine ? st.still.samples : 0;
  fs.seed = st.still.seed;
  m.refined = refine;
  st.frame_requested = !refine;
  st.frame_t0_ns = steady_ns();
  m.width = st.scene->width();
  m.height = st.scene->height();
  m.display = uint8_t(st.hs.display);
  m.quality = st.hs.jpeg_quality;
  m.video_kbps = st.video_kbps ? st.video_kbps : st.settings->video_kbps;
  m.keyframe_requests = st.keyframe_requests;
  m.render_start_ns = steady_ns();
  m.dropped = st.dropped;  // for the display channel's Stats record
  m.scene_bytes = scene_bytes(*st.scene);
  m.triangles = st.scene->triangle_count();
  // Settings that change nothing on this scene (AO without a sky, AO on the rasterizer) are
  // said once, as a notice: the frame renders as asked. Checked when they or the sky change.
  const std::pair<uint32_t, uint64_t> now{st.render.ao_samples, st.scene->environment_version()};
  if (now != st.checked) {
    st.checked = now;
    for (std::string& why : ineffective_settings(*st.scene, int(now.first), st.hs.renderer == RendererKind::rasterizer))
      if (st.noted.insert(why).second) fail(self, Error{ErrorCode::no_effect, std::move(why), kNoRecord});
  }
  if (st.closed) return;
  fs.scene = SceneSnapshot{st.scene};  // read-only until the frame actor answers: updates are cached meanwhile
  // An interactive frame below the page's samples (FrameBudget's levels); every other frame
  // renders the page's settings, except that the still's refinements (sample 1 on) trace the
  // node's still-ao-samples AO rays when the page has AO on: their average converges to the
  // same image, sooner (renderer/sampling.h, kStillAoSamples).
  InteractiveSamples samples = st.frame_level > 0 ? st.budget->samples()
                                                  : InteractiveSamples{st.render.ao_samples, st.render.max_depth};
  if (fs.sample > 0 && samples.ao_samples > 0 && st.settings->still_ao_samples > 0)
    samples.ao_samples = st.settings->still_ao_samples;
  fs.ao_samples = int32_t(samples.ao_samples);
  fs.max_depth = int32_t(samples.max_depth);
  m.ao_samples = samples.ao_samples;
  m.max_depth = samples.max_depth;
  fs.renderer = uint8_t(st.hs.renderer);
  self->request(st.frame, caf::infinite, render_atom::value, std::move(fs))
      .then(
          [self](uint32_t more) {
            auto& st = self->state;
            if (!st.reduced_frame()) {  // a sample of the still, not an interactive frame
              st.still.samples++;
              st.still.more = more != 0 && st.still.target > 1;
            }
            if (st.budget && st.frame_requested) {  // an interactive frame: its time steers the next scale
              st.budget->observe(st.frame_scale, double(steady_ns() - st.frame_t0_ns) / 1e6, st.frame_level);
              st.budget_triangles = st.frame_triangles;
            }
            frame_done(self);
          },
          [self](caf::error& e) {
            self->state.still.active = false;  // a failed sample ends the still
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
  st.full_w = h.width;
  st.full_h = h.height;
  if (st.settings->frame_budget_ms > 0) st.budget.emplace(double(st.settings->frame_budget_ms));
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
    // Indexed by DisplayKind (wire.toml's display enum); the decoder refused any other value.
    static const char* displays[] = {"jpeg", "s3tc", "mjpeg", "h264"};
    static_assert(sizeof displays / sizeof *displays == size_t(protocol::wire::enum_max::display) + 1,
                  "a display kind without a name here");
    log(self, Event(Ev::handshake, Json::object({{"display", displays[int(h.display)]},
                                                 {"quality", unsigned(h.jpeg_quality)},
                                                 {"width", h.width},
                                                 {"height", h.height},
                                                 {"nodes", r.nodes}})));
  });
}

}  // namespace session

namespace {

using namespace session;

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
  auto cancel = std::make_shared<CancelMark>();  // the root subtree raises it (frame_protocol.h, cancel)
  if (st.settings->render) st.renderer = spawn_renderer(sys, st.layout, st.settings->detached, cancel);
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
  root.cancel = std::move(cancel);
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
    // The node's shared BVHs (renderer/geometry_cache.h) as this session leaves them: how many
    // are kept, their bytes, and the lookups that found one or built anew so far.
    GeometryCache::Stats g;
    if (EmbreeDevice::geometry_stats(g))
      closed.with("geometry_cache", Json::object({{"entries", uint64_t(g.entries)}, {"bytes", g.bytes}, {"hits", g.hits},
                                                  {"misses", g.misses}, {"evictions", g.evictions}}));
    node_log(*settings, std::move(closed));
    schedule_heap_trim();  // its scene, BVH and frames are freed as its linked actors end
  });
  // Whether the client named its session (an MJPEG stream needs it), not the name: whoever
  // reads the log must not be able to watch the stream.
  log(self, Event(Ev::opened, true).with("named", !st.sink->token().empty()));
  st.share.attach(st.settings->budget);
  if (st.settings->handshake_timeout_ms > 0)
    self->delayed_send(self, std::chrono::milliseconds(st.settings->handshake_timeout_ms), hs_timeout_atom::value);
  return {
      [=](client_atom, std::vector<uint8_t>& bytes) {
        const size_t n = bytes.size();
        on_client(self, bytes);
        self->state.sink->consumed(n);
      },
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
      [=](unreported_atom) {
        self->state.unreported_due = false;
        report_unreported(self);
      },
      [=](still_atom, uint32_t seed) {
        auto& st = self->state;
        // Nothing came since the interactive frame (a request or any other message would have
        // started a frame or ended the still): its still begins.
        if (st.closed || st.in_flight || st.pending || !st.still.active || !st.still.after_scaled || st.still.seed != seed)
          return;
        start_frame(self, st.still.client_frame, true);
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

