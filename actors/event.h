#pragma once
// Typed log events. Every actor and the server report what happened as an Event: a kind
// (Ev), who reports it (its scope: a session, a node, a node's worker) and typed fields. The
// process's one logger actor writes each as one JSON line; to_json_line is the only place
// that turns events into text, so every string (names and messages from clients and peers
// included) is escaped one way (json_quote). Tests read the events themselves.
//
// A line is the scope, the kind with its value, then the fields, in the order they were
// added, e.g. {"node": "w1:7001", "session": 3, "node_lost": "w2:7002", "reason": "..."}.
// docs/operations.md lists the kinds.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <caf/typed_actor.hpp>
#include <caf/replies_to.hpp>
#include <caf/atom.hpp>
#include <caf/allowed_unsafe_message_type.hpp>

namespace tessera {

enum class Ev : uint8_t {
  // A session (actors/session_actor.cpp, frame_actor.cpp, display_actor.cpp): scope {"session": id}.
  opened, closed, handshake, error, nodes, preloaded_scene, recovering, cluster_frame, frame,
  // A subtree (actors/subtree*.cpp): a root with the session's scope, a worker with its own.
  joined, join_failed, node_lost, node_late, caught_up, rejected_tile,
  // A worker subtree (actors/subtree.cpp): scope {"node": name, "session": id}.
  update_failed, ended, bad_batch, orphaned,
  // The node actor (actors/node_actor.cpp): scope {"node": name}.
  child_connected, child_unreachable, child_lost, worker_opened, worker_closed, open_refused, heap_trimmed,
  // A cluster node at start (app/cmd_serve.cpp): scope {"node": name}; "mutual_tls" or "none".
  cluster_security,
  // The server (net/server.cpp): no scope.
  closed_slow_client, rejected, network_thread_error,
  // The server stopped reading a connection whose session had too many of its messages waiting.
  paused_reading,
  // A session: its still reached its refine target and rendering stopped.
  converged,
  // A session: a still's sample stopped early, its client having asked for a new frame.
  abandoned,
  // A session: the references of a client message, loaded or refused (update/asset_store.h).
  references,
  // The server's TLS certificate (net/server.cpp): no scope; "loaded" at start, "reloaded" or
  // "reload_failed" (SIGHUP, Server::reload_tls).
  tls_certificate,
};
// The kind's key in a JSON line ("node_lost").
const char* event_name(Ev kind);

// A JSON value built in code: null, bool, integer, number (written with fixed decimals),
// string, array or object (keys in insertion order).
class Json {
 public:
  enum class Type : uint8_t { null, boolean, integer, number, string, array, object };
  using Members = std::vector<std::pair<std::string, Json>>;

  Json() = default;
  Json(bool b) : type_(Type::boolean), i_(b) {}
  Json(int v) : type_(Type::integer), i_(v) {}
  Json(long v) : type_(Type::integer), i_(v) {}
  Json(long long v) : type_(Type::integer), i_(v) {}
  Json(unsigned v) : type_(Type::integer), i_(int64_t(v)) {}
  Json(unsigned long v) : type_(Type::integer), i_(int64_t(v)) {}
  Json(unsigned long long v) : type_(Type::integer), i_(int64_t(v)) {}
  Json(std::string s) : type_(Type::string), s_(std::move(s)) {}
  Json(const char* s) : type_(Type::string), s_(s) {}
  // A number with `decimals` digits after the point (3: milliseconds to the microsecond).
  // Not finite: written as null.
  static Json number(double v, int decimals = 3);
  static Json array(std::vector<Json> items);
  static Json object(Members members);

  Type type() const { return type_; }
  bool as_bool() const { return i_ != 0; }
  int64_t as_int() const { return i_; }
  double as_double() const { return type_ == Type::integer ? double(i_) : d_; }
  const std::string& as_string() const { return s_; }
  const std::vector<Json>& items() const { return items_; }
  const Members& members() const { return members_; }
  const Json* find(const std::string& key) const;  // an object's member, or nullptr

  void write(std::string& out) const;
  std::string dump() const;

  bool operator==(const Json& o) const;
  bool operator!=(const Json& o) const { return !(*this == o); }

 private:
  Type type_ = Type::null;
  int64_t i_ = 0;
  double d_ = 0;
  int decimals_ = 3;
  std::string s_;
  std::vector<Json> items_;
  Members members_;
};

struct Event {
  Ev kind = Ev::error;
  Json value;           // the kind's own value: "node_lost": "w2:7002"
  Json::Members scope;  // who reports it
  Json::Members fields; // what else

  Event() = default;
  Event(Ev k, Json v) : kind(k), value(std::move(v)) {}
  Event& with(std::string key, Json v) {
    fields.emplace_back(std::move(key), std::move(v));
    return *this;
  }
  // A field or a scope member by key (nullptr: none); tests read events with these.
  const Json* field(const std::string& key) const;
};

// The event as one JSON object on one line (no newline).
std::string to_json_line(const Event& e);

// Where a node's events go: NodeSettings::log (tests keep the events), else stderr.
using EventSink = std::function<void(const Event&)>;

using log_atom = caf::atom_constant<caf::atom("log")>;
using flush_atom = caf::atom_constant<caf::atom("flush")>;
// The process's logger: writes events in the order it receives them. flush answers once
// every event sent to it before has been written.
using logger_actor = caf::typed_actor<caf::reacts_to<log_atom, Event>, caf::replies_to<flush_atom>::with<bool>>;

}  // namespace tessera

// Events stay in their process (each node logs its own), so they have no wire format.
CAF_ALLOW_UNSAFE_MESSAGE_TYPE(tessera::Event)
