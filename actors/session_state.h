#pragma once
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
  std::vector<uint8_t> forward;      // accepted scene records not yet sent down the tree
  std::set<std::string> noted;       // the no_effect notices sent (each goes to the client once)
  std::pair<uint32_t, uint64_t> checked{0, 0};  // AO samples and environment version last checked for them
  static inline const char* name = "tessera.session";
};

using self_ptr = session_actor::stateful_pointer<session_state>;

// Reports an event with the session's scope.
void log(self_ptr self, Event e);
// Sends an error record; a fatal one ends the session (and closes the connection).
void fail(self_ptr self, const Error& e);
// The session's share of the node budget becomes what it holds now.
void settle_budget(self_ptr self);
// Applies what was cached during the frame, and sends the accepted records down the tree.
void apply_cached(self_ptr self);
// A message from the client: admitted against the node budget, decoded, and each record
// applied, cached (a frame is in flight) or acted on (handshake, settings, render request).
void on_client(self_ptr self, std::vector<uint8_t>& bytes);
// session_actor.cpp: the handshake (its reply waits for the tree's first commit) and frames.
void on_handshake(self_ptr self, const Handshake& h);
void start_frame(self_ptr self, uint32_t client_frame);

}  // namespace tessera::session
