// Bounding boxes of a SceneDescription ({min, max} arrays; empty: min > max).
import { transformPoint, invert } from '../math/Mat4.js';
import { pendingValues } from '../reader/GltfLoader.js';

const localCache = new WeakMap();

export function emptyBox() {
  return { min: [Infinity, Infinity, Infinity], max: [-Infinity, -Infinity, -Infinity] };
}

export function isEmpty(b) {
  return !(b.min[0] <= b.max[0]);
}

function localBox(positions) {
  let b = localCache.get(positions);
  if (b) return b;
  b = emptyBox();
  for (let i = 0; i < positions.length; i += 3)
    for (let k = 0; k < 3; k++) {
      const v = positions[i + k];
      if (v < b.min[k]) b.min[k] = v;
      if (v > b.max[k]) b.max[k] = v;
    }
  if (!pendingValues(positions)) localCache.set(positions, b);  // zeros until a deferred load is in
  return b;
}

export function extend(box, p) {
  for (let k = 0; k < 3; k++) {
    if (p[k] < box.min[k]) box.min[k] = p[k];
    if (p[k] > box.max[k]) box.max[k] = p[k];
  }
}

export function meshWorldBox(scene, mesh, box = emptyBox()) {
  const pos = scene.buffers.get(mesh.positions);
  if (!pos) return box;
  const lb = localBox(pos.data);
  if (isEmpty(lb)) return box;
  for (let c = 0; c < 8; c++)
    extend(box, transformPoint(mesh.transform, [c & 1 ? lb.max[0] : lb.min[0], c & 2 ? lb.max[1] : lb.min[1], c & 4 ? lb.max[2] : lb.min[2]]));
  return box;
}

// World box of the visible meshes whose pick element is `element` or inside it (all when null).
export function worldBox(scene, element = null) {
  const box = emptyBox();
  for (const m of scene.meshes.values()) {
    if (!m.visible) continue;
    if (element && element !== scene.xml3d && !(m.element === element || (element.contains && element.contains(m.element)))) continue;
    meshWorldBox(scene, m, box);
  }
  return box;
}

// Near and far planes for a camera (toWorld) when the view gives none: the scene's box in view
// space with a 5% margin, near >= 0.01; an empty scene or one behind the camera gives 1 and 10.
export function clippingPlanes(scene, toWorld, near = null, far = null) {
  if (near != null && far != null) return { near, far };
  const box = worldBox(scene);
  let zmin = Infinity, zmax = -Infinity;
  if (!isEmpty(box)) {
    const view = invert(toWorld);
    for (let k = 0; k < 8; k++) {
      const p = transformPoint(view, [k & 1 ? box.max[0] : box.min[0], k & 2 ? box.max[1] : box.min[1], k & 4 ? box.max[2] : box.min[2]]);
      zmin = Math.min(zmin, -p[2]); zmax = Math.max(zmax, -p[2]);
    }
  }
  if (!(zmax > 0)) return { near: near ?? 1, far: far ?? 10 };
  const margin = (zmax - Math.max(zmin, 0)) * 0.05 + 1e-3;
  far = far ?? zmax + margin;
  near = near ?? Math.max(zmin - margin, far * 1e-4, 0.01);
  return { near, far };
}
