import { test } from 'node:test';
import assert from 'node:assert/strict';
import { page } from '../dom.js';
import { MarkupReader } from '../../../src/reader/MarkupReader.js';
import { SceneSync } from '../../../src/net/SceneSync.js';
import { encodeClient, decodeClient } from '../../../src/net/Protocol.js';

const PAGE = `<xml3d><defs><material id="m" model="urn:xml3d:material:phong"><float3 name="diffuseColor">0 1 0</float3>
  <float name="refractionCoefficient">0.5</float><float name="refractionIndex">1.33</float></material></defs>
  <light model="urn:xml3d:light:point"></light>
  <mesh id="a" material="#m"><float3 name="position">0 0 0 1 0 0 0 1 0</float3></mesh>
  <mesh id="b"><float3 name="position">0 0 0 1 0 0 0 1 0</float3><int name="index">0 1 2</int></mesh></xml3d>`;
const VIEW = { width: 320, height: 240 };

test('the first diff sends every entry, data before the meshes that use it', () => {
  const doc = page(PAGE);
  const scene = new MarkupReader().read(doc.querySelector('xml3d'));
  const recs = new SceneSync().diff(scene, VIEW);
  const types = recs.map((r) => r.type);
  assert.deepEqual(types.filter((t, i) => types.indexOf(t) === i), ['buffer', 'material', 'mesh', 'light', 'resolution', 'camera', 'environment']);
  assert.equal(types.filter((t) => t === 'mesh').length, 2);
  const mat = recs.find((r) => r.type === 'material' && r.model === 'phong');
  assert.equal(mat.refraction, 0.5);
  assert.ok(Math.abs(mat.ior - 1.33) < 1e-6);
  assert.equal(recs.find((r) => r.type === 'environment').linear, false);
  assert.equal(recs.find((r) => r.type === 'light').castShadow, false, "XML3D's default: no shadows");
  // Everything encodes and decodes under the protocol's rules.
  const wire = recs.filter((r) => r.type !== 'texture');
  assert.equal(decodeClient(encodeClient(wire)).length, wire.length);
});

test('an unchanged page sends nothing; a change sends only what changed; removal sends removes', () => {
  const doc = page(PAGE);
  const reader = new MarkupReader(), sync = new SceneSync();
  const x = doc.querySelector('xml3d');
  sync.diff(reader.read(x), VIEW);
  assert.deepEqual(sync.diff(reader.read(x), VIEW), []);
  doc.getElementById('a').setAttribute('style', 'transform: translateX(2px)');
  let recs = sync.diff(reader.read(x), VIEW);
  assert.deepEqual(recs.map((r) => r.type), ['mesh']);
  assert.equal(recs[0].transform[12], 2);
  doc.getElementById('b').remove();
  recs = sync.diff(reader.read(x), VIEW);
  assert.deepEqual(recs.map((r) => `${r.type}:${r.what}`).sort(), ['remove:buffer', 'remove:buffer', 'remove:material', 'remove:mesh'].sort());
  recs = sync.diff(reader.read(x), { width: 640, height: 480 });
  assert.deepEqual(recs.map((r) => r.type), ['resolution']);
});

test('reset re-sends the whole scene (after a reconnect)', () => {
  const doc = page(PAGE);
  const reader = new MarkupReader(), sync = new SceneSync();
  const n = sync.diff(reader.read(doc.querySelector('xml3d')), VIEW).length;
  sync.reset();
  assert.equal(sync.diff(reader.read(doc.querySelector('xml3d')), VIEW).length, n);
});

test('vertex colours reach the wire: the mesh names its colour buffer, the material carries useVertexColor', () => {
  const doc = page(`<xml3d><defs>
    <data id="quad"><float3 name="position">-1 -1 0 1 -1 0 1 1 0 -1 1 0</float3>
      <float3 name="color">1 0 0 0 1 0 0 0 1 1 1 1</float3><int name="index">0 1 2 0 2 3</int></data>
    <material id="vc" model="urn:xml3d:material:matte"><bool name="useVertexColor">true</bool></material>
    <material id="plain" model="urn:xml3d:material:matte"><float3 name="diffuseColor">1 1 0</float3></material></defs>
    <mesh id="a" src="#quad" material="#vc"></mesh>
    <mesh id="b" material="#plain"><float3 name="position">0 0 0 1 0 0 0 1 0</float3></mesh></xml3d>`);
  const recs = new SceneSync().diff(new MarkupReader().read(doc.querySelector('xml3d')), VIEW);
  const meshes = recs.filter((r) => r.type === 'mesh');
  const colored = meshes.find((m) => m.colors !== 0), plain = meshes.find((m) => m.colors === 0);
  assert.ok(colored && plain, 'one mesh with a colour buffer, one without');
  const buffer = recs.find((r) => r.type === 'buffer' && r.id === colored.colors);
  assert.ok(buffer, 'the colour buffer is sent before the mesh');
  assert.ok(recs.indexOf(buffer) < recs.indexOf(colored));
  assert.equal(buffer.bufferType, 'f32');
  assert.equal(buffer.components, 3);
  assert.deepEqual([...buffer.data], [1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1]);
  const mats = new Map(recs.filter((r) => r.type === 'material').map((m) => [m.id, m]));
  assert.equal(mats.get(colored.material).useVertexColor, true);
  assert.equal(mats.get(plain.material).useVertexColor, false);
  // And through the codec.
  const wire = decodeClient(encodeClient(recs.filter((r) => r.type !== 'texture')));
  assert.equal(wire.find((r) => r.type === 'mesh' && r.id === colored.id).colors, colored.colors);
  assert.equal(wire.find((r) => r.type === 'material' && r.id === colored.material).useVertexColor, true);
});

test('references only for what the node can load as it is: XML3D textures (flipped) and sources it would refuse to decode are uploaded', () => {
  const sceneWith = (buffers, textures) => ({ buffers: new Map(buffers.map((b) => [b.id, b])), textures: new Map(textures.map((t) => [t.id, t])),
    materials: new Map(), meshes: new Map(), lights: new Map(), camera: null, environment: { ambient: [0, 0, 0], exposure: 1 } });
  const data = new Float32Array(6);
  const source = { url: 'https://cdn.example/a.bin', byteOffset: 8, byteStride: 0, source: 'f32', components: 3, values: 6 };
  const buffer = (id, s) => ({ id, type: 'f32', components: 3, data, source: s && { ...source, ...s } });
  const texture = (id, t) => ({ id, url: 'https://cdn.example/t.png', wrapS: 'repeat', wrapT: 'clamp', filter: 'linear', flipY: false, srgb: true, ...t });
  const recs = new SceneSync().diff(sceneWith([
    buffer(1, {}), buffer(2, { byteStride: 16 }), buffer(3, null), buffer(4, { url: 'file:///a.bin' }), buffer(5, { url: `https://h/${'a'.repeat(4096)}` }),
    buffer(6, { byteStride: 8 }), buffer(7, { byteStride: 14 }), buffer(8, { source: 'u16' }), buffer(9, { components: 2 }),
  ], [texture(10, {}), texture(11, { flipY: true }), texture(12, { url: 'blob:https://cdn.example/x' })]), VIEW);
  const kinds = Object.fromEntries(recs.filter((r) => r.id).map((r) => [r.id, r.type]));
  assert.deepEqual(kinds, { 1: 'buffer_ref', 2: 'buffer_ref', 3: 'buffer', 4: 'buffer', 5: 'buffer', 6: 'buffer', 7: 'buffer', 8: 'buffer', 9: 'buffer',
    10: 'texture_ref', 11: 'texture', 12: 'texture' });
  const ref = recs.find((r) => r.id === 2);
  assert.deepEqual(ref.upload, { type: 'buffer', id: 2, bufferType: 'f32', components: 3, data }, 'what to upload when the node refuses it');
  assert.equal(decodeClient(encodeClient(recs.filter((r) => r.type.endsWith('_ref')))).length, 3);
  assert.equal(new SceneSync({ references: false }).diff(sceneWith([buffer(1, {})], [texture(10, {})]), VIEW).filter((r) => r.type.endsWith('_ref')).length, 0);
});
