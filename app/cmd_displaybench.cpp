// tessera displaybench --scene S.gltf --camera-loop L.json [--size W H] [--frame-count K] [--ao A]
//                      [--qualities 50,60,70,80,85,90,95] [--reps R] [--cluster-frames C] [--threads T]
// The displays' error against run time on rendered frames: renders K frames of the camera
// loop with the ray tracer (AO on), then encodes each with JPEG at every quality and with
// S3TC/DXT1 (libsquish range fit on 1 thread and on T threads as the node encodes, cluster fit
// on T threads for the first C frames), decodes it as the client would, and prints one JSON
// line per frame and method: encode time (median and range of R runs), bytes and PSNR against
// the rendered frame. A summary line with the conditions ends the output.
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "app/command.h"
#include "app/common.h"
#include "codecs/dxt1.h"
#include "codecs/jpeg.h"
#include "renderer/raytracer.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera displaybench --scene S.gltf --camera-loop L.json [--size W H] [--frame-count K] [--ao A] [--depth D]\n"
    "                     [--qualities 50,60,70,80,85,90,95] [--reps R] [--cluster-frames C] [--threads T]\n"
    "Renders K frames evenly spaced along the camera loop (AO A rays per hit, default 4), encodes each\n"
    "as JPEG at every quality and as DXT1 (range fit on 1 and T threads; cluster fit on T threads for\n"
    "the first C frames, default 1), and prints encode ms (median of R, with min and max), bytes and\n"
    "PSNR of the decoded frame against the rendered one.\n";

struct Timing {
  double median = 0, min = 0, max = 0;
};

template <class F>
Timing time_ms(long reps, F&& f) {
  std::vector<double> t;
  for (long i = 0; i < reps; ++i) {
    auto a = std::chrono::steady_clock::now();
    f();
    t.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count());
  }
  return {median(t), *std::min_element(t.begin(), t.end()), *std::max_element(t.begin(), t.end())};
}

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) { std::fputs(kHelp, stdout); return 0; }
  int threads = 0;
  auto limit = limit_threads(args, &threads);
  SceneSetup setup = load_scene(args, 1280, 720, LoopOption::required);
  const long frame_count = args.integer("--frame-count", 3);
  const long ao = args.integer("--ao", 4);
  const long depth = args.integer("--depth", 4);
  const long reps = args.integer("--reps", 5);
  const long cluster_frames = args.integer("--cluster-frames", 1);
  std::vector<int> qualities;
  for (double q : parse_number_list("--qualities", args.str("--qualities", "50,60,70,80,85,90,95"))) {
    if (q < 1 || q > 100) throw std::invalid_argument("--qualities: each must be within 1..100");
    qualities.push_back(int(q));
  }
  args.finish();
  if (frame_count < 1 || reps < 1 || ao < 0 || depth < 1 || cluster_frames < 0)
    throw std::invalid_argument("--frame-count >= 1, --reps >= 1, --ao >= 0, --depth >= 1, --cluster-frames >= 0");
  const int W = setup.loaded.scene.width(), H = setup.loaded.scene.height();
  const std::string scene = json_str(setup.scene_path);

  RayTracer rt;
  std::vector<std::string> warnings;
  JpegEncoder jpeg;
  std::vector<uint8_t> out(dxt1_size(W, H));
  for (long i = 0; i < frame_count; ++i) {
    const size_t k = size_t(i) * setup.loop.frames.size() / size_t(frame_count);
    setup.set_frame(k);
    rt.sync(setup.loaded.scene, warnings);
    RenderSettings rs;
    rs.ao_samples = int32_t(ao);
    rs.max_depth = int32_t(depth);
    rs.frame = uint32_t(k);
    TaskResult tr;
    rt.render(Rect{0, 0, W, H}, rs, tr);
    const Image& frame = tr.image;
    auto line = [&](const char* method, int quality, const char* fit, int enc_threads, const Timing& t, size_t bytes,
                    const Image& decoded) {
      ImageError e = compare(decoded, frame);
      std::printf("{\"scene\": %s, \"frame\": %zu, \"method\": \"%s\", \"quality\": %d, \"fit\": \"%s\", "
                  "\"encode_threads\": %d, \"encode_ms\": %.3f, \"encode_ms_min\": %.3f, \"encode_ms_max\": %.3f, "
                  "\"bytes\": %zu, \"bits_per_pixel\": %.3f, \"psnr_db\": %.3f, \"rmse\": %.4f, \"rendering_ms\": %.1f}\n",
                  scene.c_str(), k, method, quality, fit, enc_threads, t.median, t.min, t.max, bytes,
                  8.0 * double(bytes) / (double(W) * H), std::isinf(e.psnr) ? 99.0 : e.psnr, e.rmse, tr.rendering_ms);
      std::fflush(stdout);
    };
    // JPEG: one encoder thread, as the node's encoder actor.
    for (int q : qualities) {
      std::string err;
      bool ok = true;
      Timing t = time_ms(reps, [&] { ok = ok && jpeg.encode(frame, q, out, err); });
      if (!ok) throw std::runtime_error("jpeg encode: " + err);
      Image dec;
      if (!jpeg_decode(out.data(), out.size(), dec, err)) throw std::runtime_error("jpeg decode: " + err);
      line("jpeg", q, "", 1, t, out.size(), dec);
    }
    // DXT1: libsquish per block; block rows spread over an arena of the given threads.
    auto dxt1 = [&](Dxt1Fit fit, const char* name, int n, long r) {
      tbb::task_arena arena(n);
      Timing t = time_ms(r, [&] { arena.execute([&] { dxt1_encode(frame, fit, out); }); });
      line("dxt1", 0, name, n, t, out.size(), dxt1_decode(out.data(), W, H));
    };
    dxt1(Dxt1Fit::range, "range", 1, reps);
    if (threads > 1) dxt1(Dxt1Fit::range, "range", threads, reps);
    if (i < cluster_frames) dxt1(Dxt1Fit::cluster, "cluster", threads, 1);
  }
  PacketLayout pl = rt.packet_layout();
  std::printf("{\"summary\": true, \"bench\": \"displaybench\", \"scene\": %s, \"width\": %d, \"height\": %d, "
              "\"frames\": %ld, \"loop_frames\": %zu, \"ao\": %ld, \"depth\": %ld, \"reps\": %ld, \"cpu\": %s, "
              "\"isa\": %s, \"threads\": %d, \"jpeg_subsampling\": \"4:2:0\"}\n",
              scene.c_str(), W, H, frame_count, setup.loop.frames.size(), ao, depth, reps,
              json_str(cpu_model()).c_str(), json_str(isa_name(pl)).c_str(), threads);
  return 0;
}

const Command reg("displaybench", "display error against encode time: JPEG qualities and DXT1 fits on rendered frames",
                  run);

}  // namespace
}  // namespace tessera::app
