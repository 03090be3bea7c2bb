#pragma once
// The reference rasterizer (paper section 5.1): OpenGL ES 3 through EGL with no window
// (EGL_PLATFORM_SURFACELESS_MESA), rendering into an offscreen framebuffer that is read
// back as RGBA. On a machine without a GPU this is Mesa's llvmpipe.
//
// It shades exactly as the web client's WebGL fallback (web/src/render/XML3DMaterial.js):
// XML3D matte / diffuse / phong with textures and alpha masks, point, directional and spot
// lights with XML3D attenuation, no shadows, no reflection, refraction or ambient occlusion,
// transparent materials alpha-blended back to front. See docs/renderer.md.
//
// A GL context belongs to a thread. The context is created lazily on the first sync or
// render, made current at the start of every call and released at its end, so the object
// may be used from any one thread at a time (a detached actor, a test, a command).
#include <memory>
#include <string>

#include "renderer/renderer.h"

namespace tessera {

class Rasterizer final : public Renderer {
 public:
  Rasterizer();
  ~Rasterizer() override;
  Rasterizer(const Rasterizer&) = delete;
  Rasterizer& operator=(const Rasterizer&) = delete;

  const char* name() const override { return "rasterizer"; }
  // Both throw std::runtime_error with a message naming the EGL/GL step that failed when
  // no context can be created (no EGL implementation, no device, no GLES 3).
  void sync(const Scene& scene, std::vector<std::string>& warnings) override;
  // Renders the rectangle with a scissor over the full frame's viewport and projection, so
  // that tiles compose into exactly the full image. The cost map stays empty (a plain area
  // split balances it, docs/renderer.md); no rays are counted.
  void render(const Rect& pixels, const RenderSettings& settings, TaskResult& out) override;
  PacketLayout packet_layout() const override { return {1, 1}; }

  // The GL_RENDERER / GL_VERSION strings of the context (creates it if needed).
  std::string gl_description();

  // What the last sync uploaded (for tests of incrementality).
  struct SyncStats {
    int geometries_uploaded = 0, textures_uploaded = 0, instances_updated = 0, instances_removed = 0;
  };
  SyncStats last_sync() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

// Tells whether an EGL surfaceless GLES 3 context can be created on this machine; on
// failure *why says why. Used by tests to skip (exit 77) on machines without Mesa's EGL.
bool rasterizer_available(std::string* why);

}  // namespace tessera
