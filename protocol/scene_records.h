#pragma once
// A Scene as client protocol records: what a client uploads to show this scene. Used by the
// e2e tests, `tessera loadtest`, `SceneSnapshot` serialisation and the web tests.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "protocol/protocol.h"
#include "core/scene.h"

namespace tessera::protocol {

struct SceneRecordOptions {
  bool deflate = false;          // compress buffer payloads
  bool resolution = true;        // include a resolution record (the scene's width x height)
  bool camera = true;
  bool environment = true;
};

// Buffers, textures (RGBA8), materials, meshes, lights, then environment, camera and
// resolution: applying them in order to an empty scene rebuilds `scene`.
std::vector<ClientRecord> scene_to_records(const Scene& scene, const SceneRecordOptions& options = {});

// The records packed into messages of at most max_message_bytes each (a record larger than
// that travels alone in its own message, where the server will reject it as too large).
std::vector<std::vector<uint8_t>> pack_messages(const std::vector<ClientRecord>& records, size_t max_message_bytes);

// Appends the records of client message `more` to client message `message` (empty: becomes
// `more`), so a node can forward exactly the records it accepted, in one message.
void append_message(std::vector<uint8_t>& message, std::vector<uint8_t>&& more);

}  // namespace tessera::protocol
