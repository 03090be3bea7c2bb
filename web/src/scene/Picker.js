// CPU picking on a SceneDescription: the nearest visible triangle along a world-space ray
// (Möller–Trumbore, through each geometry's BVH: PickBvh.js), so both backends answer
// getElementByPoint the same way.
import { invert, transformPoint, transformDirection, normalize, cross } from '../math/Mat4.js';
import { meshBvh } from './PickBvh.js';

// A world-space ray through pixel (x, y) of a width x height viewport for scene.camera.
export function generateRay(camera, x, y, width, height) {
  const aspect = width / height;
  const fovY = camera.fovX ? 2 * Math.atan(Math.tan(camera.fovX / 2) / aspect) : camera.fovY;
  const t = Math.tan(fovY / 2);
  const ndcX = (2 * (x + 0.5)) / width - 1, ndcY = 1 - (2 * (y + 0.5)) / height;
  const dirCam = [ndcX * t * aspect, ndcY * t, -1];
  return {
    origin: transformPoint(camera.toWorld, [0, 0, 0]),
    direction: normalize(transformDirection(camera.toWorld, dirCam)),
  };
}

const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];

// A visible mesh's positions, indices (or null) and picking tree; null for a mesh that is
// hidden or has no positions.
function meshGeometry(scene, mesh) {
  const pos = mesh.visible && scene.buffers.get(mesh.positions);
  if (!pos) return null;
  const P = pos.data, idx = mesh.indices ? scene.buffers.get(mesh.indices).data : null;
  return { P, idx, bvh: meshBvh(P, idx, idx ? idx.length : P.length / 3) };
}

// The picking trees of the scene's visible meshes that are not built yet, to build ahead of the
// first pick (XML3DHandler does so in idle time); pick() builds the ones its ray needs itself.
export function unbuiltPickTrees(scene) {
  const out = [];
  for (const mesh of scene.meshes.values()) {
    const g = meshGeometry(scene, mesh);
    if (g && !g.bvh.built) out.push(g.bvh);
  }
  return out;
}

export function pick(scene, ray) {
  let best = null;
  for (const mesh of scene.meshes.values()) {
    const g = meshGeometry(scene, mesh);
    const inv = g && invert(mesh.transform);
    if (!inv) continue;
    const { P, idx } = g;
    const o = transformPoint(inv, ray.origin), d = transformDirection(inv, ray.direction);
    const h = g.bvh.nearest(o, d);
    if (!h) continue;
    const t = h.t, i = h.tri;
    const hit = transformPoint(mesh.transform, [o[0] + d[0] * t, o[1] + d[1] * t, o[2] + d[2] * t]);
    const dist = Math.hypot(hit[0] - ray.origin[0], hit[1] - ray.origin[1], hit[2] - ray.origin[2]);
    if (!best || dist < best.distance) {
      // Normal: geometric, world space (inverse transpose), facing the ray.
      const ia = idx ? idx[i] : i, ib = idx ? idx[i + 1] : i + 1, ic = idx ? idx[i + 2] : i + 2;
      const a = [P[ia * 3], P[ia * 3 + 1], P[ia * 3 + 2]];
      const e1 = [P[ib * 3] - a[0], P[ib * 3 + 1] - a[1], P[ib * 3 + 2] - a[2]];
      const e2 = [P[ic * 3] - a[0], P[ic * 3 + 1] - a[1], P[ic * 3 + 2] - a[2]];
      const nl = cross(e1, e2);
      let nw = normalize([inv[0] * nl[0] + inv[1] * nl[1] + inv[2] * nl[2], inv[4] * nl[0] + inv[5] * nl[1] + inv[6] * nl[2],
        inv[8] * nl[0] + inv[9] * nl[1] + inv[10] * nl[2]]);
      if (dot(nw, ray.direction) > 0) nw = [-nw[0], -nw[1], -nw[2]];
      best = { mesh, element: mesh.element, distance: dist, point: hit, normal: nw };
    }
  }
  return best;
}
