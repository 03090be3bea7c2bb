#include "net/scene_records.h"

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

}  // namespace tessera::protocol
