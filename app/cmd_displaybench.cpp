// tessera displaybench --scene S.gltf --camera-loop L.json [--size W H] [--frame-count K] [--ao A]
//                      [--qualities 50,60,70,80,85,90,95] [--reps R] [--cluster-frames C] [--threads T]
//                      [--video-frames N] [--bitrates 1000,2000,4000,8000,16000] [--fps F]
// The displays' error against run time on rendered frames: renders K frames of the camera
// loop with the ray tracer (AO on), then encodes each with JPEG at every quality and with
// S3TC/DXT1 (libsquish range fit on 1 thread and on T threads as the node encodes, cluster fit
// on T threads for the first C frames), decodes it as the client would, and prints one JSON
// line per frame and method: encode time (median and range of R runs), bytes and PSNR against
// the rendered frame. With --video-frames N it then renders N consecutive loop frames and
// encodes them as one H.264 stream per bitrate (as a session does: the first frame a keyframe,
// the rest P-frames), decoding each with OpenH264 as the browser would, beside JPEG q85 of the
// same frames: one JSON line per bitrate (and for JPEG) with bytes per frame, encode ms and PSNR.
// A summary line with the conditions ends the output.
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "app/command.h"
#include "app/common.h"
#include "codecs/dxt1.h"
#include "codecs/h264.h"
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
    "PSNR of the decoded frame against the rendered one.\n"
    "--video-frames N (default 0: none) then renders N consecutive loop frames and encodes them as\n"
    "an H.264 stream at each of --bitrates (kbit/s at --fps, default 30) and as JPEG q85: bytes per\n"
    "frame (P-frames and all), encode ms and PSNR of each decoded frame against the rendered one;\n"
    "--video-threads T (1..4, default 1, as the node) codes T slices in parallel; --per-frame also\n"
    "prints each H.264 frame's bytes, encode ms and PSNR.\n";

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
  const long video_frames = args.integer("--video-frames", 0);
  const double fps = args.number("--fps", 30);
  const long video_threads = args.integer("--video-threads", 1);
  const bool per_frame = args.flag("--per-frame");
  std::vector<uint32_t> bitrates;
  for (double b : parse_number_list("--bitrates", args.str("--bitrates", "1000,2000,4000,8000,16000"))) {
    if (b < kH264MinKbps || b > kH264MaxKbps) throw std::invalid_argument("--bitrates: each must be within 100..200000");
    bitrates.push_back(uint32_t(b));
  }
  std::vector<int> qualities;
  for (double q : parse_number_list("--qualities", args.str("--qualities", "50,60,70,80,85,90,95"))) {
    if (q < 1 || q > 100) throw std::invalid_argument("--qualities: each must be within 1..100");
    qualities.push_back(int(q));
  }
  args.finish();
  if (frame_count < 1 || reps < 1 || ao < 0 || depth < 1 || cluster_frames < 0 || video_frames < 0 || !(fps >= 1))
    throw std::invalid_argument(
        "--frame-count >= 1, --reps >= 1, --ao >= 0, --depth >= 1, --cluster-frames >= 0, --video-frames >= 0, --fps >= 1");
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
  // H.264: N consecutive loop frames (each seeded as the node seeds successive frames) as one
  // stream per bitrate, beside JPEG q85 of the same frames.
  std::vector<Image> seq;
  for (long i = 0; i < video_frames; ++i) {
    const size_t k = size_t(i) % setup.loop.frames.size();
    setup.set_frame(k);
    rt.sync(setup.loaded.scene, warnings);
    RenderSettings rs;
    rs.ao_samples = int32_t(ao);
    rs.max_depth = int32_t(depth);
    rs.frame = uint32_t(i + 1);
    TaskResult tr;
    rt.render(Rect{0, 0, W, H}, rs, tr);
    seq.push_back(std::move(tr.image));
  }
  struct StreamFigures {
    std::vector<double> encode_ms, psnr;
    double bytes_all = 0, bytes_p = 0;
    size_t p_frames = 0;
  };
  auto stream_line = [&](const char* method, uint32_t kbps, const StreamFigures& f) {
    std::vector<double> ps = f.psnr;
    std::sort(ps.begin(), ps.end());
    std::printf("{\"scene\": %s, \"video\": true, \"method\": \"%s\", \"bitrate_kbps\": %u, \"fps\": %.1f, "
                "\"frames\": %zu, \"bytes_per_frame\": %.0f, \"bytes_per_p_frame\": %.0f, \"mbit_s_at_fps\": %.2f, "
                "\"encode_ms_median\": %.3f, \"psnr_db_median\": %.3f, \"psnr_db_min\": %.3f}\n",
                scene.c_str(), method, kbps, fps, f.psnr.size(), f.bytes_all / double(f.psnr.size()),
                f.p_frames ? f.bytes_p / double(f.p_frames) : 0.0, f.bytes_all * 8 * fps / double(f.psnr.size()) / 1e6,
                median(f.encode_ms), ps.empty() ? 0.0 : ps[ps.size() / 2], ps.empty() ? 0.0 : ps.front());
    std::fflush(stdout);
  };
  if (!seq.empty()) {
    StreamFigures jf;
    for (const Image& img : seq) {
      std::string err;
      Timing t = time_ms(reps, [&] { jpeg.encode(img, 85, out, err); });
      Image dec;
      if (!jpeg_decode(out.data(), out.size(), dec, err)) throw std::runtime_error("jpeg decode: " + err);
      jf.encode_ms.push_back(t.median);
      jf.psnr.push_back(compare(dec, img).psnr);
      jf.bytes_all += double(out.size());
      jf.bytes_p += double(out.size());
      jf.p_frames++;
    }
    stream_line("jpeg_q85", 0, jf);
    for (uint32_t kbps : bitrates) {
      H264Encoder enc{int(video_threads)};
      H264Decoder dec;
      StreamFigures hf;
      for (const Image& img : seq) {
        H264Unit unit;
        std::string err;
        auto a = std::chrono::steady_clock::now();
        if (!enc.encode(img.rgba.data(), W, H, kbps, float(fps), false, out, unit, err))
          throw std::runtime_error("h264 encode: " + err);
        hf.encode_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count());
        Image got;
        if (!dec.decode(out.data(), out.size(), got, err, W, H)) throw std::runtime_error("h264 decode: " + err);
        hf.psnr.push_back(compare(got, img).psnr);
        if (per_frame)
          std::printf("{\"scene\": %s, \"video_frame\": %zu, \"bitrate_kbps\": %u, \"keyframe\": %s, "
                      "\"bytes\": %zu, \"encode_ms\": %.3f, \"psnr_db\": %.3f}\n",
                      scene.c_str(), hf.psnr.size() - 1, kbps, unit.keyframe ? "true" : "false", out.size(),
                      hf.encode_ms.back(), hf.psnr.back());
        hf.bytes_all += double(out.size());
        if (!unit.keyframe) hf.bytes_p += double(out.size()), hf.p_frames++;
      }
      stream_line("h264", kbps, hf);
    }
  }
  PacketLayout pl = rt.packet_layout();
  std::printf("{\"summary\": true, \"bench\": \"displaybench\", \"scene\": %s, \"width\": %d, \"height\": %d, "
              "\"frames\": %ld, \"loop_frames\": %zu, \"video_frames\": %ld, \"ao\": %ld, \"depth\": %ld, "
              "\"reps\": %ld, \"cpu\": %s, \"isa\": %s, \"threads\": %d, \"jpeg_subsampling\": \"4:2:0\", "
              "\"h264\": \"OpenH264 constrained baseline, no frame skip\", \"video_threads\": %ld}\n",
              scene.c_str(), W, H, frame_count, setup.loop.frames.size(), video_frames, ao, depth, reps,
              json_str(cpu_model()).c_str(), json_str(isa_name(pl)).c_str(), threads, video_threads);
  return 0;
}

const Command reg("displaybench", "display error against encode time: JPEG qualities and DXT1 fits on rendered frames",
                  run);

}  // namespace
}  // namespace tessera::app
