#include "update/scene_update.h"

#include <string>

namespace tessera {

using namespace protocol;

namespace {

Error apply_error(ErrorCode c, std::string m) {
  Error e;
  e.code = c;
  e.message = std::move(m);
  return e;
}

}  // namespace

uint64_t scene_bytes(const Scene& scene) { return scene.held_bytes(); }

uint64_t PendingBytes::size_of(const Scene& scene, RecordType what, Id id) const {
  if (auto it = latest_.find({what, id}); it != latest_.end()) return it->second;
  if (what == RecordType::buffer) {
    const Buffer* b = scene.buffer(id);
    return b ? b->bytes() : 0;
  }
  const Texture* t = scene.texture(id);
  return t ? t->rgba.size() : 0;
}

Status PendingBytes::admit(const Scene& scene, const ClientRecord& record, const Limits& limits) {
  RecordType what;
  Id id;
  uint64_t bytes = 0;
  if (const auto* b = std::get_if<SetBuffer>(&record)) {
    what = RecordType::buffer, id = b->id, bytes = b->buffer.bytes();
  } else if (const auto* t = std::get_if<SetTexture>(&record)) {
    what = RecordType::texture, id = t->id, bytes = t->texture.rgba.size();
  } else if (const auto* r = std::get_if<Remove>(&record);
             r && (r->what == RecordType::buffer || r->what == RecordType::texture)) {
    what = r->what, id = r->id;  // frees what it removes
  } else {
    return Ok{};  // holds no bytes
  }
  const uint64_t old = size_of(scene, what, id);
  // Held once everything admitted so far is applied; freed_ never exceeds what is held.
  const uint64_t held = scene_bytes(scene) + added_ - freed_ - old;
  const uint64_t limit = limits.max_client_bytes;
  if (bytes > limit || held > limit - bytes)
    return apply_error(ErrorCode::limit_exceeded,
                       std::string(protocol::to_string(what)) + " " + std::to_string(id) +
                           ": with the updates waiting for the frame in flight, the scene's buffers and textures would "
                           "exceed the limit of " + std::to_string(limit) + " bytes");
  latest_[{what, id}] = bytes;
  added_ += bytes;
  freed_ += old;
  return Ok{};
}

void PendingBytes::clear() {
  latest_.clear();
  added_ = freed_ = 0;
}

bool is_scene_update(const ClientRecord& r) {
  return !(std::holds_alternative<Handshake>(r) || std::holds_alternative<Settings>(r) ||
           std::holds_alternative<RenderRequest>(r) || std::holds_alternative<Refine>(r) ||
           std::holds_alternative<Budget>(r));
}

Status apply(Scene& scene, ClientRecord&& record, const Limits& lim) {
  struct Visitor {
    Scene& s;
    const Limits& lim;
    Status operator()(Handshake&) { return apply_error(ErrorCode::not_scene_update, "handshake is not a scene update"); }
    Status operator()(Settings&) { return apply_error(ErrorCode::not_scene_update, "settings are not a scene update"); }
    Status operator()(Refine&) { return apply_error(ErrorCode::not_scene_update, "a refine record is not a scene update"); }
    Status operator()(Budget&) { return apply_error(ErrorCode::not_scene_update, "a budget record is not a scene update"); }
    Status operator()(Video&) { return apply_error(ErrorCode::not_scene_update, "a video record is not a scene update"); }
    // The session resolves references into buffer and texture records first (update/asset_store.h).
    Status operator()(SetBufferRef&) {
      return apply_error(ErrorCode::not_scene_update, "a buffer_ref is resolved before it is applied");
    }
    Status operator()(SetTextureRef&) {
      return apply_error(ErrorCode::not_scene_update, "a texture_ref is resolved before it is applied");
    }
    Status operator()(RenderRequest&) {
      return apply_error(ErrorCode::not_scene_update, "a render request is not a scene update");
    }
    Status operator()(Resolution& r) {
      s.set_resolution(r.width, r.height);
      return Ok{};
    }
    Status operator()(SetCamera& c) {
      s.set_camera(c.camera);
      return Ok{};
    }
    Status operator()(SetEnvironment& e) {
      s.set_environment(e.environment);
      return Ok{};
    }
    Status bytes_check(uint64_t old_bytes, uint64_t new_bytes, const char* what, Id id) {
      uint64_t total = scene_bytes(s) - old_bytes;
      if (new_bytes > lim.max_client_bytes || total > lim.max_client_bytes - new_bytes)
        return apply_error(ErrorCode::limit_exceeded, std::string(what) + " " + std::to_string(id) + ": the scene's buffers and textures would exceed the limit of " +
                                                          std::to_string(lim.max_client_bytes) + " bytes");
      return Ok{};
    }
    Status operator()(SetBuffer& b) {
      const Buffer* old = s.buffer(b.id);
      if (auto st = bytes_check(old ? old->bytes() : 0, b.buffer.bytes(), "buffer", b.id); !st) return st;
      // Only meshes that take their triangles from this buffer change the count (O(log n):
      // the scene keeps reference counts per buffer).
      {
        uint64_t tris = s.triangles_with_buffer(b.id, &b.buffer);
        if (tris > lim.max_triangles && tris != s.triangle_count())  // a buffer no mesh draws from changes nothing
          return apply_error(ErrorCode::limit_exceeded, "buffer " + std::to_string(b.id) + ": scene would hold " +
                                                            std::to_string(tris) + " triangles, limit " +
                                                            std::to_string(lim.max_triangles));
      }
      s.set_buffer(b.id, std::move(b.buffer));
      return Ok{};
    }
    Status operator()(SetTexture& t) {
      const Texture* old = s.texture(t.id);
      if (auto st = bytes_check(old ? old->rgba.size() : 0, t.texture.rgba.size(), "texture", t.id); !st) return st;
      s.set_texture(t.id, std::move(t.texture));
      return Ok{};
    }
    Status operator()(SetMaterial& m) {
      s.set_material(m.id, std::move(m.material));
      return Ok{};
    }
    Status operator()(SetMesh& m) {
      const Mesh& mesh = m.mesh;
      // Progressive loading: a mesh whose buffers have not all arrived is accepted as is.
      bool complete = s.buffer(mesh.positions) && (mesh.normals == kNoId || s.buffer(mesh.normals)) &&
                      (mesh.texcoords == kNoId || s.buffer(mesh.texcoords)) &&
                      (mesh.colors == kNoId || s.buffer(mesh.colors)) &&
                      (mesh.indices == kNoId || s.buffer(mesh.indices));
      if (complete) {
        std::string why = s.validate_mesh(mesh);
        if (!why.empty()) return apply_error(ErrorCode::bad_mesh, "mesh " + std::to_string(m.id) + ": " + why);
      }
      uint64_t tris = s.triangles_with_mesh(m.id, &mesh);  // O(log n): the scene keeps a running total
      if (tris > lim.max_triangles)
        return apply_error(ErrorCode::limit_exceeded, "mesh " + std::to_string(m.id) + ": scene would hold " +
                                                          std::to_string(tris) + " triangles, limit " +
                                                          std::to_string(lim.max_triangles));
      s.set_mesh(m.id, mesh);
      return Ok{};
    }
    Status operator()(SetLight& l) {
      s.set_light(l.id, l.light);
      return Ok{};
    }
    Status operator()(Remove& r) {
      bool found = false;
      switch (r.what) {
        case RecordType::buffer: found = s.remove_buffer(r.id); break;
        case RecordType::texture: found = s.remove_texture(r.id); break;
        case RecordType::material: found = s.remove_material(r.id); break;
        case RecordType::mesh: found = s.remove_mesh(r.id); break;
        case RecordType::light: found = s.remove_light(r.id); break;
        default: return apply_error(ErrorCode::bad_op, "remove of a record type without ids");
      }
      if (!found)
        return apply_error(ErrorCode::unknown_id, std::string("remove ") + protocol::to_string(r.what) + " " +
                                                      std::to_string(r.id) + ": no such id");
      return Ok{};
    }
  };
  return std::visit(Visitor{scene, lim}, record);
}

}  // namespace tessera
