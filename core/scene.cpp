#include "core/scene.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include "core/validate.h"

namespace tessera {

uint64_t Scene::next_version() {
  static std::atomic<uint64_t> counter{0};
  return counter.fetch_add(1, std::memory_order_relaxed) + 1;
}

bool Texture::has_alpha() const {
  // The AND of every texel in parallel chunks: its alpha byte stays 255 only if every texel's
  // is (a San Miguel-sized scene's textures hold 230 M texels; both renderers ask at sync).
  const uint8_t* p = rgba.data();
  const size_t texels = rgba.size() / 4;
  const uint32_t all = tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, texels, 1 << 16), ~uint32_t(0),
      [&](const tbb::blocked_range<size_t>& r, uint32_t acc) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          uint32_t t;
          std::memcpy(&t, p + i * 4, 4);
          acc &= t;
        }
        return acc;
      },
      [](uint32_t a, uint32_t b) { return a & b; });
  uint8_t alpha[4];
  std::memcpy(alpha, &all, 4);
  return alpha[3] != 255;
}

std::vector<std::pair<Id, const Mesh*>> Scene::renderable_meshes(std::vector<std::string>& warnings) const {
  std::vector<std::pair<Id, const Mesh*>> out;
  for (auto& [id, e] : meshes()) {
    if (!e.value.visible) continue;
    std::string err = validate_mesh(e.value);
    if (err.empty()) out.emplace_back(id, &e.value);
    else warnings.push_back("mesh " + std::to_string(id) + " not rendered: " + err);
  }
  return out;
}

std::string Scene::validate_mesh(const Mesh& m) const {
  const Buffer* pos = buffer(m.positions);
  if (!pos) return "mesh references missing position buffer " + std::to_string(m.positions);
  if (pos->type != Buffer::Type::f32 || pos->components != 3) return "position buffer must be float3";
  size_t nv = pos->count();
  // The per-buffer facts (computed when the buffer was set) make this O(log n) per mesh.
  const BufferIndex& pos_index = buffer_index_.at(m.positions);
  if (!pos_index.finite) return "position buffer " + std::to_string(m.positions) + " holds NaN or Inf";
  if (m.normals != kNoId) {
    const Buffer* n = buffer(m.normals);
    if (!n) return "mesh references missing normal buffer " + std::to_string(m.normals);
    if (n->type != Buffer::Type::f32 || n->components != 3) return "normal buffer must be float3";
    if (n->count() != nv) return "normal count " + std::to_string(n->count()) + " != vertex count " + std::to_string(nv);
  }
  if (m.texcoords != kNoId) {
    const Buffer* t = buffer(m.texcoords);
    if (!t) return "mesh references missing texcoord buffer " + std::to_string(m.texcoords);
    if (t->type != Buffer::Type::f32 || t->components != 2) return "texcoord buffer must be float2";
    if (t->count() != nv) return "texcoord count " + std::to_string(t->count()) + " != vertex count " + std::to_string(nv);
  }
  if (m.colors != kNoId) {
    const Buffer* c = buffer(m.colors);
    if (!c) return "mesh references missing colour buffer " + std::to_string(m.colors);
    if (c->type != Buffer::Type::f32 || c->components != 3) return "colour buffer must be float3";
    if (c->count() != nv) return "colour count " + std::to_string(c->count()) + " != vertex count " + std::to_string(nv);
    if (!buffer_index_.at(m.colors).finite) return "colour buffer " + std::to_string(m.colors) + " holds NaN or Inf";
  }
  if (m.indices != kNoId) {
    const Buffer* ib = buffer(m.indices);
    if (!ib) return "mesh references missing index buffer " + std::to_string(m.indices);
    if (ib->type != Buffer::Type::u32 || ib->components != 1) return "index buffer must be uint32 scalars";
    if (ib->u.size() % 3) return "index count " + std::to_string(ib->u.size()) + " is not a multiple of 3";
    if (buffer_index_.at(m.indices).max_index > nv)  // some index is out of range: name the first
      for (uint32_t i : ib->u)
        if (i >= nv) return "index " + std::to_string(i) + " out of range (vertex count " + std::to_string(nv) + ")";
  } else if (nv % 3) {
    return "non-indexed mesh needs a multiple of 3 vertices, has " + std::to_string(nv);
  }
  if (!m.transform.finite()) return "mesh transform holds NaN or Inf";
  const TransformFigures f = transform_figures(m.transform);  // once a sync per mesh: computed once
  std::string why = check_transform(f, kMeshLimits);
  if (why.empty()) why = check_world_extent(f, pos_index.max_abs);
  if (!why.empty()) return "mesh transform: " + why;
  return {};
}

uint64_t Scene::mesh_triangles(const Mesh& m) const {
  if (!m.visible) return 0;
  return m.indices != kNoId ? index_triangles(buffer(m.indices)) : position_triangles(buffer(m.positions));
}

void Scene::count_mesh(const Mesh& m, int sign) {
  if (!m.visible) return;
  if (sign > 0) triangles_ += mesh_triangles(m);
  else triangles_ -= mesh_triangles(m);
  const Id id = m.indices != kNoId ? m.indices : m.positions;
  BufferIndex& ix = buffer_index_[id];
  (m.indices != kNoId ? ix.index_refs : ix.position_refs) += uint32_t(sign);
  if (ix.index_refs == 0 && ix.position_refs == 0 && !buffer(id)) buffer_index_.erase(id);
}

void Scene::set_buffer(Id id, Buffer b) {
  BufferIndex& ix = buffer_index_[id];
  const Buffer* old = buffer(id);
  // Triangles of the meshes that take theirs from this buffer change with it.
  triangles_ -= ix.index_refs * index_triangles(old) + ix.position_refs * position_triangles(old);
  triangles_ += ix.index_refs * index_triangles(&b) + ix.position_refs * position_triangles(&b);
  held_bytes_ -= old ? old->bytes() : 0;
  held_bytes_ += b.bytes();
  ix.finite = true;
  ix.max_abs = 0;
  for (float v : b.f) {
    ix.finite = ix.finite && std::isfinite(v);
    ix.max_abs = std::max(ix.max_abs, std::fabs(v));
  }
  ix.max_index = 0;
  for (uint32_t i : b.u) ix.max_index = std::max<uint64_t>(ix.max_index, uint64_t(i) + 1);
  put(buffers_, id, std::move(b));
}

bool Scene::remove_buffer(Id id) {
  const Buffer* old = buffer(id);
  if (!old) return false;
  BufferIndex& ix = buffer_index_[id];
  triangles_ -= ix.index_refs * index_triangles(old) + ix.position_refs * position_triangles(old);
  held_bytes_ -= old->bytes();
  ix.finite = true;
  ix.max_abs = 0;
  ix.max_index = 0;
  if (ix.index_refs == 0 && ix.position_refs == 0) buffer_index_.erase(id);
  return drop(buffers_, id);
}

void Scene::set_texture(Id id, Texture t) {
  const Texture* old = texture(id);
  held_bytes_ -= old ? old->rgba.size() : 0;
  held_bytes_ += t.rgba.size();
  put(textures_, id, std::move(t));
}

bool Scene::remove_texture(Id id) {
  const Texture* old = texture(id);
  if (!old) return false;
  held_bytes_ -= old->rgba.size();
  return drop(textures_, id);
}

void Scene::set_mesh(Id id, Mesh m) {
  auto it = meshes_.find(id);
  if (it != meshes_.end()) count_mesh(it->second.value, -1);
  count_mesh(m, +1);
  put(meshes_, id, std::move(m));
}

bool Scene::remove_mesh(Id id) {
  auto it = meshes_.find(id);
  if (it == meshes_.end()) return false;
  count_mesh(it->second.value, -1);
  return drop(meshes_, id);
}

uint64_t Scene::triangles_with_buffer(Id id, const Buffer* b) const {
  auto it = buffer_index_.find(id);
  if (it == buffer_index_.end()) return triangles_;
  const BufferIndex& ix = it->second;
  const Buffer* old = buffer(id);
  return triangles_ - ix.index_refs * index_triangles(old) - ix.position_refs * position_triangles(old) +
         ix.index_refs * index_triangles(b) + ix.position_refs * position_triangles(b);
}

uint64_t Scene::triangles_with_mesh(Id id, const Mesh* m) const {
  uint64_t n = triangles_;
  auto it = meshes_.find(id);
  if (it != meshes_.end()) n -= mesh_triangles(it->second.value);
  if (m) n += mesh_triangles(*m);
  return n;
}

}  // namespace tessera
