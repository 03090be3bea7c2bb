// Decodes client messages written by the web client with protocol/protocol.cpp and applies them to
// a Scene (a check that JS-encoded bytes are accepted by the server's decoder).
//   decode_check msg1.bin [msg2.bin ...]
#include <cstdio>
#include <fstream>
#include <iterator>
#include "protocol/protocol.h"
using namespace tessera;
using namespace tessera::protocol;
int main(int argc, char** argv) {
  Scene scene;
  Limits lim;
  for (int i = 1; i < argc; i++) {
    std::ifstream f(argv[i], std::ios::binary);
    std::vector<uint8_t> b((std::istreambuf_iterator<char>(f)), {});
    auto r = decode_client(b.data(), b.size(), lim);
    if (!r) { std::printf("%s: %s: %s (record %u)\n", argv[i], to_string(r.code()), r.error().message.c_str(), r.error().record); return 1; }
    for (auto& rec : r.value()) {
      if (!is_scene_update(rec)) continue;
      auto s = apply(scene, std::move(rec), lim);
      if (!s) { std::printf("%s: apply: %s: %s\n", argv[i], to_string(s.code()), s.error().message.c_str()); return 1; }
    }
  }
  for (auto& [id, m] : scene.meshes()) {
    std::string e = scene.validate_mesh(m.value);
    std::printf("mesh %u: %s\n", id, e.empty() ? "ok" : e.c_str());
  }
  std::printf("buffers %zu materials %zu meshes %zu lights %zu triangles %zu\n", scene.buffers().size(), scene.materials().size(),
              scene.meshes().size(), scene.lights().size(), scene.triangle_count());
  return 0;
}
