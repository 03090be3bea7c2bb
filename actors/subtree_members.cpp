// A subtree's membership (subtree_state.h): children that join, fail and are committed.
#include <chrono>

#include "actors/checks.h"
#include "actors/errors.h"
#include "actors/subtree_state.h"

namespace tessera {

using protocol::ErrorCode;

namespace {

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
