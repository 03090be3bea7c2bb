// libFuzzer target: decoded scenes all the way through a small render. An input is either a
// client-protocol message (protocol/protocol.h) whose scene updates are applied to a fresh Scene
// as a session applies them, or, when it starts with '{', a glTF file loaded by load_gltf.
// The scene is then synced into the ray tracer and rendered at 16x16 twice: with the general
// kernel (AO 1, depth 2) and the plain one (no AO, depth 1). Nothing may abort; a renderer may
// refuse with an exception. The ray tracer is made once and emptied (synced with an empty
// scene) between inputs. TBB runs one thread: an abort then happens on the fuzzer's thread,
// so libFuzzer writes the input and the stack (two workers aborting at once lose both).
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <vector>

#include <tbb/global_control.h>

#include "protocol/protocol.h"
#include "update/scene_update.h"
#include "core/gltf_loader.h"
#include "renderer/raytracer.h"
#include "tests/fuzz/fuzz_common.h"

using namespace tessera;
using namespace tessera::protocol;

namespace {

Limits fuzz_limits() {
  Limits lim;
  lim.max_message_bytes = 1 << 20;
  lim.max_message_payload_bytes = 8 << 20;
  lim.max_buffer_bytes = 4 << 20;
  lim.max_client_bytes = 8 << 20;
  lim.max_texture_size = 256;
  lim.max_triangles = 1 << 16;
  lim.max_vertices = 1 << 18;
  return lim;
}

bool scene_from_message(const uint8_t* data, size_t size, Scene& scene) {
  static const Limits lim = fuzz_limits();
  auto msg = decode_client(data, size, lim);
  if (!msg.ok()) return false;
  for (auto& r : msg.value()) {
    if (std::holds_alternative<Handshake>(r) || std::holds_alternative<Settings>(r) ||
        std::holds_alternative<Resolution>(r) || std::holds_alternative<RenderRequest>(r) ||
        std::holds_alternative<Refine>(r) || std::holds_alternative<Budget>(r))
      continue;  // session-level records; the render below uses its own settings
    (void)apply(scene, std::move(r), lim);
  }
  return true;
}

bool scene_from_gltf(const uint8_t* data, size_t size, Scene& scene) {
  try {
    LoadedScene loaded = load_gltf(fuzz::write_file("render.gltf", data, size));
    if (loaded.scene.triangle_count() > (1u << 16)) return false;
    scene = std::move(loaded.scene);
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
  static RayTracer rt;
  Scene scene;
  bool ok = size > 0 && data[0] == '{' ? scene_from_gltf(data, size, scene) : scene_from_message(data, size, scene);
  if (!ok) return 0;
  scene.set_resolution(16, 16);
  std::vector<std::string> warnings;
  try {
    rt.sync(scene, warnings);
    for (auto [ao, depth] : {std::pair{1, 2}, std::pair{0, 1}}) {
      RenderSettings s;
      s.ao_samples = ao;
      s.max_depth = depth;
      TaskResult out;
      rt.render({0, 0, 16, 16}, s, out);
      if (out.image.width != 16 || out.image.height != 16 || out.image.rgba.size() != 16 * 16 * 4) {
        std::fprintf(stderr, "render gave a %dx%d image\n", out.image.width, out.image.height);
        std::abort();
      }
    }
  } catch (const std::exception&) {
    // refused with a message: fine
  }
  Scene empty;
  rt.sync(empty, warnings);
  return 0;
}
