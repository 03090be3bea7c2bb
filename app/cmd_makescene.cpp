// tessera make-scene --out DIR [--unique-triangles N] [--instanced-triangles M] [--textures T]
//                    [--texture-size S] [--seed K]: writes a synthetic glTF scene of that size
// (app/synthetic_scene.h), San Miguel's figures by default, and prints what it wrote as JSON.
#include <chrono>
#include <cstdio>

#include "app/args.h"
#include "app/command.h"
#include "app/common.h"
#include "app/synthetic_scene.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera make-scene --out DIR [--unique-triangles N] [--instanced-triangles M] [--textures T]\n"
    "                   [--texture-size S] [--seed K]\n"
    "Writes DIR/scene.gltf, DIR/scene.bin, DIR/textures/*.jpg and DIR/camera-loop.json: a synthetic\n"
    "scene for measuring loading (docs/results/load.md). N unique triangles in bumpy meshes of\n"
    "128..4608 triangles, instances of a tenth of them up to M triangles in all, T textures of\n"
    "S x S JPEG noise, a camera and a sun, and a camera loop around it.\n"
    "Defaults: San Miguel's size, N 1600000, M 9500000, T 222, S 1024 (about 140 MB); seed 1.\n"
    "The same options give the same files.\n";

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) { std::fputs(kHelp, stdout); return 0; }
  SyntheticSceneSpec spec;
  const std::string out = args.required("--out");
  const long unique = args.integer("--unique-triangles", long(spec.unique_triangles));
  const long instanced = args.integer("--instanced-triangles", long(spec.instanced_triangles));
  spec.textures = int(args.integer("--textures", spec.textures));
  spec.texture_size = int(args.integer("--texture-size", spec.texture_size));
  spec.seed = uint32_t(args.integer("--seed", long(spec.seed)));
  args.finish();
  if (unique < 1 || instanced < 1) throw std::invalid_argument("--unique-triangles and --instanced-triangles must be positive");
  spec.unique_triangles = uint64_t(unique);
  spec.instanced_triangles = uint64_t(instanced);
  const auto t0 = std::chrono::steady_clock::now();
  const SyntheticSceneFigures f = write_synthetic_scene(out, spec);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  std::printf("{\"out\": %s, \"unique_triangles\": %llu, \"instanced_triangles\": %llu, \"meshes\": %d, \"nodes\": %d, "
              "\"textures\": %d, \"materials\": %d, \"bin_bytes\": %llu, \"texture_bytes\": %llu, \"json_bytes\": %llu, "
              "\"ms\": %.0f}\n",
              json_str(out + "/scene.gltf").c_str(), (unsigned long long)f.unique_triangles, (unsigned long long)f.instanced_triangles,
              f.meshes, f.nodes, f.textures, f.materials, (unsigned long long)f.bin_bytes, (unsigned long long)f.texture_bytes,
              (unsigned long long)f.json_bytes, ms);
  return 0;
}

const Command reg("make-scene", "write a synthetic glTF scene of a chosen size (San Miguel's by default)", run);

}  // namespace
}  // namespace tessera::app
