// libFuzzer target: the glTF loader (core/gltf_loader.h load_gltf) on arbitrary files.
// The input is written to a temporary file (.glb when it starts with the binary magic
// "glTF", else .gltf) and loaded; the loader may only throw (std::exception), never crash,
// and a scene it returns must hold only meshes whose buffers exist.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <exception>

#include "core/gltf_loader.h"
#include "tests/fuzz/fuzz_common.h"

using namespace tessera;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  bool glb = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
  std::string path = fuzz::write_file(glb ? "input.glb" : "input.gltf", data, size);
  try {
    LoadedScene s = load_gltf(path);
    for (auto& [id, m] : s.scene.meshes())
      if (!s.scene.buffers().count(m.value.positions)) {
        std::fprintf(stderr, "mesh %u refers to a missing position buffer\n", id);
        std::abort();
      }
    (void)s.scene.triangle_count();
    (void)s.bounds.extent();
  } catch (const std::exception&) {
    // refused with a message: fine
  }
  return 0;
}
