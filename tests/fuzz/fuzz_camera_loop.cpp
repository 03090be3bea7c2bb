// libFuzzer target: the camera-loop reader (core/gltf_loader.h load_camera_loop) on
// arbitrary files. It may only throw (std::exception); every frame of a loop it accepts is
// turned into a camera as `tessera render/bench --camera-loop` do.
#include <cstdint>
#include <exception>

#include "core/gltf_loader.h"
#include "tests/fuzz/fuzz_common.h"

using namespace tessera;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string path = fuzz::write_file("camera-loop.json", data, size);
  try {
    CameraLoop loop = load_camera_loop(path);
    for (size_t i = 0; i < loop.frames.size() && i < 64; ++i) (void)loop.camera(i);
  } catch (const std::exception&) {
    // refused with a message: fine
  }
  return 0;
}
