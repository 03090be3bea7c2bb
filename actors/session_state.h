#pragma once
#include <deque>
// The session (sync) actor's state and the functions on it, shared by session_actor.cpp (its
// behaviour, handshake and frames) and session_input.cpp (the client's messages: admission,
// decoding, applying or caching updates). Private to those two files.
#include <memory>
#include <optional>
#include <set>
#include <utility>
#include <string>
#include <vector>

#include <caf/all.hpp>

#include "actors/node.h"
#include "lb/frame_budget.h"
#include "protocol/protocol.h"
#include "update/scene_update.h"

namespace tessera::session {

using namespace protocol;

struct session_state {
  std::shared_ptr<ClientSink> sink;
  std::shared_ptr<const NodeSettings> settings;
  uint64_t id = 0;
  std::shared_ptr<Scene> scene = std::make_shared<Scene>();
  bool handshake_done = false;
  bool closed = false;
  bool preloaded = false;
  // The scene is the preloaded copy (maybe_preload), not yet replaced by the client's own: the
  // first entry the client's records bring (buffer, texture, material, mesh, light) drops it
  // (drop_preload).
  bool showing_preload = false;
  bool client_camera = false, client_environment = false;  // the client has set its own
  bool cluster = false;              // this process has a node actor: accepted records go down the tree
  Handshake hs;
  protocol::Settings render;
  PacketLayout layout;
  renderer_actor renderer;
  tiler_actor tiler;
  encoder_actor encoder;
  display_actor display;
  subtree_actor subtree;             // the root of the client's tree
  frame_actor frame;
  std::vector<ClientRecord> cached;  // scene updates that arrived while a frame was rendering
  PendingBytes cached_bytes;         // their buffers and textures count against max_client_bytes
  // This session's part of the node-wide budget (NodeSettings::budget): its scene's buffers
  // and textures plus what the cached updates hold, and, while a message is decoded, what it
  // declares.
  BudgetShare share;
  bool in_flight = false;            // the frame actor renders a frame: the scene is read-only
  std::optional<uint32_t> pending;   // the latest render request that arrived while rendering
  uint32_t seq = 0, dropped = 0, errors = 0;
  // Non-fatal error replies (and their log lines) are limited to kErrorBurst at once and
  // kErrorsPerSecond after (session::fail): a client's flood of bad records filled the log by
  // hundreds of MB and one message of 65,536 bad records got as many replies. The rest are
  // counted and said with the next one reported.
  static constexpr double kErrorBurst = 32, kErrorsPerSecond = 32;
  double error_tokens = kErrorBurst;
  int64_t error_tokens_ns = 0;  // when error_tokens was last filled up (steady_ns)
  uint32_t unreported_errors = 0;
  bool unreported_due = false;  // an unreported_atom is on its way
  std::vector<uint8_t> forward;      // accepted scene records not yet sent down the tree
  std::set<std::string> noted;       // the no_effect notices sent (each goes to the client once)
  // The progressive still (docs/protocol.md, "Refinement"): after a requested frame, while no
  // client message arrives, the session renders the still's next sample as soon as the last
  // one is rendered, up to its target; any client message ends it.
  std::optional<uint32_t> refine;    // the client's refine record (else NodeSettings::refine_samples)
  // The H.264 display (protocol record video): the client's bitrate (0: NodeSettings::video_kbps)
  // and the keyframes it has asked for so far (FrameMeta::keyframe_requests).
  uint32_t video_kbps = 0;
  uint32_t keyframe_requests = 0;
  struct Still {
    bool active = false;             // more samples are wanted
    uint32_t target = 0;             // samples per pixel it refines to
    uint32_t client_frame = 0;       // the requested frame it refines
    uint32_t seed = 0;               // that frame's sequence number: seeds every sample
    uint32_t samples = 0;            // samples (rounds, when refined adaptively) rendered so far
    bool more = false;               // the frame actor wants more: not converged (its answer)
    bool after_scaled = false;       // it follows a scaled interactive frame: sample 0 is still to come
  } still;
  // Interactive frames within NodeSettings::frame_budget_ms: the scale controller, the
  // client's own resolution (the scene's is the scaled one while an interactive frame renders),
  // and what the frame in flight is.
  std::optional<FrameBudget> budget;
  uint64_t frame_triangles = 0;                 // the scene's, when the frame in flight started
  std::optional<uint64_t> budget_triangles;     // the scene's when the budget last observed a frame
  int32_t full_w = 0, full_h = 0;
  double frame_scale = 1;            // of the frame in flight (1: it is a sample of the still)
  int frame_level = 0;               // of the frame in flight (FrameBudget::level; 0: the page's samples)
  // The frame in flight is below the still's resolution or samples (an interactive frame within
  // a budget), so it is no sample of the still.
  bool reduced_frame() const { return frame_scale < 1 || frame_level > 0; }
  bool frame_requested = false;      // the frame in flight answers a render request
  int64_t frame_t0_ns = 0;
  // The still's average in the frame actor (AdaptiveStill::bytes), counted in `share`.
  uint64_t acc_bytes = 0;
  std::pair<uint32_t, uint64_t> checked{0, 0};  // AO samples and environment version last checked for them
  // References being loaded on a thread of their own (session_input.cpp): the client's later
  // messages wait here, in order, until the answers are sent and the message applied.
  bool resolving = false;
  std::deque<std::vector<uint8_t>> held;
  uint64_t held_bytes = 0;                      // their sizes, at most Limits::max_message_bytes
  static inline const char* name = "tessera.session";
};

using self_ptr = session_actor::stateful_pointer<session_state>;

// Reports an event with the session's scope.
void log(self_ptr self, Event e);
// Sends an error record; a fatal one ends the session (and closes the connection).
void fail(self_ptr self, const Error& e);
// Says in one error reply how many errors the rate limit held back, when it allows one more.
void report_unreported(self_ptr self);
// The session's share of the node budget becomes what it holds now.
void settle_budget(self_ptr self);
// Applies what was cached during the frame, and sends the accepted records down the tree.
void apply_cached(self_ptr self);
// A message from the client: admitted against the node budget, decoded, and each record
// applied, cached (a frame is in flight) or acted on (handshake, settings, render request).
void on_client(self_ptr self, std::vector<uint8_t>& bytes);
// session_actor.cpp: the handshake (its reply waits for the tree's first commit) and frames.
void on_handshake(self_ptr self, const Handshake& h);
// Renders the next frames at w x h (a Resolution record applied here and sent down the tree).
void set_resolution(self_ptr self, int32_t w, int32_t h);
// A frame: the answer to a render request (a new still), or with `refine` the still's next sample.
void start_frame(self_ptr self, uint32_t client_frame, bool refine = false);

}  // namespace tessera::session
