#pragma once
// The client protocol: binary messages on the sync and display WebSockets (docs/protocol.md
// documents every byte). Pure code: bytes in, records out and back; no scene, no sockets, no actors.
//
// A WebSocket binary message is a header followed by one or more records:
//   message = "TS" u8 version u8 channel u32 record_count, record*
//   record  = u8 type u8 op u16 reserved(0) u32 body_length, body
// Everything is little endian. Decoding validates the whole message before anything is
// returned (all or nothing); `apply` (update/scene_update.h) then changes the scene record by
// record, checking what depends on the scene (mesh consistency, per-client totals).
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "core/scene.h"
// Generated at build time from protocol/wire.toml (protocol/gen_wire.py): the framing constants
// (kVersion, kMagic0/1, kMessageHeaderSize, kRecordHeaderSize, kNoRecord), the enums RecordType,
// Channel, Op, RendererKind, DisplayKind, FrameEncoding and TextureFormat, the flag bits, and
// protocol::wire: every record's body size, field offsets and ranges, and the default limits.
#include "protocol/wire.h"

namespace tessera::protocol {

// ---------------------------------------------------------------------------------------
// Errors are values.

enum class ErrorCode : uint16_t {
  ok = 0,
  truncated = 1,         // fewer bytes than the header or a declared length needs
  bad_magic = 2,         // not "TS"
  bad_version = 3,       // protocol version not supported (fatal)
  bad_channel = 4,       // a server message on the client channel or vice versa
  too_large = 5,         // message size or record count beyond the limits
  unknown_record = 6,    // record type not defined for this direction
  bad_op = 7,            // op not defined, or remove on a record that has no id
  bad_length = 8,        // body length does not match what the record needs
  bad_reserved = 9,      // a reserved byte or flag bit is not zero
  bad_id = 10,           // id 0 where an id is required
  bad_enum = 11,         // enum value out of range
  bad_components = 12,   // component count not 1..4, or values not a multiple of it
  not_finite = 13,       // NaN or infinity where a finite number is required
  out_of_range = 14,     // a number outside its documented range
  limit_exceeded = 15,   // beyond a Limits value (resolution, bytes, triangles, texture size)
  bad_payload = 16,      // deflate data corrupt, truncated, or not the declared size
  bad_texture = 17,      // texture bytes do not decode or do not match the declared size
  bad_mesh = 18,         // mesh inconsistent with buffers already in the scene
  unknown_id = 19,       // remove of an id the scene does not hold
  bad_handshake = 20,    // handshake missing, repeated or not alone in its message (fatal)
  not_scene_update = 21, // apply() given a record that is not a scene update
  internal = 22,         // server-side failure (server -> client only)
  no_effect = 23,        // a setting changes nothing on this scene (server -> client, once; a notice, not fatal)
  // A node's own failures (64 and up): its actors' and its cluster's errors, from the renderer's
  // reply to a parent's view of its children (actors/errors.h). They never go on the wire to a
  // client: to_reply sends them as `internal`, with their name in the message.
  bad_task = 64,         // a render task the renderer cannot take (renderer kind, scene, resolution)
  render_failed = 65,    // the renderer failed (Embree's error, no GL context, out of memory)
  no_scene = 66,         // a worker has no valid scene (its last update failed)
  bad_batch = 67,        // a worker refused its parent's batch
  bad_tile = 68,         // a child's tile or batch reply failed its parent's checks
  node_lost = 69,        // a node or its link went down, or it stopped answering
  no_node = 70,          // no node could render the task
  node_late = 71,        // a node that still answers returned no tiles in time (they are rendered elsewhere)
};
constexpr uint16_t kMaxErrorCode = 23;  // the largest code on the wire

const char* to_string(ErrorCode c);
// Whether the session ends after this error (the server closes both channels).
bool is_fatal(ErrorCode c);

struct Error {
  ErrorCode code = ErrorCode::ok;
  std::string message;          // human readable, names the record and the field
  uint32_t record = kNoRecord;  // index of the offending record in its message
};

template <class T>
class Result {
 public:
  Result(T v) : v_(std::move(v)) {}
  Result(Error e) : v_(std::move(e)) {}
  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }
  T& value() { return std::get<0>(v_); }
  const T& value() const { return std::get<0>(v_); }
  const Error& error() const { return std::get<1>(v_); }
  ErrorCode code() const { return ok() ? ErrorCode::ok : error().code; }

 private:
  std::variant<T, Error> v_;
};
struct Ok {};
using Status = Result<Ok>;

// ---------------------------------------------------------------------------------------
// Limits, enforced before any allocation that depends on a declared size.

// The defaults are protocol/wire.toml's [limits].
struct Limits {
  uint32_t max_message_bytes = wire::limits::max_message_bytes;  // one WebSocket message
  uint32_t max_records = wire::limits::max_records;              // records in one message
  int32_t max_width = wire::limits::max_width, max_height = wire::limits::max_height;  // resolution
  uint64_t max_message_payload_bytes = wire::limits::max_message_payload_bytes;  // inflated buffers + decoded textures in one message
  uint64_t max_buffer_bytes = wire::limits::max_buffer_bytes;    // one buffer, inflated
  uint64_t max_client_bytes = wire::limits::max_client_bytes;    // buffers + textures held in one client's scene
  uint64_t max_triangles = wire::limits::max_triangles;          // scene total, instances counted each time
  uint64_t max_vertices = wire::limits::max_vertices;            // elements in one buffer
  int32_t max_texture_size = wire::limits::max_texture_size;     // texture width and height each
  uint32_t max_nodes = wire::limits::max_nodes;                  // handshake max_nodes
  uint32_t max_ao_samples = wire::limits::max_ao_samples;
  uint32_t max_refine_samples = wire::limits::max_refine_samples;
  uint32_t max_frame_budget_ms = wire::limits::max_frame_budget_ms;
  uint32_t max_depth = wire::limits::max_depth;
};

// ---------------------------------------------------------------------------------------
// Record types and enums on the wire: protocol/wire.h (RecordType, Channel, Op, RendererKind,
// DisplayKind, FrameEncoding, TextureFormat; kBufferDeflate, kMaterialAlphaMask,
// kMaterialDoubleSided).

const char* to_string(RecordType t);  // "handshake", "buffer", ...

// ---------------------------------------------------------------------------------------
// Client -> server records.

struct Handshake {
  RendererKind renderer = RendererKind::raytracer;
  DisplayKind display = DisplayKind::jpeg;
  uint8_t jpeg_quality = 85;  // 1..100
  uint32_t max_nodes = 0;     // 0: as many as the server offers
  int32_t width = 640, height = 480;
};

struct Settings {
  uint32_t ao_samples = 0;  // ambient occlusion rays per hit, 0 = off
  uint32_t max_depth = 4;   // reflection/refraction bounces
};

struct Resolution {
  int32_t width = 640, height = 480;
};

// The samples per pixel a still refines to after each requested frame (docs/protocol.md,
// "Refinement"); 0 or 1: none.
struct Refine {
  uint32_t samples = 0;
};

// The H.264 display (docs/protocol.md, "Video"): the target bitrate (0: unchanged; else
// kMinVideoKbps..200000) and a keyframe request, for the frames after it.
constexpr uint32_t kMinVideoKbps = 100;
struct Video {
  uint32_t bitrate_kbps = 0;
  bool keyframe = false;
};

// Interactive frames are rendered at a lower resolution to take about frame_ms (docs/protocol.md,
// "Refinement"); 0: always the client's resolution.
struct Budget {
  uint32_t frame_ms = 0;
};

struct SetCamera {
  Camera camera;
};
struct SetEnvironment {
  Environment environment;
};

struct SetBuffer {
  Id id = kNoId;
  Buffer buffer;
  bool deflate = false;  // encode: compress the payload; decode: it was compressed
};

struct SetTexture {
  Id id = kNoId;
  Texture texture;             // decoded RGBA8 (after decode; before encode when format is rgba8)
  TextureFormat format = TextureFormat::rgba8;
  std::vector<uint8_t> encoded;  // PNG/JPEG bytes when format != rgba8 (encode only; decode leaves it empty)
};

// References (docs/protocol.md, "References"): the node loads the content from `url` itself.
// A buffer: value_count values of `source` type from byte_offset on, one element (components
// values) every byte_stride bytes (0: packed), widened to u32 for an integer source.
struct SetBufferRef {
  Id id = kNoId;
  Buffer::Type type = Buffer::Type::f32;
  uint8_t components = 1;
  SourceType source = SourceType::f32;
  uint32_t value_count = 0;
  uint32_t byte_stride = 0;
  uint64_t byte_offset = 0;
  std::string url;
};
// Bytes of one value of a reference's source type.
constexpr uint32_t source_size(SourceType s) {
  return s == SourceType::u16 ? 2 : s == SourceType::u8 ? 1 : 4;
}
// A texture: a PNG or JPEG file, with the sampler and colour space a texture record carries.
struct SetTextureRef {
  Id id = kNoId;
  Sampler sampler;
  bool srgb = true;
  std::string url;
};

struct SetMaterial {
  Id id = kNoId;
  Material material;
};
struct SetMesh {
  Id id = kNoId;
  Mesh mesh;
};
struct SetLight {
  Id id = kNoId;
  Light light;
};

struct Remove {
  RecordType what = RecordType::buffer;  // buffer, texture, material, mesh or light
  Id id = kNoId;
};

struct RenderRequest {
  uint32_t frame = 0;  // client's frame number, echoed in the frame reply
};

using ClientRecord = std::variant<Handshake, Settings, Resolution, SetCamera, SetEnvironment, SetBuffer, SetTexture,
                                  SetMaterial, SetMesh, SetLight, Remove, RenderRequest, Refine, Budget, SetBufferRef,
                                  SetTextureRef, Video>;

// ---------------------------------------------------------------------------------------
// Server -> client records.

struct HandshakeReply {
  RendererKind renderer = RendererKind::raytracer;  // accepted settings
  DisplayKind display = DisplayKind::jpeg;
  uint8_t jpeg_quality = 85;
  uint32_t nodes = 1;                 // nodes the session renders on
  int32_t width = 640, height = 480;  // accepted initial resolution
  uint32_t max_message_bytes = 0;     // the server's Limits, so the client can split uploads
  uint64_t max_buffer_bytes = 0;
  std::string server_version;         // e.g. "tessera 0.1.0", at most 255 bytes
};

struct FrameTimings {
  float kernel_ms = 0, rendering_ms = 0, sat_ms = 0, tiling_ms = 0, pipeline_ms = 0, encode_ms = 0;
};

struct Frame {
  uint32_t frame = 0;  // the client's frame number from the render request
  int32_t width = 0, height = 0;
  FrameEncoding encoding = FrameEncoding::jpeg;
  bool refined = false;   // sent unasked: a refinement of the last requested frame
  bool converged = false;  // a refinement, and the still's last: it is converged
  uint16_t samples = 1;   // samples per pixel averaged in the image
  FrameTimings timings;
  std::vector<uint8_t> payload;  // JPEG file, or DXT1 blocks (dxt1_size(width, height) bytes)
};

struct ErrorReply {
  ErrorCode code = ErrorCode::internal;
  bool fatal = false;           // the server closes the session after sending it
  uint32_t record = kNoRecord;  // offending record in the client's message
  std::string message;          // at most 65535 bytes
};

struct Stats {
  uint32_t frames = 0;          // frames sent in this session
  uint32_t dropped = 0;         // render requests merged into a later frame
  uint64_t bytes_sent = 0;      // frame payload bytes in this session
  uint64_t scene_bytes = 0;     // buffers + textures held for this client
  uint64_t triangles = 0;       // scene triangles (instances counted each time)
  uint32_t nodes = 1;
  float fps = 0;                // over the last second
  float mean_pipeline_ms = 0;   // over the last second
};

// The node's answer to a buffer_ref or texture_ref: loaded (the id is set) or refused, and why.
struct Reference {
  RefKind what = RefKind::buffer;
  bool ok = false;
  Id id = kNoId;
  uint64_t bytes = 0;     // the content's size in the scene; 0 when refused
  std::string message;    // why it was refused (at most 65535 bytes); empty when ok
};

using ServerRecord = std::variant<HandshakeReply, Frame, ErrorReply, Stats, Reference>;

// ---------------------------------------------------------------------------------------
// Encoding (infallible for valid values; values outside the wire's ranges are the caller's bug
// and are written as given, so the decoder's checks can be tested).

std::vector<uint8_t> encode(const std::vector<ClientRecord>& records);
std::vector<uint8_t> encode(const std::vector<ServerRecord>& records);
std::vector<uint8_t> encode(const ClientRecord& record);
std::vector<uint8_t> encode(const ServerRecord& record);

// Appends the message header and the frame record header (everything but the payload) to
// `out`, so a server can encode the image straight after it (JpegEncoder offset).
void encode_frame_header(const Frame& frame_without_payload, size_t payload_size, std::vector<uint8_t>& out);

// ---------------------------------------------------------------------------------------
// Decoding: validates framing, lengths, ids, enums, finiteness, ranges and Limits; inflates
// buffers and decodes textures (within the limits). All or nothing.

Result<std::vector<ClientRecord>> decode_client(const uint8_t* data, size_t size, const Limits& limits);
Result<std::vector<ServerRecord>> decode_server(const uint8_t* data, size_t size, const Limits& limits);

// Session order on the sync channel: the first message is exactly one handshake, and no
// handshake comes later (bad_handshake, fatal). `handshake_done` is the session's state.
Status check_session_order(bool handshake_done, const std::vector<ClientRecord>& records);

// Convenience for the sync channel: an ErrorReply for a failed decode/apply.
ErrorReply to_reply(const Error& e);

}  // namespace tessera::protocol
