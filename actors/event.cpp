// Typed log events and the logger actor. See event.h.
#include "actors/event.h"

#include <cmath>
#include <cstdio>

#include <caf/all.hpp>

#include "actors/node.h"

namespace tessera {

const char* event_name(Ev kind) {
  switch (kind) {
    case Ev::opened: return "opened";
    case Ev::closed: return "closed";
    case Ev::handshake: return "handshake";
    case Ev::error: return "error";
    case Ev::nodes: return "nodes";
    case Ev::preloaded_scene: return "preloaded_scene";
    case Ev::recovering: return "recovering";
    case Ev::cluster_frame: return "cluster_frame";
    case Ev::frame: return "frame";
    case Ev::joined: return "joined";
    case Ev::join_failed: return "join_failed";
    case Ev::node_lost: return "node_lost";
    case Ev::node_late: return "node_late";
    case Ev::caught_up: return "caught_up";
    case Ev::rejected_tile: return "rejected_tile";
    case Ev::update_failed: return "update_failed";
    case Ev::ended: return "ended";
    case Ev::bad_batch: return "bad_batch";
    case Ev::orphaned: return "orphaned";
    case Ev::child_connected: return "child_connected";
    case Ev::child_unreachable: return "child_unreachable";
    case Ev::child_lost: return "child_lost";
    case Ev::worker_opened: return "worker_opened";
    case Ev::worker_closed: return "worker_closed";
    case Ev::open_refused: return "open_refused";
    case Ev::heap_trimmed: return "heap_trimmed";
    case Ev::cluster_security: return "cluster_security";
    case Ev::converged: return "converged";
    case Ev::abandoned: return "abandoned";
    case Ev::references: return "references";
    case Ev::tls_certificate: return "tls_certificate";
    case Ev::closed_slow_client: return "closed_slow_client";
    case Ev::rejected: return "rejected";
    case Ev::network_thread_error: return "network_thread_error";
    case Ev::paused_reading: return "paused_reading";
  }
  return "event";
}

Json Json::number(double v, int decimals) {
  Json j;
  if (!std::isfinite(v)) return j;  // null
  j.type_ = Type::number;
  j.d_ = v;
  j.decimals_ = decimals < 0 ? 0 : decimals > 9 ? 9 : decimals;
  return j;
}

Json Json::array(std::vector<Json> items) {
  Json j;
  j.type_ = Type::array;
  j.items_ = std::move(items);
  return j;
}

Json Json::object(Members members) {
  Json j;
  j.type_ = Type::object;
  j.members_ = std::move(members);
  return j;
}

const Json* Json::find(const std::string& key) const {
  for (auto& m : members_)
    if (m.first == key) return &m.second;
  return nullptr;
}

namespace {

void write_members(const Json::Members& ms, std::string& out, bool& first) {
  for (auto& m : ms) {
    if (!first) out += ", ";
    first = false;
    out += json_quote(m.first);
    out += ": ";
    m.second.write(out);
  }
}

}  // namespace

void Json::write(std::string& out) const {
  switch (type_) {
    case Type::null: out += "null"; break;
    case Type::boolean: out += i_ ? "true" : "false"; break;
    case Type::integer: out += std::to_string(i_); break;
    case Type::number: {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.*f", decimals_, d_);
      out += buf;
      break;
    }
    case Type::string: out += json_quote(s_); break;
    case Type::array: {
      out += '[';
      for (size_t i = 0; i < items_.size(); ++i) {
        if (i) out += ", ";
        items_[i].write(out);
      }
      out += ']';
      break;
    }
    case Type::object: {
      out += '{';
      bool first = true;
      write_members(members_, out, first);
      out += '}';
      break;
    }
  }
}

std::string Json::dump() const {
  std::string s;
  write(s);
  return s;
}

bool Json::operator==(const Json& o) const {
  if (type_ != o.type_) return false;
  switch (type_) {
    case Type::null: return true;
    case Type::boolean:
    case Type::integer: return i_ == o.i_;
    case Type::number: return d_ == o.d_;
    case Type::string: return s_ == o.s_;
    case Type::array: return items_ == o.items_;
    case Type::object: return members_ == o.members_;
  }
  return false;
}

const Json* Event::field(const std::string& key) const {
  for (auto* ms : {&scope, &fields})
    for (auto& m : *ms)
      if (m.first == key) return &m.second;
  return nullptr;
}

std::string to_json_line(const Event& e) {
  std::string out = "{";
  bool first = true;
  write_members(e.scope, out, first);
  write_members({{event_name(e.kind), e.value}}, out, first);
  write_members(e.fields, out, first);
  out += '}';
  return out;
}

namespace {

void write_event(const EventSink& sink, const Event& e) {
  if (sink) {
    sink(e);
  } else {
    const std::string line = to_json_line(e) + "\n";
    std::fwrite(line.data(), 1, line.size(), stderr);
  }
}

struct logger_state {
  EventSink sink;
  static inline const char* name = "tessera.logger";
};

logger_actor::behavior_type logger_impl(logger_actor::stateful_pointer<logger_state> self, EventSink sink) {
  self->state.sink = std::move(sink);
  return {
      [=](log_atom, const Event& e) { write_event(self->state.sink, e); },
      [=](flush_atom) { return true; },
  };
}

}  // namespace

logger_actor spawn_logger(caf::actor_system& sys, EventSink sink) {
  // Hidden: the logger outlives the actors whose events it writes, and a node waiting for its
  // actors to end (await_all_actors_done) does not wait for it.
  return sys.spawn<caf::hidden>(logger_impl, std::move(sink));
}

void flush_logger(caf::actor_system& sys, const logger_actor& logger) {
  if (!logger) return;
  caf::scoped_actor self{sys};
  self->request(logger, std::chrono::seconds(5), flush_atom::value).receive([](bool) {}, [](caf::error&) {});
}

void stop_logger(caf::actor_system& sys, logger_actor& logger) {
  if (!logger) return;
  {
    caf::scoped_actor self{sys};
    self->monitor(logger);
    self->send_exit(logger, caf::exit_reason::user_shutdown);
    self->receive([](const caf::down_msg&) {}, caf::after(std::chrono::seconds(5)) >> [] {});
  }
  logger = nullptr;
}

void node_log(const NodeSettings& settings, Event e) {
  if (auto logger = settings.logger.lock()) {
    caf::anon_send(caf::actor_cast<logger_actor>(logger), log_atom::value, std::move(e));
  } else {
    write_event(settings.log, e);
  }
}

}  // namespace tessera
