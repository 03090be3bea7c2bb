// Renderer actor: syncs its renderer (the ray tracer or the rasterizer, as the task says)
// with the snapshot, renders the task, builds and serialises the SAT of the task's cost map
// (SAT generation happens on the rendering node, paper 6.2, so only the SAT travels to the
// tiler). The rasterizer's GL context is created on its first task, in this actor's thread;
// when it cannot be created the task fails with the reason and the actor keeps serving.
#include <chrono>
#include <cstring>
#include <exception>

#include <caf/all.hpp>

#include "actors/checks.h"
#include "actors/errors.h"
#include "actors/node.h"
#include "renderer/rasterizer.h"
#include "renderer/raytracer.h"
#include "lb/reproject.h"
#include "lb/sat.h"

namespace tessera {
namespace {

struct renderer_state {
  std::unique_ptr<RayTracer> rt;
  std::unique_ptr<Rasterizer> raster;  // created on the first rasterizer task
  std::vector<std::string> warnings;
  static inline const char* name = "tessera.renderer";
};

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

renderer_actor::behavior_type renderer_impl(renderer_actor::stateful_pointer<renderer_state> self, PacketLayout layout,
                                            std::shared_ptr<const CancelMark> cancel) {
  // Its scene copy, BVH and buffers are the bulk of a session's memory, and they are freed when
  // this actor ends, which on a busy node can be well after its session ended: trim after it.
  self->attach_functor([] { schedule_heap_trim(); });
  return {
      // A task it cannot take is a bad_task error; a renderer that fails (Embree's error, a
      // GL context that cannot be made, memory) a render_failed error with the reason.
      [=](render_atom, const SceneSnapshot& snap, const RenderTask& task) -> caf::result<TileResult> {
        using protocol::ErrorCode;
        if (task.renderer > 1) return make_error(ErrorCode::bad_task, "unknown renderer " + std::to_string(int(task.renderer)));
        if (task.radiance && task.renderer != 0)
          return make_error(ErrorCode::bad_task, "radiance asked of the rasterizer (progressive stills are ray traced)");
        if (task.guides > kOpenGuides || (task.guides != kNoGuides && !task.radiance))
          return make_error(ErrorCode::bad_task, "guides kind " + std::to_string(int(task.guides)) +
                                                     " (guides go with radiance: 1 all, 2 the open fraction)");
        if (!snap.scene) return make_error(ErrorCode::bad_task, "render task without a scene");
        if (snap.scene->width() != task.width || snap.scene->height() != task.height)
          return make_error(ErrorCode::bad_task, "scene resolution does not match the task");
        if (!task.plan.empty() && !task.radiance)
          return make_error(ErrorCode::bad_task, "a plan of blocks for a task that is no sample of a still");
        if (std::string why = check_plan(task.plan_blocks, task.plan, task.width, task.height, task.pixels); !why.empty())
          return make_error(ErrorCode::bad_task, why);
        TileResult out;
        out.frame = task.frame;
        out.pixels = task.pixels;
        try {
          auto& st = self->state;
          Renderer* renderer = nullptr;
          if (task.renderer == 1) {
            if (!st.raster) st.raster = std::make_unique<Rasterizer>();
            renderer = st.raster.get();
          } else {
            if (!st.rt) st.rt = std::make_unique<RayTracer>(layout);
            renderer = st.rt.get();
          }
          st.warnings.clear();
          renderer->sync(*snap.scene, st.warnings);
          RenderSettings s;
          s.ao_samples = task.ao_samples;
          s.max_depth = task.max_depth;
          s.frame = task.seed ? task.seed : task.frame;
          s.sample = task.sample;
          if (!task.plan.empty()) {
            s.block_samples = task.plan.data();
            s.plan_blocks = task.plan_blocks;
          }
          s.radiance = task.radiance;
          s.guides = task.guides != kNoGuides;
          s.cost_map = true;
          s.hit_points = task.hit_points && task.renderer == 0;
          if (cancel) {
            s.cancel_through = &cancel->through;
            s.cancel_frame = task.frame;
          }
          TaskResult r;
          renderer->render(task.pixels, s, r);
          out.cancelled = r.cancelled;
          out.pixels = r.pixels;
          out.kernel_ms = r.kernel_ms;
          out.rendering_ms = r.rendering_ms;
          // Stopped early: nobody reads its pixels, so none are copied or sent (check_tile).
          if (r.cancelled) return out;
          out.rays = r.rays.total();
          out.rgba = std::move(r.image.rgba);
          if (task.radiance) {
            out.radiance.resize(r.radiance.size() * sizeof(float));
            if (!r.radiance.empty()) std::memcpy(out.radiance.data(), r.radiance.data(), out.radiance.size());
          }
          if (task.guides == kAllGuides) {
            out.guides.resize(r.guides.size() * sizeof(float));
            if (!r.guides.empty()) std::memcpy(out.guides.data(), r.guides.data(), out.guides.size());
          } else if (task.guides == kOpenGuides) {  // the open fraction alone (the last of a pixel's guides)
            const size_t pixels = r.guides.size() / kGuideFloats;
            out.guides.resize(pixels * sizeof(float));
            for (size_t p = 0; p < pixels; ++p)
              std::memcpy(out.guides.data() + p * sizeof(float), &r.guides[p * kGuideFloats + kGuideFloats - 1], sizeof(float));
          }
          if (!r.cost.cost.empty()) {
            auto t0 = std::chrono::steady_clock::now();
            Sat sat = Sat::from_cost_map(r.cost);
            sat.serialize_into(out.sat);
            out.sat_ms = ms_since(t0);
          }
          if (s.hit_points && r.points.packets == r.cost.packets && !r.points.xyzw.empty())
            out.depth = encode_depths(r.points, ViewRays::of(snap.scene->camera(), task.width, task.height));
        } catch (const std::exception& e) {
          return make_error(ErrorCode::render_failed, e.what());
        }
        return out;
      },
  };
}

}  // namespace

renderer_actor spawn_renderer(caf::actor_system& sys, PacketLayout layout, bool detached,
                              std::shared_ptr<const CancelMark> cancel) {
  if (detached) return sys.spawn<caf::detached>(renderer_impl, layout, std::move(cancel));
  return sys.spawn(renderer_impl, layout, std::move(cancel));
}

}  // namespace tessera
