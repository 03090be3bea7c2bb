#pragma once
// The core of `tessera applybench`: times apply (update/scene_update.h) on a scene of many small
// meshes, as a client uploading a large scene sends it. Header-only and dependent only on
// protocol/protocol.h, update/scene_update.h and core/scene.h, so bench/apply_before_after.sh
// can compile it against an older protocol.cpp/scene.cpp to show the before/after figures in
// one run.
#include <chrono>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "protocol/protocol.h"
#include "core/scene.h"
#include "update/scene_update.h"

namespace tessera::bench {

struct ApplyFigures {
  size_t meshes = 0, records = 0;
  double total_ms = 0;
  double first_ms_per_1k = 0, last_ms_per_1k = 0;  // mesh records: the first and the last 1000
};

// Applies, for each of `meshes` meshes, a float3 position buffer (one triangle), a uint32 index
// buffer and the mesh; with `shared_vertices` > 0 every mesh instead instances one shared
// geometry of that many vertices (the per-record validation then reads a big buffer).
inline ApplyFigures apply_meshes(size_t meshes, size_t shared_vertices) {
  using namespace protocol;
  using Clock = std::chrono::steady_clock;
  std::vector<ClientRecord> recs;
  auto make_buffers = [&](Id pos, Id idx, size_t verts) {
    SetBuffer p;
    p.id = pos;
    p.buffer.type = Buffer::Type::f32;
    p.buffer.components = 3;
    for (size_t v = 0; v < verts; ++v) {
      p.buffer.f.push_back(float(v % 7));
      p.buffer.f.push_back(float(v % 5));
      p.buffer.f.push_back(float(v % 3));
    }
    SetBuffer i;
    i.id = idx;
    i.buffer.type = Buffer::Type::u32;
    i.buffer.components = 1;
    for (size_t v = 0; v + 2 < verts; v += 3) i.buffer.u.insert(i.buffer.u.end(), {uint32_t(v), uint32_t(v + 1), uint32_t(v + 2)});
    recs.push_back(std::move(p));
    recs.push_back(std::move(i));
  };
  if (shared_vertices) make_buffers(1, 2, shared_vertices);
  std::vector<size_t> mesh_at;  // index in recs of each mesh record
  for (size_t k = 0; k < meshes; ++k) {
    Id base = Id(10 + 2 * k);
    if (!shared_vertices) make_buffers(base, base + 1, 3);
    SetMesh m;
    m.id = Id(k + 1);
    m.mesh.positions = shared_vertices ? 1 : base;
    m.mesh.indices = shared_vertices ? 2 : base + 1;
    m.mesh.transform = Mat4::translate({float(k), 0, 0});
    mesh_at.push_back(recs.size());
    recs.push_back(std::move(m));
  }
  Scene scene;
  Limits lim;
  lim.max_triangles = uint64_t(1) << 40;
  std::vector<double> t_rec(recs.size());
  const auto t0 = Clock::now();
  for (size_t r = 0; r < recs.size(); ++r) {
    const auto a = Clock::now();
    Status s = apply(scene, std::move(recs[r]), lim);
    t_rec[r] = std::chrono::duration<double, std::milli>(Clock::now() - a).count();
    if (!s) throw std::runtime_error("apply failed: " + s.error().message);
  }
  ApplyFigures f;
  f.total_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  f.meshes = meshes;
  f.records = recs.size();
  const size_t k = std::min<size_t>(1000, meshes);
  for (size_t i = 0; i < k; ++i) {
    f.first_ms_per_1k += t_rec[mesh_at[i]];
    f.last_ms_per_1k += t_rec[mesh_at[meshes - k + i]];
  }
  f.first_ms_per_1k *= 1000.0 / double(k ? k : 1);
  f.last_ms_per_1k *= 1000.0 / double(k ? k : 1);
  if (scene.meshes().size() != meshes) throw std::runtime_error("scene holds the wrong number of meshes");
  return f;
}

}  // namespace tessera::bench
