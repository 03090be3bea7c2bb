import { test } from 'node:test';
import assert from 'node:assert/strict';
import { page } from '../dom.js';
import { loadGltf, sourceOf, pendingValues } from '../../../src/reader/GltfLoader.js';
import { MarkupReader } from '../../../src/reader/MarkupReader.js';
import { Resources } from '../../../src/reader/Resources.js';

// scene.bin: packed float3 positions (0..36), an interleaved view of float3 positions and
// normals with byteStride 24 (36..108), u16 indices (108..114), normalised u8 texcoords (116..122).
const BIN_URL = 'http://localhost/m/scene.bin';
function sceneBin() {
  const bin = new ArrayBuffer(124), dv = new DataView(bin);
  [0, 0, 0, 1, 0, 0, 0, 1, 0].forEach((v, i) => dv.setFloat32(4 * i, v, true));
  for (let k = 0; k < 3; k++)
    for (let c = 0; c < 3; c++) {
      dv.setFloat32(36 + 24 * k + 4 * c, 10 * k + c, true);
      dv.setFloat32(36 + 24 * k + 12 + 4 * c, c === 2 ? 1 : 0, true);
    }
  [0, 1, 2].forEach((v, i) => dv.setUint16(108 + 2 * i, v, true));
  [0, 0, 255, 0, 0, 255].forEach((v, i) => dv.setUint8(116 + i, v));
  return bin;
}
const gltf = (uri) => ({
  asset: { version: '2.0' }, scene: 0, scenes: [{ nodes: [0] }], nodes: [{ mesh: 0 }],
  meshes: [{ primitives: [
    { attributes: { POSITION: 0, TEXCOORD_0: 4 }, indices: 2 },
    { attributes: { POSITION: 1, NORMAL: 3 }, indices: 2 },
    { attributes: { POSITION: 0 }, indices: 2, mode: 5 },
  ] }],
  accessors: [
    { bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' },
    { bufferView: 1, componentType: 5126, count: 3, type: 'VEC3' },
    { bufferView: 2, componentType: 5123, count: 3, type: 'SCALAR' },
    { bufferView: 1, byteOffset: 12, componentType: 5126, count: 3, type: 'VEC3' },
    { bufferView: 3, componentType: 5121, normalized: true, count: 3, type: 'VEC2' },
  ],
  bufferViews: [{ buffer: 0, byteOffset: 0, byteLength: 36 }, { buffer: 0, byteOffset: 36, byteLength: 72, byteStride: 24 },
    { buffer: 0, byteOffset: 108, byteLength: 6 }, { buffer: 0, byteOffset: 116, byteLength: 6 }],
  buffers: [{ uri, byteLength: 124 }],
});

// What a node reads from the file for a source: the check that a source describes its array.
function readSource(bin, s) {
  const dv = new DataView(bin), size = { f32: 4, u32: 4, u16: 2, u8: 1 }[s.source];
  const stride = s.byteStride || s.components * size, out = [];
  for (let k = 0; k < s.values / s.components; k++)
    for (let c = 0; c < s.components; c++) {
      const p = s.byteOffset + k * stride + c * size;
      out.push(s.source === 'f32' ? dv.getFloat32(p, true) : s.source === 'u16' ? dv.getUint16(p, true) : s.source === 'u8' ? dv.getUint8(p) : dv.getUint32(p, true));
    }
  return out;
}

test('glTF accessors read straight from an external buffer name their source: packed, strided, widened u16 indices', async () => {
  const bin = sceneBin();
  const g = await loadGltf(gltf('scene.bin'), 'http://localhost/m/scene.gltf', async () => bin);
  const [a, b] = g.meshes;
  assert.deepEqual(sourceOf(a.positions), { url: BIN_URL, byteOffset: 0, byteStride: 0, source: 'f32', components: 3, values: 9 });
  assert.deepEqual(sourceOf(b.positions), { url: BIN_URL, byteOffset: 36, byteStride: 24, source: 'f32', components: 3, values: 9 });
  assert.deepEqual(sourceOf(b.normals), { url: BIN_URL, byteOffset: 48, byteStride: 24, source: 'f32', components: 3, values: 9 });
  assert.ok(a.indices instanceof Uint32Array);
  assert.deepEqual(sourceOf(a.indices), { url: BIN_URL, byteOffset: 108, byteStride: 0, source: 'u16', components: 1, values: 3 });
  assert.equal(b.indices, a.indices, 'an accessor shared by primitives gives one array, with its source');
  for (const arr of [a.positions, b.positions, b.normals, a.indices]) assert.deepEqual(readSource(bin, sourceOf(arr)), [...arr]);
  assert.equal(sourceOf(a.texcoords), null, 'normalised bytes are scaled: no source');
  assert.deepEqual([...a.texcoords], [0, 0, 1, 0, 0, 1]);
});

test('glTF buffers in data: URIs have no source', async () => {
  const uri = 'data:application/octet-stream;base64,' + Buffer.from(sceneBin()).toString('base64');
  const g = await loadGltf(gltf(uri), 'http://localhost/m/scene.gltf', async () => assert.fail('nothing is fetched'));
  const [a, b] = g.meshes;
  for (const arr of [a.positions, a.indices, b.positions, b.normals]) assert.equal(sourceOf(arr), null);
  assert.deepEqual([...b.positions], [0, 1, 2, 10, 11, 12, 20, 21, 22]);
});

test('the scene\'s buffers carry the sources of glTF arrays; a triangle strip\'s unrolled indices have none', async () => {
  const bin = new Uint8Array(sceneBin());
  const files = { 'http://localhost/m/scene.gltf': gltf('scene.bin'), [BIN_URL]: bin };
  const fetch = async (url) => (files[url] === undefined ? { ok: false, status: 404 } : {
    ok: true, status: 200, json: async () => files[url], arrayBuffer: async () => files[url].buffer });
  let loaded;
  const done = new Promise((r) => (loaded = r));
  const reader = new MarkupReader({ resources: new Resources({ fetch, onLoad: () => loaded() }) });
  const doc = page('<xml3d><model src="m/scene.gltf"></model><mesh><float3 name="position">0 0 0 1 0 0 0 1 0</float3></mesh></xml3d>');
  reader.read(doc.querySelector('xml3d'));
  await done;
  const scene = reader.read(doc.querySelector('xml3d'));
  assert.deepEqual(scene.errors, []);
  const [list, interleaved, strip, markup] = [...scene.meshes.values()];
  const source = (id) => scene.buffers.get(id).source;
  assert.equal(source(list.positions).byteOffset, 0);
  assert.equal(source(list.indices).source, 'u16');
  assert.equal(source(list.texcoords), null);
  assert.equal(source(interleaved.normals).byteStride, 24);
  assert.equal(strip.positions, list.positions, 'the same array, the same buffer');
  assert.notEqual(strip.indices, list.indices);
  assert.equal(source(strip.indices), null, 'indices made by unrolling a strip');
  assert.equal(source(markup.positions), null);
});

// Deferred loads: a packed file (float3 positions and normals, u16 indices) whose arrays are all
// views of the file's bytes or widened indices, so that nothing needs the values at once.
const packed = () => ({
  asset: { version: '2.0' }, scenes: [{ nodes: [0] }], nodes: [{ mesh: 0 }],
  meshes: [{ primitives: [{ attributes: { POSITION: 0, NORMAL: 1 }, indices: 2 }] }],
  accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }, { bufferView: 1, componentType: 5126, count: 3, type: 'VEC3' },
    { bufferView: 2, componentType: 5123, count: 3, type: 'SCALAR' }],
  bufferViews: [{ buffer: 0, byteOffset: 0, byteLength: 36 }, { buffer: 0, byteOffset: 36, byteLength: 36 },
    { buffer: 0, byteOffset: 72, byteLength: 6 }],
  buffers: [{ uri: 'packed.bin', byteLength: 80 }],
});
function packedBin() {
  const bin = new ArrayBuffer(80), dv = new DataView(bin);
  [0, 0, 0, 1, 0, 0, 0, 1, 0].forEach((v, i) => dv.setFloat32(4 * i, v, true));
  [0, 0, 1, 0, 0, 1, 0, 0, 1].forEach((v, i) => dv.setFloat32(36 + 4 * i, v, true));
  [2, 1, 0].forEach((v, i) => dv.setUint16(72 + 2 * i, v, true));
  return bin;
}
const until = async (cond, ms = 2000) => {
  for (const t0 = Date.now(); !cond(); await new Promise((r) => setTimeout(r, 5))) if (Date.now() - t0 > ms) throw new Error('timed out');
};
const later = () => { let resolve; const p = new Promise((r) => (resolve = r)); return { p, resolve }; };

test('a deferred load returns before its buffers are in: views of zeros with their sources, filled in place when the download is in', async () => {
  const download = later();
  const g = await loadGltf(packed(), 'http://localhost/m/packed.gltf', () => download.p, { defer: true });
  assert.equal(g.deferred, true);
  const [m] = g.meshes;
  for (const arr of [m.positions, m.normals, m.indices]) {
    assert.ok(arr.every((v) => v === 0), 'zeros until the values are in');
    assert.ok(pendingValues(arr), 'and said to be pending');
  }
  assert.deepEqual(sourceOf(m.positions), { url: 'http://localhost/m/packed.bin', byteOffset: 0, byteStride: 0, source: 'f32', components: 3, values: 9 });
  assert.equal(sourceOf(m.indices).source, 'u16');
  download.resolve(packedBin());
  await g.ready;
  assert.deepEqual([...m.positions], [0, 0, 0, 1, 0, 0, 0, 1, 0]);
  assert.deepEqual([...m.normals], [0, 0, 1, 0, 0, 1, 0, 0, 1]);
  assert.deepEqual([...m.indices], [2, 1, 0], 'widened again from the values');
  for (const arr of [m.positions, m.normals, m.indices]) assert.equal(pendingValues(arr), null);
  // Without defer the same file waits for its buffers, as before.
  const whole = await loadGltf(packed(), 'http://localhost/m/packed.gltf', async () => packedBin());
  assert.equal(whole.deferred, false);
  assert.equal(whole.ready, null);
  assert.deepEqual([...whole.meshes[0].indices], [2, 1, 0]);
});

test('a file with arrays converted from its values (strided, normalised, strips) loads whole even when deferred', async () => {
  let fetched = 0;
  const g = await loadGltf(gltf('scene.bin'), 'http://localhost/m/scene.gltf', async () => { fetched++; return sceneBin(); }, { defer: true });
  assert.equal(g.deferred, false);
  assert.equal(fetched, 1);
  assert.deepEqual([...g.meshes[1].positions], [0, 1, 2, 10, 11, 12, 20, 21, 22]);
  assert.equal(pendingValues(g.meshes[1].positions), null);
});

test('a deferred download shorter than the glTF says fails with the file and both sizes', async () => {
  const g = await loadGltf(packed(), 'http://localhost/m/packed.gltf', async () => new ArrayBuffer(40), { defer: true });
  await assert.rejects(g.ready, /packed\.bin: 40 bytes, the glTF says 80/);
  assert.ok(pendingValues(g.meshes[0].positions), 'never filled');
});

test('Resources with deferBuffers: loaded at once and filling until the values are in; a whole load of the same file shares the download', async () => {
  const download = later();
  const fetches = [];
  const fetch = async (url) => {
    fetches.push(url);
    return { ok: true, status: 200, json: async () => packed(), arrayBuffer: () => download.p };
  };
  const calls = [];
  const deferredRes = new Resources({ fetch, deferBuffers: true, onLoad: (k, e) => calls.push(['deferred', e.state, e.filling]) });
  const wholeRes = new Resources({ fetch, onLoad: (k, e) => calls.push(['whole', e.state, e.filling]) });
  const d = deferredRes.get('http://localhost/m/packed.gltf');
  const w = wholeRes.get('http://localhost/m/packed.gltf');
  await new Promise((r) => setTimeout(r, 20));
  assert.equal(d.state, 'loaded');
  assert.equal(d.filling, true);
  assert.equal(deferredRes.pending, 1, 'counted as pending (the load event waits)');
  assert.equal(w.state, 'loading');
  assert.deepEqual(calls, [['deferred', 'loaded', true]]);
  download.resolve(packedBin());
  await new Promise((r) => setTimeout(r, 20));
  assert.equal(d.filling, false);
  assert.equal(deferredRes.pending, 0);
  assert.equal(w.state, 'loaded');
  assert.deepEqual([...d.data.meshes[0].indices], [2, 1, 0]);
  assert.deepEqual([...w.data.meshes[0].indices], [2, 1, 0]);
  assert.equal(fetches.filter((u) => u.endsWith('.bin')).length, 1, 'one download for both loads');
  assert.deepEqual(calls.filter((c) => c[0] === 'deferred'), [['deferred', 'loaded', true], ['deferred', 'loaded', false]]);
});

test('deferred loads start their buffer downloads when the download gate opens; whole loads do not wait for it', async () => {
  const fetches = [];
  const fetch = async (url) => {
    fetches.push(url);
    return { ok: true, status: 200, json: async () => packed(), arrayBuffer: async () => packedBin() };
  };
  let open;
  const res = new Resources({ fetch, deferBuffers: true });
  res.downloadGate = new Promise((r) => (open = r));
  const e = res.get('http://localhost/m/packed.gltf');
  await new Promise((r) => setTimeout(r, 20));
  assert.equal(e.state, 'loaded');
  assert.deepEqual(fetches, ['http://localhost/m/packed.gltf'], 'the JSON only, until the gate opens');
  open();
  await new Promise((r) => setTimeout(r, 20));
  assert.equal(e.filling, false);
  assert.deepEqual([...e.data.meshes[0].positions], [0, 0, 0, 1, 0, 0, 0, 1, 0]);
  // A Resources without deferral fetches at once, whatever its gate.
  const whole = new Resources({ fetch });
  whole.downloadGate = new Promise(() => {});
  const w = whole.get('http://localhost/m/other.gltf');
  await new Promise((r) => setTimeout(r, 20));
  assert.equal(w.state, 'loaded');
});

test('the reader checks a deferred glTF\'s values once they are in: zeros pass while pending, an index out of range then drops the mesh', async () => {
  const download = later();
  const bad = packedBin();
  new DataView(bad).setUint16(72, 7, true);  // index 7 of 3 vertices
  const fetch = async () => ({ ok: true, status: 200, json: async () => packed(), arrayBuffer: () => download.p });
  let loads = 0;
  const resources = new Resources({ fetch, deferBuffers: true, onLoad: () => loads++ });
  const reader = new MarkupReader({ resources });
  const doc = page('<xml3d><model src="http://localhost/m/bad-index.gltf"></model></xml3d>');
  reader.read(doc.querySelector('xml3d'));
  await until(() => loads === 1);
  const pending = reader.read(doc.querySelector('xml3d'));
  assert.equal(pending.meshes.size, 1, 'sent while its values are on their way (the node checks what it loads)');
  assert.deepEqual(pending.errors, []);
  download.resolve(bad);
  await until(() => loads === 2);
  const loaded = reader.read(doc.querySelector('xml3d'));
  assert.equal(loaded.meshes.size, 0);
  assert.match(loaded.errors.map((e) => e.message).join('\n'), /index 7 out of range \(3 vertices\)/);
});

test('the reader checks a deferred glTF\'s positions once they are in: NaN drops the mesh then', async () => {
  const download = later();
  const bad = packedBin();
  new DataView(bad).setFloat32(4, NaN, true);
  const fetch = async () => ({ ok: true, status: 200, json: async () => packed(), arrayBuffer: () => download.p });
  let loads = 0;
  const reader = new MarkupReader({ resources: new Resources({ fetch, deferBuffers: true, onLoad: () => loads++ }) });
  const doc = page('<xml3d><model src="http://localhost/m/bad-positions.gltf"></model></xml3d>');
  reader.read(doc.querySelector('xml3d'));
  await until(() => loads === 1);
  assert.equal(reader.read(doc.querySelector('xml3d')).meshes.size, 1);
  download.resolve(bad);
  await until(() => loads === 2);
  const loaded = reader.read(doc.querySelector('xml3d'));
  assert.equal(loaded.meshes.size, 0);
  assert.match(loaded.errors.map((e) => e.message).join('\n'), /positions hold NaN or Infinity/);
});

// ---- conformance: what real exporters write (the node's loader reads the same, test_gltf.cpp) ----

// A glTF over one data: buffer made of `views` (typed arrays, each padded to 4 bytes).
function overViews(views, rest) {
  const parts = [], bufferViews = [];
  let at = 0;
  for (const v of views) {
    const bytes = new Uint8Array(v.buffer, v.byteOffset, v.byteLength);
    bufferViews.push({ buffer: 0, byteOffset: at, byteLength: bytes.length });
    parts.push(bytes);
    at += bytes.length;
    const pad = (4 - (at % 4)) % 4;
    if (pad) { parts.push(new Uint8Array(pad)); at += pad; }
  }
  const all = Buffer.concat(parts.map((p) => Buffer.from(p)));
  return { asset: { version: '2.0' }, scene: 0, scenes: [{ nodes: [0] }], nodes: [{ mesh: 0 }], bufferViews,
    buffers: [{ uri: 'data:application/octet-stream;base64,' + all.toString('base64'), byteLength: all.length }], ...rest };
}
const noFetch = async () => assert.fail('nothing is fetched');
const near = (got, want) => {
  assert.equal(got.length, want.length);
  for (let i = 0; i < want.length; i++) assert.ok(Math.abs(got[i] - want[i]) < 1e-6, `${i}: ${got[i]} vs ${want[i]}`);
};

test('glTF sparse accessors replace the elements they name, over a bufferView or zeros; bad ones are errors', async () => {
  const views = [new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0]), new Uint16Array([0, 2]), new Float32Array([5, 6, 7, 8, 9, 10]),
    new Uint16Array([2, 0])];
  const sparse = (indices) => ({ count: 2, indices: { bufferView: indices, componentType: 5123 }, values: { bufferView: 2 } });
  const file = (accessor) => overViews(views, { meshes: [{ primitives: [{ attributes: { POSITION: 0 } }] }], accessors: [accessor] });
  let g = await loadGltf(file({ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3', sparse: sparse(1) }), 'http://localhost/s.gltf', noFetch);
  assert.deepEqual([...g.meshes[0].positions], [5, 6, 7, 1, 0, 0, 8, 9, 10]);
  g = await loadGltf(file({ componentType: 5126, count: 3, type: 'VEC3', sparse: sparse(1) }), 'http://localhost/z.gltf', noFetch);
  assert.deepEqual([...g.meshes[0].positions], [5, 6, 7, 0, 0, 0, 8, 9, 10]);
  await assert.rejects(loadGltf(file({ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3', sparse: sparse(3) }), 'http://localhost/o.gltf', noFetch),
    /accessor 0: sparse index 0 out of range or not increasing/);
  // The file's own bytes are not changed: another accessor over the same view reads them as they are.
  g = await loadGltf(overViews(views, { meshes: [{ primitives: [{ attributes: { POSITION: 0 } }, { attributes: { POSITION: 1 } }] }],
    accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3', sparse: sparse(1) },
      { bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }] }), 'http://localhost/t.gltf', noFetch);
  assert.deepEqual([...g.meshes[1].positions], [0, 0, 0, 1, 0, 0, 0, 1, 0]);
});

test('glTF triangle fans become triangle lists; quantized attributes are scaled; points and lines are counted', async () => {
  const views = [new Int16Array([0, 0, 0, 0, 32767, 0, 0, 0, 0, 32767, 0, 0, 32767, 32767, 0, 0]), new Uint8Array([3, 2, 1, 0])];
  const file = overViews(views, {
    extensionsUsed: ['KHR_mesh_quantization'], extensionsRequired: ['KHR_mesh_quantization'],
    meshes: [{ primitives: [{ attributes: { POSITION: 0 }, mode: 6 }, { attributes: { POSITION: 0 }, indices: 1, mode: 6 },
      { attributes: { POSITION: 0 }, mode: 1 }] }],
    accessors: [{ bufferView: 0, byteOffset: 0, componentType: 5122, normalized: true, count: 4, type: 'VEC3' },
      { bufferView: 1, componentType: 5121, count: 4, type: 'SCALAR' }],
  });
  file.bufferViews[0].byteStride = 8;  // normalized shorts, 4-byte aligned vertices
  const g = await loadGltf(file, 'http://localhost/f.gltf', noFetch);
  assert.equal(g.meshes.length, 2, 'both fans drawn');
  assert.deepEqual([...g.meshes[0].positions], [0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0]);
  assert.deepEqual([...g.meshes[0].indices], [1, 2, 0, 2, 3, 0]);
  assert.deepEqual([...g.meshes[1].indices], [2, 1, 3, 1, 0, 3]);
  assert.equal(g.meshes[0].strip, false);
  assert.equal(g.undrawn, 1);
  assert.deepEqual(g.warnings, []);
});

test('a glTF material\'s texCoord set and KHR_texture_transform are baked into the coordinates; unlit and spec-gloss materials', async () => {
  const views = [new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0]), new Float32Array([0, 0, 1, 0, 0, 1]), new Float32Array([0.5, 0.5, 1, 0.5, 0.5, 1])];
  const file = (materials, extensionsUsed = []) => overViews(views, {
    extensionsUsed, images: [{ uri: 't.png' }], textures: [{ source: 0 }], materials,
    meshes: [{ primitives: [{ attributes: { POSITION: 0, TEXCOORD_0: 1, TEXCOORD_1: 2 }, material: 0 }] }],
    accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }, { bufferView: 1, componentType: 5126, count: 3, type: 'VEC2' },
      { bufferView: 2, componentType: 5126, count: 3, type: 'VEC2' }],
  });
  let g = await loadGltf(file([{ pbrMetallicRoughness: { baseColorTexture: { index: 0, texCoord: 1 } } }]), 'http://localhost/a.gltf', noFetch);
  near(g.meshes[0].texcoords, [0.5, 0.5, 1, 0.5, 0.5, 1]);
  // Scale, then a quarter turn (columns (cos, -sin), (sin, cos): counter-clockwise with v down, as the
  // TextureTransformTest sample model and three.js, not the transposed matrix of the extension's GLSL
  // listing), then the offset: u' = 3 v + 0.5, v' = -2 u + 0.25.
  g = await loadGltf(file([{ pbrMetallicRoughness: { baseColorTexture: { index: 0, extensions: { KHR_texture_transform:
    { offset: [0.5, 0.25], rotation: Math.PI / 2, scale: [2, 3] } } } } }], ['KHR_texture_transform']), 'http://localhost/b.gltf', noFetch);
  near(g.meshes[0].texcoords, [0.5, 0.25, 0.5, -1.75, 3.5, 0.25]);
  assert.equal(sourceOf(g.meshes[0].texcoords), null);
  assert.deepEqual(g.warnings, []);
  g = await loadGltf(file([{ pbrMetallicRoughness: { baseColorTexture: { index: 0 } }, emissiveTexture: { index: 0, texCoord: 1 } }]),
    'http://localhost/c.gltf', noFetch);
  near(g.meshes[0].texcoords, [0, 0, 1, 0, 0, 1]);
  assert.match(g.warnings[0], /emissive texture reads other texture coordinates/);
  g = await loadGltf(file([{ pbrMetallicRoughness: { baseColorFactor: [0.2, 0.4, 0.6, 1], metallicFactor: 1 },
    extensions: { KHR_materials_unlit: {} } }], ['KHR_materials_unlit']), 'http://localhost/d.gltf', noFetch);
  assert.equal(g.meshes[0].material.model, 'matte');
  assert.deepEqual(g.meshes[0].material.diffuseColor, [0.2, 0.4, 0.6]);
  assert.equal(g.meshes[0].material.reflectionCoefficient, 0);
  g = await loadGltf(file([{ emissiveFactor: [1, 0.5, 0], extensions: { KHR_materials_emissive_strength: { emissiveStrength: 4 } } }],
    ['KHR_materials_emissive_strength']), 'http://localhost/s.gltf', noFetch);
  assert.deepEqual(g.meshes[0].material.emissiveColor, [4, 2, 0], 'emissiveFactor times emissiveStrength, as on the node');
  g = await loadGltf(file([{ extensions: { KHR_materials_pbrSpecularGlossiness: { diffuseFactor: [0.5, 0.25, 1, 1],
    diffuseTexture: { index: 0, texCoord: 1 } } } }], ['KHR_materials_pbrSpecularGlossiness']), 'http://localhost/e.gltf', noFetch);
  assert.deepEqual(g.meshes[0].material.diffuseColor, [0.5, 0.25, 1]);
  assert.equal(g.meshes[0].material.diffuseTexture.url, 'http://localhost/t.png');
  assert.equal(g.meshes[0].material.reflectionCoefficient, 0);
  near(g.meshes[0].texcoords, [0.5, 0.5, 1, 0.5, 0.5, 1]);
});

test('glTF extensions: a required one the reader lacks is an error naming it, a used one a warning; .glb images become blob: URLs', async () => {
  const views = [new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0]), new Uint8Array([0x89, 0x50, 0x4e, 0x47])];
  const base = { meshes: [{ primitives: [{ attributes: { POSITION: 0 }, material: 0 }] }],
    accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }] };
  await assert.rejects(loadGltf(overViews(views, { ...base, materials: [{}], extensionsRequired: ['KHR_draco_mesh_compression'] }),
    'http://localhost/d.gltf', noFetch), /requires glTF extensions this loader does not implement: KHR_draco_mesh_compression/);
  const g = await loadGltf(overViews(views, { ...base, extensionsUsed: ['KHR_materials_clearcoat', 'KHR_materials_ior'],
    images: [{ bufferView: 1, mimeType: 'image/png' }], textures: [{ source: 0 }], materials: [{ pbrMetallicRoughness: { baseColorTexture: { index: 0 } } }] }),
  'http://localhost/g.gltf', noFetch);
  assert.deepEqual(g.warnings, ['glTF extensions ignored: KHR_materials_clearcoat']);
  const url = g.meshes[0].material.diffuseTexture.url;
  assert.match(url, /^blob:/);
  const bytes = new Uint8Array(await (await fetch(url)).arrayBuffer());
  assert.deepEqual([...bytes], [0x89, 0x50, 0x4e, 0x47], 'the image\'s bytes from the binary chunk');
});

test('glTF materials become the XML3D materials of tests/data/gltf-materials.json, as on the node', async () => {
  const fs = await import('node:fs');
  const table = JSON.parse(fs.readFileSync(new URL('../../../../tests/data/gltf-materials.json', import.meta.url), 'utf8'));
  const views = [new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0])];
  const g = await loadGltf(overViews(views, {
    extensionsUsed: ['KHR_materials_transmission', 'KHR_materials_ior', 'KHR_materials_emissive_strength', 'KHR_materials_unlit', 'KHR_materials_pbrSpecularGlossiness'],
    materials: table.cases.map((c) => c.material),
    meshes: [{ primitives: table.cases.map((_, k) => ({ attributes: { POSITION: 0 }, material: k })) }],
    accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }],
  }), 'http://localhost/materials.gltf', noFetch);
  assert.deepEqual(g.warnings, []);
  assert.equal(g.meshes.length, table.cases.length);
  table.cases.forEach((c, k) => {
    const m = g.meshes[k].material, x = c.expect, at = c.name;
    const close = (got, want, what) => assert.ok(Math.abs(got - want) < 1e-5, `${at}: ${what} ${got}, expected ${want}`);
    assert.equal(m.model, x.model, at);
    for (const [key, want] of [['diffuseColor', x.diffuse], ['specularColor', x.specular], ['emissiveColor', x.emissive]])
      want.forEach((v, j) => close(m[key][j], v, `${key}[${j}]`));
    if (x.shininess !== undefined) close(m.shininess, x.shininess, 'shininess');
    close(m.opacity, x.opacity, 'opacity');
    close(m.reflectionCoefficient, x.reflection, 'reflection');
    close(m.refractionCoefficient, x.refraction, 'refraction');
    if (x.ior !== undefined) close(m.refractionIndex, x.ior, 'ior');
    assert.equal(m.alphaMask, x.alphaMask, at);
    if (x.alphaCutoff !== undefined) close(m.alphaCutoff, x.alphaCutoff, 'alphaCutoff');
    assert.equal(m.doubleSided, x.doubleSided, at);
  });
});

test('glTF accessors and bufferViews that do not fit are errors naming them, before anything is read or allocated', async () => {
  const views = [new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0])];
  const file = (accessor, view = {}) => {
    const f = overViews(views, { meshes: [{ primitives: [{ attributes: { POSITION: 0 } }] }], accessors: [accessor] });
    Object.assign(f.bufferViews[0], view);
    return f;
  };
  const cases = [
    [{ bufferView: 0, componentType: 5126, count: 4, type: 'VEC3' }, {}, /accessor 0: 4 elements \(stride 12, byteOffset 0\) read past the end of bufferView 0 \(36 bytes\)/],
    [{ bufferView: 0, byteOffset: 4, componentType: 5126, count: 3, type: 'VEC3' }, {}, /read past the end of bufferView 0/],
    [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }, { byteStride: 16 }, /stride 16.*read past the end/],
    [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }, { byteLength: 4000 }, /bufferView 0 \(byteOffset 0, byteLength 4000\) exceeds buffer 0 \(36 bytes\)/],
    [{ componentType: 5126, count: 2 ** 30, type: 'VEC3' }, {}, /accessor 0 without a bufferView has 1073741824 elements \(at most 16777216\)/],
    [{ bufferView: 0, componentType: 5126, count: -1, type: 'VEC3' }, {}, /accessor 0: count -1 is not a count/],
    [{ bufferView: 7, componentType: 5126, count: 3, type: 'VEC3' }, {}, /accessor 0: bufferView 7 or its buffer does not exist/],
  ];
  for (const [a, v, message] of cases) await assert.rejects(loadGltf(file(a, v), 'http://localhost/bad.gltf', noFetch), message);
  // A fan without indices: its POSITION count is checked before it sizes the fan's order.
  const fan = file({ bufferView: 0, componentType: 5126, count: 2 ** 29, type: 'VEC3' });
  fan.meshes[0].primitives[0].mode = 6;
  await assert.rejects(loadGltf(fan, 'http://localhost/fan.gltf', noFetch), /accessor 0: 536870912 elements .* read past the end of bufferView 0/);
  const f = file({ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' });
  f.meshes[0].primitives[0].attributes.POSITION = 5;
  await assert.rejects(loadGltf(f, 'http://localhost/bad.gltf', noFetch), /accessor 5 does not exist/);
});

test('glTF nodes reached twice (a second parent, a cycle) are an error, not a walk that never ends', async () => {
  const views = [new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0])];
  const base = { meshes: [{ primitives: [{ attributes: { POSITION: 0 } }] }], accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }] };
  // 64 nodes, each listing the next one twice: 2^64 visits without the check.
  const dag = Array.from({ length: 64 }, (_, k) => (k < 63 ? { mesh: 0, children: [k + 1, k + 1] } : { mesh: 0 }));
  const t0 = Date.now();
  await assert.rejects(loadGltf({ ...overViews(views, base), nodes: dag }, 'http://localhost/dag.gltf', noFetch), /node 63 is reached twice/);  // depth first: the last one's second parent
  assert.ok(Date.now() - t0 < 5000);
  await assert.rejects(loadGltf({ ...overViews(views, base), nodes: [{ children: [1] }, { children: [0] }] }, 'http://localhost/cycle.gltf', noFetch),
    /node 0 is reached twice/);
  await assert.rejects(loadGltf({ ...overViews(views, base), nodes: [{ children: [9] }] }, 'http://localhost/missing.gltf', noFetch),
    /node 9 does not exist/);
  await assert.rejects(loadGltf({ ...overViews(views, base), nodes: [{ mesh: 3 }] }, 'http://localhost/nomesh.gltf', noFetch),
    /node 0 names mesh 3, which does not exist/);
  const nocam = await loadGltf({ ...overViews(views, base), nodes: [{ mesh: 0, camera: 2 }] }, 'http://localhost/nocam.gltf', noFetch);
  assert.equal(nocam.camera, null, 'a camera that does not exist is ignored');
  const tree = await loadGltf({ ...overViews(views, base), nodes: [{ children: [1, 2] }, { mesh: 0 }, { mesh: 0, translation: [1, 0, 0] }] },
    'http://localhost/tree.gltf', noFetch);
  assert.equal(tree.meshes.length, 2, 'one mesh instanced by two nodes is fine');
});

test('glTF animations, skins and morph targets are not played and one warning says so; the rest pose loads', async () => {
  const views = [new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0]), new Float32Array([0, 0, 1, 0, 0, 1, 0, 0, 1]), new Float32Array([0, 1])];
  const accessors = [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }, { bufferView: 1, componentType: 5126, count: 3, type: 'VEC3' },
    { bufferView: 2, componentType: 5126, count: 2, type: 'SCALAR', min: [0], max: [1] }];
  let g = await loadGltf(overViews(views, { meshes: [{ primitives: [{ attributes: { POSITION: 0 } }] }], accessors }), 'http://localhost/still.gltf', noFetch);
  assert.deepEqual(g.warnings, []);
  const file = overViews(views, { meshes: [{ primitives: [{ attributes: { POSITION: 0 }, targets: [{ POSITION: 1 }] }] }], accessors });
  file.animations = [{ samplers: [{ input: 2, output: 2 }], channels: [{ sampler: 0, target: { node: 0, path: 'weights' } }] }];
  g = await loadGltf(file, 'http://localhost/morph.gltf', noFetch);
  assert.equal(g.meshes.length, 1);
  near(g.meshes[0].positions, [0, 0, 0, 1, 0, 0, 0, 1, 0]);
  assert.deepEqual(g.warnings, ['1 animation, 1 primitive with morph targets not played: the meshes are drawn in the file\'s rest pose']);
});

test('a glTF without scenes draws every node tree from its roots, children once, through their parents', async () => {
  const views = [new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0])];
  const base = { meshes: [{ primitives: [{ attributes: { POSITION: 0 } }] }], accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }] };
  const file = overViews(views, base);
  delete file.scene;
  delete file.scenes;
  // Two trees: node 0 (moved by 5 in x) with its child 1, and node 2 alone.
  file.nodes = [{ children: [1], translation: [5, 0, 0] }, { mesh: 0 }, { mesh: 0, translation: [0, 7, 0] }];
  const g = await loadGltf(file, 'http://localhost/noscenes.gltf', noFetch);
  assert.equal(g.meshes.length, 2);
  const moved = g.meshes.map((m) => [m.matrix[12], m.matrix[13]]).sort((a, b) => a[0] - b[0]);
  assert.deepEqual(moved, [[0, 7], [5, 0]], 'the child drawn once, under its parent');
});

test('mutated glTF files load or fail with an Error, quickly: never a hang, a TypeError or a huge allocation', async () => {
  // A seeded generator over a valid file with every feature above: each round changes one to
  // three values somewhere in the JSON (a number to an extreme, a value to another type, a key
  // dropped) and loads the result.
  let seed = 12345;
  const rand = () => ((seed = (seed * 1103515245 + 12345) >>> 0) / 2 ** 32);
  const views = [new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0]), new Uint16Array([0, 1, 2, 2, 1, 3]), new Uint16Array([1]),
    new Float32Array([2, 2, 0]), new Float32Array([0, 0, 1, 0, 0, 1, 1, 1])];
  const valid = overViews(views, {
    extensionsUsed: ['KHR_texture_transform', 'KHR_materials_unlit'],
    nodes: [{ children: [1, 2] }, { mesh: 0, translation: [1, 2, 3] }, { mesh: 1, rotation: [0, 0, 0, 1], scale: [2, 2, 2] }],
    meshes: [{ primitives: [{ attributes: { POSITION: 0, TEXCOORD_0: 2 }, indices: 1, material: 0 }] },
      { primitives: [{ attributes: { POSITION: 3 }, mode: 6, material: 1 }, { attributes: { POSITION: 0 }, mode: 5 }] }],
    materials: [{ pbrMetallicRoughness: { baseColorTexture: { index: 0, extensions: { KHR_texture_transform: { offset: [0.5, 0], rotation: 1, scale: [2, 2] } } } } },
      { extensions: { KHR_materials_unlit: {} } }],
    images: [{ uri: 't.png' }], textures: [{ source: 0 }],
    accessors: [{ bufferView: 0, componentType: 5126, count: 4, type: 'VEC3' }, { bufferView: 1, componentType: 5123, count: 6, type: 'SCALAR' },
      { bufferView: 4, componentType: 5126, count: 4, type: 'VEC2' },
      { bufferView: 0, componentType: 5126, count: 4, type: 'VEC3', sparse: { count: 1, indices: { bufferView: 2, componentType: 5123 }, values: { bufferView: 3 } } }],
  });
  const extremes = [-1, 0, 1, 3, 7, 2 ** 31, 2 ** 53, -(2 ** 31), 1e300, 0.5, null, 'x', [], {}, true];
  const paths = (o, at = []) => (o && typeof o === 'object'
    ? Object.entries(o).flatMap(([k, v]) => (at.length === 0 && k === 'buffers' ? [] : [[...at, k], ...paths(v, [...at, k])]))
    : []);
  const all = paths(valid);
  let loaded = 0, refused = 0;
  for (let round = 0; round < 400; round++) {
    const f = structuredClone(valid);
    for (let m = 1 + Math.floor(rand() * 3); m > 0; m--) {
      const p = all[Math.floor(rand() * all.length)];
      let o = f;
      for (const k of p.slice(0, -1)) o = o && typeof o === 'object' ? o[k] : undefined;
      if (!o || typeof o !== 'object') continue;
      if (rand() < 0.15) delete o[p[p.length - 1]];
      else o[p[p.length - 1]] = extremes[Math.floor(rand() * extremes.length)];
    }
    const t0 = Date.now();
    try {
      await loadGltf(f, 'http://localhost/m.gltf', async () => new ArrayBuffer(0));
      loaded++;
    } catch (e) {
      assert.ok(e instanceof Error, `round ${round}: threw ${e}`);
      // Of the Error class itself, with a message: a TypeError here would be the reader tripping
      // over the file, not refusing it (loadGltf turns those into "malformed glTF: ...").
      assert.equal(e.constructor, Error, `round ${round}: ${e.constructor.name}: ${e.message}`);
      if (process.env.GLTF_FUZZ_LOG) console.log(`FUZZ ${e.message}`);
      refused++;
    }
    assert.ok(Date.now() - t0 < 2000, `round ${round} took ${Date.now() - t0} ms`);
  }
  assert.ok(loaded > 50 && refused > 20, `loaded ${loaded}, refused ${refused}`);
});
