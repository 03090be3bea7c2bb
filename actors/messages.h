#pragma once
// Message types and atoms shared by the actor protocols (renderer_protocol.h,
// tiler_protocol.h, encoder_protocol.h, display_protocol.h, session_protocol.h).
//
// Every type has an inspect overload and is registered by register_message_types (node.h),
// so each message can cross a process boundary: a child node will later be just another
// remote renderer actor. Pixels and SATs travel as byte vectors (STACK.md: element-wise
// serialisation of uint32 vectors is 60x slower).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <caf/atom.hpp>
#include <caf/binary_deserializer.hpp>
#include <caf/sec.hpp>
#include <caf/meta/type_name.hpp>
#include <caf/meta/load_callback.hpp>
#include <caf/actor.hpp>
#include <caf/error.hpp>

#include "core/rect.h"
#include "core/scene.h"
#include "protocol/protocol.h"

namespace tessera {

// Atoms (at most 10 characters).
using render_atom = caf::atom_constant<caf::atom("render")>;
using tasks_atom = caf::atom_constant<caf::atom("tasks")>;
using sats_atom = caf::atom_constant<caf::atom("sats")>;
using encode_atom = caf::atom_constant<caf::atom("encode")>;
using display_atom = caf::atom_constant<caf::atom("display")>;
using client_atom = caf::atom_constant<caf::atom("client")>;
using status_atom = caf::atom_constant<caf::atom("status")>;
using children_atom = caf::atom_constant<caf::atom("children")>;
using open_atom = caf::atom_constant<caf::atom("open")>;
using update_atom = caf::atom_constant<caf::atom("update")>;
using nodes_atom = caf::atom_constant<caf::atom("nodes")>;
using links_atom = caf::atom_constant<caf::atom("links")>;
using tick_atom = caf::atom_constant<caf::atom("tick")>;
using scene_atom = caf::atom_constant<caf::atom("scene")>;
using snapshot_atom = caf::atom_constant<caf::atom("snapshot")>;

// --- Byte vectors from other processes ----------------------------------------------------
//
// CAF 0.17 loads a byte vector by resizing it to the length its stream claims and only then
// reading the bytes (data_processor::apply_sequence), so a peer's 166-byte message claiming
// 2^32-1 bytes of tile pixels made a node allocate and zero 4 GiB (tests/fuzz: fuzz_cluster).
// Every byte-vector field of a message that can cross a process boundary goes through
// BytesField, which refuses a claimed length beyond what the stream still holds (a
// binary_deserializer, as CAF's middleman uses) before anything is allocated, or beyond
// kMaxPeerBytes where the deserializer cannot tell.
constexpr size_t kMaxPeerBytes = size_t(1) << 30;  // a scene snapshot of the largest client scene

struct BytesField {
  std::vector<uint8_t>& v;
};
template <class Inspector>
typename std::enable_if<Inspector::reads_state, typename Inspector::result_type>::type inspect(Inspector& f,
                                                                                               BytesField& x) {
  return f(x.v);
}
template <class Inspector>
typename std::enable_if<Inspector::writes_state, typename Inspector::result_type>::type inspect(Inspector& f,
                                                                                                BytesField& x) {
  size_t n = 0;
  if (auto err = f.begin_sequence(n)) return err;
  size_t left = kMaxPeerBytes;
  if (auto* bin = dynamic_cast<caf::binary_deserializer*>(&f)) left = std::min(left, bin->remaining());
  if (n > left) return caf::make_error(caf::sec::end_of_stream);
  x.v.resize(n);
  if (n > 0)
    if (auto err = f.apply_raw(n, x.v.data())) return err;
  return f.end_sequence();
}

// The encoded client-protocol records of a scene update sent down the tree (update_atom).
struct Payload {
  std::vector<uint8_t> bytes;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, Payload& x) {
  return f(caf::meta::type_name("tessera::payload"), BytesField{x.bytes});
}

template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, Rect& x) {
  return f(caf::meta::type_name("tessera::rect"), x.x0, x.y0, x.x1, x.y1);
}

// The scene a renderer renders, as of the start of a frame. In one process it is a shared,
// read-only pointer (the session changes its scene only between frames, so nothing is
// copied); serialised it becomes the client protocol's records (protocol/scene_records.h), so a
// remote renderer rebuilds the same scene.
struct SceneSnapshot {
  std::shared_ptr<const Scene> scene;
};
std::vector<uint8_t> scene_snapshot_bytes(const SceneSnapshot& s);
caf::error scene_snapshot_from_bytes(const std::vector<uint8_t>& bytes, SceneSnapshot& out);

template <class Inspector>
typename std::enable_if<Inspector::reads_state, typename Inspector::result_type>::type inspect(Inspector& f,
                                                                                               SceneSnapshot& x) {
  auto bytes = scene_snapshot_bytes(x);
  return f(caf::meta::type_name("tessera::scene_snapshot"), BytesField{bytes});
}
template <class Inspector>
typename std::enable_if<Inspector::writes_state, typename Inspector::result_type>::type inspect(Inspector& f,
                                                                                                SceneSnapshot& x) {
  std::vector<uint8_t> bytes;
  auto load = caf::meta::load_callback([&]() -> caf::error { return scene_snapshot_from_bytes(bytes, x); });
  return f(caf::meta::type_name("tessera::scene_snapshot"), BytesField{bytes}, load);
}

// One rendering task: a pixel rectangle of frame `frame` at width x height.
struct RenderTask {
  uint32_t frame = 0;  // the session's frame sequence number (not the client's)
  int32_t width = 0, height = 0;
  Rect pixels;
  int32_t ao_samples = 0;
  int32_t max_depth = 4;
  uint8_t renderer = 0;  // protocol::RendererKind: 0 ray tracer, 1 rasterizer
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, RenderTask& x) {
  return f(caf::meta::type_name("tessera::render_task"), x.frame, x.width, x.height, x.pixels, x.ao_samples,
           x.max_depth, x.renderer);
}

// What a rendering node returns for a task: RGBA pixels of the rectangle and the serialised
// SAT of its cost map (Sat wire format), plus its measurements.
struct TileResult {
  uint32_t frame = 0;
  Rect pixels;
  std::vector<uint8_t> rgba;  // pixels.width() * pixels.height() * 4
  std::vector<uint8_t> sat;   // Sat::serialize(); empty when no cost map was measured
  double kernel_ms = 0, rendering_ms = 0, sat_ms = 0;
  uint64_t rays = 0;
  protocol::ErrorCode code = protocol::ErrorCode::ok;  // not ok: the task failed (pixels are not valid)
  std::string error;                                   // why, when it failed
  bool failed() const { return code != protocol::ErrorCode::ok; }
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, TileResult& x) {
  return f(caf::meta::type_name("tessera::tile_result"), x.frame, x.pixels, BytesField{x.rgba}, BytesField{x.sat}, x.kernel_ms,
           x.rendering_ms, x.sat_ms, x.rays, x.code, x.error);
}

// Tiler: the task list for a frame, and the SATs of the previous one.
struct TaskRequest {
  uint32_t frame = 0;
  int32_t width = 0, height = 0;
  int32_t packet_w = 4, packet_h = 4;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, TaskRequest& x) {
  return f(caf::meta::type_name("tessera::task_request"), x.frame, x.width, x.height, x.packet_w, x.packet_h);
}
struct TaskList {
  uint32_t frame = 0;
  std::vector<Rect> tasks;  // pixel rectangles, one per rendering node (index = node)
  double tiling_ms = 0;
  bool from_sats = false;   // false: even split (first frame, or the size changed)
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, TaskList& x) {
  return f(caf::meta::type_name("tessera::task_list"), x.frame, x.tasks, x.tiling_ms, x.from_sats);
}
struct SatReport {
  uint32_t frame = 0;
  int32_t width = 0, height = 0;
  int32_t packet_w = 4, packet_h = 4;
  std::vector<std::vector<uint8_t>> sats;  // one serialised SAT per node (empty: missing)
  std::vector<double> perf;                // single-core performance of the node behind each SAT
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, SatReport& x) {
  return f(caf::meta::type_name("tessera::sat_report"), x.frame, x.width, x.height, x.packet_w, x.packet_h, x.sats,
           x.perf);
}

// Timestamps and figures of one frame as it moves down the pipeline. Times are steady-clock
// nanoseconds of the master node.
struct FrameMeta {
  uint32_t seq = 0;           // session frame sequence
  uint32_t client_frame = 0;  // the client's frame number (echoed in the Frame record)
  int32_t width = 0, height = 0;
  uint8_t display = 0;        // protocol::DisplayKind
  uint8_t quality = 85;
  double kernel_ms = 0, rendering_ms = 0, sat_ms = 0, tiling_ms = 0;
  int64_t render_start_ns = 0, render_end_ns = 0;
  uint32_t nodes = 1;
  // The session's figures as of the start of the frame, for the display channel's Stats record.
  uint32_t dropped = 0;       // render requests merged into a later frame so far
  uint64_t scene_bytes = 0;   // buffers + textures held for the client
  uint64_t triangles = 0;     // scene triangles (instances counted each time)
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, FrameMeta& x) {
  return f(caf::meta::type_name("tessera::frame_meta"), x.seq, x.client_frame, x.width, x.height, x.display,
           x.quality, x.kernel_ms, x.rendering_ms, x.sat_ms, x.tiling_ms, x.render_start_ns, x.render_end_ns, x.nodes,
           x.dropped, x.scene_bytes, x.triangles);
}

// Sync actor -> frame actor (frame_protocol.h): render one frame. `meta` has the session's
// figures as of the frame's start; `scene` is read-only until the frame actor answers.
struct FrameStart {
  FrameMeta meta;
  SceneSnapshot scene;
  int32_t ao_samples = 0, max_depth = 4;
  uint8_t renderer = 0;  // protocol::RendererKind
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, FrameStart& x) {
  return f(caf::meta::type_name("tessera::frame_start"), x.meta, x.scene, x.ao_samples, x.max_depth, x.renderer);
}

// Frame actor -> display channel: the tiles of one frame.
struct FrameTiles {
  FrameMeta meta;
  std::vector<TileResult> tiles;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, FrameTiles& x) {
  return f(caf::meta::type_name("tessera::frame_tiles"), x.meta, x.tiles);
}

// Display -> encoder: a composed image.
struct EncodeJob {
  FrameMeta meta;
  std::vector<uint8_t> rgba;  // width * height * 4
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, EncodeJob& x) {
  return f(caf::meta::type_name("tessera::encode_job"), x.meta, BytesField{x.rgba});
}
// Encoder -> display: the encoded frame. `message` starts with header_bytes of room for the
// protocol header (the display writes it when it knows the pipeline time) followed by the
// payload (JPEG file or DXT1 blocks).
struct EncodedFrame {
  FrameMeta meta;
  std::vector<uint8_t> message;
  uint32_t header_bytes = 0;
  double encode_ms = 0;
  int64_t encode_start_ns = 0, encode_end_ns = 0;
  std::string error;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, EncodedFrame& x) {
  return f(caf::meta::type_name("tessera::encoded_frame"), x.meta, BytesField{x.message}, x.header_bytes, x.encode_ms,
           x.encode_start_ns, x.encode_end_ns, x.error);
}

// --- Cluster (cluster_protocol.h) --------------------------------------------------------

// One rendering node of a sub-tree, as its parent sees it (paper 5.2: the master gets the
// flattened list of its sub-trees' rendering nodes).
struct NodeInfo {
  std::string name;            // "host:port" of its cluster endpoint, or "local"
  int32_t logical_cores = 1;   // renderer coefficient = logical_cores x single_core_perf
  double single_core_perf = 1;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, NodeInfo& x) {
  return f(caf::meta::type_name("tessera::node_info"), x.name, x.logical_cores, x.single_core_perf);
}

// The tasks of one frame for a sub-tree: tasks[i] is the pixel rectangle of entry i of the
// receiver's flattened node list (as last returned by its nodes query); empty: nothing.
struct RenderBatch {
  uint32_t frame = 0;
  int32_t width = 0, height = 0;
  int32_t ao_samples = 0, max_depth = 4;
  uint32_t timeout_ms = 5000;  // the sender gives up on this batch after this long
  std::vector<Rect> tasks;
  uint8_t renderer = 0;        // protocol::RendererKind of the session
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, RenderBatch& x) {
  return f(caf::meta::type_name("tessera::render_batch"), x.frame, x.width, x.height, x.ao_samples, x.max_depth,
           x.timeout_ms, x.tasks, x.renderer);
}
// tiles[i] answers tasks[i] (its code set when that node failed); changed: the sub-tree lost or
// gained nodes, so its parent should ask for the node list again before the next frame.
struct BatchReply {
  std::vector<TileResult> tiles;
  bool changed = false;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, BatchReply& x) {
  return f(caf::meta::type_name("tessera::batch_reply"), x.tiles, x.changed);
}

// Parent -> node: open a worker for one session on this node's sub-tree.
struct OpenRequest {
  uint64_t session = 0;
  std::string master;        // for log lines
  int32_t packet_w = 4, packet_h = 4;  // the master's packet layout (one packet space per cluster)
  uint32_t timeout_ms = 0;   // how long the parent waits for the reply (0: not said)
  uint32_t keepalive_ms = 0; // the parent sends the worker something (at least an empty update)
                             // this often; a worker that hears nothing for a multiple of it ends
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, OpenRequest& x) {
  return f(caf::meta::type_name("tessera::open_request"), x.session, x.master, x.packet_w, x.packet_h, x.timeout_ms,
           x.keepalive_ms);
}
struct OpenReply {
  caf::actor worker;            // a worker_actor
  std::vector<NodeInfo> nodes;  // its flattened list
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, OpenReply& x) {
  return f(caf::meta::type_name("tessera::open_reply"), x.worker, x.nodes);
}
// A node's live children, for its own workers.
struct ChildLink {
  std::string name;
  caf::actor node;  // a node_actor
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, ChildLink& x) {
  return f(caf::meta::type_name("tessera::child_link"), x.name, x.node);
}

// A session's state, for tests and monitoring.
struct SessionStatus {
  bool handshake_done = false;
  bool in_flight = false;        // a frame is being rendered (scene updates are cached)
  bool render_pending = false;   // a render request waits for the frame in flight
  uint32_t pending_frame = 0;
  uint32_t cached_updates = 0;
  uint32_t frames_started = 0;
  uint32_t dropped = 0;          // render requests merged into a later one
  uint32_t errors_sent = 0;
  uint64_t scene_version = 0;
  uint64_t triangles = 0;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, SessionStatus& x) {
  return f(caf::meta::type_name("tessera::session_status"), x.handshake_done, x.in_flight, x.render_pending,
           x.pending_frame, x.cached_updates, x.frames_started, x.dropped, x.errors_sent, x.scene_version,
           x.triangles);
}

}  // namespace tessera
