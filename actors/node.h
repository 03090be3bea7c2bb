#pragma once
// A node's settings and the factories of its actors (single node: every actor of a
// session runs in this process).
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <caf/weak_intrusive_ptr.hpp>
#include <caf/actor_control_block.hpp>

#include <caf/actor_system.hpp>
#include <caf/actor_system_config.hpp>

#include "actors/client_sink.h"
#include "actors/cluster_protocol.h"
#include "actors/display_protocol.h"
#include "actors/encoder_protocol.h"
#include "actors/frame_protocol.h"
#include "actors/event.h"
#include "actors/renderer_protocol.h"
#include "actors/session_protocol.h"
#include "actors/subtree_protocol.h"
#include "actors/tiler_protocol.h"
#include "protocol/memory_budget.h"
#include "renderer/adaptive.h"
#include "renderer/denoise.h"
#include "renderer/sampling.h"
#include "update/asset_store.h"
#include "protocol/protocol.h"
#include "lb/tiler.h"

namespace tessera {

struct NodeSettings {
  protocol::Limits limits;
  NodeCoefficient coefficient;          // this node's renderer coefficient (tiler input)
  PacketLayout packet_layout{0, 0};     // {0, 0}: detect from the CPU
  int renderer = -1;                    // -1: each session's handshake chooses; else the protocol::RendererKind for all
  bool detached = true;                 // renderer and encoder on their own threads (false in deterministic tests)
  std::shared_ptr<const Scene> preload; // given to sessions whose scene has no meshes at their first frame
  std::string server_version = "tessera 0.1.0";
  // Where events go (actors/event.h). While the process's logger lives (spawn_logger; its
  // owner holds the only strong handle, so it ends before the actor system), actors send their
  // events to it and it calls `log`; otherwise node_log calls `log` on the caller's thread.
  // Default `log`: one JSON line per event on stderr.
  EventSink log;
  caf::weak_actor_ptr logger;
  // --- Cluster (cluster_protocol.h, docs/operations.md) ---
  bool render = true;                 // false: a hub or a dedicated master (renders only lost tiles)
  std::string name = "local";         // this node in node lists and log lines (host:cluster-port)
  std::vector<std::string> children;  // "host:port" of the child nodes' cluster endpoints
  uint32_t task_timeout_ms = 5000;    // a sub-tree that has not answered a frame's tasks by then is
                                      // failed (at least 3x the last frame's rendering time)
  uint32_t reconnect_ms = 1000;       // retry period for lost children; also the period of the
                                      // keep-alive a parent sends its children's workers
  uint32_t max_workers = 32;          // live workers on this node (every session of every parent);
                                      // further open requests are refused
  uint32_t keepalive_misses = 10;     // a worker whose parent was silent for this many of the
                                      // parent's keep-alive periods ends itself
  uint64_t max_update_bytes = kMaxPeerBytes;  // the largest scene update a worker reassembles
                                              // from its parent's chunks; a larger one breaks
                                              // its scene until a reset update replaces it
  caf::weak_actor_ptr node;           // this process's node actor (none: a single node)
  bool cluster_tls = false;           // children are reached over mutual TLS, through CAF's OpenSSL
                                      // module (the process loaded it; docs/operations.md)
  // Why CAF's handshake with the child at host:port was cut off, in words ("": not known): the
  // node logs it with child_unreachable. Blocking (a TLS handshake of its own): the node actor
  // calls it on a thread of its own. Set by tessera serve (app/cluster_tls.h); none: not asked.
  std::function<std::string(const std::string& host, uint16_t port)> diagnose_link;
  // --- Resource bounds (docs/operations.md, "Resource bounds") ---
  // Samples per pixel a still refines to after each requested frame, for a client that does
  // not say (protocol record refine); 0 or 1: no refinement.
  uint32_t refine_samples = 0;
  // AO rays per hit in each sample of a refining still after its requested frame
  // (renderer/sampling.h, kStillAoSamples); 0: the session's own count. A session with AO off
  // traces none.
  uint32_t still_ao_samples = sampling::kStillAoSamples;
  // A refining still on a scene with a sky and AO is denoised (renderer/denoise.h) while its
  // plain average's estimated PSNR is below this (dB); 0: never denoised.
  double denoise_below_db = kDenoiseBelowDb;
  // A refining still's rounds after its first samples render only the blocks where a sample
  // lowers the error most (renderer/adaptive.h), this share of a whole sample's cost each
  // (AdaptiveOptions::round_cost); 0: every pixel every round, up to the target.
  double adaptive_round = AdaptiveOptions{}.round_cost;
  // The H.264 display's bitrate (kbit/s) for a client that does not say (protocol record video).
  uint32_t video_kbps = 8000;
  // Interactive frames (requested while the view changes) are rendered at a scale that keeps
  // them within this many ms (lb/frame_budget.h); the still after them at full resolution.
  // 0: every frame at the client's resolution.
  uint32_t frame_budget_ms = 0;
  // The still after scaled interactive frames starts this many ms after the last of them, unless
  // a request comes first: while the user drags, its full-resolution sample would be abandoned
  // by the next request, and on a machine shared with the browser it would also take the cores
  // the browser needs to send that request (docs/results/web.md, "A drag"). 0: at once.
  uint32_t still_delay_ms = 50;
  // The balancer carries each frame's cost into the next frame's camera with the packets'
  // first-hit depths, which the workers then return with their tiles (lb/reproject.h,
  // docs/load-balancing.md). false: the paper's predictor, the previous frame's map as it is.
  bool reproject = true;
  uint32_t handshake_timeout_ms = 5000;  // a session without a valid handshake by then is closed
                                         // with a fatal bad_handshake (0: no timeout)
  std::shared_ptr<MemoryBudget> budget;  // node-wide: every session's scene bytes and the frames
                                         // queued for its client (none: only max_client_bytes)
  // References (docs/protocol.md, "References"): what this node loads itself, and its cache of
  // decoded textures shared by every session (none: every reference is refused).
  std::shared_ptr<AssetStore> assets;
  NodeInfo info() const { return NodeInfo{name, coefficient.logical_cores, coefficient.single_core_perf}; }
};

// Registers every message type of actors/messages.h (both sides of a remote link need it).
void register_message_types(caf::actor_system_config& cfg);

// Steady-clock nanoseconds: the time stamps of FrameMeta and EncodedFrame.
int64_t steady_ns();

// Reports an event: to settings.logger if there is one, else straight to settings.log.
void node_log(const NodeSettings& settings, Event e);
// The process's logger actor: writes the events it receives through `sink` (default stderr).
logger_actor spawn_logger(caf::actor_system& sys, EventSink sink);
// Waits until the logger has written every event sent to it before (at a node's shutdown).
void flush_logger(caf::actor_system& sys, const logger_actor& logger);
// Ends the logger and waits (up to 5 s) until it has: its sink goes with it, before the actor
// system does. Dropping the last handle alone leaves the hidden actor to be cleaned up by a
// scheduler that may already be stopping, and LeakSanitizer then reports its sink.
void stop_logger(caf::actor_system& sys, logger_actor& logger);

// Hands the heap that ended sessions and workers freed back to the OS (glibc keeps freed
// memory in its arenas: without this an idle node's RSS stays at its peak). Debounced: one
// trim about `delay_ms` after the last call, on a background thread of its own, so neither an
// actor nor the network thread waits for it. No-op where the C library has no malloc_trim.
void schedule_heap_trim(uint32_t delay_ms = 500);
// The node's tick calls this once a second: a trim is scheduled when the memory the process
// holds beyond its heap's live bytes grew by `regrow_bytes` since the last trim. What an ended
// session held is not all freed by the time of the trim its end scheduled: on a loaded
// machine its scene may still sit in a message to a child or in a worker that ends seconds
// later. Cheap (one read of /proc/self/statm and mallinfo2); false where glibc cannot say.
bool trim_heap_if_regrown(int64_t regrow_bytes = int64_t(16) << 20);
// A string as a JSON string literal, quotes included: '"', '\\' and control characters escaped,
// bytes that are not UTF-8 replaced by U+FFFD. Every string a client, a peer or an error
// message supplies goes into a log line through this, so no text can forge log lines.
std::string json_quote(const std::string& s);

// cancel: the frames its owner abandons (CancelMark); none: every task runs to its end.
renderer_actor spawn_renderer(caf::actor_system& sys, PacketLayout layout, bool detached,
                              std::shared_ptr<const CancelMark> cancel = nullptr);
tiler_actor spawn_tiler(caf::actor_system& sys, std::vector<double> coefficients);
encoder_actor spawn_encoder(caf::actor_system& sys, bool detached);
display_actor spawn_display(caf::actor_system& sys, std::shared_ptr<ClientSink> sink, encoder_actor encoder,
                            std::shared_ptr<const NodeSettings> settings, uint64_t session_id);
// The node actor of this process (cluster_protocol.h): connects to settings->children over
// CAF's middleman (when loaded; over its OpenSSL module when settings->cluster_tls), reconnects
// lost ones, and opens workers for sessions.
node_actor spawn_node(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings);
// A subtree (subtree_protocol.h). `parent` is watched: when it goes down the subtree ends.
// A root (source set) renders the session's scene on the session's renderer; a worker builds
// its scene from its parent's updates and spawns its own renderer when the node renders.
struct SubtreeSpec {
  OpenRequest req;               // session, master name, packet layout, the parent's timeout and keep-alive
  caf::strong_actor_ptr parent;
  renderer_actor renderer;       // none: its own, when settings->render
  scene_source_actor source;     // a root's scene owner: the session's sync actor
  std::shared_ptr<CancelMark> cancel;  // what `renderer` reads (none: its own renderer gets one)
};
subtree_actor spawn_subtree(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings, node_actor node,
                            SubtreeSpec spec);
// A worker of one session on this node's sub-tree (spawn_subtree without renderer or source).
subtree_actor spawn_worker(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings, node_actor node,
                           OpenRequest request, caf::strong_actor_ptr parent);
// The frame actor of a session (frame_protocol.h), linked to nothing: its spawner links it.
frame_actor spawn_frame(caf::actor_system& sys, std::shared_ptr<const NodeSettings> settings, uint64_t session_id,
                        PacketLayout layout, FrameActors actors);

// A session with its own renderer, tiler, encoder and display actors, all linked to it:
// when the session ends (client gone, fatal error, exit message), they end too.
session_actor spawn_session(caf::actor_system& sys, std::shared_ptr<ClientSink> sink,
                            std::shared_ptr<const NodeSettings> settings, uint64_t session_id);

}  // namespace tessera
