// Tiler actor: the SAT array of the last frame -> the tasks of the next (lb/tiler.h).
#include <chrono>
#include <cmath>
#include <optional>

#include <caf/all.hpp>

#include "actors/node.h"
#include "lb/sat.h"
#include "lb/tiler.h"

namespace tessera {
namespace {

struct tiler_state {
  std::vector<double> coefficients;
  std::optional<SatArray> sats;
  int32_t width = 0, height = 0;
  PacketLayout layout;
  static inline const char* name = "tessera.tiler";
};

tiler_actor::behavior_type tiler_impl(tiler_actor::stateful_pointer<tiler_state> self, std::vector<double> coefficients) {
  self->state.coefficients = std::move(coefficients);
  return {
      [=](sats_atom, const SatReport& r) {
        auto& st = self->state;
        st.sats.reset();
        st.width = r.width;
        st.height = r.height;
        st.layout = {r.packet_w, r.packet_h};
        try {
          SatArray arr(packet_space(r.width, r.height, st.layout));
          for (size_t i = 0; i < r.sats.size(); ++i) {
            if (r.sats[i].empty()) continue;  // a node without a SAT: filled by SatArray's missing-area rule
            std::string err;
            auto sat = Sat::try_deserialize(r.sats[i].data(), r.sats[i].size(), &err);
            if (!sat) continue;
            double perf = i < r.perf.size() && r.perf[i] > 0 ? r.perf[i] : 1.0;
            arr.add(std::move(*sat), perf);
          }
          arr.finalize();
          st.sats = std::move(arr);
        } catch (const std::exception&) {
          st.sats.reset();  // inconsistent SATs: the next frame is split by area
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
        for (const Rect& r : tile(use ? &*st.sats : nullptr, space, st.coefficients))
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
