// Markup that real XML3D 5 pages use and the reader once got wrong (issue 20). Each test
// fails without its fix; the matching conformance page is in web/test/pages/.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { page } from '../dom.js';
import { MarkupReader } from '../../../src/reader/MarkupReader.js';
import { Resources } from '../../../src/reader/Resources.js';

const read = (body, opts = {}) => {
  const doc = page(body);
  const scene = new MarkupReader(opts).read(doc.querySelector('xml3d'));
  return { doc, scene };
};
const only = (map) => { assert.equal(map.size, 1); return [...map.values()][0]; };
const near = (a, b, eps = 1e-5) => assert.ok(Math.abs(a - b) < eps, `${a} != ${b}`);

const TRI = '<float3 name="position">-1 -1 0 1 -1 0 0 1 0</float3>';

test('useVertexColor true takes effect (not read as an RGB triple because it ends in "Color")', () => {
  const { scene } = read(`<xml3d><defs><material id="m" model="urn:xml3d:material:matte">
      <bool name="useVertexColor">true</bool></material></defs>
    <mesh material="#m">${TRI}<float3 name="color">1 0 0 0 1 0 0 0 1</float3></mesh>
    <mesh material="#m">${TRI}<bool name="useVertexColor">false</bool></mesh></xml3d>`);
  const [a, b] = [...scene.meshes.values()];
  assert.equal(scene.materials.get(a.material).useVertexColor, true);
  assert.ok(a.colors, 'the colour buffer is kept');
  assert.equal(scene.materials.get(b.material).useVertexColor, false, 'a mesh-level override turns it off');
  assert.deepEqual(scene.errors, []);
});

test('several models using the same asset each render (meshes keyed by model and asset mesh)', () => {
  const doc = page(`<xml3d><defs>
    <asset id="a"><assetdata name="geo">${TRI}</assetdata>
      <assetmesh name="one" includes="geo"></assetmesh>
      <assetmesh name="two" includes="geo" style="transform: translateY(5px)"></assetmesh></asset></defs>
    <model id="m1" src="#a" style="transform: translateX(-2px)"></model>
    <model id="m2" src="#a" style="transform: translateX(2px)"></model>
    <group style="transform: translateZ(-3px)"><model id="m3" src="#a"></model></group></xml3d>`);
  const reader = new MarkupReader();
  const scene = reader.read(doc.querySelector('xml3d'));
  const ms = [...scene.meshes.values()];
  assert.equal(ms.length, 6, 'three models x two asset meshes');
  assert.deepEqual(ms.map((m) => m.element.id), ['m1', 'm1', 'm2', 'm2', 'm3', 'm3']);
  assert.deepEqual(ms.map((m) => [m.transform[12], m.transform[13], m.transform[14]]),
    [[-2, 0, 0], [-2, 5, 0], [2, 0, 0], [2, 5, 0], [0, 0, -3], [0, 5, -3]]);
  assert.equal(new Set(ms.map((m) => m.positions)).size, 1, 'the asset data is shared, not copied');
  // Ids are stable across re-reads.
  const again = reader.read(doc.querySelector('xml3d'));
  assert.deepEqual([...again.meshes.keys()], [...scene.meshes.keys()]);
  assert.deepEqual(scene.errors, []);
});

test('filter keep({newName: oldName}) keeps only the mapped entries, renamed', () => {
  const { scene } = read(`<xml3d><defs>
    <data id="raw"><float3 name="pos">0 0 0 1 0 0 0 1 0 1 1 0</float3><int name="idx">0 1 2 2 1 3</int>
      <float3 name="normal">0 0 1 0 0 1 0 0 1 0 0 1</float3></data></defs>
    <mesh id="k"><data filter="keep({position: pos, index: idx})" src="#raw"></data></mesh>
    <mesh id="r"><data filter="rename( {position : pos, index : idx} )" src="#raw"></data></mesh>
    <mesh id="l"><data filter="keep(pos, idx)" src="#raw"></data>${TRI}</mesh></xml3d>`);
  const [k, r, l] = [...scene.meshes.values()];
  assert.deepEqual([...scene.buffers.get(k.indices).data], [0, 1, 2, 2, 1, 3], 'the renamed index is kept');
  assert.deepEqual([...scene.buffers.get(k.positions).data].slice(9), [1, 1, 0]);
  assert.equal(k.normals, 0, 'keep drops what the mapping does not name');
  assert.ok(r.normals && r.indices, 'rename keeps the other entries');
  assert.equal(l.indices, 0, 'keep(pos, idx) keeps names, renames nothing');
  assert.deepEqual(scene.errors, []);
});

test('filter: one entry under several names, and a malformed mapping is reported', () => {
  const { scene } = read(`<xml3d>
    <mesh id="twice"><data filter="keep({position: p, normal: p})"><float3 name="p">0 0 1 1 0 1 0 1 1</float3>
      <float name="junk">1</float></data></mesh>
    <mesh id="bad"><data filter="keep({position p})">${TRI}</data></mesh></xml3d>`);
  const [twice, bad] = [...scene.meshes.values()];
  assert.equal(twice.normals, twice.positions, 'position and normal are the same entry');
  assert.ok(bad.positions, 'a bad filter leaves the data unfiltered');
  assert.deepEqual(scene.errors.map((e) => e.message), ['bad filter "keep({position p})"']);
});

// As in MarkupReader.test.js: files served from a map, XML parsed by linkedom.
function fakeFetch(files) {
  return async (url) => {
    const body = files[url];
    if (body === undefined) return { ok: false, status: 404 };
    return { ok: true, status: 200, text: async () => body, json: async () => JSON.parse(body) };
  };
}

test('display:none on an asset mesh in an external XML document hides it', async () => {
  const { DOMParser } = await import('linkedom');
  const files = {
    'http://localhost/res/assets.xml': `<xml3d xmlns="http://www.xml3d.org/2009/xml3d">
      <asset id="a"><assetdata name="geo"><float3 name="position">0 0 0 1 0 0 0 1 0</float3></assetdata>
        <assetmesh id="shown" name="shown" includes="geo"></assetmesh>
        <assetmesh id="gone" name="gone" includes="geo" style="display:none"></assetmesh>
        <assetmesh id="gone2" name="gone2" includes="geo" style="transform: translateX(1px); display: none !important"></assetmesh>
        <assetmesh id="moved" name="moved" includes="geo" style="transform: translateX(4px)"></assetmesh></asset></xml3d>`,
  };
  let loaded;
  const done = new Promise((r) => (loaded = r));
  const resources = new Resources({ fetch: fakeFetch(files), onLoad: () => loaded(),
    parseXml: (t) => new DOMParser().parseFromString(t, 'text/xml') });
  const doc = page(`<xml3d><model id="m" src="res/assets.xml#a"></model></xml3d>`);
  // What a browser's getComputedStyle answers: values for the page's elements, empty strings
  // for elements of a document without a browsing context (the parsed XML file).
  const computedStyle = (el) => (el.ownerDocument === doc
    ? { display: 'inline', visibility: 'visible', transform: 'none' }
    : { display: '', visibility: '', transform: '' });
  const reader = new MarkupReader({ resources, computedStyle });
  reader.read(doc.querySelector('xml3d'));
  await done;
  const scene = reader.read(doc.querySelector('xml3d'));
  assert.deepEqual(scene.errors, []);
  const ms = [...scene.meshes.values()];
  assert.equal(ms.length, 2, 'the two display:none asset meshes are not drawn');
  near(ms[0].transform[12], 0);
  near(ms[1].transform[12], 4);  // the inline CSS transform still applies
});

test('spot softness above 1 is not clamped: the inner cone angle cutoff*(1 - softness) is honoured', () => {
  const spot = (cutoff, softness) => `<light model="urn:xml3d:light:spot"><float name="cutoffAngle">${cutoff}</float>
    <float name="softness">${softness}</float></light>`;
  const { scene } = read(`<xml3d>${spot(0.8, 1.5)}${spot(0.8, 2)}${spot(0.8, 1.25)}${spot(0.5, 3)}
    ${spot(Math.PI / 4, 9)}${spot(0.8, 0.3)}${spot(0.8, -0.5)}</xml3d>`);
  const soft = [...scene.lights.values()].map((l) => l.softness);
  near(soft[0], 0.5);   // cos(0.8 * -0.5) = cos(0.4): inner angle 0.4 of 0.8 (clamped, it was 1)
  near(soft[1], 0);     // cos(-0.8) = cos(cutoff): hard edge
  near(soft[2], 0.75);  // inner angle 0.2
  near(soft[3], 0);     // inner angle 1 > cutoff 0.5: hard edge
  near(soft[4], 1);     // cos(-2 pi) = 1: fades over the whole cone
  near(soft[5], 0.3);   // 0..1 as given
  near(soft[6], 0);     // inner angle 1.2 > cutoff: hard edge
  assert.deepEqual(scene.errors, []);
});

test('compute attributes and <dataflow> elements give one warning each that names the element', () => {
  const { scene } = read(`<xml3d><defs>
      <dataflow id="morph" out="position"><float3 name="a" param="true"></float3>
        <compute>position = xflow.add(a, a);</compute></dataflow>
      <data id="moved" compute="position = xflow.add(position, offset)">${TRI}<float3 name="offset">0 0 1</float3></data></defs>
    <mesh id="m1" src="#moved"></mesh><mesh id="m2" src="#moved"></mesh>
    <mesh compute="position = dataflow['#morph']">${TRI}</mesh></xml3d>`);
  assert.deepEqual(scene.warnings.map((w) => w.message), [
    '<dataflow id="morph"> is ignored: Xflow (dataflow, compute) is not supported',
    '<data id="moved"> compute="position = xflow.add(position, offset)" is ignored: Xflow is not supported, the element\'s data is used without it',
    '<mesh> compute="position = dataflow[\'#morph\']" is ignored: Xflow is not supported, the element\'s data is used without it',
  ]);
  assert.equal(scene.warnings[1].element.id, 'moved');
  assert.equal(scene.meshes.size, 3, 'the data is still used without the computation');
  assert.deepEqual(scene.errors, [], 'valid markup: no error, no red status line');
});

test('the page logs each unsupported-markup warning once with console.warn, across re-reads', async () => {
  const { XML3DHandler } = await import('../../../src/ui/XML3DHandler.js');
  const doc = page(`<xml3d><mesh id="m" compute="position = xflow.morph(position, d, w)">${TRI}</mesh></xml3d>`);
  const reader = new MarkupReader();
  const handler = { shownErrors: new Set() };
  const logged = [];
  const warn = console.warn;
  console.warn = (...args) => logged.push(args);
  try {
    for (let i = 0; i < 3; i++) XML3DHandler.prototype.reportWarnings.call(handler, reader.read(doc.querySelector('xml3d')).warnings);
  } finally { console.warn = warn; }
  assert.equal(logged.length, 1);
  assert.match(logged[0][0], /^XML3D: <mesh id="m"> compute="position = xflow\.morph\(position, d, w\)" is ignored/);
  assert.equal(logged[0][1].id, 'm', 'the element itself is logged too');
  assert.equal(handler.warnings.length, 1);
});

// Item 10: what the client cannot show gets one warning naming the element; nothing is dropped
// without a word. Points and lines are valid XML3D (a warning, no red status line); a type that
// is not XML3D stays an error.
test('points and lines meshes, z-index and unknown view models give one warning each that names the element', () => {
  const { scene } = read(`<xml3d view="#v">
      <view id="v" model="urn:xml3d:view:orthographic"></view>
      <mesh id="pts" type="points">${TRI}</mesh><mesh id="ln" type="lines">${TRI}</mesh>
      <mesh id="ls" type="linestrips">${TRI}</mesh><mesh id="ln2" type="lines">${TRI}</mesh>
      <mesh id="top" style="z-index: 2">${TRI}</mesh><mesh id="flat" style="z-index: auto">${TRI}</mesh>
      <mesh id="quads" type="quads">${TRI}</mesh></xml3d>`);
  assert.deepEqual(scene.warnings.map((w) => w.message), [
    '<mesh id="pts"> type="points" is not drawn: only triangles and tristrips are',
    '<mesh id="ln"> type="lines" is not drawn: only triangles and tristrips are',
    '<mesh id="ls"> type="linestrips" is not drawn: only triangles and tristrips are',
    '<mesh id="ln2"> type="lines" is not drawn: only triangles and tristrips are',
    '<mesh id="top"> z-index: 2 is ignored: the scene is drawn in one depth order (no render bins)',
    '<view id="v"> model="urn:xml3d:view:orthographic" is not a known view model; drawn as urn:xml3d:view:perspective',
  ]);
  assert.deepEqual(scene.warnings.map((w) => w.element.id), ['pts', 'ln', 'ls', 'ln2', 'top', 'v']);
  assert.deepEqual([...scene.meshes.values()].map((m) => m.element.id), ['top', 'flat'], 'the triangle meshes are drawn');
  assert.deepEqual(scene.errors.map((e) => e.message), ['<mesh id="quads"> type="quads" is not drawn (triangles and tristrips are)']);
});

test('a projective view with a centred perspective projectionMatrix is drawn with its field of view', () => {
  // gluPerspective(fovY = 0.6, aspect 2, near 1, far 100), column-major.
  const f = 1 / Math.tan(0.3), a = 2, n = 1, far = 100;
  const P = [f / a, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + n) / (n - far), -1, 0, 0, (2 * far * n) / (n - far), 0];
  const { scene } = read(`<xml3d><view id="p" model="urn:xml3d:view:projective">
      <float4x4 name="projectionMatrix">${P.join(' ')}</float4x4></view><mesh>${TRI}</mesh></xml3d>`);
  near(scene.camera.fovY, 0.6);
  assert.deepEqual(scene.warnings, []);
  assert.deepEqual(scene.errors, []);
  // Off-axis (m[8] != 0), orthographic (m[11] = 0, m[15] = 1) and missing matrices: a warning,
  // and the view's fovVertical (default pi/4).
  const offAxis = [...P]; offAxis[8] = 0.2;
  const ortho = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -0.02, 0, 0, 0, -1, 1];
  for (const m of [offAxis, ortho, null]) {
    const body = m ? `<float4x4 name="projectionMatrix">${m.join(' ')}</float4x4>` : '';
    const { scene: s } = read(`<xml3d><view id="q" model="urn:xml3d:view:projective">${body}</view><mesh>${TRI}</mesh></xml3d>`);
    near(s.camera.fovY, Math.PI / 4);
    assert.equal(s.warnings.length, 1);
    assert.match(s.warnings[0].message, /^<view id="q"> model="urn:xml3d:view:projective": its projectionMatrix is not a centred perspective projection/);
    assert.deepEqual(s.errors, []);
  }
});

test('glTF primitives of points or lines in a model give one warning naming the model', async () => {
  const pos = new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0]);
  const gltf = {
    asset: { version: '2.0' }, scene: 0, scenes: [{ nodes: [0] }], nodes: [{ mesh: 0 }],
    meshes: [{ primitives: [{ attributes: { POSITION: 0 } }, { attributes: { POSITION: 0 }, mode: 1 }, { attributes: { POSITION: 0 }, mode: 0 }] }],
    accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }],
    bufferViews: [{ buffer: 0, byteOffset: 0, byteLength: 36 }],
    buffers: [{ uri: 'data:application/octet-stream;base64,' + Buffer.from(pos.buffer).toString('base64'), byteLength: 36 }],
  };
  const fetch = async (url) => ({ ok: true, status: 200, json: async () => gltf, arrayBuffer: async () => new ArrayBuffer(0), text: async () => JSON.stringify(gltf), url });
  let loaded;
  const done = new Promise((r) => (loaded = r));
  const resources = new Resources({ fetch, onLoad: () => loaded() });
  const doc = page('<xml3d><model id="g" src="m/lines.gltf"></model></xml3d>');
  const reader = new MarkupReader({ resources });
  reader.read(doc.querySelector('xml3d'));
  await done;
  const scene = reader.read(doc.querySelector('xml3d'));
  assert.equal(scene.meshes.size, 1, 'the triangles are drawn');
  assert.deepEqual(scene.warnings.map((w) => w.message),
    ['<model id="g"> src="m/lines.gltf": 2 glTF primitives of points or lines not drawn: only triangles, triangle strips and fans are']);
  assert.equal(scene.warnings[0].element.id, 'g');
  assert.deepEqual(scene.errors, []);
});

// Item 6: nested and derived assets.
const SQUARE = '<float3 name="position">-1 -1 0 1 -1 0 1 1 0 -1 1 0</float3><int name="index">0 1 2 0 2 3</int>';
const MATS = `<material id="red" model="urn:xml3d:material:matte"><float3 name="diffuseColor">1 0 0</float3></material>
  <material id="blue" model="urn:xml3d:material:matte"><float3 name="diffuseColor">0 0 1</float3></material>`;
const xyz = (m) => [m.transform[12], m.transform[13], m.transform[14]];

test('nested named assets: includes reaches parent.name and sub.name, and a nested asset has its own transform', () => {
  const { scene } = read(`<xml3d><defs>
    <asset id="car"><assetdata name="shape">${SQUARE}</assetdata>
      <assetmesh name="body" includes="wheels.rim"></assetmesh>
      <asset name="wheels" style="transform: translateY(-2px)">
        <assetdata name="rim" includes="parent.shape"><float3 name="normal">0 0 1 0 0 1 0 0 1 0 0 1</float3></assetdata>
        <assetmesh name="front" includes="rim" style="transform: translateX(1px)"></assetmesh>
        <assetmesh name="back" includes="parent.shape, rim" style="transform: translateX(-1px)"></assetmesh>
      </asset></asset></defs>
    <model id="m" src="#car"></model></xml3d>`);
  assert.deepEqual(scene.errors, []);
  const ms = [...scene.meshes.values()];
  assert.equal(ms.length, 3);
  assert.deepEqual(ms.map(xyz), [[0, 0, 0], [1, -2, 0], [-1, -2, 0]]);
  assert.ok(ms.every((m) => m.positions && m.normals && m.indices), 'positions, normals and indices through the includes');
  assert.ok(ms.every((m) => m.element.id === 'm'), 'the model is what events and picking report');
});

test('a model whose src is another model takes its asset and overrides, and adds its own', () => {
  const doc = page(`<xml3d><defs>${MATS}
    <asset id="a"><assetdata name="geo">${SQUARE}</assetdata>
      <assetmesh name="one" includes="geo"></assetmesh>
      <assetmesh name="two" includes="geo" style="transform: translateX(3px)"></assetmesh></asset></defs>
    <model id="base" src="#a"><assetmesh name="two" material="#blue"></assetmesh></model>
    <model id="derived" src="#base" style="transform: translateY(5px)"><assetmesh name="one" material="#red"></assetmesh></model></xml3d>`);
  const reader = new MarkupReader();
  const scene = reader.read(doc.querySelector('xml3d'));
  assert.deepEqual(scene.errors, []);
  const ms = [...scene.meshes.values()];
  assert.deepEqual(ms.map((m) => m.element.id), ['base', 'base', 'derived', 'derived']);
  const colour = (m) => scene.materials.get(m.material).diffuseColor;
  assert.deepEqual(colour(ms[1]), [0, 0, 1], 'base: two is blue');
  assert.deepEqual(colour(ms[2]), [1, 0, 0], 'derived: one is red');
  assert.deepEqual(colour(ms[3]), [0, 0, 1], 'derived keeps the base model\'s override of two');
  assert.deepEqual(ms.map(xyz), [[0, 0, 0], [3, 0, 0], [0, 5, 0], [3, 5, 0]], 'the asset mesh transform survives the override');
  assert.deepEqual([...reader.read(doc.querySelector('xml3d')).meshes.keys()], [...scene.meshes.keys()], 'ids are stable');
});

test('pick on a model draws only the named or classed asset meshes; pick on both model and src model intersects', () => {
  const { scene } = read(`<xml3d><defs>
    <asset id="a"><assetdata name="geo">${SQUARE}</assetdata>
      <assetmesh name="one" includes="geo" class="glass front"></assetmesh>
      <assetmesh name="two" includes="geo" class="glass"></assetmesh>
      <assetmesh name="three" includes="geo"></assetmesh></asset></defs>
    <model id="byName" src="#a" pick="one, three"></model>
    <model id="byClass" src="#a" pick=".glass.front"></model>
    <model id="all" src="#a" pick="*"></model>
    <model id="narrow" src="#byName" pick="three, two"></model>
    <model id="none" src="#a" pick="four"></model></xml3d>`);
  assert.deepEqual(scene.errors, []);
  const drawn = (id) => [...scene.meshes.values()].filter((m) => m.element.id === id).length;
  assert.deepEqual(['byName', 'byClass', 'all', 'narrow', 'none'].map(drawn), [2, 1, 3, 1, 0]);
});

test('match posts apply to every selected entry; a nested asset of the same name extends the src one', () => {
  const { scene } = read(`<xml3d><defs>${MATS}
    <material id="green" model="urn:xml3d:material:matte"><float3 name="diffuseColor">0 1 0</float3></material>
    <asset id="a"><assetdata name="geo">${SQUARE}</assetdata>
      <assetmesh name="one" includes="geo" class="paint"></assetmesh>
      <assetmesh name="two" includes="geo"></assetmesh>
      <asset name="sub"><assetmesh name="inner" includes="parent.geo"></assetmesh></asset></asset></defs>
    <model id="m" src="#a"><assetmesh match=".paint" material="#green"></assetmesh>
      <asset name="sub"><assetmesh name="inner" material="#blue" style="transform: translateZ(-4px)"></assetmesh></asset></model></xml3d>`);
  assert.deepEqual(scene.errors, []);
  const ms = [...scene.meshes.values()];
  assert.equal(ms.length, 3);
  const colour = (m) => scene.materials.get(m.material).diffuseColor;
  assert.deepEqual(colour(ms[0]), [0, 1, 0], 'match=".paint" gave one its material');
  assert.notDeepEqual(colour(ms[1]), [0, 1, 0], 'two has no class paint');
  assert.deepEqual(colour(ms[2]), [0, 0, 1], 'the model\'s sub asset overrides the src asset\'s entry');
  assert.deepEqual(xyz(ms[2]), [0, 0, -4]);
  assert.ok(ms[2].positions, 'its data still comes through parent.geo');
});

test('cyclic asset src and bad includes are errors on their elements, and nothing hangs', () => {
  const { scene } = read(`<xml3d><defs>
    <asset id="loop1" src="#loop2"><assetdata name="geo">${SQUARE}</assetdata><assetmesh name="x" includes="geo"></assetmesh></asset>
    <asset id="loop2" src="#loop1"></asset>
    <asset id="b"><assetmesh id="bad" name="y" includes="parent.geo"></assetmesh>
      <assetmesh id="bad2" name="z" includes="nosub.geo"></assetmesh>
      <assetdata name="p" includes="q"></assetdata><assetdata name="q" includes="p"></assetdata>
      <assetmesh id="rec" name="w" includes="p">${SQUARE}</assetmesh></asset></defs>
    <model id="m1" src="#loop1"></model><model id="m2" src="#b"></model></xml3d>`);
  const msgs = scene.errors.map((e) => e.message).join('\n');
  assert.match(msgs, /cyclic asset reference/);
  assert.match(msgs, /includes "parent.geo": the asset has no parent asset/);
  assert.match(msgs, /includes "nosub.geo": no nested asset named "nosub"/);
  assert.match(msgs, /recursive include/);
  assert.equal([...scene.meshes.values()].filter((m) => m.element.id === 'm1').length, 1, 'the asset still draws once');
});

test('glTF COLOR_0 reaches the mesh as RGB (alpha dropped, normalised bytes scaled) with useVertexColor; a bad one warns', async () => {
  const pos = new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0]);
  const rgba = new Uint8Array([255, 0, 0, 255, 0, 255, 0, 128, 0, 0, 255, 0]);
  const bytes = Buffer.concat([Buffer.from(pos.buffer), Buffer.from(rgba.buffer)]);
  const gltf = {
    asset: { version: '2.0' }, scene: 0, scenes: [{ nodes: [0] }], nodes: [{ mesh: 0 }],
    meshes: [{ primitives: [{ attributes: { POSITION: 0, COLOR_0: 1 } }, { attributes: { POSITION: 0, COLOR_0: 2 } },
      { attributes: { POSITION: 0 } }] }],
    accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' },
      { bufferView: 1, componentType: 5121, normalized: true, count: 3, type: 'VEC4' },
      { bufferView: 1, componentType: 5121, normalized: true, count: 2, type: 'VEC4' }],
    bufferViews: [{ buffer: 0, byteOffset: 0, byteLength: 36 }, { buffer: 0, byteOffset: 36, byteLength: 12 }],
    buffers: [{ uri: 'data:application/octet-stream;base64,' + bytes.toString('base64'), byteLength: 48 }],
  };
  const fetch = async (url) => ({ ok: true, status: 200, json: async () => gltf, arrayBuffer: async () => new ArrayBuffer(0), text: async () => JSON.stringify(gltf), url });
  let loaded;
  const done = new Promise((r) => (loaded = r));
  const resources = new Resources({ fetch, onLoad: () => loaded() });
  const doc = page('<xml3d><model id="g" src="m/colors.gltf"></model></xml3d>');
  const reader = new MarkupReader({ resources });
  reader.read(doc.querySelector('xml3d'));
  await done;
  const scene = reader.read(doc.querySelector('xml3d'));
  const [coloured, bad, plain] = [...scene.meshes.values()];
  assert.ok(coloured.colors, 'the colour buffer is there');
  assert.deepEqual([...scene.buffers.get(coloured.colors).data], [1, 0, 0, 0, 1, 0, 0, 0, 1]);
  assert.equal(scene.buffers.get(coloured.colors).components, 3);
  assert.equal(scene.materials.get(coloured.material).useVertexColor, true);
  assert.equal(bad.colors, 0, 'two colours for three vertices are left out');
  assert.equal(plain.colors, 0);
  assert.notEqual(scene.materials.get(plain.material).useVertexColor, true);
  assert.deepEqual(scene.warnings.map((w) => w.message),
    ['<model id="g"> src="m/colors.gltf": COLOR_0 of 1 glTF primitive left out: not one RGB or RGBA colour per vertex']);
  assert.deepEqual(scene.errors, []);
});
