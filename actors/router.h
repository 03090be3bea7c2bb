#pragma once
// The fan-out of one sub-tree, shared by the session (the root of a client's tree) and the
// workers below it (cluster_protocol.h): which nodes the sub-tree has, how a batch of tasks
// is split between this node's own renderer and its children, collecting and validating what
// comes back, failing the tasks of children that are down or too late, and children that
// join (again) while the session runs.
//
// Header-only because every function runs inside an actor (templated on its self pointer);
// all of it runs on that actor's thread.
#include <chrono>
#include <algorithm>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <caf/all.hpp>

#include "actors/cluster_protocol.h"
#include "actors/node.h"
#include "core/rect.h"

namespace tessera {

// Why a tile that a node returned cannot be used (empty string: it can). `expected` is the
// task that was sent; pixels and SAT must match it exactly.
std::string check_tile(const TileResult& t, uint32_t frame, const Rect& expected, PacketLayout layout, int32_t width,
                       int32_t height);

// Why a sub-tree's node list cannot be used (empty string: it can): every node needs a name,
// 1..65536 logical cores and a finite single-core performance in (0, 1000].
std::string check_nodes(const std::vector<NodeInfo>& nodes);

// A node list as a JSON array of {"name", "cores", "perf"}, for events.
Json nodes_value(const std::vector<NodeInfo>& nodes);

// Why a peer's open request cannot be served (empty string: it can): a session id, a master
// name like a node name (1..256 bytes, no control characters, quotes or backslashes), a packet
// layout the ray tracer has (w and h powers of two, 4, 8 or 16 rays), a reply timeout of at
// most an hour and a keep-alive period of 10 ms..60 s.
std::string check_open(const OpenRequest& req);

// Why a batch from a worker's parent cannot be rendered (empty string: it can), by the rules
// that apply to a client's requests on this node: the frame within the limits' max_width x
// max_height, ao_samples and max_depth within max_ao_samples and max_depth, a known renderer
// kind, a timeout of 1 ms..1 h, and every task inside the frame. (The task count is checked
// against the node list by Router::dispatch.)
std::string check_batch(const RenderBatch& b, const protocol::Limits& limits);

// The task of one node in a batch.
inline RenderTask task_of(const RenderBatch& b, const Rect& pixels) {
  RenderTask t;
  t.frame = b.frame;
  t.width = b.width;
  t.height = b.height;
  t.pixels = pixels;
  t.ao_samples = b.ao_samples;
  t.max_depth = b.max_depth;
  t.renderer = b.renderer;
  return t;
}

// What waits to go to one child, in order: scene updates, sent in chunks of at most
// kUpdateChunkBytes with at most kUpdateWindowBytes sent and not yet acknowledged, and the
// batches that must reach the child after them. A small update (a frame's camera) goes as one
// plain message while less than a chunk is unacknowledged; the next acknowledged chunk
// covers it, because a worker takes its messages in order. Without the window a burst of uploads went
// into the CAF connection's write buffers whole, and those buffers keep their largest size
// for as long as the connection lives (a dedicated master held 248 MB of them after six
// 15.6 MB uploads to two workers; docs/results/soak.md).
struct Outbox {
  struct Item {
    std::shared_ptr<const std::vector<uint8_t>> update;  // null: `send` is a deferred batch
    size_t offset = 0;                                   // bytes of `update` already sent
    bool reset = false;
    std::function<void()> send;
  };
  std::deque<Item> items;
  uint64_t sent = 0;   // update bytes sent to the child so far
  uint64_t acked = 0;  // of those, the bytes up to the last acknowledged chunk
  uint64_t in_flight() const { return sent - acked; }
};
constexpr size_t kUpdateChunkBytes = size_t(256) << 10;
constexpr size_t kUpdateWindowBytes = size_t(1) << 20;

struct RouterChild {
  std::string name;            // the child's cluster address as this node knows it
  worker_actor worker;
  std::vector<NodeInfo> nodes; // its flattened list as of the last commit
  bool alive = true;
  bool routed = false;         // part of the committed list (batches are indexed by it)
  Outbox outbox;
};

// One batch in flight: the reply being assembled, part by part (this node's own task, then
// one part per routed child).
struct BatchJoin {
  BatchReply reply;
  std::vector<bool> part_done;
  size_t left = 0;
  std::function<void(BatchReply&&)> done;

  void finish_part(size_t part) {
    if (part_done[part]) return;
    part_done[part] = true;
    if (--left == 0 && done) {
      auto d = std::move(done);
      done = nullptr;
      d(std::move(reply));
    }
  }
};

class Router {
 public:
  using LocalRender = std::function<void(const RenderTask&, std::function<void(TileResult&&)>)>;

  std::optional<NodeInfo> self_node;  // set when this node renders
  std::vector<RouterChild> children;
  bool changed = false;               // membership changed since the last commit
  PacketLayout layout;
  std::function<void(Event)> log;
  uint32_t keepalive_ms = 1000;       // how often keepalive() is called (told to the workers opened)

  // The committed flattened list: this node first (if it renders), then each routed child's.
  std::vector<NodeInfo> list() const {
    std::vector<NodeInfo> out;
    if (self_node) out.push_back(*self_node);
    for (auto& c : children)
      if (c.routed) out.insert(out.end(), c.nodes.begin(), c.nodes.end());
    return out;
  }
  bool committing() const { return committing_; }
  size_t alive_children() const {
    size_t n = 0;
    for (auto& c : children) n += c.alive;
    return n;
  }

  // A child's worker is down (down message) or failed a request: its outstanding tasks
  // fail now, it leaves at the next commit.
  void child_failed(const caf::actor_addr& who, const std::string& why) {
    for (auto& c : children)
      if (c.alive && c.worker.address() == who) {
        mark_dead(c, why);  // may run batch callbacks that change `children`: stop here
        return;
      }
  }

  // Sends encoded scene records to every live child (routed or joining), in chunks behind
  // what is already queued for it (Outbox).
  template <class Self>
  void forward(Self* self, const std::vector<uint8_t>& records, bool reset) {
    std::shared_ptr<const std::vector<uint8_t>> data;
    for (auto& c : children)
      if (c.alive) {
        if (!data) data = std::make_shared<const std::vector<uint8_t>>(records);
        enqueue_update(self, c, data, reset);
      }
  }

  // Tells every live child that its parent is alive (an empty update, as the adoption notice):
  // called every keepalive_ms. A worker that hears nothing from its parent for
  // NodeSettings::keepalive_misses periods ends itself (cluster.cpp).
  template <class Self>
  void keepalive(Self* self) {
    for (auto& c : children)
      if (c.alive) self->send(c.worker, update_atom::value, Payload{}, false);
  }

  // Splits a batch indexed by list() between the local renderer and the children.
  template <class Self>
  void dispatch(Self* self, const RenderBatch& b, const LocalRender& local, std::function<void(BatchReply&&)> done) {
    auto join = std::make_shared<BatchJoin>();
    join->done = std::move(done);
    join->reply.tiles.resize(b.tasks.size());
    for (size_t i = 0; i < b.tasks.size(); ++i) {
      join->reply.tiles[i].frame = b.frame;
      join->reply.tiles[i].pixels = b.tasks[i];
    }
    const std::vector<NodeInfo> nodes = list();
    if (b.tasks.size() != nodes.size()) {
      for (auto& t : join->reply.tiles)
        t.error = "batch of " + std::to_string(b.tasks.size()) + " tasks for a sub-tree of " +
                  std::to_string(nodes.size()) + " nodes";
      join->reply.changed = true;
      auto d = std::move(join->done);
      d(std::move(join->reply));
      return;
    }
    // Parts: [own task] + one per routed child.
    size_t parts = (self_node ? 1 : 0);
    for (auto& c : children) parts += c.routed;
    join->part_done.assign(parts + 1, false);  // +1: this call's own guard part
    join->left = parts + 1;
    size_t part = 0, at = 0;
    if (self_node) {
      const size_t my_part = part++;
      const size_t my_at = at++;
      if (b.tasks[my_at].empty()) {
        join->finish_part(my_part);
      } else {
        local(task_of(b, b.tasks[my_at]), [join, my_part, my_at](TileResult&& r) {
          if (join->part_done[my_part]) return;
          if (r.pixels.empty() && r.error.empty()) r.pixels = join->reply.tiles[my_at].pixels;
          join->reply.tiles[my_at] = std::move(r);
          join->finish_part(my_part);
        });
      }
    }
    for (auto& c : children) {
      if (!c.routed) continue;
      const size_t my_part = part++;
      const size_t begin = at, count = c.nodes.size();
      at += count;
      RenderBatch sub = b;
      sub.tasks.assign(b.tasks.begin() + long(begin), b.tasks.begin() + long(begin + count));
      // Children below answer earlier than we must, so a late grandchild fails at its own
      // parent and the healthy tiles of that sub-tree still arrive in time.
      sub.timeout_ms = std::max<uint32_t>(50, b.timeout_ms * 4 / 5);
      bool any = false;
      for (auto& r : sub.tasks) any |= !r.empty();
      if (!c.alive) {
        fail_range(*join, begin, count, "node " + c.name + " is down");
        join->finish_part(my_part);
        continue;
      }
      if (!any) {
        join->finish_part(my_part);
        continue;
      }
      auto& out = outstanding_of(c);
      out.erase(std::remove_if(out.begin(), out.end(),
                               [](const Outstanding& o) {
                                 auto j = o.join.lock();
                                 return !j || j->part_done[o.part];
                               }),
                out.end());
      out.push_back({join, my_part, begin, count});
      const std::string name = c.name;
      const caf::actor_addr addr = c.worker.address();
      const worker_actor worker = c.worker;
      // The batch goes after the updates queued for this child (the worker renders the scene
      // as of the frame); its timeout runs from when it is sent.
      auto send = [=, sub = std::move(sub)]() mutable {
      self->request(worker, std::chrono::milliseconds(b.timeout_ms), render_atom::value, std::move(sub))
          .then(
              [=](BatchReply& r) {
                if (join->part_done[my_part]) return;
                if (r.changed) changed = true;
                if (r.tiles.size() != count) {
                  log_bad(name, "returned " + std::to_string(r.tiles.size()) + " tiles for " +
                                    std::to_string(count) + " tasks");
                  fail_range(*join, begin, count, "node " + name + " returned a malformed batch");
                } else {
                  for (size_t i = 0; i < count; ++i) {
                    TileResult& t = r.tiles[i];
                    const Rect want = join->reply.tiles[begin + i].pixels;
                    if (t.error.empty()) {
                      std::string bad = check_tile(t, b.frame, want, layout, b.width, b.height);
                      if (!bad.empty()) {
                        log_bad(name, bad);
                        t = TileResult{};
                        t.error = "node " + name + " sent an impossible tile: " + bad;
                      }
                    }
                    t.frame = b.frame;
                    t.pixels = want;
                    join->reply.tiles[begin + i] = std::move(t);
                  }
                }
                join->finish_part(my_part);
              },
              [=](caf::error& e) {
                child_failed(addr, to_string(e));
                if (join->part_done[my_part]) return;
                fail_range(*join, begin, count, "node " + name + ": " + to_string(e));
                join->finish_part(my_part);
              });
      };
      if (c.outbox.items.empty()) {
        send();
      } else {
        Outbox::Item item;
        item.send = std::move(send);
        c.outbox.items.push_back(std::move(item));
      }
    }
    join->reply.changed = changed;
    join->finish_part(parts);  // the guard: done runs once, after every part was started
  }

  // Commits membership: dead children leave, joined children enter, and every live child
  // commits its own sub-tree; `done` gets the new flattened list. Waits for a commit in
  // flight, and with wait_joins for the joins in flight too (the first list of a session or
  // worker should have its children). Later commits must not: a child that is cut off but
  // still connected has a join in flight almost always (each lasting the timeout, retried
  // every reconnect period), so every frame would wait for it. A join that completes sets
  // `changed`, and the next commit takes it in.
  template <class Self>
  void commit(Self* self, uint32_t timeout_ms, std::function<void(std::vector<NodeInfo>)> done,
              bool wait_joins = true) {
    if (committing_ || (wait_joins && opening_ > 0)) {
      after_.push_back([=] { commit(self, timeout_ms, done, wait_joins); });
      return;
    }
    std::vector<RouterChild> keep;
    for (auto& c : children) {
      if (c.alive) keep.push_back(std::move(c));
      else self->send_exit(c.worker, caf::exit_reason::user_shutdown);  // a zombie must not render on
    }
    children = std::move(keep);
    changed = false;
    if (children.empty()) {
      done(list());
      return;
    }
    committing_ = true;
    auto left = std::make_shared<size_t>(children.size());
    auto finish = [=] {
      if (--*left > 0) return;
      committing_ = false;
      std::vector<RouterChild> alive;
      for (auto& c : children)
        if (c.alive) alive.push_back(std::move(c));
      children = std::move(alive);
      done(list());
      run_after();
    };
    for (auto& c : children) {
      const caf::actor_addr addr = c.worker.address();
      self->request(c.worker, std::chrono::milliseconds(timeout_ms), nodes_atom::value)
          .then(
              [=](std::vector<NodeInfo>& nodes) {
                if (std::string bad = check_nodes(nodes); !bad.empty()) {
                  child_failed(addr, "impossible node list: " + bad);
                  finish();
                  return;
                }
                for (auto& x : children)
                  if (x.worker.address() == addr) {
                    x.nodes = std::move(nodes);
                    x.routed = x.alive;
                  }
                finish();
              },
              [=](caf::error& e) {
                child_failed(addr, "nodes query: " + to_string(e));
                finish();
              });
    }
  }

  // Opens workers on the children that `node` is connected to and this router does not
  // have yet; each new one gets the whole scene (snapshot()) and enters at the next commit.
  template <class Self>
  void join_children(Self* self, const node_actor& node, const OpenRequest& req, uint32_t timeout_ms,
                     std::function<std::vector<std::pair<std::vector<uint8_t>, bool>>()> snapshot) {
    if (!node) return;
    OpenRequest open = req;
    open.timeout_ms = timeout_ms;  // a worker opened later than that is an orphan (cluster.cpp)
    open.keepalive_ms = keepalive_ms;
    ++opening_;
    self->request(node, std::chrono::milliseconds(timeout_ms), links_atom::value)
        .then(
            [=](std::vector<ChildLink>& links) {
              for (auto& l : links) {
                bool have = joining_.count(l.name) > 0;
                for (auto& c : children) have |= c.alive && c.name == l.name;
                if (have || !l.node) continue;
                joining_.insert(l.name);
                ++opening_;
                const std::string name = l.name;
                self->request(caf::actor_cast<node_actor>(l.node), std::chrono::milliseconds(timeout_ms),
                              open_atom::value, open)
                    .then(
                        [=](OpenReply& r) {
                          joining_.erase(name);
                          auto w = caf::actor_cast<worker_actor>(r.worker);
                          if (w) {
                            self->monitor(w);
                            // First an empty update, the worker's sign that it was adopted: it
                            // arrives at once, however long the scene takes (cluster.cpp).
                            self->send(w, update_atom::value, Payload{}, false);
                            RouterChild c;
                            c.name = name;
                            c.worker = w;
                            c.nodes = std::move(r.nodes);
                            children.push_back(std::move(c));
                            for (auto& [bytes, reset] : snapshot())
                              enqueue_update(self, children.back(),
                                             std::make_shared<const std::vector<uint8_t>>(std::move(bytes)), reset);
                            changed = true;
                            if (log) log(Event(Ev::joined, name).with("nodes", nodes_value(children.back().nodes)));
                          }
                          opened();
                        },
                        [=](caf::error& e) {
                          joining_.erase(name);
                          if (log) log(Event(Ev::join_failed, name).with("reason", to_string(e)));
                          opened();
                        });
              }
              opened();
            },
            [=](caf::error&) { opened(); });
  }

 private:
  template <class Self>
  void enqueue_update(Self* self, RouterChild& c, std::shared_ptr<const std::vector<uint8_t>> data, bool reset) {
    Outbox::Item item;
    item.update = std::move(data);
    item.reset = reset;
    c.outbox.items.push_back(std::move(item));
    pump(self, c);
  }

  // Sends what the child's window allows: chunks of the update at the head, and the batches
  // queued behind an update once all of it has been sent. An acknowledgement opens the window
  // again; an error fails the child.
  template <class Self>
  void pump(Self* self, RouterChild& c) {
    Outbox& box = c.outbox;
    while (!box.items.empty()) {
      Outbox::Item& it = box.items.front();
      if (!it.update) {
        auto send = std::move(it.send);
        box.items.pop_front();
        send();
        continue;
      }
      const size_t size = it.update->size();
      if (it.offset == 0 && box.in_flight() + size <= kUpdateChunkBytes) {
        self->send(c.worker, update_atom::value, Payload{*it.update}, it.reset);
        box.sent += size;
        box.items.pop_front();
        continue;
      }
      if (box.in_flight() >= kUpdateWindowBytes) return;
      const size_t n = std::min(kUpdateChunkBytes, size - it.offset);
      Payload chunk;
      chunk.bytes.assign(it.update->begin() + long(it.offset), it.update->begin() + long(it.offset + n));
      it.offset += n;
      const bool last = it.offset == it.update->size();
      const bool reset = it.reset;
      if (last) box.items.pop_front();
      box.sent += n;
      const uint64_t mark = box.sent;
      const caf::actor_addr addr = c.worker.address();
      self->request(c.worker, caf::infinite, update_atom::value, std::move(chunk), reset, last)
          .then(
              [=](uint64_t) {
                for (auto& x : children)
                  if (x.alive && x.worker.address() == addr) {
                    x.outbox.acked = std::max(x.outbox.acked, mark);
                    pump(self, x);
                    return;
                  }
              },
              [=](caf::error& e) { child_failed(addr, "scene update: " + to_string(e)); });
    }
  }

  struct Outstanding {
    std::weak_ptr<BatchJoin> join;
    size_t part, begin, count;
  };
  void fail_range(BatchJoin& j, size_t begin, size_t count, const std::string& why) {
    for (size_t i = begin; i < begin + count; ++i) {
      TileResult& t = j.reply.tiles[i];
      t.rgba.clear();
      t.sat.clear();
      if (t.error.empty()) t.error = why;
    }
  }
  void mark_dead(RouterChild& c, const std::string& why) {
    c.alive = false;
    changed = true;
    c.outbox = Outbox{};  // its queued batches are failed below, through outstanding_
    const std::string name = c.name;
    auto it = outstanding_.find(c.worker.address());
    std::vector<Outstanding> outs;
    if (it != outstanding_.end()) {
      outs = std::move(it->second);
      outstanding_.erase(it);
    }
    if (log) log(Event(Ev::node_lost, name).with("reason", why));
    for (auto& o : outs) {
      auto j = o.join.lock();
      if (!j || j->part_done[o.part]) continue;
      fail_range(*j, o.begin, o.count, "node " + name + " is down: " + why);
      j->reply.changed = true;
      j->finish_part(o.part);
    }
  }
  void log_bad(const std::string& name, const std::string& what) {
    if (log) log(Event(Ev::rejected_tile, name).with("reason", what));
  }
  void opened() {
    if (--opening_ == 0) run_after();
  }
  // Runs what waited for the router to be idle (a commit that waits for joins defers itself
  // again while joins are in flight).
  void run_after() {
    if (committing_) return;
    auto a = std::move(after_);
    after_.clear();
    for (auto& f : a) f();
  }
  std::vector<Outstanding>& outstanding_of(RouterChild& c) { return outstanding_[c.worker.address()]; }

  size_t opening_ = 0;
  bool committing_ = false;
  std::set<std::string> joining_;
  std::vector<std::function<void()>> after_;
  std::map<caf::actor_addr, std::vector<Outstanding>> outstanding_;
};

}  // namespace tessera
