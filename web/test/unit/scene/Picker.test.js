import { test } from 'node:test';
import assert from 'node:assert/strict';
import { pick } from '../../../src/scene/Picker.js';
import { meshBvh } from '../../../src/scene/PickBvh.js';
import { invert, transformPoint, transformDirection, normalize, cross } from '../../../src/math/Mat4.js';

// A deterministic generator (xorshift), so a failure names its seed.
function rng(seed) {
  let s = seed >>> 0 || 1;
  return () => {
    s ^= s << 13; s >>>= 0;
    s ^= s >>> 17;
    s ^= s << 5; s >>>= 0;
    return s / 4294967296;
  };
}

const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];

// The oracle: every triangle of every mesh, as Picker.js did before the BVH (triangles with a
// corner that is not a finite number skipped).
function pickAll(scene, ray) {
  let best = null;
  for (const mesh of scene.meshes.values()) {
    if (!mesh.visible) continue;
    const pos = scene.buffers.get(mesh.positions);
    const inv = invert(mesh.transform);
    if (!pos || !inv) continue;
    const o = transformPoint(inv, ray.origin), d = transformDirection(inv, ray.direction);
    const P = pos.data, idx = mesh.indices ? scene.buffers.get(mesh.indices).data : null;
    const n = idx ? idx.length : P.length / 3;
    for (let i = 0; i + 2 < n; i += 3) {
      const ia = idx ? idx[i] : i, ib = idx ? idx[i + 1] : i + 1, ic = idx ? idx[i + 2] : i + 2;
      const v = [P[ia * 3], P[ia * 3 + 1], P[ia * 3 + 2], P[ib * 3], P[ib * 3 + 1], P[ib * 3 + 2], P[ic * 3], P[ic * 3 + 1], P[ic * 3 + 2]];
      if (!v.every(Number.isFinite)) continue;
      const a = v.slice(0, 3), e1 = [v[3] - a[0], v[4] - a[1], v[5] - a[2]], e2 = [v[6] - a[0], v[7] - a[1], v[8] - a[2]];
      const p = cross(d, e2), det = dot(e1, p);
      if (Math.abs(det) < 1e-12) continue;
      const s = [o[0] - a[0], o[1] - a[1], o[2] - a[2]];
      const u = dot(s, p) / det;
      if (u < 0 || u > 1) continue;
      const q = cross(s, e1), w = dot(d, q) / det;
      if (w < 0 || u + w > 1) continue;
      const t = dot(e2, q) / det;
      if (t <= 1e-6) continue;
      const hit = transformPoint(mesh.transform, [o[0] + d[0] * t, o[1] + d[1] * t, o[2] + d[2] * t]);
      const dist = Math.hypot(hit[0] - ray.origin[0], hit[1] - ray.origin[1], hit[2] - ray.origin[2]);
      if (!best || dist < best.distance) best = { element: mesh.element, distance: dist, tri: i };
    }
  }
  return best;
}

// A scene of `meshes` meshes of random triangles (indexed or not) under random rotations,
// non-uniform scales and translations.
function randomScene(r, { meshes = 4, triangles = 300, spread = 4, size = 0.6 } = {}) {
  const buffers = new Map(), list = new Map();
  let id = 1;
  for (let m = 0; m < meshes; m++) {
    const indexed = m % 2 === 0, nv = indexed ? triangles * 2 : triangles * 3;
    const P = new Float32Array(nv * 3);
    for (let v = 0; v < nv; v += indexed ? 1 : 3) {
      const c = [0, 1, 2].map(() => (r() - 0.5) * spread);
      for (let k = 0; k < (indexed ? 1 : 3); k++) for (let a = 0; a < 3; a++) P[(v + k) * 3 + a] = c[a] + (r() - 0.5) * size;
    }
    const pid = id++;
    buffers.set(pid, { id: pid, data: P });
    let iid = 0;
    if (indexed) {
      const I = new Uint32Array(triangles * 3);
      for (let k = 0; k < I.length; k += 3) {  // corners near each other: a vertex and two of the next ones
        const a = Math.floor(r() * (nv - 2));
        I[k] = a, I[k + 1] = a + 1, I[k + 2] = a + 2;
      }
      iid = id++;
      buffers.set(iid, { id: iid, data: I });
    }
    const ang = r() * Math.PI, c = Math.cos(ang), s = Math.sin(ang);
    const sx = 0.5 + r(), sy = 0.5 + r(), sz = 0.5 + r();
    const transform = new Float32Array([c * sx, 0, -s * sx, 0, 0, sy, 0, 0, s * sz, 0, c * sz, 0, r() - 0.5, r() - 0.5, r() - 0.5, 1]);
    list.set(m + 1, { id: m + 1, element: { name: `mesh${m}` }, positions: pid, indices: iid, transform, visible: true });
  }
  return { buffers, meshes: list };
}

function randomRay(r) {
  const origin = [(r() - 0.5) * 12, (r() - 0.5) * 12, 6 + r() * 4];
  const target = [(r() - 0.5) * 4, (r() - 0.5) * 4, (r() - 0.5) * 4];
  return { origin, direction: normalize([target[0] - origin[0], target[1] - origin[1], target[2] - origin[2]]) };
}

test('BVH picking finds what testing every triangle finds', () => {
  for (let seed = 1; seed <= 8; seed++) {
    const r = rng(seed);
    const scene = randomScene(r);
    let hits = 0;
    for (let k = 0; k < 150; k++) {
      const ray = randomRay(r);
      const want = pickAll(scene, ray), got = pick(scene, ray);
      assert.equal(!!got, !!want, `seed ${seed} ray ${k}: hit ${!!got}, expected ${!!want}`);
      if (!want) continue;
      hits++;
      assert.equal(got.element, want.element, `seed ${seed} ray ${k}`);
      assert.ok(Math.abs(got.distance - want.distance) <= 1e-9 * want.distance, `seed ${seed} ray ${k}: ${got.distance} vs ${want.distance}`);
    }
    assert.ok(hits > 40, `seed ${seed}: only ${hits} of 150 rays hit (the test needs hits to compare)`);
  }
});

test('Rays along an axis, through shared edges and box faces, are not lost by the box tests', () => {
  // A grid of unit quads (two triangles each) in the plane z = 0; rays straight down the z axis
  // (two direction components exactly 0) through vertices, edges and cell centres.
  const n = 16, P = [], I = [];
  for (let y = 0; y <= n; y++) for (let x = 0; x <= n; x++) P.push(x, y, 0);
  for (let y = 0; y < n; y++)
    for (let x = 0; x < n; x++) {
      const a = y * (n + 1) + x;
      I.push(a, a + 1, a + n + 2, a, a + n + 2, a + n + 1);
    }
  const scene = {
    buffers: new Map([[1, { data: new Float32Array(P) }], [2, { data: new Uint32Array(I) }]]),
    meshes: new Map([[1, { element: 'grid', positions: 1, indices: 2, transform: new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]), visible: true }]]),
  };
  for (let y = 0; y <= 2 * n; y++)
    for (let x = 0; x <= 2 * n; x++) {
      const ray = { origin: [x / 2, y / 2, 5], direction: [0, 0, -1] };
      const want = pickAll(scene, ray), got = pick(scene, ray);
      assert.equal(!!got, !!want, `(${x / 2}, ${y / 2})`);
      if (want) assert.equal(got.distance, want.distance, `(${x / 2}, ${y / 2})`);
    }
});

test('Triangles with corners that are not numbers, or indices out of range, are never picked', () => {
  const P = new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0, NaN, 0, 0, Infinity, 1, 0]);
  // Triangle 0 is nearest along the ray but has a NaN corner; triangle 1 an index past the end;
  // triangle 2 is the only real one (at z = 0 via vertices 0, 1, 2 moved back by the transform).
  const I = new Uint32Array([3, 1, 2, 0, 1, 99, 0, 1, 2]);
  const scene = {
    buffers: new Map([[1, { data: P }], [2, { data: I }]]),
    meshes: new Map([[1, { element: 'm', positions: 1, indices: 2, transform: new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]), visible: true }]]),
  };
  const hit = pick(scene, { origin: [0.2, 0.2, 3], direction: [0, 0, -1] });
  assert.ok(hit);
  assert.equal(hit.distance, 3);
  assert.deepEqual(hit.normal, [0, 0, 1]);
});

test('A BVH of clustered, exponentially spaced triangles stays shallow enough and exact', () => {
  // Centroids at 2^-k: a middle split peels one triangle a level; the median fallback must
  // keep the build fast and the answers exact.
  const count = 3000, P = new Float32Array(count * 9);
  for (let k = 0; k < count; k++) {
    const x = Math.pow(2, -(k % 120)) * (1 + k / count);
    P.set([x, -1, 0, x, 1, 0, x * 1.001, 0, 0], k * 9);
  }
  const scene = {
    buffers: new Map([[1, { data: P }]]),
    meshes: new Map([[1, { element: 'm', positions: 1, indices: 0, transform: new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]), visible: true }]]),
  };
  // Splits that leave each side at least an eighth give a depth of at most log(n) / log(8 / 7);
  // middle splits alone go one level per distinct power of two (about 120 here).
  const bvh = meshBvh(P, null, P.length / 3);
  bvh.build();
  const depth = bvh.depth;
  assert.ok(depth <= Math.ceil(Math.log(count) / Math.log(8 / 7)), `depth ${depth}`);
  const r = rng(7);
  for (let k = 0; k < 100; k++) {
    const ray = { origin: [r() * 1.2, (r() - 0.5) * 1.5, 5], direction: normalize([0.01 * (r() - 0.5), 0.01 * (r() - 0.5), -1]) };
    const want = pickAll(scene, ray), got = pick(scene, ray);
    assert.equal(!!got, !!want, `ray ${k}`);
    if (want) assert.ok(Math.abs(got.distance - want.distance) <= 1e-9 * want.distance, `ray ${k}`);
  }
});

test('A geometry\'s BVH is built once and found again by its arrays', () => {
  const P = new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0]);
  const a = meshBvh(P, null, 3);
  assert.equal(meshBvh(P, null, 3), a);
  assert.notEqual(meshBvh(new Float32Array(P), null, 3), a);
  const I = new Uint32Array([0, 1, 2]);
  assert.notEqual(meshBvh(P, I, 3), a);
  assert.equal(meshBvh(P, I, 3), meshBvh(P, I, 3));
});
