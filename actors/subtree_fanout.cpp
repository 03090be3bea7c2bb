// A subtree's children (subtree_state.h): scene updates down in windows, batches out and
// tiles in (membership: subtree_members.cpp). Fan-out and fan-in are CAF requests; a batch's reply is a response
// promise held in its Join until every part is in; the children's timeouts are the requests'.
#include <algorithm>
#include <chrono>

#include "actors/checks.h"
#include "actors/errors.h"
#include "actors/subtree_state.h"

namespace tessera {

using protocol::ErrorCode;

SubtreeChild* find_child(subtree_state& st, const caf::actor_addr& who) {
  for (auto& c : st.children)
    if (c.alive && c.actor.address() == who) return &c;
  return nullptr;
}

void fail_part(Join& j, const Join::Part& p, ErrorCode code, const std::string& why) {
  for (size_t i = p.begin; i < p.begin + p.count; ++i) {
    TileResult& t = j.reply.tiles[i];
    t.rgba.clear();
    t.sat.clear();
    if (!t.failed()) t.code = code, t.error = why;
  }
}

namespace {

void send_batch(subtree_ptr self, SubtreeChild& c, uint64_t id, size_t part);

// A late child that has answered every batch sent to it, with nothing queued for it, is on time
// again (updates sent and not yet taken come before any new batch: a worker takes its messages
// in order).
void check_caught_up(subtree_ptr self, SubtreeChild& c) {
  if (!c.late || c.outstanding > 0 || !c.outbox.items.empty()) return;
  c.late = false;
  subtree_log(self, Event(Ev::caught_up, c.name));
}

// Is a late child still there? It answers a ping unless it is hung or cut off (its renderer
// may be busy: the ping goes to its subtree actor). No answer within the task timeout: lost.
void ping(subtree_ptr self, SubtreeChild& c) {
  if (c.probing) return;
  c.probing = true;
  const caf::actor_addr addr = c.actor.address();
  const uint32_t ms = self->state.settings->task_timeout_ms;
  self->request(c.actor, std::chrono::milliseconds(ms), ping_atom::value)
      .then(
          [=](uint64_t) {
            if (SubtreeChild* x = find_child(self->state, addr)) x->probing = false;
          },
          [=](caf::error& e) {
            child_failed(self, addr, ErrorCode::node_lost,
                         "late, and no answer to a ping within " + std::to_string(ms) + " ms: " + to_string(e));
          });
}

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
                check_caught_up(self, *x);
              }
            },
            [=](caf::error& e) { child_failed(self, addr, ErrorCode::node_lost, "scene update: " + to_string(e)); });
  }
}

}  // namespace

void enqueue_update(subtree_ptr self, SubtreeChild& c, std::shared_ptr<const std::vector<uint8_t>> data, bool reset) {
  Outbox::Item item;
  item.update = std::move(data);
  item.reset = reset;
  c.outbox.items.push_back(std::move(item));
  pump(self, c);
}

namespace {

// The child's part of batch `id` goes out (its deadline runs from the dispatch: a batch that
// waits behind updates the child has not taken counts as late too). What comes back is checked
// tile by tile against the tasks that were sent; what comes back after the deadline is dropped.
void send_batch(subtree_ptr self, SubtreeChild& c, uint64_t id, size_t part) {
  auto j = self->state.joins.find(id);
  if (j == self->state.joins.end() || j->second.parts[part].done) return;
  const Join::Part p = j->second.parts[part];
  const RenderBatch& b = j->second.batch;
  RenderBatch sub = b;
  sub.tasks.assign(b.tasks.begin() + long(p.begin), b.tasks.begin() + long(p.begin + p.count));
  if (!b.plan.empty() && b.plan.size() == uint64_t(b.plan_blocks.area())) {  // the child gets the part of the plan its tasks need
    Rect need;
    for (const Rect& t : sub.tasks) {
      const Rect tb = intersect(b.plan_blocks, plan_blocks_of(t));
      if (tb.empty()) continue;
      need = need.empty() ? tb
                          : Rect{std::min(need.x0, tb.x0), std::min(need.y0, tb.y0), std::max(need.x1, tb.x1),
                                 std::max(need.y1, tb.y1)};
    }
    sub.plan = crop_plan(b.plan_blocks, b.plan, need);
    sub.plan_blocks = sub.plan.empty() ? Rect{} : need;
  }
  // Children below answer earlier than we must, so a late grandchild fails at its own
  // parent and the healthy tiles of that sub-tree still arrive in time.
  sub.timeout_ms = std::max<uint32_t>(50, b.timeout_ms * 4 / 5);
  const caf::actor_addr addr = c.actor.address();
  ++c.outstanding;
  self->request(c.actor, caf::infinite, render_atom::value, std::move(sub))
      .then(
          [=](BatchReply& r) {
            auto& st = self->state;
            if (SubtreeChild* x = find_child(st, addr)) {
              --x->outstanding;
              check_caught_up(self, *x);
            }
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
                                                     join.batch.width, join.batch.height, join.batch.radiance,
                                                     join.batch.guides);
                  if (!bad.empty()) {
                    subtree_log(self, Event(Ev::rejected_tile, p.name).with("reason", bad));
                    t = TileResult{};
                    t.code = ErrorCode::bad_tile;
                    t.error = "node " + p.name + " sent an impossible tile: " + bad;
                  }
                } else if (t.code == ErrorCode::ok || uint16_t(t.code) > uint16_t(ErrorCode::node_late)) {
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
  const size_t nodes = node_list(st).size();
  if (b.tasks.size() != nodes) {
    BatchReply reply = failed_batch(b, ErrorCode::bad_batch, "batch of " + std::to_string(b.tasks.size()) +
                                                                 " tasks for a sub-tree of " + std::to_string(nodes) + " nodes");
    reply.changed = true;
    promise.deliver(std::move(reply));
    return;
  }
  BatchReply reply;
  reply.tiles.resize(b.tasks.size());
  for (size_t i = 0; i < b.tasks.size(); ++i) {
    reply.tiles[i].frame = b.frame;
    reply.tiles[i].pixels = b.tasks[i];
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
    if (c->late) {
      fail_part(join, p, ErrorCode::node_late, "node " + p.name + " is still late with earlier work");
      finish_part(self, id, part);
      continue;
    }
    self->delayed_send(self, std::chrono::milliseconds(join.batch.timeout_ms), deadline_atom::value, id, uint64_t(part));
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

void part_deadline(subtree_ptr self, uint64_t id, size_t part) {
  auto& st = self->state;
  auto it = st.joins.find(id);
  if (it == st.joins.end() || part >= it->second.parts.size() || it->second.parts[part].done) return;
  Join& j = it->second;
  const Join::Part p = j.parts[part];
  fail_part(j, p, ErrorCode::node_late,
            "node " + p.name + " returned no tiles within " + std::to_string(j.batch.timeout_ms) + " ms");
  if (SubtreeChild* c = find_child(st, p.child); c && !c->late) {
    c->late = true;
    subtree_log(self, Event(Ev::node_late, c->name).with("frame", j.batch.frame).with("timeout_ms", j.batch.timeout_ms));
    ping(self, *c);
  }
  finish_part(self, id, part);
}

void probe_late(subtree_ptr self) {
  for (auto& c : self->state.children)
    if (c.alive && c.late) ping(self, c);
}

}  // namespace tessera
