#pragma once
// The atoms and the message types that several actor protocols share (payloads, scene
// snapshots, a frame's measurements); each actor's own messages are in its protocol header
// (renderer_protocol.h, tiler_protocol.h, subtree_protocol.h, ...).
//
// Every type has an inspect overload and is registered by register_message_types (node.h),
// so each message can cross a process boundary. Pixels and SATs travel as byte vectors
// (STACK.md: element-wise serialisation of uint32 vectors is 60x slower).
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
using ping_atom = caf::atom_constant<caf::atom("ping")>;
using deadline_atom = caf::atom_constant<caf::atom("deadline")>;
using cancel_atom = caf::atom_constant<caf::atom("cancel")>;

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
  // A progressive still: the samples averaged in this frame's image (1: a plain frame) and
  // whether it refines the last requested frame (sent unasked, with that frame's number).
  uint32_t samples = 1;
  bool refined = false;
  // The still's last refinement: converged (every block at its target, or, refined adaptively,
  // with an error out of sight); nothing follows until the client asks again.
  bool converged = false;
  // Refined adaptively (renderer/adaptive.h): the round, and the blocks it rendered (0: all).
  uint32_t round = 0, blocks = 0;
  // A refined frame of a still being denoised (renderer/denoise.h): the plain average's
  // estimated PSNR (dB; 0: not estimated), whether the frame shows it denoised, and the time
  // that took (estimate, filter and encoding to 8 bits).
  double estimated_db = 0;
  bool denoised = false;
  double denoise_ms = 0;
  // The H.264 display: the bitrate to encode at (kbit/s), and how many keyframes the client has
  // asked for so far; a frame whose count is above the encoder's last one is a keyframe (a count,
  // not a flag, so that a frame replaced before encoding does not lose the request).
  uint32_t video_kbps = 0;
  uint32_t keyframe_requests = 0;
  // The AO rays per hit and depth it was rendered with (an interactive frame's may be below the
  // page's: FrameBudget's levels).
  uint32_t ao_samples = 0, max_depth = 0;
};
template <class Inspector>
typename Inspector::result_type inspect(Inspector& f, FrameMeta& x) {
  return f(caf::meta::type_name("tessera::frame_meta"), x.seq, x.client_frame, x.width, x.height, x.display,
           x.quality, x.kernel_ms, x.rendering_ms, x.sat_ms, x.tiling_ms, x.render_start_ns, x.render_end_ns, x.nodes,
           x.dropped, x.scene_bytes, x.triangles, x.samples, x.refined, x.converged, x.round, x.blocks, x.estimated_db, x.denoised, x.denoise_ms, x.video_kbps,
           x.keyframe_requests, x.ao_samples, x.max_depth);
}

}  // namespace tessera
