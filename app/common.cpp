#include "app/common.h"

#include <algorithm>
#include <cstdarg>
#include <cstdio>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <thread>

#include "renderer/embree_device.h"
#include "renderer/rasterizer.h"
#include "renderer/raytracer.h"

namespace tessera::app {

std::string cpu_model() {
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("model name", 0) == 0) {
      auto p = line.find(':');
      return p == std::string::npos ? line : line.substr(p + 2);
    }
  return "unknown";
}

int hardware_threads() { return int(std::max(1u, std::thread::hardware_concurrency())); }

std::unique_ptr<tbb::global_control> limit_threads(Args& args, int* threads, int default_threads) {
  int t = int(args.integer("--threads", default_threads > 0 ? default_threads : hardware_threads()));
  if (t < 1 || t > 1024) throw std::invalid_argument("--threads must be in 1..1024");
  if (threads) *threads = t;
  return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, size_t(t));
}

RenderSettings read_settings(Args& args) {
  RenderSettings s;
  s.ao_samples = int(args.integer("--ao", 0));
  s.max_depth = int(args.integer("--depth", 4));
  s.shadows = args.integer("--shadows", 1) != 0;
  s.ao_distance = float(args.number("--ao-distance", 0));
  if (s.ao_samples < 0 || s.ao_samples > 4096) throw std::invalid_argument("--ao must be in 0..4096");
  if (s.max_depth < 1 || s.max_depth > 64) throw std::invalid_argument("--depth must be in 1..64");
  if (!(s.ao_distance >= 0 && std::isfinite(s.ao_distance)))
    throw std::invalid_argument("--ao-distance must be a finite number >= 0 (0: 10% of the scene's extent)");
  return s;
}

std::string read_renderer_kind(Args& args) {
  std::string kind = args.str("--renderer", "raytracer");
  if (kind != "raytracer" && kind != "rasterizer")
    throw std::invalid_argument("--renderer must be raytracer or rasterizer, not '" + kind + "'");
  return kind;
}

std::unique_ptr<Renderer> make_renderer(const std::string& kind) {
  if (kind == "rasterizer") return std::make_unique<Rasterizer>();
  if (kind == "raytracer") return std::make_unique<RayTracer>();
  throw std::invalid_argument("unknown renderer '" + kind + "'");
}

void SceneSetup::set_frame(size_t k) {
  if (!loop.frames.empty()) loaded.scene.set_camera(loop.camera(k));
}

long read_frame(Args& args, const SceneSetup& setup) {
  const long frame = args.integer("--frame", 0);
  const long last = setup.loop.frames.empty() ? long(UINT32_MAX) : long(setup.loop.frames.size()) - 1;
  if (frame < 0 || frame > last) {
    if (setup.loop.frames.empty())
      throw std::invalid_argument("--frame " + std::to_string(frame) + " outside 0.." + std::to_string(last) +
                                  " (without --camera-loop it seeds the AO pattern)");
    throw std::invalid_argument("--frame " + std::to_string(frame) + " outside the camera loop's frames 0.." +
                                std::to_string(last));
  }
  return frame;
}

size_t SceneSetup::replay(long f, long step, RenderSettings& settings) {
  const size_t k = size_t(f * step) % loop.frames.size();
  set_frame(k);
  settings.frame = uint32_t(k);
  return k;
}

SceneSetup load_scene(Args& args, int default_w, int default_h, LoopOption loop_option) {
  SceneSetup s;
  s.scene_path = args.required("--scene");
  long w = args.integer("--size", default_w, 0), h = args.integer("--size", default_h, 1);
  if (w < 0 || h < 0 || w > 16384 || h > 16384) throw std::invalid_argument("--size must be within 0..16384");
  std::string loop = args.str("--camera-loop");
  if (loop_option == LoopOption::required && loop.empty()) throw std::invalid_argument("--camera-loop is required");
  bool plain = args.flag("--plain");
  const std::string bvh = args.str("--bvh-quality", "medium");
  if (bvh != "high" && bvh != "medium") throw std::invalid_argument("--bvh-quality must be high or medium, not '" + bvh + "'");
  EmbreeDevice::set_high_quality_bvh(bvh == "high");
  GltfOptions options;
  options.default_lighting = args.flag("--default-light");
  s.loaded = load_gltf(s.scene_path, options);
  if (plain) {  // strip every optional shading feature (for kernel comparisons)
    Scene& sc = s.loaded.scene;
    std::vector<std::pair<Id, Material>> mats;
    for (auto& [id, e] : sc.materials()) mats.emplace_back(id, e.value);
    for (auto& [id, m] : mats) {
      m.diffuse_texture = m.specular_texture = m.emissive_texture = kNoId;
      m.reflection = m.refraction = 0;
      m.alpha_mask = false;
      m.opacity = 1;
      sc.set_material(id, m);
    }
  }
  s.loaded.scene.set_resolution(int32_t(w), int32_t(h));
  if (!loop.empty()) s.loop = load_camera_loop(loop);
  return s;
}

std::vector<double> parse_number_list(const std::string& option, const std::string& text) {
  std::vector<double> v;
  size_t p = 0;
  while (p < text.size()) {
    size_t q = text.find(',', p);
    if (q == std::string::npos) q = text.size();
    std::string item = text.substr(p, q - p);
    char* end = nullptr;
    double x = std::strtod(item.c_str(), &end);
    if (item.empty() || !end || *end) throw std::invalid_argument(option + ": '" + item + "' is not a number");
    v.push_back(x);
    p = q + 1;
  }
  return v;
}

std::string json_str(const std::string& s) {
  std::string o = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') { o += '\\'; o += c; }
    else if (static_cast<unsigned char>(c) < 0x20) { o += ' '; }
    else o += c;
  }
  return o + "\"";
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

std::string format(const char* fmt, ...) {
  va_list a, b;
  va_start(a, fmt);
  va_copy(b, a);
  const int n = std::max(std::vsnprintf(nullptr, 0, fmt, a), 0);
  va_end(a);
  std::string s(size_t(n) + 1, '\0');
  std::vsnprintf(s.data(), s.size(), fmt, b);
  va_end(b);
  s.resize(size_t(n));
  return s;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t rank = size_t(std::ceil(q * double(v.size())));
  return v[std::min(v.size() - 1, rank > 0 ? rank - 1 : 0)];
}

}  // namespace tessera::app
