// tessera quality: image quality against time, for a fixed frame and for a still that refines
// (progressive samples averaged, renderer/sampling.h), against a converged reference.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <sys/stat.h>

#include "app/command.h"
#include "app/common.h"
#include "renderer/accumulation.h"
#include "renderer/adaptive.h"
#include "renderer/denoise.h"
#include "renderer/raytracer.h"
#include "renderer/sampling.h"

namespace tessera::app {
namespace {

const char* kHelp =
    "tessera quality --scene S.gltf --camera-loop L.json [--frame K] [--size W H] [--threads T]\n"
    "                [--mode fixed|progressive|progressive+denoise|adaptive|adaptive+denoise] [--seconds S]\n"
    "                [--ao N] [--depth D]\n"
    "                [--ao-list 1,2,4,8,16,32] [--max-samples M]\n"
    "                [--reference-samples R] [--reference-ao A] [--cache DIR]\n"
    "Image quality against render time, as PSNR against a converged reference: the average of R\n"
    "progressive samples (default 1024; jittered anti-aliasing, A AO rays each, default 4), made\n"
    "once and cached in DIR (default $XDG_CACHE_HOME/tessera or ~/.cache/tessera) by scene file,\n"
    "size, frame and settings.\n"
    "  fixed: today's frame (one sample per pixel, N AO rays per hit) for each N of --ao-list.\n"
    "  progressive: a still that refines: sample after sample (--ao N rays each, default 4, the\n"
    "  node's still-ao-samples) averaged, until --seconds (default 5) of rendering or\n"
    "  --max-samples (default 65536).\n"
    "  progressive+denoise: the same, denoised as the node denoises a still (renderer/denoise.h,\n"
    "  with the guides of its first sample) while the plain average's estimated PSNR is below\n"
    "  --denoise-below-db D (default the node's, 0..99; 99: always), averaged plainly after; while\n"
    "  denoised, only the steps the node shows are measured (samples 1-4, then each a quarter\n"
    "  more), the others count in the time. The denoising counts in the time.\n"
    "  --denoise-iterations K (default 5) sets its passes, --denoise-sigma S (default 4) its value\n"
    "  weight; --denoise-from S (default 2, the node's rule) the first sample denoised.\n"
    "  adaptive: the progressive still refined adaptively (renderer/adaptive.h): every packet's\n"
    "  first --adaptive-uniform U samples (default 4), then rounds that each render the packets\n"
    "  where a sample lowers the error most per unit of time, --adaptive-round F (default 0.125) of\n"
    "  a whole sample's cost a round, until every packet has --max-samples or an error out of\n"
    "  sight (--adaptive-done E, default 0.25, in 8-bit steps squared). \"samples\" is then the\n"
    "  mean over the pixels (the work in whole samples), the step the round. Each round's line\n"
    "  also has plan_ms, render_ms, add_ms (adding it to the still) and average_ms, and\n"
    "  planned_cost_ms and cost_ms: the plan's blocks at their last measured cost and the round's\n"
    "  own cost map, summed over the packets and divided by --threads.\n"
    "  adaptive+denoise: the node's default: denoised as progressive+denoise while every pixel\n"
    "  renders each round, adaptive rounds once the plain average is clean enough.\n"
    "--write-png F writes the last image measured (the last step's average, or the last fixed frame).\n"
    "One JSON line per step (samples, elapsed_ms, psnr_db), then a summary line with\n"
    "seconds_to_psnr for 30, 35 and 40 dB (null: not reached), the step that reached each level\n"
    "(samples_to_psnr, or ao_to_psnr for fixed: exact, unlike the seconds on a shared machine),\n"
    "the median time of a sample, the load and the ISA.\n";

std::string load_now() {
  std::ifstream f("/proc/loadavg");
  std::string a;
  f >> a;
  return a.empty() ? "?" : a;
}

std::string cache_dir(const std::string& given) {
  if (!given.empty()) return given;
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return std::string(x) + "/tessera";
  if (const char* h = std::getenv("HOME"); h && *h) return std::string(h) + "/.cache/tessera";
  return ".cache/tessera";
}

void make_dirs(const std::string& path) {
  for (size_t at = 1; at != std::string::npos; at = path.find('/', at + 1)) ::mkdir(path.substr(0, at).c_str(), 0755);
  ::mkdir(path.c_str(), 0755);
}

uint64_t fnv1a(const std::string& s, uint64_t h = 1469598103934665603ull) {
  for (unsigned char c : s) h = (h ^ c) * 1099511628211ull;
  return h;
}

// What makes a reference: the scene file's bytes, the view and the settings, and a version that
// changes with what the renderer computes.
std::string reference_key(const SceneSetup& setup, long frame, const RenderSettings& s, uint32_t samples) {
  std::ifstream f(setup.scene_path, std::ios::binary);
  std::stringstream bytes;
  bytes << f.rdbuf();
  std::ostringstream k;
  k << std::hex << fnv1a(bytes.str()) << std::dec << "-" << setup.loaded.scene.width() << "x"
    << setup.loaded.scene.height() << "-f" << frame << "-ao" << s.ao_samples << "-d" << s.max_depth << "-s"
    << samples << "-v5";  // v5: trilinear texture filtering (mip levels by ray cones)
  return k.str();
}

// Renders samples [first, first + n) of the still and adds them to `acc`. With `ao`, every
// sample also writes its guides: the first sample's are kept in *guides, and every sample's
// open fractions go to *ao.
void refine(RayTracer& rt, const Rect& full, RenderSettings s, uint32_t first, uint32_t n, Accumulation& acc,
            StillAo* ao = nullptr, std::vector<float>* guides = nullptr) {
  TaskResult r;
  s.cost_map = false;
  s.radiance = true;
  s.guides = ao != nullptr;
  for (uint32_t i = 0; i < n; ++i) {
    s.sample = first + i;
    rt.render(full, s, r);
    acc.add(r.radiance, full.width(), full.height(), 0, 0);
    acc.end_sample();
    if (!ao) continue;
    if (s.sample == 0) {
      ao->reset(full.width(), full.height());
      *guides = r.guides;
    }
    ao->add(r.guides);
  }
}

// When each level was first reached: seconds (noisy on a shared machine) and the step that
// reached it (exact: samples of a refining still, AO rays per hit of a fixed frame).
struct Levels {
  double at[3] = {-1, -1, -1};  // seconds to 30, 35, 40 dB; -1: not reached
  long step[3] = {-1, -1, -1};
  void see(double psnr, double seconds, long at_step) {
    const double level[3] = {30, 35, 40};
    for (int i = 0; i < 3; ++i)
      if (psnr >= level[i] && (at[i] < 0 || seconds < at[i])) at[i] = seconds, step[i] = at_step;
  }
  std::string json(bool steps) const {
    std::string out = "{";
    const char* names[3] = {"30", "35", "40"};
    for (int i = 0; i < 3; ++i) {
      char buf[64];
      if (at[i] < 0) std::snprintf(buf, sizeof buf, "%s\"%s\": null", i ? ", " : "", names[i]);
      else if (steps) std::snprintf(buf, sizeof buf, "%s\"%s\": %ld", i ? ", " : "", names[i], step[i]);
      else std::snprintf(buf, sizeof buf, "%s\"%s\": %.3f", i ? ", " : "", names[i], at[i]);
      out += buf;
    }
    return out + "}";
  }
};

double finite_db(double psnr) { return std::isinf(psnr) ? 99.0 : psnr; }

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) {
    std::fputs(kHelp, stdout);
    return 0;
  }
  int threads = 0;
  auto limit = limit_threads(args, &threads);
  SceneSetup setup = load_scene(args, 1280, 720);
  const long frame = read_frame(args, setup);
  const std::string mode = args.str("--mode", "progressive");
  const double seconds = args.number("--seconds", 5);
  const int ao = int(args.integer("--ao", sampling::kStillAoSamples));
  const int depth = int(args.integer("--depth", 4));
  std::vector<int> ao_list;
  for (double v : parse_number_list("--ao-list", args.str("--ao-list", "1,2,4,8,16,32"))) ao_list.push_back(int(v));
  const long max_samples = args.integer("--max-samples", 65536);
  const long ref_samples = args.integer("--reference-samples", 1024);
  const int ref_ao = int(args.integer("--reference-ao", 4));
  const std::string dir = cache_dir(args.str("--cache", ""));
  const std::string png_out = args.str("--write-png", "");
  DenoiseOptions denoise_options;
  denoise_options.iterations = int(args.integer("--denoise-iterations", denoise_options.iterations));
  denoise_options.sigma_value = float(args.number("--denoise-sigma", denoise_options.sigma_value));
  const double denoise_below_db = args.number("--denoise-below-db", kDenoiseBelowDb);
  const long denoise_from = args.integer("--denoise-from", 2);
  AdaptiveOptions adaptive;
  adaptive.uniform = uint32_t(args.integer("--adaptive-uniform", adaptive.uniform));
  adaptive.round_cost = args.number("--adaptive-round", adaptive.round_cost);
  adaptive.done_below = args.number("--adaptive-done", adaptive.done_below);
  args.finish();
  if (denoise_from < 1 || denoise_from > 4) throw std::invalid_argument("--denoise-from must be in 1..4");
  const bool adaptive_mode = mode == "adaptive" || mode == "adaptive+denoise";
  const bool denoised = mode == "progressive+denoise" || mode == "adaptive+denoise";
  if (mode != "fixed" && mode != "progressive" && !denoised && !adaptive_mode)
    throw std::invalid_argument("--mode must be fixed, progressive, progressive+denoise, adaptive or adaptive+denoise");
  if (adaptive.uniform < 2 || adaptive.uniform > 65536) throw std::invalid_argument("--adaptive-uniform must be in 2..65536");
  if (!(adaptive.round_cost > 0 && adaptive.round_cost <= 1)) throw std::invalid_argument("--adaptive-round must be in (0, 1]");
  if (!(adaptive.done_below >= 0 && adaptive.done_below <= 1e6)) throw std::invalid_argument("--adaptive-done must be in 0..1e6");
  if (denoise_options.iterations < 0 || denoise_options.iterations > 10)
    throw std::invalid_argument("--denoise-iterations must be in 0..10");
  if (!(denoise_options.sigma_value > 0) || !std::isfinite(denoise_options.sigma_value))
    throw std::invalid_argument("--denoise-sigma must be a number > 0");
  if (!(denoise_below_db >= 0 && denoise_below_db <= 99)) throw std::invalid_argument("--denoise-below-db must be in 0..99");
  if (!(seconds > 0)) throw std::invalid_argument("--seconds must be > 0");
  if (ao < 0 || ao > 4096 || ref_ao < 1 || ref_ao > 4096) throw std::invalid_argument("--ao 0..4096, --reference-ao 1..4096");
  if (depth < 1 || depth > 64) throw std::invalid_argument("--depth must be in 1..64");
  if (max_samples < 1 || max_samples > 65536) throw std::invalid_argument("--max-samples must be in 1..65536");
  if (ref_samples < 1 || ref_samples > 65536) throw std::invalid_argument("--reference-samples must be in 1..65536");
  for (int n : ao_list)
    if (n < 0 || n > 4096) throw std::invalid_argument("--ao-list values must be in 0..4096");
  setup.set_frame(size_t(frame));

  RayTracer rt;
  std::vector<std::string> warnings;
  rt.sync(setup.loaded.scene, warnings);
  for (auto& w : warnings) std::fprintf(stderr, "quality: %s\n", w.c_str());
  const int W = setup.loaded.scene.width(), H = setup.loaded.scene.height();
  const Rect full{0, 0, W, H};
  const bool srgb = setup.loaded.scene.environment().linear;
  // Denoising filters the AO of what shows the sky's ambient light (renderer/denoise.h): on a
  // scene without one, or with AO off, there is nothing to filter, and the guides would only
  // cost time. Said once, as the node says of settings that change nothing.
  const bool filter = denoised && ao > 0 && max_component(setup.loaded.scene.environment().ambient) > 0;
  if (denoised && !filter)
    std::fprintf(stderr, "quality: %s has nothing to filter here (%s): the still is averaged plainly\n", mode.c_str(),
                 ao > 0 ? "the scene has no sky or ambient light" : "--ao 0");
  RenderSettings base;
  base.max_depth = depth;
  base.frame = uint32_t(frame);

  // The reference, from the cache or made now.
  RenderSettings ref_settings = base;
  ref_settings.ao_samples = ref_ao;
  // Its own scrambling of the sequences: the same seeds would put the first samples of the
  // measured run exactly where the reference's are, and its PSNR would read high.
  ref_settings.frame = base.frame ^ 0x5EED5EEDu;
  const std::string path =
      dir + "/quality-" + reference_key(setup, frame, ref_settings, uint32_t(ref_samples)) + ".png";
  Image ref;
  double ref_s = 0;
  bool cached = false;
  try {
    ref = read_image(path);
    cached = ref.width == W && ref.height == H;
  } catch (const std::exception&) {
  }
  if (!cached) {
    std::fprintf(stderr, "quality: making the reference (%ld samples, %d AO rays each) into %s\n", ref_samples, ref_ao,
                 path.c_str());
    const auto t0 = std::chrono::steady_clock::now();
    Accumulation acc;
    acc.reset(W, H, srgb);
    refine(rt, full, ref_settings, 0, uint32_t(ref_samples), acc);
    ref = acc.average();
    ref_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    make_dirs(dir);
    write_png(path, ref);
  }

  // One untimed render first: the first one after a sync pays for page faults and the
  // threads' start (about 25% more on the living room), which would be charged to step 1.
  {
    RenderSettings warm = base;
    warm.ao_samples = 1;
    warm.cost_map = false;
    TaskResult r;
    rt.render(full, warm, r);
  }
  const std::string load0 = load_now();
  Levels levels;
  double last_db = 0, elapsed_s = 0;
  uint32_t samples = 0;
  std::vector<double> step_ms;  // progressive: each sample's time
  if (mode == "fixed") {
    TaskResult r;
    for (int n : ao_list) {
      RenderSettings s = base;
      s.ao_samples = n;
      s.cost_map = false;
      const auto t0 = std::chrono::steady_clock::now();
      rt.render(full, s, r);
      const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double db = finite_db(compare(r.image, ref).psnr);
      if (!png_out.empty()) write_png(png_out, r.image);
      levels.see(db, t, n);
      last_db = db;
      elapsed_s = t;
      samples = 1;
      std::printf("{\"mode\": \"fixed\", \"ao\": %d, \"samples\": 1, \"elapsed_ms\": %.1f, \"psnr_db\": %.3f}\n", n,
                  t * 1e3, db);
      std::fflush(stdout);
    }
  } else if (adaptive_mode) {
    // Round after round, as the node refines a still (frame_actor.cpp): with denoising, every
    // pixel each round while the plain average is denoised (its shown steps only measured, as
    // in progressive+denoise), adaptive rounds after. Rendering, accumulating, planning and
    // denoising count as time (not the PSNR).
    AdaptiveStill still;
    still.reset(W, H, srgb, uint32_t(max_samples), adaptive);
    StillAo still_ao;
    std::vector<float> guides;
    bool denoising = filter;
    uint32_t shown = 0;
    RenderSettings s = base;
    s.ao_samples = ao;
    s.radiance = true;
    TaskResult r;
    using clock = std::chrono::steady_clock;
    const auto ms = [](clock::time_point a, clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
    while (elapsed_s < seconds && !still.converged()) {
      const auto t0 = clock::now();
      still.set_uniform(denoising);
      s.block_samples = still.plan().data();
      s.plan_blocks = still.blocks();
      s.guides = denoising;
      if (still.converged()) break;
      const auto t1 = clock::now();
      const double planned_ns = still.planned_cost();
      rt.render(full, s, r);
      const auto t2 = clock::now();
      double cost_ns = 0;  // the round's cost map: its packets' summed time
      for (uint32_t c : r.cost.cost) cost_ns += c;
      still.add(r.radiance, &r.cost, rt.packet_layout());
      if (denoising) {
        if (still.rounds() == 1) {
          still_ao.reset(W, H);
          guides = r.guides;
        }
        still_ao.add(r.guides);
      }
      const auto t3 = clock::now();
      const uint32_t rounds = still.rounds();
      if (denoising && rounds >= uint32_t(denoise_from) && !shown_while_denoising(rounds, shown, uint32_t(max_samples))) {
        const double dt = std::chrono::duration<double>(clock::now() - t0).count();
        elapsed_s += dt;
        step_ms.push_back(dt * 1e3);
        continue;
      }
      shown = rounds;
      Image avg;
      if (denoising && rounds >= uint32_t(denoise_from)) {
        DenoisedStep step = denoise_step(still, guides, still_ao, denoise_below_db, denoise_options);
        denoising = step.denoised;
        avg = std::move(step.image);
      } else {
        avg = still.average();
      }
      const auto t4 = clock::now();
      const double dt = std::chrono::duration<double>(t4 - t0).count();
      elapsed_s += dt;
      step_ms.push_back(dt * 1e3);
      const double db = finite_db(compare(avg, ref).psnr);
      if (!png_out.empty()) write_png(png_out, avg);
      levels.see(db, elapsed_s, long(rounds));
      last_db = db;
      samples = rounds;
      std::printf("{\"mode\": \"%s\", \"ao\": %d, \"round\": %u, \"samples\": %.3f, \"blocks\": %zu, "
                  "\"plan_ms\": %.1f, \"render_ms\": %.1f, \"planned_cost_ms\": %.1f, \"cost_ms\": %.1f, "
                  "\"add_ms\": %.1f, \"average_ms\": %.1f, \"elapsed_ms\": %.1f, \"psnr_db\": %.3f}\n",
                  mode.c_str(), ao, rounds, still.mean_samples(), still.planned(), ms(t0, t1), ms(t1, t2),
                  planned_ns / 1e6 / threads, cost_ns / 1e6 / threads, ms(t2, t3), ms(t3, t4), elapsed_s * 1e3, db);
      std::fflush(stdout);
    }
  } else {
    // Sample after sample; only rendering and accumulating count as time (not the PSNR).
    Accumulation acc;
    acc.reset(W, H, srgb);
    StillAo still_ao;
    std::vector<float> guides;
    RenderSettings s = base;
    s.ao_samples = ao;
    // Denoising as the node does (frame_actor.cpp): while the plain average's estimated PSNR
    // is below --denoise-below-db (NodeSettings::denoise_below_db), and only at the steps the
    // node shows (shown_while_denoising); the samples between count in the time and are not
    // measured. Past the threshold the still is averaged plainly, and its later samples write
    // no guides.
    bool denoising = filter;
    uint32_t shown = 0;
    while (elapsed_s < seconds && acc.samples() < uint32_t(max_samples)) {
      const auto t0 = std::chrono::steady_clock::now();
      refine(rt, full, s, acc.samples(), 1, acc, denoising ? &still_ao : nullptr, &guides);
      if (denoising && acc.samples() >= uint32_t(denoise_from) && !shown_while_denoising(acc.samples(), shown, uint32_t(max_samples))) {
        const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        elapsed_s += dt;
        step_ms.push_back(dt * 1e3);
        continue;
      }
      shown = acc.samples();
      double estimate = -1;  // the plain average's estimated PSNR; -1: not estimated
      Image avg;
      if (denoising && acc.samples() >= uint32_t(denoise_from)) {  // before: plain frames, as in the node
        DenoisedStep step = denoise_step(acc, guides, still_ao, denoise_below_db, denoise_options);
        estimate = step.estimate_db;
        denoising = step.denoised;
        avg = std::move(step.image);
      } else {
        avg = acc.average();
      }
      const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      elapsed_s += dt;
      step_ms.push_back(dt * 1e3);
      const double db = finite_db(compare(avg, ref).psnr);
      if (!png_out.empty()) write_png(png_out, avg);
      levels.see(db, elapsed_s, long(acc.samples()));
      last_db = db;
      samples = acc.samples();
      std::printf("{\"mode\": \"%s\", \"ao\": %d, \"samples\": %u, \"elapsed_ms\": %.1f, \"psnr_db\": %.3f",
                  mode.c_str(), ao, samples, elapsed_s * 1e3, db);
      if (estimate >= 0) {  // untimed: how the estimate and the plain average compare
        const double plain_db = finite_db(compare(acc.average(), ref).psnr);
        std::printf(", \"plain_psnr_db\": %.3f, \"estimated_plain_db\": %.3f, \"denoised\": %s", plain_db,
                    finite_db(estimate), denoising ? "true" : "false");
      }
      std::printf("}\n");
      std::fflush(stdout);
    }
  }
  const PacketLayout pl = rt.packet_layout();
  std::printf(
      "{\"summary\": true, \"mode\": \"%s\", \"scene\": %s, \"frame\": %ld, \"width\": %d, \"height\": %d, "
      "\"depth\": %d, \"ao\": %s, \"samples\": %u, \"elapsed_s\": %.3f, \"psnr_db\": %.3f, \"seconds_to_psnr\": %s, "
      "\"%s\": %s, \"ms_per_sample_median\": %s, "
      "\"reference\": {\"samples\": %ld, \"ao\": %d, \"cached\": %s, \"made_s\": %.1f, \"path\": %s}, "
      "\"cpu\": %s, \"isa\": %s, \"packet\": \"%dx%d\", \"threads\": %d, \"load_start\": \"%s\", \"load_end\": \"%s\"}\n",
      mode.c_str(), json_str(setup.scene_path).c_str(), frame, W, H, depth,
      mode == "fixed" ? "null" : std::to_string(ao).c_str(), samples, elapsed_s, last_db,
      levels.json(false).c_str(), mode == "fixed" ? "ao_to_psnr" : "samples_to_psnr", levels.json(true).c_str(),
      step_ms.empty() ? "null" : std::to_string(median(step_ms)).c_str(), ref_samples, ref_ao, cached ? "true" : "false", ref_s, json_str(path).c_str(),
      json_str(cpu_model()).c_str(), json_str(isa_name(pl)).c_str(), pl.w, pl.h, threads, load0.c_str(),
      load_now().c_str());
  return 0;
}

const Command reg("quality", "image quality (PSNR) against time: a fixed frame and a refining still", run);

}  // namespace
}  // namespace tessera::app
