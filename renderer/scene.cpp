#include "renderer/scene.h"

#include <cmath>

namespace tessera {

bool Texture::has_alpha() const {
  for (size_t i = 3; i < rgba.size(); i += 4)
    if (rgba[i] != 255) return true;
  return false;
}

std::string Scene::validate_mesh(const Mesh& m) const {
  const Buffer* pos = buffer(m.positions);
  if (!pos) return "mesh references missing position buffer " + std::to_string(m.positions);
  if (pos->type != Buffer::Type::f32 || pos->components != 3) return "position buffer must be float3";
  size_t nv = pos->count();
  for (float v : pos->f)
    if (!std::isfinite(v)) return "position buffer " + std::to_string(m.positions) + " holds NaN or Inf";
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
  if (m.indices != kNoId) {
    const Buffer* ib = buffer(m.indices);
    if (!ib) return "mesh references missing index buffer " + std::to_string(m.indices);
    if (ib->type != Buffer::Type::u32 || ib->components != 1) return "index buffer must be uint32 scalars";
    if (ib->u.size() % 3) return "index count " + std::to_string(ib->u.size()) + " is not a multiple of 3";
    for (uint32_t i : ib->u)
      if (i >= nv) return "index " + std::to_string(i) + " out of range (vertex count " + std::to_string(nv) + ")";
  } else if (nv % 3) {
    return "non-indexed mesh needs a multiple of 3 vertices, has " + std::to_string(nv);
  }
  if (!m.transform.finite()) return "mesh transform holds NaN or Inf";
  return {};
}

size_t Scene::triangle_count() const {
  size_t n = 0;
  for (auto& [id, e] : meshes_) {
    if (!e.value.visible) continue;
    if (const Buffer* ib = buffer(e.value.indices)) n += ib->u.size() / 3;
    else if (const Buffer* pb = buffer(e.value.positions)) n += pb->count() / 3;
  }
  return n;
}

}  // namespace tessera
