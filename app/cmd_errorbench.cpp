// tessera errorbench --scene S.gltf --camera-loop L.json [--frame K] [--size W H] [--reps R]
// Image error against a high-sample reference versus render time, for AO rays per hit and
// recursion depth (the user's "error against run time").
#include <cstdio>

#include "app/command.h"
#include "app/common.h"
#include "renderer/raytracer.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera errorbench --scene S.gltf --camera-loop L.json [--frame K] [--size W H] [--threads T] [--reps R]\n"
    "                   [--ao-list 1,2,4,8,16,32] [--ao-ref 256] [--depth-max 6] [--depth-ref 12] [--ao-depth 4]\n"
    "Prints one JSON line per setting: render time (median of R) and RMSE/PSNR against a reference.\n"
    "AO series: depth --ao-depth, reference --ao-ref rays per hit. Depth series: AO off, reference\n"
    "depth --depth-ref.\n";

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) { std::fputs(kHelp, stdout); return 0; }
  int threads = 0;
  auto limit = limit_threads(args, &threads);
  SceneSetup setup = load_scene(args, 640, 360);
  long frame = read_frame(args, setup);
  long reps = args.integer("--reps", 3);
  std::vector<int> ao_list;
  for (double v : parse_number_list("--ao-list", args.str("--ao-list", "1,2,4,8,16,32"))) ao_list.push_back(int(v));
  int ao_ref = int(args.integer("--ao-ref", 256));
  int depth_max = int(args.integer("--depth-max", 6));
  int depth_ref = int(args.integer("--depth-ref", 12));
  int ao_depth = int(args.integer("--ao-depth", 4));
  args.finish();
  if (reps < 1) throw std::invalid_argument("--reps must be >= 1");
  setup.set_frame(size_t(frame));
  RayTracer rt;
  std::vector<std::string> warnings;
  rt.sync(setup.loaded.scene, warnings);
  const Rect full{0, 0, setup.loaded.scene.width(), setup.loaded.scene.height()};

  auto render = [&](int ao, int depth, double* ms) {
    RenderSettings s;
    s.ao_samples = ao;
    s.max_depth = depth;
    s.frame = uint32_t(frame);
    std::vector<double> times;
    TaskResult r;
    for (long i = 0; i < reps; ++i) {
      rt.render(full, s, r);
      times.push_back(r.rendering_ms);
    }
    if (ms) *ms = median(times);
    return r.image;
  };
  auto report = [&](const char* series, int ao, int depth, const Image& ref, double ref_ms) {
    double ms = 0;
    Image img = render(ao, depth, &ms);
    ImageError e = compare(img, ref);
    std::printf("{\"series\": \"%s\", \"scene\": %s, \"ao\": %d, \"depth\": %d, \"rendering_ms\": %.3f, \"rmse\": %.4f, "
                "\"psnr_db\": %.3f, \"reference_ms\": %.1f}\n",
                series, json_str(setup.scene_path).c_str(), ao, depth, ms, e.rmse, std::isinf(e.psnr) ? 99.0 : e.psnr, ref_ms);
    std::fflush(stdout);
  };

  double ref_ms = 0;
  {
    long keep = reps;
    reps = 1;
    Image ref = render(ao_ref, ao_depth, &ref_ms);
    reps = keep;
    for (int ao : ao_list) report("ao", ao, ao_depth, ref, ref_ms);
  }
  {
    long keep = reps;
    reps = 1;
    Image ref = render(0, depth_ref, &ref_ms);
    reps = keep;
    for (int d = 1; d <= depth_max; ++d) report("depth", 0, d, ref, ref_ms);
  }
  PacketLayout pl = rt.packet_layout();
  std::printf("{\"summary\": true, \"scene\": %s, \"frame\": %ld, \"width\": %d, \"height\": %d, \"ao_reference\": %d, "
              "\"depth_reference\": %d, \"ao_series_depth\": %d, \"reps\": %ld, \"cpu\": %s, \"isa\": %s, \"packet\": \"%dx%d\", "
              "\"threads\": %d}\n",
              json_str(setup.scene_path).c_str(), frame, full.x1, full.y1, ao_ref, depth_ref, ao_depth, reps,
              json_str(cpu_model()).c_str(), json_str(isa_name(pl)).c_str(), pl.w, pl.h, threads);
  return 0;
}

const Command reg("errorbench", "image error vs render time for AO rays and recursion depth", run);

}  // namespace
}  // namespace tessera::app
