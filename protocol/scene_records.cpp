#include "protocol/scene_records.h"

namespace tessera::protocol {

std::vector<ClientRecord> scene_to_records(const Scene& scene, const SceneRecordOptions& options) {
  std::vector<ClientRecord> out;
  for (const auto& [id, e] : scene.buffers()) {
    SetBuffer b;
    b.id = id;
    b.buffer = e.value;
    b.deflate = options.deflate;
    out.push_back(std::move(b));
  }
  for (const auto& [id, e] : scene.textures()) {
    SetTexture t;
    t.id = id;
    t.texture = e.value;
    t.format = TextureFormat::rgba8;
    out.push_back(std::move(t));
  }
  for (const auto& [id, e] : scene.materials()) out.push_back(SetMaterial{id, e.value});
  for (const auto& [id, e] : scene.meshes()) out.push_back(SetMesh{id, e.value});
  for (const auto& [id, e] : scene.lights()) out.push_back(SetLight{id, e.value});
  if (options.environment) out.push_back(SetEnvironment{scene.environment()});
  if (options.camera) out.push_back(SetCamera{scene.camera()});
  if (options.resolution) out.push_back(Resolution{scene.width(), scene.height()});
  return out;
}

std::vector<std::vector<uint8_t>> pack_messages(const std::vector<ClientRecord>& records, size_t max_message_bytes) {
  std::vector<std::vector<uint8_t>> out;
  std::vector<ClientRecord> batch;
  size_t batch_bytes = kMessageHeaderSize;
  auto flush = [&] {
    if (batch.empty()) return;
    out.push_back(encode(batch));
    batch.clear();
    batch_bytes = kMessageHeaderSize;
  };
  for (const auto& r : records) {
    // Record size: encode it alone (cheap compared with the upload itself).
    size_t bytes = encode(r).size() - kMessageHeaderSize;
    if (batch_bytes + bytes > max_message_bytes) flush();
    batch.push_back(r);
    batch_bytes += bytes;
  }
  flush();
  return out;
}

void append_message(std::vector<uint8_t>& message, std::vector<uint8_t>&& more) {
  if (more.size() < kMessageHeaderSize) return;
  if (message.empty()) {
    message = std::move(more);
    return;
  }
  // The record count is the header's last field (u32, little endian).
  auto count = [](const std::vector<uint8_t>& m) {
    return uint32_t(m[4]) | uint32_t(m[5]) << 8 | uint32_t(m[6]) << 16 | uint32_t(m[7]) << 24;
  };
  const uint32_t n = count(message) + count(more);
  message.insert(message.end(), more.begin() + long(kMessageHeaderSize), more.end());
  for (int i = 0; i < 4; ++i) message[size_t(4 + i)] = uint8_t(n >> (8 * i));
}

}  // namespace tessera::protocol
