#pragma once
// Scene updates: decoded client records (protocol/protocol.h) applied to a Scene, and the
// admission of updates that wait while a frame renders. Pure code: no bytes, no sockets, no
// actors. The protocol layer turns bytes into records; this layer changes the scene with them.
//
// It sits above protocol/ only for the error vocabulary it reports in (protocol::Status and
// ErrorCode, which the session sends to the client as they are) and the records' types.
#include <cstdint>
#include <map>
#include <utility>

#include "core/scene.h"
#include "protocol/protocol.h"

namespace tessera {

// Resolution, camera, environment and the set/remove records of entries; not the handshake,
// settings or render requests (the session handles those).
bool is_scene_update(const protocol::ClientRecord& r);

// Applies one scene update. Scene-dependent checks:
// - a mesh whose referenced buffers are all present must pass Scene::validate_mesh, else
//   bad_mesh and the scene is unchanged; a mesh with missing buffers is accepted (progressive
//   loading: it is rendered once its buffers arrive and validate_mesh passes);
// - buffers and textures held for the client stay within limits.max_client_bytes;
// - the scene's triangle count stays within limits.max_triangles;
// - remove of an id the scene does not hold: unknown_id.
// Returns not_scene_update for handshake, settings and render requests (the session handles them).
protocol::Status apply(Scene& scene, protocol::ClientRecord&& record, const protocol::Limits& limits);

// Buffers + textures held by the scene (what max_client_bytes limits).
uint64_t scene_bytes(const Scene& scene);

// Scene updates that wait to be applied (a session caches them while a frame renders from
// the scene) count against max_client_bytes as if they had been applied in order: admit()
// checks one more waiting update against the buffers and textures the scene would hold once
// it and every update admitted before it were applied (a replacement counts the size it
// replaces out, a removal frees it). limit_exceeded says the update must not wait (it is
// dropped; what waits already is kept). The scene must not change until clear().
class PendingBytes {
 public:
  protocol::Status admit(const Scene& scene, const protocol::ClientRecord& record, const protocol::Limits& limits);
  void clear();  // the waiting updates were applied (or dropped)
  uint64_t waiting_bytes() const { return added_; }  // bytes the admitted updates hold while they wait
 private:
  uint64_t size_of(const Scene& scene, protocol::RecordType what, Id id) const;  // as the waiting updates leave it
  std::map<std::pair<protocol::RecordType, Id>, uint64_t> latest_;  // last waiting size per entry
  uint64_t added_ = 0, freed_ = 0;
};

}  // namespace tessera
