// libFuzzer target: what a hostile cluster peer can send (actors/cluster_protocol.h). The
// first byte picks the message; the rest is read by CAF 0.17's binary_deserializer, as the
// middleman reads a message's fields, into:
//   0  RenderBatch (parent -> worker), checked by check_batch, then the worker's task_of for
//      each task (an accepted batch's plan of blocks must cover every task)
//   1  BatchReply (worker -> parent), each tile checked by check_tile (checks.h) against a
//      task of the parent's own 64x48 frame, as Router does
//   2  TileResult alone, checked the same way
//   3  OpenRequest (parent -> node)
//   4  std::vector<NodeInfo> (a nodes query's answer), checked by check_nodes
//   5  SceneSnapshot: its load callback runs scene_snapshot_from_bytes, i.e. apply_records
//      of the client-protocol records inside (actors/node.h)
//   6  the raw payload of an update (update_atom, bytes, reset) given to apply_records with
//      a node's default limits
//   7  an update's Payload as the middleman deserialises it, then given to apply_records
// Messages holding actor handles (OpenReply, ChildLink) are left out: deserialising a handle
// needs the middleman's proxy registry, CAF's code rather than ours.
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include <caf/binary_deserializer.hpp>
#include <caf/error.hpp>

#include "actors/messages.h"
#include "actors/node.h"
#include "actors/checks.h"
#include "lb/reproject.h"
#include "lb/sat.h"

using namespace tessera;

namespace {

constexpr uint32_t kFrame = 7;
constexpr int32_t kWidth = 64, kHeight = 48;
const Rect kTasks[2] = {{0, 0, 32, 48}, {32, 0, 64, 48}};

template <class T>
bool read(const uint8_t* data, size_t size, T& x) {
  caf::binary_deserializer src{nullptr, reinterpret_cast<const char*>(data), size};
  caf::error err = src(x);
  return !err;
}

void check(const TileResult& t, size_t i, PacketLayout layout) {
  std::string bad = check_tile(t, kFrame, kTasks[i % 2], layout, kWidth, kHeight);
  // An accepted tile has its pixels, or stopped early (TileResult::cancelled) with none at all.
  const size_t want = t.cancelled ? 0 : size_t(kTasks[i % 2].area()) * 4;
  if (bad.empty() && (t.rgba.size() != want || (t.cancelled && (!t.sat.empty() || !t.depth.empty() || !t.radiance.empty())))) {
    std::fprintf(stderr, "check_tile passed a tile with %zu bytes of pixels (stopped early: %d)\n", t.rgba.size(),
                 int(t.cancelled));
    std::abort();
  }
  // What the master's tiler does with an accepted tile's SAT and depths: decode the depths and
  // carry the cost into a turned camera (any float in them must be safe).
  if (bad.empty() && !t.sat.empty() && !t.depth.empty()) {
    Sat sat = Sat::deserialize(t.sat);
    SatArray arr(packet_space(kWidth, kHeight, layout));
    arr.add(sat);
    arr.finalize();
    Camera a, b;
    b.to_world = Mat4::rotate({0, 1, 0}, 0.1f);
    const Rect space = arr.packet_space();
    PacketPoints pts{space, std::vector<float>(size_t(space.area()) * 4, -1.0f)};
    if (!decode_depths(t.depth.data(), t.depth.size(), sat.packets(), ViewRays::of(a, kWidth, kHeight), layout, pts)) {
      std::fprintf(stderr, "check_tile passed depths that do not decode\n");
      std::abort();
    }
    ReprojectStats st;
    CostMap m = reproject(arr.cost_map(), pts, ViewRays::of(b, kWidth, kHeight), layout, &st);
    if (m.packets != space || m.cost.size() != size_t(space.area())) std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const uint8_t mode = data[0] % 8;
  const PacketLayout layout = (data[0] & 0x80) ? PacketLayout{4, 2} : PacketLayout{4, 4};
  ++data;
  --size;
  switch (mode) {
    case 0: {
      RenderBatch b;
      if (read(data, size, b)) {
        static const NodeSettings settings;
        const bool accepted = check_batch(b, settings.limits).empty();
        for (const Rect& r : b.tasks) {
          const RenderTask t = task_of(b, r);
          // An accepted batch's plan covers each task's blocks exactly as the renderer checks it.
          if (accepted && !b.plan.empty() && !r.empty() &&
              (t.plan.empty() || !check_plan(t.plan_blocks, t.plan, b.width, b.height, r).empty())) {
            std::fprintf(stderr, "an accepted batch's plan does not cover its task\n");
            std::abort();
          }
        }
      }
      break;
    }
    case 1: {
      BatchReply r;
      if (read(data, size, r))
        for (size_t i = 0; i < r.tiles.size(); ++i) check(r.tiles[i], i, layout);
      break;
    }
    case 2: {
      TileResult t;
      if (read(data, size, t)) check(t, 0, layout);
      break;
    }
    case 3: {
      OpenRequest o;
      (void)read(data, size, o);
      break;
    }
    case 4: {
      std::vector<NodeInfo> nodes;
      if (read(data, size, nodes) && check_nodes(nodes).empty()) (void)nodes_value(nodes).dump();
      break;
    }
    case 5: {
      SceneSnapshot s;
      if (read(data, size, s)) {
        if (!s.scene) std::abort();  // accepted without a scene
        (void)scene_snapshot_bytes(s);
      }
      break;
    }
    case 6: {
      static const NodeSettings settings;
      Scene scene;
      (void)apply_records(scene, std::vector<uint8_t>(data, data + size), settings.limits);
      break;
    }
    case 7: {  // an update message's payload as the middleman reads it, then applied
      static const NodeSettings settings;
      Payload p;
      if (read(data, size, p)) {
        Scene scene;
        (void)apply_records(scene, p.bytes, settings.limits);
      }
      break;
    }
  }
  return 0;
}
