// tessera render --scene S.gltf [--camera-loop L.json --frame K] --size W H [--ao N] [--depth D] --out F.png
#include <cstdio>

#include "app/command.h"
#include "app/common.h"
#include "renderer/raytracer.h"

namespace tessera::app {
namespace {

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) {
    std::puts("tessera render --scene S.gltf [--camera-loop L.json --frame K] [--size W H] [--ao N] [--depth D]\n"
              "               [--shadows 0|1] [--ao-distance X] [--threads T] --out F.png\n"
              "Renders one image with the ray tracer and prints its figures as one JSON line.");
    return 0;
  }
  int threads = 0;
  auto limit = limit_threads(args, &threads);
  SceneSetup setup = load_scene(args);
  long frame = args.integer("--frame", 0);
  std::string out_path = args.required("--out");
  RenderSettings settings = read_settings(args);
  args.finish();
  settings.frame = uint32_t(frame);
  setup.set_frame(size_t(frame));

  for (auto& w : setup.loaded.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  RayTracer rt;
  std::vector<std::string> warnings;
  rt.sync(setup.loaded.scene, warnings);
  for (auto& w : warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  const Scene& scene = setup.loaded.scene;
  TaskResult res;
  rt.render({0, 0, scene.width(), scene.height()}, settings, res);
  if (res.image.width > 0 && res.image.height > 0) write_png(out_path, res.image);
  else std::fprintf(stderr, "warning: empty image (size %dx%d); nothing written\n", scene.width(), scene.height());
  std::printf("{\"out\": %s, \"width\": %d, \"height\": %d, \"kernel_ms\": %.3f, \"rendering_ms\": %.3f, "
              "\"rays\": {\"primary\": %llu, \"shadow\": %llu, \"ao\": %llu, \"secondary\": %llu}, \"threads\": %d}\n",
              json_str(out_path).c_str(), scene.width(), scene.height(), res.kernel_ms, res.rendering_ms,
              (unsigned long long)res.rays.primary, (unsigned long long)res.rays.shadow, (unsigned long long)res.rays.ao,
              (unsigned long long)res.rays.secondary, threads);
  return 0;
}

const Command reg("render", "render one image of a glTF scene to PNG", run);

}  // namespace
}  // namespace tessera::app
