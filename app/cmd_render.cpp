// tessera render --scene S.gltf [--camera-loop L.json --frame K] --size W H [--ao N] [--depth D]
//                [--renderer raytracer|rasterizer] --out F.png
#include <cstdio>

#include "app/command.h"
#include "app/common.h"

namespace tessera::app {
namespace {

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) {
    std::puts("tessera render --scene S.gltf [--camera-loop L.json --frame K] [--size W H] [--ao N] [--depth D]\n"
              "               [--shadows 0|1] [--ao-distance X] [--threads T] [--renderer raytracer|rasterizer]\n"
              "               [--bvh-quality medium|high] [--default-light] --out F.png\n"
              "Renders one image (with the ray tracer by default) and prints its figures as one JSON line.\n"
              "A glTF with lit materials and no lights and no sky renders them black (as an XML3D page\n"
              "without lights); --default-light lights it with a sun over the camera's shoulder and a sky.\n"
              "The rasterizer has no AO, reflection, refraction or shadows; --threads does not limit it\n"
              "(llvmpipe's threads are set by LP_NUM_THREADS).");
    return 0;
  }
  int threads = 0;
  auto limit = limit_threads(args, &threads);
  SceneSetup setup = load_scene(args);
  long frame = read_frame(args, setup);
  std::string out_path = args.required("--out");
  RenderSettings settings = read_settings(args);
  std::string kind = read_renderer_kind(args);
  args.finish();
  settings.frame = uint32_t(frame);
  setup.set_frame(size_t(frame));

  for (auto& w : setup.loaded.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  if (const std::string note = lighting_note(setup.scene_path, setup.loaded); !note.empty())
    std::fprintf(stderr, "note: %s\n", note.c_str());
  std::unique_ptr<Renderer> renderer = make_renderer(kind);
  std::vector<std::string> warnings;
  renderer->sync(setup.loaded.scene, warnings);
  for (auto& w : warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  const Scene& scene = setup.loaded.scene;
  for (auto& w : ineffective_settings(scene, settings.ao_samples, kind == "rasterizer"))
    std::fprintf(stderr, "warning: %s\n", w.c_str());
  TaskResult res;
  renderer->render({0, 0, scene.width(), scene.height()}, settings, res);
  if (res.image.width > 0 && res.image.height > 0) write_png(out_path, res.image);
  else std::fprintf(stderr, "warning: empty image (size %dx%d); nothing written\n", scene.width(), scene.height());
  std::printf("{\"out\": %s, \"width\": %d, \"height\": %d, \"kernel_ms\": %.3f, \"rendering_ms\": %.3f, "
              "\"rays\": {\"primary\": %llu, \"shadow\": %llu, \"ao\": %llu, \"secondary\": %llu}, \"threads\": %d, "
              "\"renderer\": %s}\n",
              json_str(out_path).c_str(), scene.width(), scene.height(), res.kernel_ms, res.rendering_ms,
              (unsigned long long)res.rays.primary, (unsigned long long)res.rays.shadow, (unsigned long long)res.rays.ao,
              (unsigned long long)res.rays.secondary, threads, json_str(kind).c_str());
  return 0;
}

const Command reg("render", "render one image of a glTF scene to PNG", run);

}  // namespace
}  // namespace tessera::app
