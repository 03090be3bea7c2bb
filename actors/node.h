#pragma once
// A node's settings and the factories of its actors (single node: every actor of a
// session runs in this process).
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include <caf/actor_system.hpp>
#include <caf/actor_system_config.hpp>

#include "actors/client_sink.h"
#include "actors/display_protocol.h"
#include "actors/encoder_protocol.h"
#include "actors/renderer_protocol.h"
#include "actors/session_protocol.h"
#include "actors/tiler_protocol.h"
#include "net/protocol.h"
#include "renderer/tiler.h"

namespace tessera {

struct NodeSettings {
  protocol::Limits limits;
  NodeCoefficient coefficient;          // this node's renderer coefficient (tiler input)
  PacketLayout packet_layout{0, 0};     // {0, 0}: detect from the CPU
  int renderer = -1;                    // -1: each session's handshake chooses; else the protocol::RendererKind for all
  bool detached = true;                 // renderer and encoder on their own threads (false in deterministic tests)
  std::shared_ptr<const Scene> preload; // given to sessions whose scene has no meshes at their first frame
  std::string server_version = "tessera 0.1.0";
  // One line per event (JSON for per-frame figures); default: stderr. Called from actor threads.
  std::function<void(const std::string&)> log;
};

// Registers every message type of actors/messages.h (both sides of a remote link need it).
void register_message_types(caf::actor_system_config& cfg);

// Writes a log line through settings.log, or to stderr.
void node_log(const NodeSettings& settings, const std::string& line);

renderer_actor spawn_renderer(caf::actor_system& sys, PacketLayout layout, bool detached);
tiler_actor spawn_tiler(caf::actor_system& sys, std::vector<double> coefficients);
encoder_actor spawn_encoder(caf::actor_system& sys, bool detached);
display_actor spawn_display(caf::actor_system& sys, std::shared_ptr<ClientSink> sink, encoder_actor encoder,
                            std::shared_ptr<const NodeSettings> settings, uint64_t session_id);
// A session with its own renderer, tiler, encoder and display actors, all linked to it:
// when the session ends (client gone, fatal error, exit message), they end too.
session_actor spawn_session(caf::actor_system& sys, std::shared_ptr<ClientSink> sink,
                            std::shared_ptr<const NodeSettings> settings, uint64_t session_id);

}  // namespace tessera
