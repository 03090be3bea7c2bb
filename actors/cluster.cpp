// Node and worker actors of the cluster (cluster_protocol.h) and the tile checks of the
// router (router.h).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <utility>

#include <malloc.h>

#include <caf/all.hpp>
#include <caf/io/middleman.hpp>
#include <caf/io/middleman_actor.hpp>

#include "actors/node.h"
#include "actors/router.h"
#include "lb/sat.h"
#include "update/scene_update.h"

namespace tessera {

std::string check_tile(const TileResult& t, uint32_t frame, const Rect& expected, PacketLayout layout, int32_t width,
                       int32_t height) {
  auto str = [](const Rect& r) {
    return "[" + std::to_string(r.x0) + "," + std::to_string(r.y0) + "," + std::to_string(r.x1) + "," +
           std::to_string(r.y1) + "]";
  };
  if (t.frame != frame) return "tile of frame " + std::to_string(t.frame) + " in frame " + std::to_string(frame);
  if (!(t.pixels == expected)) return "tile " + str(t.pixels) + " for task " + str(expected);
  if (t.rgba.size() != size_t(expected.area()) * 4)
    return "tile " + str(expected) + " with " + std::to_string(t.rgba.size()) + " bytes of pixels, expected " +
           std::to_string(size_t(expected.area()) * 4);
  if (!std::isfinite(t.kernel_ms) || t.kernel_ms < 0 || !std::isfinite(t.rendering_ms) || t.rendering_ms < 0 ||
      !std::isfinite(t.sat_ms) || t.sat_ms < 0)
    return "impossible timings";
  if (!t.sat.empty()) {
    std::string err;
    auto sat = Sat::try_deserialize(t.sat.data(), t.sat.size(), &err);
    if (!sat) return "cost SAT: " + err;
    // The packets the task covers (its pixel rectangle, rounded out to packets).
    Rect want{expected.x0 / layout.w, expected.y0 / layout.h, (expected.x1 + layout.w - 1) / layout.w,
              (expected.y1 + layout.h - 1) / layout.h};
    if (!(sat->packets() == want) || !packet_space(width, height, layout).contains(sat->packets()))
      return "cost SAT over packets " + str(sat->packets()) + " for task packets " + str(want);
  }
  return {};
}

namespace {
// A node or master name: 1..256 bytes, no control characters, quotes or backslashes.
bool usable_name(const std::string& name) {
  bool ok = !name.empty() && name.size() <= 256;
  for (unsigned char c : name) ok &= c >= 0x20 && c != 0x7f && c != '"' && c != '\\';
  return ok;
}
}  // namespace

std::string check_nodes(const std::vector<NodeInfo>& nodes) {
  if (nodes.size() > 65536) return std::to_string(nodes.size()) + " nodes";
  for (const NodeInfo& n : nodes) {
    if (!usable_name(n.name)) return "a node without a usable name";
    if (n.logical_cores < 1 || n.logical_cores > 65536)
      return "node " + n.name + " claims " + std::to_string(n.logical_cores) + " logical cores";
    if (!std::isfinite(n.single_core_perf) || n.single_core_perf <= 0 || n.single_core_perf > 1000)
      return "node " + n.name + " claims a single-core performance of " + std::to_string(n.single_core_perf);
  }
  return {};
}

Json nodes_value(const std::vector<NodeInfo>& nodes) {
  std::vector<Json> out;
  out.reserve(nodes.size());
  for (const NodeInfo& n : nodes)
    out.push_back(Json::object({{"name", n.name}, {"cores", n.logical_cores}, {"perf", Json::number(n.single_core_perf)}}));
  return Json::array(std::move(out));
}

std::string check_open(const OpenRequest& req) {
  if (req.session == 0) return "session 0";
  if (!usable_name(req.master)) return "a master name that is empty, longer than 256 bytes or not printable";
  auto pow2 = [](int32_t v) { return v >= 1 && v <= 16 && (v & (v - 1)) == 0; };
  const int64_t rays = int64_t(req.packet_w) * req.packet_h;
  if (!pow2(req.packet_w) || !pow2(req.packet_h) || (rays != 4 && rays != 8 && rays != 16))
    return "packet layout " + std::to_string(req.packet_w) + "x" + std::to_string(req.packet_h) +
           " (the ray tracer has 4, 8 or 16 rays per packet)";
  if (req.timeout_ms > 3'600'000) return "reply timeout of " + std::to_string(req.timeout_ms) + " ms";
  if (req.keepalive_ms < 10 || req.keepalive_ms > 60'000)
    return "keep-alive period of " + std::to_string(req.keepalive_ms) + " ms (10..60000)";
  return {};
}

std::string check_batch(const RenderBatch& b, const protocol::Limits& lim) {
  if (b.width < 1 || b.height < 1 || b.width > lim.max_width || b.height > lim.max_height)
    return "frame " + std::to_string(b.width) + "x" + std::to_string(b.height) + " outside 1x1.." +
           std::to_string(lim.max_width) + "x" + std::to_string(lim.max_height);
  if (b.ao_samples < 0 || uint32_t(b.ao_samples) > lim.max_ao_samples)
    return "ao_samples " + std::to_string(b.ao_samples) + " outside 0.." + std::to_string(lim.max_ao_samples);
  if (b.max_depth < 0 || uint32_t(b.max_depth) > lim.max_depth)
    return "max_depth " + std::to_string(b.max_depth) + " outside 0.." + std::to_string(lim.max_depth);
  if (b.renderer > uint8_t(protocol::RendererKind::rasterizer)) return "renderer kind " + std::to_string(int(b.renderer));
  if (b.timeout_ms < 1 || b.timeout_ms > 3'600'000) return "timeout of " + std::to_string(b.timeout_ms) + " ms";
  if (b.tasks.size() > 65536) return std::to_string(b.tasks.size()) + " tasks";
  const Rect frame{0, 0, b.width, b.height};
  for (const Rect& t : b.tasks)
    if (!t.empty() && !frame.contains(t))
      return "task [" + std::to_string(t.x0) + "," + std::to_string(t.y0) + "," + std::to_string(t.x1) + "," +
             std::to_string(t.y1) + "] outside the frame " + std::to_string(b.width) + "x" + std::to_string(b.height);
  return {};
}

std::string apply_records(Scene& scene, const std::vector<uint8_t>& bytes, const protocol::Limits& node_limits) {
  if (bytes.empty()) return {};
  // The scene-level limits are this node's own; a forwarded message may be bigger than a
  // client's (a whole scene when a node joins), so the message-level ones are lifted.
  protocol::Limits lim = node_limits;
  lim.max_message_bytes = std::max<uint32_t>(lim.max_message_bytes, uint32_t(std::min<size_t>(bytes.size(), 0xffffffffu)));
  lim.max_records = 0xffffffffu;
  lim.max_message_payload_bytes = std::max<uint64_t>(lim.max_message_payload_bytes, lim.max_client_bytes);
  auto res = protocol::decode_client(bytes.data(), bytes.size(), lim);
  if (!res) return res.error().message;
  std::string first;
  for (auto& r : res.value()) {
    auto st = apply(scene, std::move(r), lim);
    if (!st && first.empty()) first = st.error().message;
  }
  return first;
}

namespace {

// --- Worker -----------------------------------------------------------------------------

struct worker_state {
  std::shared_ptr<const NodeSettings> settings;
  node_actor node;
  OpenRequest req;
  caf::actor_addr parent;
  std::shared_ptr<Scene> scene = std::make_shared<Scene>();
  std::vector<std::pair<std::vector<uint8_t>, bool>> cached;  // updates that arrived while rendering
  std::vector<uint8_t> partial;  // the chunks of an update received so far (cluster_protocol.h)
  bool partial_reset = false;
  bool partial_dropped = false;  // the update being received went over settings->max_update_bytes
  bool in_flight = false;
  std::string broken;  // an update this node could not apply: its tiles would be wrong
  // A parent that adopts this worker (the open's reply reached it in time) sends it an empty
  // update at once, then the scene; one whose open request timed out never will (see the
  // tick handler).
  bool adopted = false;
  std::chrono::steady_clock::time_point opened_at = std::chrono::steady_clock::now();
  // The last message from the parent (an update, a keep-alive, a batch, a nodes query), on the
  // actor clock: a parent that is silent for keepalive_misses of its periods is gone.
  caf::actor_clock::time_point last_heard;
  bool committed = false;  // the first node list (for the open reply) was committed
  renderer_actor renderer;
  Router router;
  static inline const char* name = "tessera.worker";
};
using worker_ptr = worker_actor::stateful_pointer<worker_state>;

void worker_log(worker_ptr self, Event e) {
  auto& st = self->state;
  e.scope = {{"node", st.settings->name}, {"session", st.req.session}};
  node_log(*st.settings, std::move(e));
}

// A message from this worker's parent (or from anyone, for a worker without one): it is alive.
void heard(worker_ptr self) {
  auto& st = self->state;
  const auto& sender = self->current_sender();
  if (!st.parent || (sender && sender->address() == st.parent)) st.last_heard = self->clock().now();
}

// Every tile of a batch that this node will not render, failed with `why`.
BatchReply failed_batch(const RenderBatch& b, const std::string& why) {
  BatchReply r;
  r.tiles.resize(std::min<size_t>(b.tasks.size(), 65536));
  for (size_t i = 0; i < r.tiles.size(); ++i) {
    r.tiles[i].frame = b.frame;
    r.tiles[i].pixels = b.tasks[i];
    r.tiles[i].error = why;
  }
  return r;
}

void worker_apply(worker_ptr self, const std::vector<uint8_t>& bytes, bool reset) {
  auto& st = self->state;
  if (reset) {
    st.scene = std::make_shared<Scene>();
    st.broken.clear();
  }
  std::string err = apply_records(*st.scene, bytes, st.settings->limits);
  if (!err.empty() && st.broken.empty()) {
    st.broken = err;
    worker_log(self, Event(Ev::update_failed, err));
  }
}

// A whole update from the parent: down to the children, and applied here now or after the
// render in flight.
void worker_update(worker_ptr self, std::vector<uint8_t> bytes, bool reset) {
  auto& st = self->state;
  st.router.forward(self, bytes, reset);
  if (st.in_flight) st.cached.emplace_back(std::move(bytes), reset);
  else worker_apply(self, bytes, reset);
}

void worker_apply_cached(worker_ptr self) {
  auto& st = self->state;
  auto cached = std::move(st.cached);
  st.cached.clear();
  for (auto& [bytes, reset] : cached) worker_apply(self, bytes, reset);
}

worker_actor::behavior_type worker_impl(worker_ptr self, std::shared_ptr<const NodeSettings> settings, node_actor node,
                                        OpenRequest req, caf::strong_actor_ptr parent) {
  auto& st = self->state;
  st.settings = std::move(settings);
  st.node = std::move(node);
  st.req = req;
  st.router.layout = {req.packet_w, req.packet_h};
  st.router.log = [self](Event e) { worker_log(self, std::move(e)); };
  if (st.settings->render) {
    st.router.self_node = st.settings->info();
    st.renderer = spawn_renderer(self->system(), st.router.layout, st.settings->detached);
    self->link_to(st.renderer);
  }
  if (parent) {
    st.parent = caf::actor_cast<caf::actor_addr>(parent);
    self->monitor(parent);
  }
  if (st.node) self->monitor(st.node);  // the node shuts down: its workers go with it
  st.last_heard = self->clock().now();
  self->set_down_handler([=](caf::down_msg& m) {
    const bool from_parent = m.source == self->state.parent;
    if (from_parent || (self->state.node && m.source == self->state.node.address())) {
      // The session ended (or the parent worker did), its connection to this node broke, or
      // this node is shutting down.
      worker_log(self, Event(Ev::ended, from_parent ? "parent down" : "node down").with("reason", to_string(m.reason)));
      self->quit(caf::exit_reason::user_shutdown);
      return;
    }
    self->state.router.child_failed(m.source, to_string(m.reason));
  });
  auto snapshot = [self] {
    auto& st = self->state;
    std::vector<std::pair<std::vector<uint8_t>, bool>> out;
    out.emplace_back(scene_snapshot_bytes(SceneSnapshot{st.scene}), true);
    for (auto& c : st.cached) out.push_back(c);  // not applied here yet, but already forwarded
    return out;
  };
  auto join = [self, snapshot] {
    auto& st = self->state;
    OpenRequest r = st.req;
    r.master = st.settings->name;
    st.router.join_children(self, st.node, r, st.settings->task_timeout_ms, snapshot);
  };
  st.router.keepalive_ms = st.settings->reconnect_ms;  // this worker's tick period
  join();
  self->delayed_send(self, std::chrono::milliseconds(st.settings->reconnect_ms), tick_atom::value);
  return {
      [=](update_atom, Payload& payload, bool reset) {
        heard(self);
        self->state.adopted = true;
        if (payload.bytes.empty() && !reset) return;  // the parent's notice that it adopted this worker
        worker_update(self, std::move(payload.bytes), reset);
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
            worker_log(self, Event(Ev::update_failed, st.broken));
          }
          st.partial_dropped = true;
          st.partial = {};
        } else {
          st.partial.insert(st.partial.end(), chunk.bytes.begin(), chunk.bytes.end());
        }
        if (last) {
          if (!st.partial_dropped) worker_update(self, std::exchange(st.partial, {}), st.partial_reset);
          st.partial_dropped = false;
        }
        return n;
      },
      [=](render_atom, RenderBatch& batch) -> caf::result<BatchReply> {
        heard(self);
        // Checked like a client's requests on this node: a bad batch fails every tile and the
        // worker serves on.
        if (std::string bad = check_batch(batch, self->state.settings->limits); !bad.empty()) {
          worker_log(self, Event(Ev::bad_batch, bad));
          return failed_batch(batch, "node " + self->state.settings->name + " refused the batch: " + bad);
        }
        auto rp = self->make_response_promise<BatchReply>();
        auto local = [self](const RenderTask& t, std::function<void(TileResult&&)> cb) {
          auto& st = self->state;
          if (!st.broken.empty()) {
            TileResult r;
            r.frame = t.frame;
            r.pixels = t.pixels;
            r.error = "node " + st.settings->name + " has no valid scene: " + st.broken;
            cb(std::move(r));
            return;
          }
          if (st.scene->width() != t.width || st.scene->height() != t.height) st.scene->set_resolution(t.width, t.height);
          st.in_flight = true;
          self->request(st.renderer, caf::infinite, render_atom::value, SceneSnapshot{st.scene}, t)
              .then(
                  [=](TileResult& r) {
                    self->state.in_flight = false;
                    worker_apply_cached(self);
                    cb(std::move(r));
                  },
                  [=](caf::error& e) {
                    self->state.in_flight = false;
                    worker_apply_cached(self);
                    TileResult r;
                    r.frame = t.frame;
                    r.pixels = t.pixels;
                    r.error = "renderer: " + to_string(e);
                    cb(std::move(r));
                  });
        };
        self->state.router.dispatch(self, batch, local, [rp](BatchReply&& r) mutable { rp.deliver(std::move(r)); });
        return rp;
      },
      [=](nodes_atom) -> caf::result<std::vector<NodeInfo>> {
        heard(self);
        auto& st = self->state;
        auto rp = self->make_response_promise<std::vector<NodeInfo>>();
        // The first list (the open reply) waits for the children being opened; the parent's
        // later commits do not (router.h, commit).
        const bool first = !st.committed;
        st.committed = true;
        st.router.commit(
            self, st.settings->task_timeout_ms, [rp](std::vector<NodeInfo> l) mutable { rp.deliver(std::move(l)); },
            first);
        return rp;
      },
      [=](tick_atom) {
        auto& st = self->state;
        // An orphan: the open request reached this node after its parent had given up on it
        // (a link that was cut and came back delivers the requests it held), so the reply was
        // dropped and nobody will ever use this worker. It would live as long as the session.
        // The parent's timeout has passed since this worker was opened; one more is allowed
        // for its adoption notice (an empty update, sent before the scene) to arrive.
        if (!st.adopted && st.req.timeout_ms > 0 &&
            std::chrono::steady_clock::now() - st.opened_at > std::chrono::milliseconds(2 * uint64_t(st.req.timeout_ms))) {
          worker_log(self, Event(Ev::orphaned, true));
          self->quit(caf::exit_reason::user_shutdown);
          return;
        }
        // A parent that stopped answering (hung, or cut off without the connection noticing)
        // sends no keep-alives: after keepalive_misses of its periods this worker ends.
        const auto silent = self->clock().now() - st.last_heard;
        if (st.req.keepalive_ms > 0 &&
            silent > std::chrono::milliseconds(uint64_t(st.req.keepalive_ms) * st.settings->keepalive_misses)) {
          worker_log(self, Event(Ev::ended, "parent silent")
                               .with("silent_ms", std::chrono::duration_cast<std::chrono::milliseconds>(silent).count()));
          self->quit(caf::exit_reason::user_shutdown);
          return;
        }
        // Anyone holding this worker's handle can send it a tick: only its own (delayed_send
        // to itself) runs the periodic work, so ticks from elsewhere start no further loops.
        if (self->current_sender() != self->ctrl()) return;
        st.router.keepalive(self);
        join();
        self->delayed_send(self, std::chrono::milliseconds(self->state.settings->reconnect_ms), tick_atom::value);
      },
  };
}

// --- Node -------------------------------------------------------------------------------

struct node_state {
  std::shared_ptr<const NodeSettings> settings;
  struct Child {
    std::string name, host;
    uint16_t port = 0;
    node_actor node;
    bool connecting = false;
    bool reported = false;  // a failure to connect was logged (log the next change only)
  };
  std::vector<Child> children;
  std::map<caf::actor_addr, uint64_t> workers;  // live workers (monitored) and their sessions
  int trim_in = 0;  // ticks until the heap is trimmed (set when the last worker ends)
  static inline const char* name = "tessera.node";
};
using node_ptr = node_actor::stateful_pointer<node_state>;

void node_event(node_ptr self, Event e) {
  e.scope = {{"node", self->state.settings->name}};
  node_log(*self->state.settings, std::move(e));
}

void connect_child(node_ptr self, size_t i) {
  auto& c = self->state.children[i];
  if (c.node || c.connecting || !self->system().has_middleman()) return;
  c.connecting = true;
  auto mm = self->system().middleman().actor_handle();
  self->request(mm, std::chrono::seconds(5), caf::connect_atom::value, c.host, c.port)
      .then(
          [=](const caf::node_id&, caf::strong_actor_ptr& p, const std::set<std::string>&) {
            auto& c = self->state.children[i];
            c.connecting = false;
            if (!p) return;
            c.node = caf::actor_cast<node_actor>(p);
            c.reported = false;
            self->monitor(c.node);
            node_event(self, Event(Ev::child_connected, c.name));
          },
          [=](caf::error& e) {
            auto& c = self->state.children[i];
            c.connecting = false;
            if (!c.reported)
              node_event(self, Event(Ev::child_unreachable, c.name).with("reason", self->system().render(e)));
            c.reported = true;
          });
}

node_actor::behavior_type node_impl(node_ptr self, std::shared_ptr<const NodeSettings> settings) {
  auto& st = self->state;
  st.settings = std::move(settings);
  for (const auto& spec : st.settings->children) {
    node_state::Child c;
    c.name = spec;
    auto colon = spec.rfind(':');
    c.host = spec.substr(0, colon);
    c.port = uint16_t(std::stoi(spec.substr(colon + 1)));
    st.children.push_back(std::move(c));
  }
  for (size_t i = 0; i < st.children.size(); ++i) connect_child(self, i);
  self->set_down_handler([=](caf::down_msg& m) {
    auto& st = self->state;
    if (auto w = st.workers.find(m.source); w != st.workers.end()) {
      const uint64_t session = w->second;
      st.workers.erase(w);
      // The last worker gone: trim (and log it) on the node's tick; while others live, every
      // ended worker's heap goes back all the same (one debounced trim, actors/node.h).
      if (st.workers.empty()) st.trim_in = 2;
      else schedule_heap_trim(1000);
      node_event(self, Event(Ev::worker_closed, session).with("live_workers", st.workers.size()));
      return;
    }
    for (auto& c : st.children)
      if (c.node && c.node.address() == m.source) {
        c.node = nullptr;
        node_event(self, Event(Ev::child_lost, c.name).with("reason", to_string(m.reason)));
      }
  });
  self->delayed_send(self, std::chrono::milliseconds(st.settings->reconnect_ms), tick_atom::value);
  return {
      [=](open_atom, const OpenRequest& req) -> caf::result<OpenReply> {
        auto& st = self->state;
        // The worker watches whoever opened it: read the sender before the promise takes it over.
        auto parent = self->current_sender();
        std::string refused = parent ? check_open(req) : "an open request without a sender";
        const bool full = refused.empty() && st.workers.size() >= st.settings->max_workers;
        if (full)
          refused = "node " + st.settings->name + " has " + std::to_string(st.workers.size()) +
                    " live workers, its max-workers";
        if (!refused.empty()) {
          node_event(self, Event(Ev::open_refused, refused)
                               .with("session", req.session)
                               .with("from", parent ? to_string(parent->node()) : std::string("?")));
          return caf::make_error(full ? caf::sec::runtime_error : caf::sec::invalid_argument, "open refused: " + refused);
        }
        auto rp = self->make_response_promise<OpenReply>();
        auto w = spawn_worker(self->system(), st.settings, caf::actor_cast<node_actor>(self), req, parent);
        self->monitor(w);
        st.workers.emplace(w.address(), req.session);
        node_event(self, Event(Ev::worker_opened, req.session)
                             .with("master", req.master)
                             .with("live_workers", st.workers.size()));
        self->request(w, std::chrono::milliseconds(2 * st.settings->task_timeout_ms), nodes_atom::value)
            .then([=](std::vector<NodeInfo>& l) mutable { rp.deliver(OpenReply{caf::actor_cast<caf::actor>(w), l}); },
                  [=](caf::error& e) mutable {
                    self->send_exit(w, caf::exit_reason::user_shutdown);
                    rp.deliver(e);
                  });
        return rp;
      },
      [=](links_atom) {
        std::vector<ChildLink> out;
        for (auto& c : self->state.children)
          if (c.node) out.push_back(ChildLink{c.name, caf::actor_cast<caf::actor>(c.node)});
        return out;
      },
      [=](tick_atom) {
        auto& st = self->state;
        if (self->current_sender() != self->ctrl()) return;  // a peer's tick starts no second loop
        for (size_t i = 0; i < st.children.size(); ++i) connect_child(self, i);
        // The last worker ended a tick or two ago (its renderer has freed its scene by now):
        // hand the freed heap back to the OS, so an idle node's RSS returns to its baseline.
        if (st.trim_in > 0 && --st.trim_in == 0 && st.workers.empty()) {
          malloc_trim(0);
          node_event(self, Event(Ev::heap_trimmed, true));
        }
        self->delayed_send(self, std::chrono::milliseconds(st.settings->reconnect_ms), tick_atom::value);
      },
  };
}

}  // namespace

worker_actor spawn_worker(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings, node_actor node,
                          OpenRequest request, caf::strong_actor_ptr parent) {
  return sys.spawn(worker_impl, std::move(settings), std::move(node), std::move(request), std::move(parent));
}

node_actor spawn_node(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings) {
  for (const auto& spec : settings->children) {
    auto colon = spec.rfind(':');
    bool ok = colon != std::string::npos && colon > 0 && colon + 1 < spec.size() &&
              spec.find_first_not_of("0123456789", colon + 1) == std::string::npos && spec.size() - colon <= 6 &&
              std::stoi(spec.substr(colon + 1)) > 0 && std::stoi(spec.substr(colon + 1)) < 65536;
    if (!ok) throw std::invalid_argument("child node '" + spec + "' is not host:port");
  }
  return sys.spawn(node_impl, std::move(settings));
}

}  // namespace tessera
