#pragma once
// glTF 2.0 scenes into the scene model: meshes (instanced through nodes), materials
// (incl. KHR_materials_transmission, KHR_materials_ior, KHR_materials_emissive_strength,
// alphaMode MASK/BLEND), KHR_lights_punctual, cameras, and the sky described in
// scenes[0].extras.environment as an ambient term.
#include <string>
#include <vector>

#include "core/scene.h"

namespace tessera {

struct Bounds {
  Vec3 lo{1e30f, 1e30f, 1e30f}, hi{-1e30f, -1e30f, -1e30f};
  void extend(const Vec3& p) {
    lo = {std::fmin(lo.x, p.x), std::fmin(lo.y, p.y), std::fmin(lo.z, p.z)};
    hi = {std::fmax(hi.x, p.x), std::fmax(hi.y, p.y), std::fmax(hi.z, p.z)};
  }
  bool valid() const { return lo.x <= hi.x; }
  float extent() const { return valid() ? length(hi - lo) : 0.0f; }
};

struct LoadedScene {
  Scene scene;
  // Where the load's time went (tessera bench prints them as "load"): tinygltf reading the
  // JSON and the buffers, decoding the images the textures use, and building the scene.
  struct Times {
    double parse_ms = 0, images_ms = 0, convert_ms = 0;
  } times;
  Bounds bounds;                      // world bounds of all instances
  bool has_camera = false;            // the scene's first camera node was found
  // The file has lit materials but no lights and no sky, so they render black, as they do in
  // an XML3D page without lights (`dark`); with GltfOptions::default_lighting the scene holds a
  // default sun and sky instead (`default_lighting`). Callers say either in a note (not a
  // warning: nothing was left out).
  bool dark = false;
  bool default_lighting = false;
  std::vector<std::string> warnings;  // things left out or repaired, each naming the file
};

struct GltfOptions {
  bool parallel_images = true;  // decode the images on every TBB thread (false: one after another)
  // A file with lit materials and no lights and no sky gets a sun over the camera's shoulder
  // and a sky (the commands' --default-light), as glTF viewers light such models.
  bool default_lighting = false;
};
// Throws std::runtime_error naming the file and what is wrong; never crashes on a broken file.
LoadedScene load_gltf(const std::string& path, const GltfOptions& options = {});
// What callers print when LoadedScene::dark or ::default_lighting is set ("" when neither).
std::string lighting_note(const std::string& path, const LoadedScene& loaded);

// A recorded camera loop (../shared/scenes/*/camera-loop.json).
struct CameraLoop {
  float fov_y_deg = 45;
  struct Frame {
    Vec3 eye, target, up;
  };
  std::vector<Frame> frames;
  Camera camera(size_t frame) const;  // frame taken modulo the loop length
};
CameraLoop load_camera_loop(const std::string& path);

}  // namespace tessera
