import { test } from 'node:test';
import assert from 'node:assert/strict';
import { page } from '../dom.js';
import { MarkupReader } from '../../../src/reader/MarkupReader.js';
import { Resources } from '../../../src/reader/Resources.js';
import { setScriptValue } from '../../../src/reader/Values.js';

const read = (body, opts = {}) => {
  const doc = page(body);
  const scene = new MarkupReader(opts).read(doc.querySelector('xml3d'));
  return { doc, scene };
};
const only = (map) => { assert.equal(map.size, 1); return [...map.values()][0]; };
const near = (a, b, eps = 1e-5) => assert.ok(Math.abs(a - b) < eps, `${a} != ${b}`);
const nearArr = (a, b, eps = 1e-5) => { assert.equal(a.length, b.length); a.forEach((x, i) => near(x, b[i], eps)); };

const TRI = '<float3 name="position">-1 -1 0 1 -1 0 0 1 0</float3>';

test('a mesh without material gets the red matte default material', () => {
  const { scene } = read(`<xml3d><mesh type="triangles">${TRI}</mesh></xml3d>`);
  const mesh = only(scene.meshes);
  const mat = scene.materials.get(mesh.material);
  assert.equal(mat.model, 'matte');
  assert.deepEqual(mat.diffuseColor, [1, 0, 0]);
  assert.equal(mesh.indices, 0);
  assert.deepEqual([...scene.buffers.get(mesh.positions).data], [-1, -1, 0, 1, -1, 0, 0, 1, 0]);
  assert.equal(scene.errors.length, 0);
});

test('phong material defaults follow xml3d.js code (shininess 0.2, white diffuse, black specular)', () => {
  const { scene } = read(`<xml3d><defs><material id="m" model="urn:xml3d:material:phong"></material></defs>
    <mesh material="#m">${TRI}</mesh></xml3d>`);
  const mat = scene.materials.get(only(scene.meshes).material);
  assert.equal(mat.model, 'phong');
  near(mat.shininess, 0.2);
  assert.deepEqual(mat.diffuseColor, [1, 1, 1]);
  assert.deepEqual(mat.specularColor, [0, 0, 0]);
  assert.equal(mat.opacity, 1);
  assert.equal(mat.refractionIndex, 1);
});

test('material parameters, the paper extensions, and mesh-level overrides', () => {
  const { scene } = read(`<xml3d><defs>
    <material id="glass" model="urn:xml3d:material:phong">
      <float3 name="diffuseColor">0 0 1</float3><float name="shininess">0.5</float>
      <float name="reflectionCoefficient">0.1</float><float name="refractionCoefficient">0.9</float>
      <float name="refractionIndex">1.5</float></material></defs>
    <group material="#glass"><mesh id="a">${TRI}</mesh>
    <mesh id="b">${TRI}<float3 name="diffuseColor">0 1 0</float3></mesh></group></xml3d>`);
  const [a, b] = [...scene.meshes.values()];
  const ma = scene.materials.get(a.material), mb = scene.materials.get(b.material);
  assert.deepEqual(ma.diffuseColor, [0, 0, 1]);
  near(ma.reflectionCoefficient, 0.1); near(ma.refractionCoefficient, 0.9); near(ma.refractionIndex, 1.5);
  assert.deepEqual(mb.diffuseColor, [0, 1, 0]);
  near(mb.refractionIndex, 1.5);
  assert.notEqual(a.material, b.material);
});

test('shared position data with per-mesh index gives one buffer and two index buffers', () => {
  const { scene } = read(`<xml3d><defs><data id="quad"><float3 name="position">0 0 0 1 0 0 1 1 0 0 1 0</float3></data></defs>
    <mesh src="#quad"><int name="index">0 1 2</int></mesh><mesh src="#quad"><int name="index">0 2 3</int></mesh></xml3d>`);
  const [a, b] = [...scene.meshes.values()];
  assert.equal(a.positions, b.positions);
  assert.deepEqual([...scene.buffers.get(b.indices).data], [0, 2, 3]);
  assert.equal(scene.buffers.get(a.indices).type, 'u32');
});

test('tristrips are unrolled into triangles with alternating winding', () => {
  const { scene } = read(`<xml3d><mesh type="tristrips"><float3 name="position">0 0 0 1 0 0 0 1 0 1 1 0 0 2 0 1 2 0</float3>
    <int name="vertexCount">4 2</int></mesh></xml3d>`);
  const mesh = only(scene.meshes);
  assert.deepEqual([...scene.buffers.get(mesh.indices).data], [0, 1, 2, 2, 1, 3]);
});

test('nested data: outer values win over nested ones, later siblings win', () => {
  const { scene } = read(`<xml3d><mesh>
    <data><float3 name="position">9 9 9 9 9 9 9 9 9</float3></data>
    <data><float3 name="position">1 1 1 1 1 1 1 1 1</float3><float3 name="normal">0 0 1 0 0 1 0 0 1</float3></data>
    ${TRI}</mesh></xml3d>`);
  const mesh = only(scene.meshes);
  assert.deepEqual([...scene.buffers.get(mesh.positions).data], [-1, -1, 0, 1, -1, 0, 0, 1, 0]);
  assert.ok(mesh.normals);
});

test('transform element: T * C * R * SO * S * SO^-1 * C^-1, and groups compose', () => {
  const { scene } = read(`<xml3d><defs><transform id="t" translation="1 2 3" rotation="0 1 0 1.5707963" scale="2 2 2"></transform>
    <transform id="u" translation="10 0 0"></transform></defs>
    <group transform="#u"><mesh transform="#t">${TRI}</mesh></group></xml3d>`);
  const m = only(scene.meshes).transform;
  // x axis (1,0,0) -> scale 2 -> rotate 90deg about y -> (0,0,-2)
  nearArr([m[0], m[1], m[2]], [0, 0, -2]);
  nearArr([m[12], m[13], m[14]], [11, 2, 3]);
});

test('transform referencing a data element with a column-major float4x4', () => {
  const { scene } = read(`<xml3d><defs><data id="d"><float4x4 name="transform">1 0 0 0 0 1 0 0 0 0 1 0 5 6 7 1</float4x4></data></defs>
    <mesh transform="#d">${TRI}</mesh></xml3d>`);
  const m = only(scene.meshes).transform;
  nearArr([m[12], m[13], m[14]], [5, 6, 7]);
});

test('CSS transforms win over the transform attribute', () => {
  const { scene } = read(`<xml3d><defs><transform id="t" translation="100 0 0"></transform></defs>
    <mesh transform="#t" style="transform: translate3d(1px, 2px, 3px) rotateZ(90deg)">${TRI}</mesh></xml3d>`);
  const m = only(scene.meshes).transform;
  nearArr([m[12], m[13], m[14]], [1, 2, 3]);
  nearArr([m[0], m[1]], [0, 1]);
});

test('display:none drops a subtree; visibility:hidden keeps the mesh invisible', () => {
  const { scene } = read(`<xml3d><group style="display:none"><mesh>${TRI}</mesh></group>
    <group style="visibility:hidden"><mesh id="h">${TRI}</mesh></group><mesh id="v">${TRI}</mesh></xml3d>`);
  const ms = [...scene.meshes.values()];
  assert.equal(ms.length, 2);
  assert.equal(ms.find((m) => m.element.id === 'h').visible, false);
  assert.equal(ms.find((m) => m.element.id === 'v').visible, true);
});

test('scene elements inside defs are ignored', () => {
  const { scene } = read(`<xml3d><defs><mesh>${TRI}</mesh></defs></xml3d>`);
  assert.equal(scene.meshes.size, 0);
});

test('default view: origin, looking down -Z, fovVertical pi/4', () => {
  const { scene } = read(`<xml3d><mesh>${TRI}</mesh></xml3d>`);
  assert.equal(scene.camera.element, null);
  near(scene.camera.fovY, Math.PI / 4);
  nearArr([...scene.camera.toWorld], [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);
});

test('xml3d@view selects the active view; fovVertical and transform are read', () => {
  const { scene } = read(`<xml3d view="#v2"><view id="v1"></view>
    <view id="v2" style="transform: translate3d(0px, 0px, 10px)"><float name="fovVertical">0.5</float></view></xml3d>`);
  assert.equal(scene.camera.element.id, 'v2');
  near(scene.camera.fovY, 0.5);
  near(scene.camera.toWorld[14], 10);
});

test('first view is used when xml3d@view is missing', () => {
  const { scene } = read(`<xml3d><view id="a"><float name="fovVertical">0.3</float></view><view id="b"></view></xml3d>`);
  assert.equal(scene.camera.element.id, 'a');
});

test('lights: defaults per model, world-space position and direction', () => {
  const { scene } = read(`<xml3d>
    <light id="d"></light>
    <group style="transform: translate3d(0px, 5px, 0px)"><light id="p" model="urn:xml3d:light:point">
      <float3 name="intensity">0.5 0.5 0.5</float3><float3 name="attenuation">1 0 0.1</float3></light></group>
    <light id="s" model="urn:xml3d:light:spot"><float name="cutoffAngle">0.3</float><float name="softness">0.5</float></light>
    <light id="off" model="urn:xml3d:light:point" style="display:none"></light></xml3d>`);
  const byId = Object.fromEntries([...scene.lights.values()].map((l) => [l.element.id, l]));
  assert.equal(byId.d.type, 'directional');
  assert.deepEqual(byId.d.direction, [0, 0, -1]);
  assert.deepEqual(byId.d.color, [1, 1, 1]);
  assert.equal(byId.p.type, 'point');
  nearArr(byId.p.position, [0, 5, 0]);
  nearArr(byId.p.color, [0.5, 0.5, 0.5]);
  nearArr(byId.p.attenuation, [1, 0, 0.1]);
  near(byId.s.cutoff, 0.3); near(byId.s.softness, 0.5);
  nearArr(byId.s.attenuation, [0, 0, 1]);
  assert.equal(byId.off.on, false);
  assert.equal(byId.d.on, true);
  // XML3D's castShadow defaults to false.
  for (const l of scene.lights.values()) assert.equal(l.castShadow, false);
});

test('lights: castShadow true makes a light cast shadows, and the node is told so', () => {
  const doc = page(`<xml3d><light id="yes"><bool name="castShadow">true</bool></light>
    <light id="no"><bool name="castShadow">false</bool></light><light id="default"></light></xml3d>`);
  const scene = new MarkupReader().read(doc.querySelector('xml3d'));
  const byId = Object.fromEntries([...scene.lights.values()].map((l) => [l.element.id, l]));
  assert.deepEqual([byId.yes.castShadow, byId.no.castShadow, byId.default.castShadow], [true, false, false]);
  assert.deepEqual(scene.errors, []);
});

test('value elements: bool, int, and numbers mixed with junk are reported', () => {
  const { scene } = read(`<xml3d><mesh><float3 name="position">0 0 0 1 0 0 0 1 0 oops</float3></mesh></xml3d>`);
  assert.equal(scene.meshes.size, 1);
  assert.match(scene.errors[0].message, /not a number: "oops"$/);
  // Words apart as the page has them (the examples' candle page has NaN tangents), a count past four.
  const many = read(`<xml3d><mesh><float3 name="position">0 0 0 1 0 0 0 1 0</float3>
    <float3 name="tangent">NaN NaN NaN NaN NaN NaN</float3></mesh></xml3d>`).scene;
  assert.match(many.errors[0].message, /<float3 name="tangent"> holds text that is not a number: "NaN NaN NaN NaN" \(and 2 more\)/);
});

test('broken references and bad data are reported, the rest is still read', () => {
  const { scene } = read(`<xml3d><mesh id="bad" material="#nope">${TRI}</mesh>
    <mesh id="idx"><float3 name="position">0 0 0 1 0 0 0 1 0</float3><int name="index">0 1 7</int></mesh>
    <mesh id="nopos"></mesh><mesh id="ok">${TRI}</mesh></xml3d>`);
  const ids = [...scene.meshes.values()].map((m) => m.element.id).sort();
  assert.deepEqual(ids, ['bad', 'ok']);
  const msgs = scene.errors.map((e) => e.message).join('\n');
  assert.match(msgs, /#nope not found/);
  assert.match(msgs, /index 7 out of range/);
  assert.match(msgs, /no position data/);
});

test('setScriptValue replaces the value and keeps it out of band', () => {
  const doc = page(`<xml3d><mesh><float3 id="p" name="position">0 0 0 1 0 0 0 1 0</float3></mesh></xml3d>`);
  const reader = new MarkupReader();
  setScriptValue(doc.getElementById('p'), new Float32Array([0, 0, 0, 2, 0, 0, 0, 2, 0]));
  const scene = reader.read(doc.querySelector('xml3d'));
  assert.deepEqual([...scene.buffers.get(only(scene.meshes).positions).data], [0, 0, 0, 2, 0, 0, 0, 2, 0]);
});

test('ids are stable across re-reads and unchanged buffers keep their id', () => {
  const doc = page(`<xml3d><mesh id="m">${TRI}</mesh><light></light></xml3d>`);
  const reader = new MarkupReader();
  const a = reader.read(doc.querySelector('xml3d'));
  const b = reader.read(doc.querySelector('xml3d'));
  assert.deepEqual([...a.meshes.keys()], [...b.meshes.keys()]);
  assert.equal(only(a.meshes).positions, only(b.meshes).positions);
  assert.deepEqual([...a.lights.keys()], [...b.lights.keys()]);
});

test('textures: wrap, filter and the image url', () => {
  const { scene } = read(`<xml3d><defs><material id="m" model="urn:xml3d:material:diffuse">
    <texture name="diffuseTexture" wrap="repeat" filter="nearest"><img src="tex/a.png"></texture></material></defs>
    <mesh material="#m">${TRI}<float2 name="texcoord">0 0 1 0 0 1</float2></mesh></xml3d>`);
  const mesh = only(scene.meshes);
  const mat = scene.materials.get(mesh.material);
  const tex = scene.textures.get(mat.diffuseTexture);
  assert.equal(tex.url, 'http://localhost/tex/a.png');
  assert.equal(tex.wrapS, 'repeat'); assert.equal(tex.wrapT, 'repeat');
  assert.equal(tex.filter, 'nearest');
  assert.equal(tex.flipY, true);
  assert.ok(mesh.texcoords);
});

test('internal assets: assetdata includes and per-model assetmesh material override', () => {
  const { scene } = read(`<xml3d><defs>
    <material id="blue" model="urn:xml3d:material:matte"><float3 name="diffuseColor">0 0 1</float3></material>
    <asset id="a"><assetdata name="geo">${TRI}</assetdata>
      <assetmesh name="one" includes="geo"></assetmesh>
      <assetmesh name="two" includes="geo" style="transform: translateX(3px)"></assetmesh></asset></defs>
    <model id="mdl" src="#a"><assetmesh name="two" material="#blue"></assetmesh></model></xml3d>`);
  const ms = [...scene.meshes.values()];
  assert.equal(ms.length, 2);
  assert.ok(ms.every((m) => m.element.id === 'mdl'));
  assert.deepEqual(scene.materials.get(ms[1].material).diffuseColor, [0, 0, 1]);
  near(ms[1].transform[12], 3);
});

function fakeFetch(files) {
  return async (url) => {
    const body = files[url];
    if (body === undefined) return { ok: false, status: 404 };
    return {
      ok: true, status: 200,
      json: async () => JSON.parse(typeof body === 'string' ? body : JSON.stringify(body)),
      text: async () => (typeof body === 'string' ? body : JSON.stringify(body)),
      arrayBuffer: async () => body.buffer || body,
    };
  };
}

test('external xml3d-json mesh loads, and a missing one is reported', async () => {
  const files = {
    'http://localhost/tri.json': { format: 'xml3d-json', version: '0.4.0', data: {
      index: { type: 'int', seq: [{ value: [0, 1, 2] }] },
      position: { type: 'float3', seq: [{ value: [0, 0, 0, 1, 0, 0, 0, 1, 0] }] } } },
  };
  let loaded;
  const done = new Promise((r) => (loaded = r));
  let n = 0;
  const resources = new Resources({ fetch: fakeFetch(files), onLoad: () => { if (++n === 2) loaded(); } });
  const doc = page(`<xml3d><mesh id="a" src="tri.json"></mesh><mesh id="b" src="missing.json"></mesh></xml3d>`);
  const reader = new MarkupReader({ resources });
  const first = reader.read(doc.querySelector('xml3d'));
  assert.equal(first.pending, 2);
  assert.equal(first.meshes.size, 0);
  await done;
  const scene = reader.read(doc.querySelector('xml3d'));
  assert.equal(scene.pending, 0);
  assert.equal(only(scene.meshes).element.id, 'a');
  assert.match(scene.errors.map((e) => e.message).join(), /missing\.json: HTTP 404/);
});

test('glTF 2.0 model: primitives with baked node matrices, materials and KHR lights', async () => {
  const pos = new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0]);
  const idx = new Uint16Array([0, 1, 2, 0]);
  const bin = new Uint8Array(44);
  bin.set(new Uint8Array(pos.buffer), 0); bin.set(new Uint8Array(idx.buffer), 36);
  const gltf = {
    asset: { version: '2.0' }, scene: 0, scenes: [{ nodes: [0, 1] }],
    nodes: [{ mesh: 0, translation: [0, 0, -5] }, { extensions: { KHR_lights_punctual: { light: 0 } }, rotation: [0, 0, 0, 1] }],
    meshes: [{ primitives: [{ attributes: { POSITION: 0 }, indices: 1, material: 0 }] }],
    materials: [{ pbrMetallicRoughness: { baseColorFactor: [0, 1, 0, 1], metallicFactor: 0, roughnessFactor: 1 },
      extensions: { KHR_materials_transmission: { transmissionFactor: 1 }, KHR_materials_ior: { ior: 1.33 } } }],
    accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }, { bufferView: 1, componentType: 5123, count: 3, type: 'SCALAR' }],
    bufferViews: [{ buffer: 0, byteOffset: 0, byteLength: 36 }, { buffer: 0, byteOffset: 36, byteLength: 6 }],
    buffers: [{ uri: 'scene.bin', byteLength: 44 }],
    extensions: { KHR_lights_punctual: { lights: [{ type: 'directional', intensity: 2 }] } },
  };
  const files = { 'http://localhost/m/scene.gltf': gltf, 'http://localhost/m/scene.bin': bin };
  let loaded;
  const done = new Promise((r) => (loaded = r));
  const resources = new Resources({ fetch: fakeFetch(files), onLoad: () => loaded() });
  const doc = page(`<xml3d><model id="m" src="m/scene.gltf"></model></xml3d>`);
  const reader = new MarkupReader({ resources });
  reader.read(doc.querySelector('xml3d'));
  await done;
  const scene = reader.read(doc.querySelector('xml3d'));
  assert.deepEqual(scene.errors, []);
  const mesh = only(scene.meshes);
  near(mesh.transform[14], -5);
  assert.deepEqual([...scene.buffers.get(mesh.indices).data], [0, 1, 2]);
  const mat = scene.materials.get(mesh.material);
  nearArr(mat.diffuseColor, [0, 0, 0]);  // all transmitted: no diffuse share (as the node's loader: tests/data/gltf-materials.json)
  near(mat.refractionCoefficient, 1); near(mat.refractionIndex, 1.33);
  const light = only(scene.lights);
  assert.equal(light.type, 'directional');
  assert.equal(light.castShadow, true, 'glTF lights cast shadows, as when the node loads the file');
  nearArr(light.color, [2, 2, 2]);
});

test('XML resource documents: mesh data and materials referenced as file.xml#id', async () => {
  const { DOMParser } = await import('linkedom');
  const files = {
    'http://localhost/res/lib.xml': `<xml3d xmlns="http://www.xml3d.org/2009/xml3d"><data id="tri">
      <float3 name="position">0 0 0 1 0 0 0 1 0</float3></data>
      <material id="green" model="urn:xml3d:material:matte"><float3 name="diffuseColor">0 1 0</float3></material></xml3d>`,
  };
  let loaded;
  const done = new Promise((r) => (loaded = r));
  const resources = new Resources({ fetch: fakeFetch(files), onLoad: () => loaded(),
    parseXml: (t) => new DOMParser().parseFromString(t, 'text/xml') });
  const doc = page(`<xml3d><mesh src="res/lib.xml#tri" material="res/lib.xml#green"></mesh></xml3d>`);
  const reader = new MarkupReader({ resources });
  reader.read(doc.querySelector('xml3d'));
  await done;
  const scene = reader.read(doc.querySelector('xml3d'));
  assert.deepEqual(scene.errors, []);
  const mesh = only(scene.meshes);
  assert.deepEqual(scene.materials.get(mesh.material).diffuseColor, [0, 1, 0]);
});
