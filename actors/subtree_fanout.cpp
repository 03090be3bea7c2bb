// A subtree's children (subtree_state.h): scene updates down in windows, batches out and
// tiles in, membership. Fan-out and fan-in are CAF requests; a batch's reply is a response
// promise held in its Join until every part is in; the children's timeouts are the requests'.
#include <algorithm>
#include <chrono>

#include "actors/checks.h"
#include "actors/errors.h"
#include "actors/subtree_state.h"

namespace tessera {

using protocol::ErrorCode;

namespace {

SubtreeChild* find_child(subtree_state& st, const caf::actor_addr& who) {
  for (auto& c : st.children)
    if (c.alive && c.actor.address() == who) return &c;
  return nullptr;
}

// The tiles of part `p` failed with `code` (those that have not failed already).
void fail_part(Join& j, const Join::Part& p, ErrorCode code, const std::string& why) {
  for (size_t i = p.begin; i < p.begin + p.count; ++i) {
    TileResult& t = j.reply.tiles[i];
    t.rgba.clear();
    t.sat.clear();
    if (!t.failed()) t.code = code, t.error = why;
  }
}

void send_batch(subtree_ptr self, SubtreeChild& c, uint64_t id, size_t part);

// Sends what the child's window allows: chunks of the update at the head, and the batches
// queued behind an update once all of it has been sent. An acknowledgement opens the window
// again; an error fails the child.
void pump(subtree_ptr self, SubtreeChild& c) {
  Outbox& box = c.outbox;
  while (!box.items.empty()) {
    Outbox::Item& it = box.items.front();
    if (!it.update) {
      const uint64_t id = it.join;
      const size_t part = it.part;
      box.items.pop_front();
      send_batch(self, c, id, part);
      continue;
    }
    const size_t size = it.update->size();
    if (it.offset == 0 && box.in_flight() + size <= kUpdateChunkBytes) {
      self->send(c.actor, update_atom::value, Payload{*it.update}, it.reset);
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
    const caf::actor_addr addr = c.actor.address();
    self->request(c.actor, caf::infinite, update_atom::value, std::move(chunk), reset, last)
        .then(
            [=](uint64_t) {
              if (SubtreeChild* x = find_child(self->state, addr)) {
                x->outbox.acked = std::max(x->outbox.acked, mark);
                pump(self, *x);
              }
            },
            [=](caf::error& e) { child_failed(self, addr, ErrorCode::node_lost, "scene update: " + to_string(e)); });
  }
}

void enqueue_update(subtree_ptr self, SubtreeChild& c, std::shared_ptr<const std::vector<uint8_t>> data, bool reset) {
  Outbox::Item item;
  item.update = std::move(data);
  item.reset = reset;
  c.outbox.items.push_back(std::move(item));
  pump(self, c);
}

// The child's part of batch `id` goes out; its timeout runs from now. What comes back is
// checked tile by tile against the tasks that were sent.
void send_batch(subtree_ptr self, SubtreeChild& c, uint64_t id, size_t part) {
  auto j = self->state.joins.find(id);
  if (j == self->state.joins.end() || j->second.parts[part].done) return;
  const Join::Part p = j->second.parts[part];
  const RenderBatch& b = j->second.batch;
  RenderBatch sub = b;
  sub.tasks.assign(b.tasks.begin() + long(p.begin), b.tasks.begin() + long(p.begin + p.count));
  // Children below answer earlier than we must, so a late grandchild fails at its own
  // parent and the healthy tiles of that sub-tree still arrive in time.
  sub.timeout_ms = std::max<uint32_t>(50, b.timeout_ms * 4 / 5);
  const caf::actor_addr addr = c.actor.address();
  self->request(c.actor, std::chrono::milliseconds(b.timeout_ms), render_atom::value, std::move(sub))
      .then(
          [=](BatchReply& r) {
            auto& st = self->state;
            auto j = st.joins.find(id);
            if (j == st.joins.end() || j->second.parts[part].done) return;
            Join& join = j->second;
            if (r.changed) st.changed = true;
            if (r.tiles.size() != p.count) {
              const std::string bad = "returned " + std::to_string(r.tiles.size()) + " tiles for " + std::to_string(p.count) + " tasks";
              subtree_log(self, Event(Ev::rejected_tile, p.name).with("reason", bad));
              fail_part(join, p, ErrorCode::bad_tile, "node " + p.name + " returned a malformed batch");
            } else {
              for (size_t i = 0; i < p.count; ++i) {
                TileResult& t = r.tiles[i];
                const Rect want = join.reply.tiles[p.begin + i].pixels;
                if (!t.failed()) {
                  const std::string bad = check_tile(t, join.batch.frame, want, {st.req.packet_w, st.req.packet_h},
                                                     join.batch.width, join.batch.height);
                  if (!bad.empty()) {
                    subtree_log(self, Event(Ev::rejected_tile, p.name).with("reason", bad));
                    t = TileResult{};
                    t.code = ErrorCode::bad_tile;
                    t.error = "node " + p.name + " sent an impossible tile: " + bad;
                  }
                } else if (t.code == ErrorCode::ok || uint16_t(t.code) > uint16_t(ErrorCode::no_node)) {
                  t.code = ErrorCode::bad_tile;  // a failure without a code of ours
                }
                t.frame = join.batch.frame;
                t.pixels = want;
                join.reply.tiles[p.begin + i] = std::move(t);
              }
            }
            finish_part(self, id, part);
          },
          [=](caf::error& e) {
            child_failed(self, addr, ErrorCode::node_lost, to_string(e));
            auto j = self->state.joins.find(id);
            if (j == self->state.joins.end() || j->second.parts[part].done) return;
            fail_part(j->second, p, ErrorCode::node_lost, "node " + p.name + ": " + to_string(e));
            finish_part(self, id, part);
          });
}

void run_waiting(subtree_ptr self) {
  auto& st = self->state;
  if (st.committing) return;
  auto waiting = std::move(st.waiting);
  st.waiting.clear();
  for (auto& [promise, wait_joins] : waiting) commit(self, std::move(promise), wait_joins);
}

void opened(subtree_ptr self) {
  if (--self->state.opening == 0) run_waiting(self);
}

}  // namespace

std::vector<NodeInfo> node_list(const subtree_state& st) {
  std::vector<NodeInfo> out;
  if (st.self_node) out.push_back(*st.self_node);
  for (auto& c : st.children)
    if (c.routed) out.insert(out.end(), c.nodes.begin(), c.nodes.end());
  return out;
}

void forward(subtree_ptr self, std::vector<uint8_t> records, bool reset) {
  std::shared_ptr<const std::vector<uint8_t>> data;
  for (auto& c : self->state.children)
    if (c.alive) {
      if (!data) data = std::make_shared<const std::vector<uint8_t>>(std::move(records));
      enqueue_update(self, c, data, reset);
    }
}

void keepalive(subtree_ptr self) {
  for (auto& c : self->state.children)
    if (c.alive) self->send(c.actor, update_atom::value, Payload{}, false);
}

void dispatch(subtree_ptr self, RenderBatch b, caf::typed_response_promise<BatchReply> promise) {
  auto& st = self->state;
  BatchReply reply;
  reply.tiles.resize(b.tasks.size());
  for (size_t i = 0; i < b.tasks.size(); ++i) {
    reply.tiles[i].frame = b.frame;
    reply.tiles[i].pixels = b.tasks[i];
  }
  const size_t nodes = node_list(st).size();
  if (b.tasks.size() != nodes) {
    for (auto& t : reply.tiles) {
      t.code = ErrorCode::bad_batch;
      t.error = "batch of " + std::to_string(b.tasks.size()) + " tasks for a sub-tree of " + std::to_string(nodes) + " nodes";
    }
    reply.changed = true;
    promise.deliver(std::move(reply));
    return;
  }
  const uint64_t id = st.next_join++;
  Join& j = st.joins[id];
  j.promise = std::move(promise);
  j.reply = std::move(reply);
  size_t at = 0;
  if (st.self_node) j.parts.push_back({caf::actor_addr{}, st.settings->name, at++, 1, false});
  for (auto& c : st.children)
    if (c.routed) {
      j.parts.push_back({c.actor.address(), c.name, at, c.nodes.size(), false});
      at += c.nodes.size();
    }
  j.batch = std::move(b);
  j.left = j.parts.size() + 1;  // +1: a guard, so the reply goes once every part was started
  for (size_t part = 0; part < j.parts.size(); ++part) {
    auto it = st.joins.find(id);  // a part that finished at once may have ended the join
    if (it == st.joins.end()) return;
    Join& join = it->second;
    const Join::Part p = join.parts[part];
    bool any = false;
    for (size_t i = p.begin; i < p.begin + p.count; ++i) any |= !join.batch.tasks[i].empty();
    if (!any) {
      finish_part(self, id, part);
      continue;
    }
    if (!p.child) {
      render_own(self, id, part, task_of(join.batch, join.batch.tasks[p.begin]));
      continue;
    }
    SubtreeChild* c = nullptr;
    for (auto& x : st.children)
      if (x.routed && x.actor.address() == p.child) c = &x;
    if (!c || !c->alive) {
      fail_part(join, p, ErrorCode::node_lost, "node " + p.name + " is down");
      finish_part(self, id, part);
      continue;
    }
    // The batch goes after the updates queued for this child (the worker renders the scene
    // as of the frame).
    if (c->outbox.items.empty()) {
      send_batch(self, *c, id, part);
    } else {
      Outbox::Item item;
      item.join = id;
      item.part = part;
      c->outbox.items.push_back(std::move(item));
    }
  }
  if (auto it = st.joins.find(id); it != st.joins.end()) {
    it->second.reply.changed = st.changed;
    finish_part(self, id, it->second.parts.size());  // the guard
  }
}

void finish_part(subtree_ptr self, uint64_t id, size_t part) {
  auto& st = self->state;
  auto it = st.joins.find(id);
  if (it == st.joins.end()) return;
  Join& j = it->second;
  if (part < j.parts.size()) {
    if (j.parts[part].done) return;
    j.parts[part].done = true;
  }
  if (--j.left > 0) return;
  auto promise = std::move(j.promise);
  auto reply = std::move(j.reply);
  st.joins.erase(it);
  promise.deliver(std::move(reply));
}

void child_failed(subtree_ptr self, const caf::actor_addr& who, ErrorCode code, const std::string& why) {
  auto& st = self->state;
  SubtreeChild* c = find_child(st, who);
  if (!c) return;
  c->alive = false;
  c->outbox = Outbox{};  // its queued batches fail below
  st.changed = true;
  const std::string name = c->name;
  subtree_log(self, Event(Ev::node_lost, name).with("reason", why));
  std::vector<std::pair<uint64_t, size_t>> parts;
  for (auto& [id, j] : st.joins)
    for (size_t k = 0; k < j.parts.size(); ++k)
      if (!j.parts[k].done && j.parts[k].child == who) parts.emplace_back(id, k);
  for (auto [id, k] : parts) {
    auto it = st.joins.find(id);
    if (it == st.joins.end()) continue;
    fail_part(it->second, it->second.parts[k], code, "node " + name + " is down: " + why);
    it->second.reply.changed = true;
    finish_part(self, id, k);
  }
}

// Dead children leave, joined children enter, and every live child commits its own sub-tree.
// Waits for a commit in flight, and with wait_joins for the joins in flight too. Later commits
// must not: a child that is cut off but still connected has a join in flight almost always
// (each lasting the timeout, retried every reconnect period), so every frame would wait for
// it. A join that completes sets `changed`, and the next commit takes it in.
void commit(subtree_ptr self, caf::typed_response_promise<std::vector<NodeInfo>> promise, bool wait_joins) {
  auto& st = self->state;
  if (st.committing || (wait_joins && st.opening > 0)) {
    st.waiting.emplace_back(std::move(promise), wait_joins);
    return;
  }
  std::vector<SubtreeChild> keep;
  for (auto& c : st.children) {
    if (c.alive) keep.push_back(std::move(c));
    else self->send_exit(c.actor, caf::exit_reason::user_shutdown);  // a zombie must not render on
  }
  st.children = std::move(keep);
  st.changed = false;
  st.committed = true;
  if (st.children.empty()) {
    promise.deliver(node_list(st));
    return;
  }
  st.committing = true;
  auto left = std::make_shared<size_t>(st.children.size());
  auto done = std::make_shared<caf::typed_response_promise<std::vector<NodeInfo>>>(std::move(promise));
  auto finish = [=] {
    if (--*left > 0) return;
    auto& st = self->state;
    st.committing = false;
    std::vector<SubtreeChild> alive;
    for (auto& c : st.children)
      if (c.alive) alive.push_back(std::move(c));
    st.children = std::move(alive);
    done->deliver(node_list(st));
    run_waiting(self);
  };
  for (auto& c : st.children) {
    const caf::actor_addr addr = c.actor.address();
    self->request(c.actor, std::chrono::milliseconds(st.settings->task_timeout_ms), nodes_atom::value)
        .then(
            [=](std::vector<NodeInfo>& nodes) {
              if (std::string bad = check_nodes(nodes); !bad.empty()) {
                child_failed(self, addr, ErrorCode::bad_tile, "impossible node list: " + bad);
              } else if (SubtreeChild* x = find_child(self->state, addr)) {
                x->nodes = std::move(nodes);
                x->routed = true;
              }
              finish();
            },
            [=](caf::error& e) {
              child_failed(self, addr, ErrorCode::node_lost, "nodes query: " + to_string(e));
              finish();
            });
  }
}

void join_children(subtree_ptr self) {
  auto& st = self->state;
  if (!st.node) return;
  OpenRequest open = st.req;
  open.master = st.settings->name;
  open.timeout_ms = st.settings->task_timeout_ms;  // a worker opened later than that is an orphan
  open.keepalive_ms = st.settings->reconnect_ms;   // this subtree's tick period
  const auto timeout = std::chrono::milliseconds(st.settings->task_timeout_ms);
  ++st.opening;
  self->request(st.node, timeout, links_atom::value)
      .then(
          [=](std::vector<ChildLink>& links) {
            auto& st = self->state;
            for (auto& l : links) {
              bool have = st.joining.count(l.name) > 0;
              for (auto& c : st.children) have |= c.alive && c.name == l.name;
              if (have || !l.node) continue;
              st.joining.insert(l.name);
              ++st.opening;
              const std::string name = l.name;
              self->request(caf::actor_cast<node_actor>(l.node), timeout, open_atom::value, open)
                  .then(
                      [=](OpenReply& r) {
                        auto w = caf::actor_cast<subtree_actor>(r.worker);
                        if (!w) {
                          self->state.joining.erase(name);
                          opened(self);
                          return;
                        }
                        self->monitor(w);
                        // First an empty update, the worker's sign that it was adopted: it
                        // arrives at once, however long the scene takes.
                        self->send(w, update_atom::value, Payload{}, false);
                        auto nodes = std::make_shared<std::vector<NodeInfo>>(std::move(r.nodes));
                        scene_snapshot(self, [=](std::vector<std::pair<std::vector<uint8_t>, bool>> snapshot) {
                          auto& st = self->state;
                          st.joining.erase(name);
                          SubtreeChild c;
                          c.name = name;
                          c.actor = w;
                          c.nodes = std::move(*nodes);
                          st.children.push_back(std::move(c));
                          for (auto& [bytes, reset] : snapshot)
                            enqueue_update(self, st.children.back(),
                                           std::make_shared<const std::vector<uint8_t>>(std::move(bytes)), reset);
                          st.changed = true;
                          subtree_log(self, Event(Ev::joined, name).with("nodes", nodes_value(st.children.back().nodes)));
                          opened(self);
                        });
                      },
                      [=](caf::error& e) {
                        self->state.joining.erase(name);
                        subtree_log(self, Event(Ev::join_failed, name).with("reason", to_string(e)));
                        opened(self);
                      });
            }
            opened(self);
          },
          [=](caf::error&) { opened(self); });
}

}  // namespace tessera
