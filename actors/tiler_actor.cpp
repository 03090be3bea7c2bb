// Tiler actor: the SAT array of the last frame -> the tasks of the next (lb/tiler.h). With the
// last frame's depths and both cameras, the last frame's cost is first carried into the new
// view (lb/reproject.h) and the tasks are tiled from that one map.
#include <chrono>
#include <cmath>
#include <optional>

#include <caf/all.hpp>

#include "actors/node.h"
#include "lb/reproject.h"
#include "lb/sat.h"
#include "lb/tiler.h"
#include "renderer/disturbance.h"  // thread_cpu_ns

namespace tessera {
namespace {

struct tiler_state {
  std::vector<double> coefficients;
  std::optional<SatArray> sats;
  int32_t width = 0, height = 0;
  PacketLayout layout;
  // The last frame's packet points (decoded from its depths) and its camera; empty when it
  // gave none (the paper's predictor then).
  PacketPoints points;
  std::vector<float> camera;
  // The last partial round's SATs (SatReport::partial), at width x height in `layout`; reset by
  // every whole frame's report.
  std::optional<SatArray> partial;
  static inline const char* name = "tessera.tiler";
};

// The report's SATs as one array, each with its node's single-core performance; a node without a
// SAT, or with one that does not parse, is left to SatArray's missing-area rule. `rects`: each
// node's packets (empty: no SAT). Throws what SatArray throws on SATs that do not fit.
SatArray sat_array(const SatReport& r, PacketLayout layout, std::vector<Rect>* rects) {
  SatArray arr(packet_space(r.width, r.height, layout));
  if (rects) rects->assign(r.sats.size(), Rect{});
  for (size_t i = 0; i < r.sats.size(); ++i) {
    if (r.sats[i].empty()) continue;
    std::string err;
    auto sat = Sat::try_deserialize(r.sats[i].data(), r.sats[i].size(), &err);
    if (!sat) continue;
    if (rects) (*rects)[i] = sat->packets();
    arr.add(std::move(*sat), i < r.perf.size() && r.perf[i] > 0 ? r.perf[i] : 1.0);
  }
  arr.finalize();
  return arr;
}

tiler_actor::behavior_type tiler_impl(tiler_actor::stateful_pointer<tiler_state> self, std::vector<double> coefficients) {
  self->state.coefficients = std::move(coefficients);
  return {
      [=](sats_atom, const SatReport& r) {
        auto& st = self->state;
        if (r.partial) {  // a partial round's: beside the whole frame's, if it matches them
          st.partial.reset();
          if (!st.sats || r.width != st.width || r.height != st.height || r.packet_w != st.layout.w ||
              r.packet_h != st.layout.h)
            return;
          try {
            st.partial = sat_array(r, st.layout, nullptr);
          } catch (const std::exception&) {
            st.partial.reset();
          }
          return;
        }
        st.partial.reset();
        st.sats.reset();
        st.points = {};
        st.camera.clear();
        st.width = r.width;
        st.height = r.height;
        st.layout = {r.packet_w, r.packet_h};
        try {
          std::vector<Rect> rects;  // each node's packets (empty: no SAT)
          st.sats = sat_array(r, st.layout, &rects);
          // The points, where the report has a camera and depths: a node's depths that do not
          // fit its SAT are left out (its packets count as unknown: filled, or a cut).
          Camera cam;
          if (unpack_camera(r.camera, cam) && r.depths.size() == r.sats.size()) {
            const ViewRays from = ViewRays::of(cam, r.width, r.height);
            const Rect space = st.sats->packet_space();
            PacketPoints pts{space, std::vector<float>(size_t(space.area()) * 4, 0.0f)};
            for (size_t i = 3; i < pts.xyzw.size(); i += 4) pts.xyzw[i] = -1;
            bool any = false;
            for (size_t i = 0; i < r.sats.size(); ++i)
              if (!rects[i].empty() && decode_depths(r.depths[i].data(), r.depths[i].size(), rects[i], from, st.layout, pts))
                any = true;
            if (any) {
              st.points = std::move(pts);
              st.camera = r.camera;
            }
          }
        } catch (const std::exception&) {
          st.sats.reset();  // inconsistent SATs: the next frame is split by area
          st.points = {};
          st.camera.clear();
        }
      },
      [=](nodes_atom, std::vector<double>& coefficients) {
        bool ok = !coefficients.empty();
        for (double c : coefficients) ok &= std::isfinite(c) && c > 0;
        if (ok) self->state.coefficients = std::move(coefficients);
      },
      [=](tasks_atom, const TaskRequest& req) -> TaskList {
        auto& st = self->state;
        auto t0 = std::chrono::steady_clock::now();
        PacketLayout layout{req.packet_w, req.packet_h};
        Rect space = packet_space(req.width, req.height, layout);
        bool use = st.sats && st.width == req.width && st.height == req.height && st.layout.w == layout.w &&
                   st.layout.h == layout.h;
        TaskList out;
        out.frame = req.frame;
        out.from_sats = use;
        out.predictor = uint8_t(use ? Predictor::previous : Predictor::area);
        const SatArray* sats = use ? &*st.sats : nullptr;
        if (use && req.partial && st.partial) {  // a partial round after another: its map, as it is
          for (const Rect& r : tile(&*st.partial, space, st.coefficients))
            out.tasks.push_back(packets_to_pixels(r, layout, req.width, req.height));
          out.tiling_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
          return out;
        }
        // Reprojection: the last frame's cost in this frame's camera, as one SAT. Not when the
        // camera did not move (the map is already where it belongs).
        std::optional<SatArray> carried;
        Camera cam;
        if (use && !st.points.xyzw.empty() && req.camera != st.camera && unpack_camera(req.camera, cam)) {
          auto t_rep = std::chrono::steady_clock::now();
          // The thread's CPU time too: the carry's own cost, apart from preemption (a dedicated
          // master shares its core with other work).
          const uint64_t cpu0 = thread_cpu_ns();
          ReprojectStats rs;
          // Large frames are carried in blocks of packets (lb/reproject.h, reproject_blocks): at
          // most about 16k items, under a millisecond or so of one core.
          int32_t block = 1;
          while (space.area() / (int64_t(block) * block) > 16384 && block < 8) block *= 2;
          CostMap map = reproject_blocks(st.sats->cost_map(), st.points, ViewRays::of(cam, req.width, req.height), layout,
                                         block, &rs);
          if (rs.cut) {
            out.predictor = uint8_t(Predictor::cut);
          } else {
            carried.emplace(space);
            carried->add(Sat::from_cost_map(map));
            carried->finalize();
            sats = &*carried;
            out.predictor = uint8_t(Predictor::reprojected);
            out.filled = rs.filled;
          }
          out.reproject_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_rep).count();
          out.reproject_cpu_ms = double(thread_cpu_ns() - cpu0) * 1e-6;
        }
        for (const Rect& r : tile(sats, space, st.coefficients))
          out.tasks.push_back(packets_to_pixels(r, layout, req.width, req.height));
        out.tiling_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        return out;
      },
  };
}

}  // namespace

tiler_actor spawn_tiler(caf::actor_system& sys, std::vector<double> coefficients) {
  return sys.spawn(tiler_impl, std::move(coefficients));
}

}  // namespace tessera
