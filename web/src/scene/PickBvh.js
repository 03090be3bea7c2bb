// A bounding volume hierarchy over one mesh's triangles in object space, so that picking
// (Picker.js: every mousemove over the scene, getElementByPoint, getElementByRay) visits a few
// dozen triangles instead of all of them. The pavilion's 130,503 triangles took about 25 ms per
// pick by brute force in headless Chromium, on the main thread, before the camera controller
// saw the mousemove.
//
// Built when a ray first enters the geometry's bounds (or ahead, in idle time: XML3DHandler)
// and kept for as long as its arrays live: the key is the positions array and the index array
// (or none). Arrays are taken as immutable once read, as the
// markup reader's own caches take them (MarkupReader.scanned, floats).
//
// The triangle test is Picker.js's (Möller–Trumbore with the same tolerances), so a BVH pick
// finds the nearest of the triangles that a brute-force pass would accept.

const LEAF = 4;  // triangles per leaf at most (unless they cannot be split)

const cache = new WeakMap();  // positions -> Map(indices or null -> Bvh)

// The BVH of triangles (positions P: x, y, z per vertex; idx: three vertex indices per
// triangle, or null for consecutive vertices) with n index entries (n / 3 triangles).
export function meshBvh(P, idx, n) {
  let byIndex = cache.get(P);
  if (!byIndex) { byIndex = new Map(); cache.set(P, byIndex); }
  const key = idx || null;
  let bvh = byIndex.get(key);
  if (!bvh || bvh.n !== n) {
    bvh = new Bvh(P, idx, n);
    byIndex.set(key, bvh);
  }
  return bvh;
}

// Reorders [first, end) so that item k is the one whose centroid coordinate `ax` would be k-th
// in sorted order, smaller or equal ones before it, larger or equal after (Hoare's selection,
// middle pivot, expected linear time). swap(i, j) exchanges two items everywhere.
function select(cen, first, end, k, ax, swap) {
  let lo = first, hi = end - 1;
  while (lo < hi) {
    const pivot = cen[((lo + hi) >> 1) * 3 + ax];
    let i = lo, j = hi;
    while (i <= j) {
      while (cen[i * 3 + ax] < pivot) i++;
      while (cen[j * 3 + ax] > pivot) j--;
      if (i <= j) swap(i++, j--);
    }
    if (k <= j) hi = j;
    else if (k >= i) lo = i;
    else return;
  }
}

// Whether the ray o + d t (i: 1 / d per axis) meets the box at b[k..k + 6) (min xyz, max xyz)
// for some t in [0, tMax]. The slabs are padded for the rounding of the triangle test, so that a
// hit on a box's face is not lost. Along an axis the ray does not move, i is infinite: outside
// the slab both ends are infinities of one sign (a miss), inside of opposite signs; on a face,
// NaN, which fails every comparison, so the box counts as entered.
function entered(b, k, ox, oy, oz, ix, iy, iz, tMax) {
  let t0 = -Infinity, t1 = tMax;
  for (let ax = 0; ax < 3; ax++) {
    const lo = b[k + ax], hi = b[k + 3 + ax];
    const pad = (Math.abs(lo) + Math.abs(hi)) * 1e-7 + 1e-12;
    const oa = ax === 0 ? ox : ax === 1 ? oy : oz, inv = ax === 0 ? ix : ax === 1 ? iy : iz;
    let a = (lo - pad - oa) * inv, c = (hi + pad - oa) * inv;
    if (a > c) { const s = a; a = c; c = s; }
    if (a > t0) t0 = a;
    if (c < t1) t1 = c;
    if (t0 > t1) return false;
  }
  return t1 >= 0;
}

class Bvh {
  // Only the bounds of the positions at first (one pass over them); the tree is built when a
  // ray first enters them, so a pick builds the trees of the meshes near its ray, not all.
  constructor(P, idx, n) {
    this.P = P;
    this.idx = idx;
    this.n = n;
    const box = [Infinity, Infinity, Infinity, -Infinity, -Infinity, -Infinity];
    for (let v = 0; v + 2 < P.length; v += 3)
      for (let ax = 0; ax < 3; ax++) {
        const x = P[v + ax];
        if (x < box[ax]) box[ax] = x;
        if (x > box[ax + 3]) box[ax + 3] = x;
      }
    this.box = box;
    this.bounds = null;
  }

  get built() { return this.bounds !== null; }

  build() {
    const { P, idx, n } = this;
    // Triangles whose corners are all finite numbers (an index out of range reads undefined:
    // the brute-force test gives NaN and skips such a triangle, so it is left out here).
    const count = Math.floor(n / 3);
    const tris = new Uint32Array(count);
    const cen = new Float64Array(count * 3), lo = new Float64Array(count * 3), hi = new Float64Array(count * 3);
    let m = 0;
    for (let k = 0; k < count; k++) {
      const i = k * 3;
      const a = idx ? idx[i] : i, b = idx ? idx[i + 1] : i + 1, c = idx ? idx[i + 2] : i + 2;
      let ok = true;
      for (let ax = 0; ax < 3; ax++) {
        const va = P[a * 3 + ax], vb = P[b * 3 + ax], vc = P[c * 3 + ax];
        if (!(Number.isFinite(va) && Number.isFinite(vb) && Number.isFinite(vc))) { ok = false; break; }
        lo[m * 3 + ax] = Math.min(va, vb, vc);
        hi[m * 3 + ax] = Math.max(va, vb, vc);
        cen[m * 3 + ax] = (lo[m * 3 + ax] + hi[m * 3 + ax]) / 2;
      }
      if (ok) tris[m++] = i;
    }
    // Nodes: bounds (min xyz, max xyz) and [first, count] into the triangle order for a leaf,
    // [left, 0] for an inner node whose children are nodes left and left + 1.
    let bounds = new Float64Array(64 * 6), info = new Int32Array(64 * 2);
    let nodes = 1;
    // The build reorders the triangles in place (tris with their centroids and bounds), so
    // that every node's triangles lie together and each pass over them reads memory in order.
    const swap = (a, b) => {
      const s = tris[a]; tris[a] = tris[b]; tris[b] = s;
      for (let q = 0; q < 3; q++) {
        const x = a * 3 + q, y = b * 3 + q;
        let v = cen[x]; cen[x] = cen[y]; cen[y] = v;
        v = lo[x]; lo[x] = lo[y]; lo[y] = v;
        v = hi[x]; hi[x] = hi[y]; hi[y] = v;
      }
    };
    const stack = [[0, 0, m, 1]];  // node, first, end (triangles), depth
    this.depth = 0;
    while (stack.length) {
      const [node, first, end, depth] = stack.pop();
      if (depth > this.depth) this.depth = depth;
      let bx0 = Infinity, by0 = Infinity, bz0 = Infinity, bx1 = -Infinity, by1 = -Infinity, bz1 = -Infinity;
      let cx0 = Infinity, cy0 = Infinity, cz0 = Infinity, cx1 = -Infinity, cy1 = -Infinity, cz1 = -Infinity;
      for (let k = first; k < end; k++) {
        const t = k * 3;
        if (lo[t] < bx0) bx0 = lo[t];
        if (lo[t + 1] < by0) by0 = lo[t + 1];
        if (lo[t + 2] < bz0) bz0 = lo[t + 2];
        if (hi[t] > bx1) bx1 = hi[t];
        if (hi[t + 1] > by1) by1 = hi[t + 1];
        if (hi[t + 2] > bz1) bz1 = hi[t + 2];
        if (cen[t] < cx0) cx0 = cen[t];
        if (cen[t + 1] < cy0) cy0 = cen[t + 1];
        if (cen[t + 2] < cz0) cz0 = cen[t + 2];
        if (cen[t] > cx1) cx1 = cen[t];
        if (cen[t + 1] > cy1) cy1 = cen[t + 1];
        if (cen[t + 2] > cz1) cz1 = cen[t + 2];
      }
      const nb = node * 6;
      bounds[nb] = bx0, bounds[nb + 1] = by0, bounds[nb + 2] = bz0, bounds[nb + 3] = bx1, bounds[nb + 4] = by1, bounds[nb + 5] = bz1;
      const count = end - first;
      const ex = cx1 - cx0, ey = cy1 - cy0, ez = cz1 - cz0;
      if (count <= LEAF || !(ex > 0 || ey > 0 || ez > 0)) {  // small, or every centroid at one point
        info[node * 2] = first;
        info[node * 2 + 1] = count;
        continue;
      }
      // Split at the middle of the centroids' extent along its longest axis. Where that leaves
      // one side with less than an eighth (clustered or adversarial coordinates, which would
      // make the tree as deep as it has triangles), split at the median centroid instead.
      const ax = ex >= ey && ex >= ez ? 0 : ey >= ez ? 1 : 2;
      const mid = ax === 0 ? (cx0 + cx1) / 2 : ax === 1 ? (cy0 + cy1) / 2 : (cz0 + cz1) / 2;
      let i = first, j = end - 1;
      while (i <= j) {
        if (cen[i * 3 + ax] < mid) i++;
        else swap(i, j--);
      }
      let split = i;
      if (Math.min(split - first, end - split) < count / 8) {
        split = (first + end) >> 1;
        select(cen, first, end, split, ax, swap);
      }
      if ((nodes + 2) * 2 > info.length) {
        const b2 = new Float64Array(bounds.length * 2); b2.set(bounds); bounds = b2;
        const i2 = new Int32Array(info.length * 2); i2.set(info); info = i2;
      }
      const left = nodes;
      nodes += 2;
      info[node * 2] = left;
      info[node * 2 + 1] = 0;
      stack.push([left + 1, split, end, depth + 1], [left, first, split, depth + 1]);
    }
    this.bounds = bounds;
    this.info = info;
    this.tris = tris.subarray(0, m);
    this.empty = m === 0;
  }

  // The nearest triangle hit by the object-space ray o + d t with t > 1e-6: { t, tri } (tri:
  // the index of the triangle's first index entry, as Picker.js counts), or null.
  nearest(o, d) {
    const [ox, oy, oz] = o, [dx, dy, dz] = d;
    const ix = 1 / dx, iy = 1 / dy, iz = 1 / dz;
    if (!this.bounds) {
      if (!entered(this.box, 0, ox, oy, oz, ix, iy, iz, Infinity)) return null;
      this.build();
    }
    if (this.empty) return null;
    const { P, idx, bounds, info, tris } = this;
    let best = Infinity, bestTri = -1;
    let stack = new Int32Array(64);
    let sp = 0;
    stack[sp++] = 0;
    while (sp > 0) {
      const node = stack[--sp];
      if (!entered(bounds, node * 6, ox, oy, oz, ix, iy, iz, best)) continue;
      const first = info[node * 2], count = info[node * 2 + 1];
      if (count === 0) {
        if (sp + 2 > stack.length) { const s2 = new Int32Array(stack.length * 2); s2.set(stack); stack = s2; }
        stack[sp++] = first + 1;
        stack[sp++] = first;
        continue;
      }
      for (let k = first; k < first + count; k++) {
        const i = tris[k];
        const ia = idx ? idx[i] : i, ib = idx ? idx[i + 1] : i + 1, ic = idx ? idx[i + 2] : i + 2;
        const ax = P[ia * 3], ay = P[ia * 3 + 1], az = P[ia * 3 + 2];
        const e1x = P[ib * 3] - ax, e1y = P[ib * 3 + 1] - ay, e1z = P[ib * 3 + 2] - az;
        const e2x = P[ic * 3] - ax, e2y = P[ic * 3 + 1] - ay, e2z = P[ic * 3 + 2] - az;
        const px = dy * e2z - dz * e2y, py = dz * e2x - dx * e2z, pz = dx * e2y - dy * e2x;
        const det = e1x * px + e1y * py + e1z * pz;
        if (Math.abs(det) < 1e-12) continue;
        const sx = ox - ax, sy = oy - ay, sz = oz - az;
        const u = (sx * px + sy * py + sz * pz) / det;
        if (u < 0 || u > 1) continue;
        const qx = sy * e1z - sz * e1y, qy = sz * e1x - sx * e1z, qz = sx * e1y - sy * e1x;
        const v = (dx * qx + dy * qy + dz * qz) / det;
        if (v < 0 || u + v > 1) continue;
        const t = (e2x * qx + e2y * qy + e2z * qz) / det;
        if (t <= 1e-6) continue;
        if (t < best || (t === best && i < bestTri)) { best = t; bestTri = i; }
      }
    }
    return bestTri < 0 ? null : { t: best, tri: bestTri };
  }
}
