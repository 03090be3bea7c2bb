// The node actor (cluster_protocol.h): connects to its children, opens workers for parents.
#include <chrono>
#include <map>
#include <utility>

#include <malloc.h>

#include <caf/all.hpp>
#include <caf/io/middleman.hpp>
#include <caf/io/middleman_actor.hpp>
#include <caf/openssl/manager.hpp>

#include "actors/checks.h"
#include "actors/node.h"

namespace tessera {

namespace {

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

// Asks a link's diagnosis (NodeSettings::diagnose_link) of a probe actor.
using diagnose_atom = caf::atom_constant<caf::atom("diagnose")>;

void node_event(node_ptr self, Event e) {
  e.scope = {{"node", self->state.settings->name}};
  node_log(*self->state.settings, std::move(e));
}

void connect_child(node_ptr self, size_t i) {
  auto& c = self->state.children[i];
  if (c.node || c.connecting || !self->system().has_middleman()) return;
  const bool tls = self->state.settings->cluster_tls;
  if (tls && !self->system().has_openssl_manager()) {
    if (!c.reported)
      node_event(self, Event(Ev::child_unreachable, c.name)
                           .with("reason", "mutual TLS is configured but CAF's OpenSSL module is not loaded"));
    c.reported = true;
    return;
  }
  c.connecting = true;
  // Over TLS: CAF's OpenSSL middleman actor (a scribe with an SSL session on the same BASP
  // broker); never the plain one, whose connection a TLS child would not answer.
  auto mm = tls ? self->system().openssl_manager().actor_handle() : self->system().middleman().actor_handle();
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
            const bool first = !c.reported;
            c.reported = true;
            Event unreachable = Event(Ev::child_unreachable, c.name).with("reason", self->system().render(e));
            auto diagnose = self->state.settings->diagnose_link;
            const bool cut = e == caf::sec::disconnect_during_handshake || e == caf::sec::cannot_connect_to_node;
            if (!first || !diagnose || !cut) {
              c.connecting = false;
              if (first) node_event(self, std::move(unreachable));
              return;
            }
            // CAF says only that its handshake was cut off (or, over TLS, that it could not
            // connect); the usual cause is TLS on one side and not the other, or another CA.
            // A TLS handshake of the node's own says which, on a thread of its own (once per
            // outage); the child counts as connecting until then.
            auto probe = self->system().spawn<caf::detached + caf::hidden>(
                [diagnose, host = c.host, port = c.port](caf::event_based_actor* a) -> caf::behavior {
                  return {[=](diagnose_atom) {
                    a->quit();
                    return diagnose(host, port);
                  }};
                });
            auto report = [=](const std::string& why) {
              self->state.children[i].connecting = false;
              Event e = unreachable;
              if (!why.empty()) e.with("tls", why);
              node_event(self, std::move(e));
            };
            self->request(probe, std::chrono::seconds(15), diagnose_atom::value)
                .then([=](std::string& why) { report(why); }, [=](caf::error&) { report(""); });
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
        } else {
          trim_heap_if_regrown();
        }
        self->delayed_send(self, std::chrono::milliseconds(st.settings->reconnect_ms), tick_atom::value);
      },
  };
}

}  // namespace

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
