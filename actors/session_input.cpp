// The session's input (session_state.h): what a client sends, admitted, decoded and applied.
#include <algorithm>
#include <string>

#include "actors/errors.h"
#include "actors/session_state.h"
#include "protocol/scene_records.h"

namespace tessera::session {

// "N errors ... not reported: more than 32 a second", as both kinds of reply say it.
static std::string unreported_text(uint32_t n, const char* which) {
  return std::to_string(n) + " errors " + which + "not reported: more than " +
         std::to_string(int(session_state::kErrorsPerSecond)) + " a second";
}

// Whether one more non-fatal error may be reported now (session_state::kErrorsPerSecond).
static bool take_error_token(session_state& st) {
  const int64_t now = steady_ns();
  if (st.error_tokens_ns > 0)
    st.error_tokens = std::min(session_state::kErrorBurst,
                               st.error_tokens + double(now - st.error_tokens_ns) * 1e-9 * session_state::kErrorsPerSecond);
  st.error_tokens_ns = now;
  if (st.error_tokens < 1) return false;
  st.error_tokens -= 1;
  return true;
}

// After a client message: errors of it (or of earlier ones) not reported are said in one reply
// when the rate allows, so that a client whose message had 65,536 bad records learns how many.
void report_unreported(self_ptr self) {
  auto& st = self->state;
  if (st.closed || st.unreported_errors == 0) return;
  if (!take_error_token(st)) {  // when the rate allows one more
    if (!st.unreported_due) {
      st.unreported_due = true;
      self->delayed_send(self, std::chrono::milliseconds(int(1000 / session_state::kErrorsPerSecond) + 1),
                         unreported_atom::value);
    }
    return;
  }
  ErrorReply r;
  r.code = ErrorCode::limit_exceeded;
  r.fatal = false;
  r.record = kNoRecord;
  r.message = unreported_text(st.unreported_errors, "were ");
  st.sink->send(encode(ServerRecord{r}));
  log(self, Event(Ev::error, to_string(r.code)).with("fatal", false).with("record", -1).with("message", r.message)
                .with("unreported", st.unreported_errors));
  st.unreported_errors = 0;
}

// Sends an error record; a fatal one ends the session (and closes the connection).
void fail(self_ptr self, const Error& e) {
  auto& st = self->state;
  if (st.closed) return;
  ErrorReply r = to_reply(e);
  st.errors++;
  if (!r.fatal && !take_error_token(st)) {  // the rate limit of session_state::kErrorsPerSecond
    st.unreported_errors++;
    return;
  }
  const uint32_t unreported = st.unreported_errors;
  if (unreported > 0) {
    r.message += " (" + unreported_text(unreported, "before this one were ") + ")";
    st.unreported_errors = 0;
  }
  st.sink->send(encode(ServerRecord{r}));
  Event ev(Ev::error, to_string(e.code));
  ev.with("fatal", r.fatal).with("record", e.record == kNoRecord ? -1 : int64_t(e.record)).with("message", e.message);
  if (unreported > 0) ev.with("unreported", unreported);
  log(self, std::move(ev));
  if (r.fatal) {
    st.closed = true;
    st.sink->close(e.message);
    self->quit(caf::exit_reason::user_shutdown);
  }
}

// The session's share of the node budget becomes what it holds now. Never more than it had
// reserved: every update grows the scene by at most the size its message declared.
void settle_budget(self_ptr self) {
  auto& st = self->state;
  st.share.set(scene_bytes(*st.scene) + st.cached_bytes.waiting_bytes() + st.acc_bytes);
}

static void flush_forward(self_ptr self);

// What makes a client's own scene, and may reuse the preloaded copy's ids: its entries.
static bool scene_content(const ClientRecord& r) {
  return std::holds_alternative<SetBuffer>(r) || std::holds_alternative<SetTexture>(r) ||
         std::holds_alternative<SetMaterial>(r) || std::holds_alternative<SetMesh>(r) ||
         std::holds_alternative<SetLight>(r) || std::holds_alternative<SetBufferRef>(r) ||
         std::holds_alternative<SetTextureRef>(r);
}

// A client that uploads its own scene never sees the preloaded one (docs/operations.md): when
// its first entry (buffer, texture, material, mesh, light) arrives after the copy was given (it asked for a frame
// before its scene was in), the copy goes, keeping the resolution and what camera and
// environment the client set. Otherwise its records would meet the copy's entries of the same
// ids: a mesh that comes before its buffers (references the node refused, uploaded after) was
// checked against the copy's buffers ("position buffer must be float3").
static void drop_preload(self_ptr self) {
  auto& st = self->state;
  st.showing_preload = false;
  Scene own;
  own.set_resolution(st.scene->width(), st.scene->height());
  if (st.client_camera) own.set_camera(st.scene->camera());
  if (st.client_environment) own.set_environment(st.scene->environment());
  *st.scene = std::move(own);
  flush_forward(self);  // what was accepted before goes down the tree first
  if (st.cluster) self->send(st.subtree, update_atom::value, Payload{scene_snapshot_bytes(SceneSnapshot{st.scene})}, true);
  log(self, Event(Ev::preloaded_scene, false).with("dropped", true));
}

static void apply_update(self_ptr self, ClientRecord&& rec, uint32_t index) {
  auto& st = self->state;
  if (st.showing_preload && scene_content(rec)) drop_preload(self);
  if (std::holds_alternative<SetCamera>(rec)) st.client_camera = true;
  if (std::holds_alternative<SetEnvironment>(rec)) st.client_environment = true;
  // Children get exactly the records this node accepted (encoded before apply moves them).
  std::vector<uint8_t> one;
  if (st.cluster) one = encode(rec);
  Status s = apply(*st.scene, std::move(rec), st.settings->limits);
  if (s && st.cluster) append_message(st.forward, std::move(one));
  if (!s) {
    Error e = s.error();
    e.record = index;
    fail(self, e);
  }
}

static void flush_forward(self_ptr self) {
  auto& st = self->state;
  if (st.forward.empty()) return;
  self->send(st.subtree, update_atom::value, Payload{std::move(st.forward)}, false);
  st.forward.clear();
}

void set_resolution(self_ptr self, int32_t w, int32_t h) {
  auto& st = self->state;
  if (st.scene->width() == w && st.scene->height() == h) return;
  apply_update(self, Resolution{w, h}, kNoRecord);
  flush_forward(self);
}

void apply_cached(self_ptr self) {
  auto& st = self->state;
  auto cached = std::move(st.cached);
  st.cached.clear();
  st.cached_bytes.clear();
  for (auto& r : cached) {
    if (st.closed) return;
    apply_update(self, std::move(r), kNoRecord);  // deferred: the record index is no longer meaningful
  }
  flush_forward(self);
  settle_budget(self);
}


// The node-wide budget, checked before anything is inflated or decoded: each buffer and
// texture the message declares is reserved from the budget; one that does not fit is
// refused (limit_exceeded, not fatal) and cut out of the message, the others go on. `kept`
// maps the indices of the message that remains to those of the client's. False: nothing is
// left to decode.
static bool admit_payloads(self_ptr self, std::vector<uint8_t>& bytes, std::vector<uint32_t>& kept) {
  auto& st = self->state;
  if (!st.settings->budget) return true;
  auto declared = declared_payloads(bytes.data(), bytes.size(), st.settings->limits);
  if (!declared) return true;  // bad framing: the decoder says why
  std::vector<uint32_t> drop;
  for (const DeclaredRecord& d : *declared) {
    if (d.bytes == 0 || st.share.reserve(d.bytes)) continue;
    drop.push_back(d.index);
    const MemoryBudget& b = *st.settings->budget;
    fail(self, Error{ErrorCode::limit_exceeded,
                     "record " + std::to_string(d.index) + ": its " +
                         std::to_string(d.bytes) + " bytes would exceed the node's memory budget (" +
                         std::to_string(b.used()) + " of " + std::to_string(b.limit()) +
                         " bytes in use by all clients); the update is dropped",
                     d.index});
  }
  if (drop.empty()) return true;
  if (drop.size() == declared->size()) return false;
  bytes = without_records(bytes.data(), bytes.size(), *declared, drop);
  for (const DeclaredRecord& d : *declared)
    if (!std::binary_search(drop.begin(), drop.end(), d.index)) kept.push_back(d.index);
  return true;
}

static void on_client_records(self_ptr self, std::vector<uint8_t>& bytes, const std::vector<uint32_t>& kept);

static bool is_reference(const ClientRecord& r) {
  return std::holds_alternative<SetBufferRef>(r) || std::holds_alternative<SetTextureRef>(r);
}

// References (docs/protocol.md, "References"): the node's AssetStore turns each buffer_ref and
// texture_ref of the message into a buffer or texture record, or refuses it (it stays a
// reference, and apply_records skips it). The client gets one reference record for each, all
// in one message, before anything of this message is applied: it sends what depends on a
// reference only after that answer. Loaded content counts against the node's memory budget as
// an upload does (admit_payloads could not: a reference declares no size).
//
// Loading (files, HTTP fetches, texture decoding) runs on a thread of its own: a slow origin
// must not hold one of CAF's few scheduler threads, which every session of the node shares.
// Meanwhile the session goes on with its frame; the client's later messages wait (st.held).
struct ReferenceJob {
  std::vector<ClientRecord> recs;
  std::vector<uint32_t> kept;
  std::vector<size_t> at;  // the references' positions in recs
  std::vector<Reference> answers;
  int64_t t0 = 0;
  AssetStats before;

  // Every reference refused with `why` (and skipped when the message is applied).
  void refuse_all(const std::string& why) {
    answers.clear();
    for (size_t i : at) {
      const bool buffer = std::holds_alternative<SetBufferRef>(recs[i]);
      const Id id = buffer ? std::get<SetBufferRef>(recs[i]).id : std::get<SetTextureRef>(recs[i]).id;
      answers.push_back(Reference{buffer ? RefKind::buffer : RefKind::texture, false, id, 0, why});
      recs[i] = SetBufferRef{};
    }
  }
};
using resolve_atom = caf::atom_constant<caf::atom("resolve")>;

static void apply_records(self_ptr self, std::vector<ClientRecord>& recs, const std::vector<uint32_t>& kept);

// Sends the answers (after the budget's say) and logs the `references` event.
static void answer_references(self_ptr self, ReferenceJob& job) {
  auto& st = self->state;
  uint64_t loaded = 0, bytes = 0;
  std::string first_refusal;
  for (size_t k = 0; k < job.at.size() && k < job.answers.size(); ++k) {
    Reference& a = job.answers[k];
    if (a.ok && st.settings->budget && !st.share.reserve(a.bytes)) {
      const MemoryBudget& b = *st.settings->budget;
      a.ok = false;
      a.message = std::string(a.what == RefKind::buffer ? "buffer " : "texture ") + std::to_string(a.id) + ": its " +
                  std::to_string(a.bytes) + " bytes would exceed the node's memory budget (" + std::to_string(b.used()) +
                  " of " + std::to_string(b.limit()) + " bytes in use by all clients)";
      a.bytes = 0;
      job.recs[job.at[k]] = SetBufferRef{};  // refused after all: skipped like the others
    }
    if (a.ok) loaded++, bytes += a.bytes;
    else if (first_refusal.empty()) first_refusal = a.message;
  }
  st.sink->send(encode(std::vector<ServerRecord>(job.answers.begin(), job.answers.end())));
  const AssetStats after = st.settings->assets ? st.settings->assets->stats() : AssetStats{};
  Event e(Ev::references, int64_t(job.at.size()));
  e.with("loaded", loaded).with("bytes", bytes).with("refused", uint64_t(job.at.size() - loaded))
      .with("cache_hits", after.hits - job.before.hits).with("cache_misses", after.misses - job.before.misses)
      .with("ms", Json::number(double(steady_ns() - job.t0) / 1e6));
  if (!first_refusal.empty()) e.with("first_refusal", first_refusal.substr(0, 512));
  log(self, std::move(e));
}

// What became of a message's references: it had none; they were answered and the message
// applied (a node that loads none); or they are loading, and the message is applied after.
enum class Refs { none, answered, loading };

static Refs start_references(self_ptr self, std::vector<ClientRecord>& recs, const std::vector<uint32_t>& kept) {
  auto& st = self->state;
  auto job = std::make_shared<ReferenceJob>();
  for (size_t i = 0; i < recs.size(); ++i)
    if (is_reference(recs[i])) job->at.push_back(i);
  if (job->at.empty()) return Refs::none;
  job->t0 = steady_ns();
  const std::shared_ptr<AssetStore> assets = st.settings->assets;
  if (!assets) {
    job->recs = std::move(recs);
    job->refuse_all("this node loads no references");
    answer_references(self, *job);
    apply_records(self, job->recs, kept);
    return Refs::answered;
  }
  job->before = assets->stats();
  job->recs = std::move(recs);
  job->kept = kept;
  st.resolving = true;
  const std::string origin = st.sink->node_origin();
  const protocol::Limits limits = st.settings->limits;
  auto load = [job, assets, origin, limits](caf::event_based_actor* a) -> caf::behavior {
    return {[=](resolve_atom) {
      a->quit();
      try {
        assets->resolve(job->recs, origin, limits, job->answers);
      } catch (const std::exception& e) {
        job->refuse_all(std::string("the node could not load the references: ") + e.what());
      }
      return true;
    }};
  };
  // Deterministic tests run every actor on the test scheduler.
  auto worker = st.settings->detached ? self->spawn<caf::detached + caf::hidden>(load) : self->spawn<caf::hidden>(load);
  auto done = [=] {
    auto& s = self->state;
    s.resolving = false;
    if (s.closed) return;
    answer_references(self, *job);
    apply_records(self, job->recs, job->kept);
    if (!s.closed) settle_budget(self);
    // The messages that waited, in order (one of them may start another wait).
    while (!s.held.empty() && !s.resolving && !s.closed) {
      std::vector<uint8_t> next = std::move(s.held.front());
      s.held.pop_front();
      s.held_bytes -= next.size();
      on_client(self, next);
    }
  };
  self->request(worker, caf::infinite, resolve_atom::value)
      .then([=](bool) { done(); },
            [=](caf::error&) {
              job->refuse_all("the node's reference loader ended");
              done();
            });
  return Refs::loading;
}

void on_client(self_ptr self, std::vector<uint8_t>& bytes) {
  auto& st = self->state;
  if (st.closed) return;
  if (st.resolving) {  // after the references being loaded, in order
    st.still.active = false;
    // Held messages are not admitted yet: bounded by one message's worth in all (a client waits
    // for the answers before it sends what depends on them; camera moves and render requests
    // are small). Beyond it a message is refused with its reason, not buffered without end.
    if (st.held_bytes + bytes.size() > st.settings->limits.max_message_bytes) {
      fail(self, Error{ErrorCode::limit_exceeded,
                       "message refused: more than " + std::to_string(st.settings->limits.max_message_bytes) +
                           " bytes of messages arrived while the session's references were loading",
                       kNoRecord});
      return;
    }
    st.held_bytes += bytes.size();
    st.held.push_back(std::move(bytes));
    return;
  }
  std::vector<uint32_t> kept;  // empty: every record of the message
  if (admit_payloads(self, bytes, kept)) on_client_records(self, bytes, kept);
  bytes = {};
  if (!st.closed && !st.resolving) settle_budget(self);  // gives back what was reserved and not kept
  report_unreported(self);
}

static void on_client_records(self_ptr self, std::vector<uint8_t>& bytes, const std::vector<uint32_t>& kept) {
  auto& st = self->state;
  auto original = [&](uint32_t i) { return i < kept.size() ? kept[i] : i; };
  auto res = decode_client(bytes.data(), bytes.size(), st.settings->limits);
  bytes = {};  // the decoded records own their data now
  if (!res) {
    Error e = res.error();
    if (e.record != kNoRecord) e.record = original(e.record);
    // Before the handshake, a message that does not decode cannot be one: the session ends.
    if (!st.handshake_done && e.code != ErrorCode::bad_handshake) {
      e.message = "the first message must be a valid handshake: " + std::string(to_string(e.code)) + ": " + e.message;
      e.code = ErrorCode::bad_handshake;
    }
    return fail(self, e);
  }
  auto& recs = res.value();
  if (Status order = check_session_order(st.handshake_done, recs); !order) return fail(self, order.error());
  st.still.active = false;  // the client has spoken: the still it saw is no longer refined
  if (start_references(self, recs, kept) == Refs::none) apply_records(self, recs, kept);
}

// The message's records in order: each applied, cached (a frame is in flight) or acted on.
static void apply_records(self_ptr self, std::vector<ClientRecord>& recs, const std::vector<uint32_t>& kept) {
  auto& st = self->state;
  auto original = [&](uint32_t i) { return i < kept.size() ? kept[i] : i; };
  for (uint32_t i = 0; i < recs.size() && !st.closed; ++i) {
    ClientRecord& rec = recs[i];
    if (is_reference(rec)) continue;  // refused, and answered
    if (auto* res = std::get_if<Resolution>(&rec)) st.full_w = res->width, st.full_h = res->height;
    if (auto* h = std::get_if<Handshake>(&rec)) {
      on_handshake(self, *h);
    } else if (auto* s = std::get_if<protocol::Settings>(&rec)) {
      st.render = *s;  // read when the next frame starts
    } else if (auto* rf = std::get_if<protocol::Refine>(&rec)) {
      st.refine = rf->samples;  // from the next requested frame on
    } else if (auto* v = std::get_if<protocol::Video>(&rec)) {
      // The H.264 display's bitrate and keyframe requests, from the next frame on.
      if (v->bitrate_kbps) st.video_kbps = v->bitrate_kbps;
      if (v->keyframe) st.keyframe_requests++;
    } else if (auto* b = std::get_if<protocol::Budget>(&rec)) {
      // The client's frame budget replaces the node's frame-budget-ms, from the next requested frame on.
      if (b->frame_ms > 0) st.budget.emplace(double(b->frame_ms)); else st.budget.reset();
    } else if (auto* rr = std::get_if<RenderRequest>(&rec)) {
      if (!st.in_flight) {
        start_frame(self, rr->frame);
      } else {
        if (st.pending) st.dropped++;  // the older request is merged into this one
        st.pending = rr->frame;
        // A still's sample nobody asked for would hold this frame back by a whole sample (a
        // full-resolution one after a scaled frame): it is abandoned, and this frame starts as
        // soon as its tasks have stopped.
        if (!st.frame_requested) self->send(st.frame, cancel_atom::value, st.seq);
      }
    } else if (st.in_flight) {
      // Waiting updates count against the client's byte limit now: one that would exceed it
      // is refused (as it would be when applied) instead of held until the frame ends.
      if (Status room = st.cached_bytes.admit(*st.scene, rec, st.settings->limits); !room) {
        Error e = room.error();
        e.record = original(i);
        fail(self, e);
        continue;
      }
      st.cached.push_back(std::move(rec));
    } else {
      apply_update(self, std::move(rec), original(i));
    }
  }
  flush_forward(self);
}


}  // namespace tessera::session
