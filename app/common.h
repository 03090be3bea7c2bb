#pragma once
// Helpers shared by the render, bench and balance subcommands.
#include <memory>
#include <string>
#include <vector>

#include <tbb/global_control.h>

#include "app/args.h"
#include "core/gltf_loader.h"
#include "renderer/renderer.h"

namespace tessera::app {

std::string cpu_model();
int hardware_threads();

// --threads N as a TBB limit that lives as long as the result.
// default_threads: the count without --threads (0: every hardware thread).
std::unique_ptr<tbb::global_control> limit_threads(Args& args, int* threads, int default_threads = 0);

// --ao N --depth D --shadows 0|1 --ao-distance X
RenderSettings read_settings(Args& args);

// --renderer raytracer|rasterizer (ray tracer by default), checked.
std::string read_renderer_kind(Args& args);
// A renderer of that kind ("raytracer" or "rasterizer").
std::unique_ptr<Renderer> make_renderer(const std::string& kind);

// Loads --scene (+ optional --camera-loop), sets the resolution from --size W H, and the
// quality of the meshes' BVHs from --bvh-quality medium|high (default medium).
struct SceneSetup {
  LoadedScene loaded;
  CameraLoop loop;     // empty frames when no loop was given
  std::string scene_path;
  void set_frame(size_t k);  // camera of loop frame k (no-op without a loop)
  // Replay step f of a loop walked every `step` frames (wrapping): the camera of that loop
  // frame, and the AO pattern seeded with it. Returns the loop frame. Needs a loop.
  size_t replay(long f, long step, RenderSettings& settings);
};
// --frame K: with a camera loop, a loop frame in 0..frames-1; without one, the AO pattern's
// seed (0..2^32-1). Anything else is refused with the valid range (it used to wrap silently).
long read_frame(Args& args, const SceneSetup& setup);
enum class LoopOption { optional, required };  // required: no --camera-loop is an error
SceneSetup load_scene(Args& args, int default_w = 1280, int default_h = 720,
                      LoopOption loop_option = LoopOption::optional);

// "1,2,4" -> {1, 2, 4}; throws std::invalid_argument naming the option on a bad number.
std::vector<double> parse_number_list(const std::string& option, const std::string& text);

// JSON string escaping for the figures we print.
std::string json_str(const std::string& s);
double median(std::vector<double> v);
// The value below which a fraction q of v lies (nearest rank; 0 when empty).
double percentile(std::vector<double> v, double q);
// printf into a std::string of whatever length the result has.
std::string format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));

}  // namespace tessera::app
