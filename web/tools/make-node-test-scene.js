// Writes the small glTF scene of the real-node browser test (test/browser/node-e2e.test.js):
//   node tools/make-node-test-scene.js   ->  test/browser/pages/node-scene.gltf, node-camera-loop.json
// Everything the reference render (`tessera render`, glTF: linear colour space, sRGB output,
// diffuse / pi) and the page's server render (XML3D: colours as given) must agree on is unlit:
// emissive colours with components 0 or 1, no lights, ambient 0. (An emissive texture would
// also agree, but the node's glTF loader ignores emissiveTexture, so the middle cube has one
// colour per face instead: a mirrored or rotated view shows.) A diffuse floor stays black
// there; pages that set ambient="..." see it lit, with ambient occlusion when ao-samples > 0.
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const out = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../test/browser/pages');

// A unit cube centred at the origin: 24 vertices (flat normals, 0..1 texcoords per face).
function cube() {
  const faces = [  // normal, u axis, v axis
    [[0, 0, 1], [1, 0, 0], [0, 1, 0]], [[0, 0, -1], [-1, 0, 0], [0, 1, 0]],
    [[1, 0, 0], [0, 0, -1], [0, 1, 0]], [[-1, 0, 0], [0, 0, 1], [0, 1, 0]],
    [[0, 1, 0], [1, 0, 0], [0, 0, -1]], [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
  ];
  const pos = [], nrm = [], uv = [], idx = [];
  for (const [n, u, v] of faces) {
    const base = pos.length / 3;
    for (const [a, b] of [[-1, -1], [1, -1], [1, 1], [-1, 1]]) {
      for (let k = 0; k < 3; k++) pos.push(0.5 * (n[k] + a * u[k] + b * v[k]));
      nrm.push(...n);
      uv.push((a + 1) / 2, (1 - b) / 2);  // glTF: v = 0 at the image's top
    }
    idx.push(base, base + 1, base + 2, base, base + 2, base + 3);
  }
  return { pos: new Float32Array(pos), nrm: new Float32Array(nrm), uv: new Float32Array(uv), idx: new Uint16Array(idx) };
}

const c = cube();
const bin = Buffer.concat([c.pos, c.nrm, c.uv, c.idx].map((a) => Buffer.from(a.buffer)));
const FACE_COLOURS = [[1, 1, 0], [1, 0, 1], [0, 1, 0], [0, 0, 1], [1, 1, 1], [1, 0.0, 0.0]];  // +z -z +x -x +y -y
const unlit = (name, emissive) => ({ name, pbrMetallicRoughness: { baseColorFactor: [0, 0, 0, 1], metallicFactor: 0, roughnessFactor: 1 },
  emissiveFactor: emissive });
const q = (deg) => [0, Math.sin(deg * Math.PI / 360), 0, Math.cos(deg * Math.PI / 360)];
const gltf = {
  asset: { version: '2.0', generator: 'tessera web/tools/make-node-test-scene.js' },
  scene: 0,
  scenes: [{ nodes: [0, 1, 2, 3] }],
  nodes: [
    { name: 'floor', mesh: 0, translation: [0, -0.05, 0], scale: [6, 0.1, 6] },
    { name: 'red', mesh: 1, translation: [-1.5, 0.5, 0.3], rotation: q(-20) },
    { name: 'faces', mesh: 2, translation: [0, 0.6, 0], rotation: q(30), scale: [1.2, 1.2, 1.2] },
    { name: 'cyan', mesh: 3, translation: [1.6, 0.4, -0.6], scale: [0.8, 0.8, 0.8] },
  ],
  meshes: [
    { primitives: [{ attributes: { POSITION: 0, NORMAL: 1, TEXCOORD_0: 2 }, indices: 3, material: 0 }] },
    { primitives: [{ attributes: { POSITION: 0, NORMAL: 1, TEXCOORD_0: 2 }, indices: 3, material: 1 }] },
    { primitives: FACE_COLOURS.map((_, f) => ({ attributes: { POSITION: 0, NORMAL: 1, TEXCOORD_0: 2 }, indices: 4 + f, material: 3 + f })) },
    { primitives: [{ attributes: { POSITION: 0, NORMAL: 1, TEXCOORD_0: 2 }, indices: 3, material: 2 }] },
  ],
  materials: [
    { name: 'floor', pbrMetallicRoughness: { baseColorFactor: [0.8, 0.8, 0.8, 1], metallicFactor: 0, roughnessFactor: 1 } },
    unlit('red', [1, 0, 0]),
    unlit('cyan', [0, 1, 1]),
    ...FACE_COLOURS.map((col, f) => unlit(`face${f}`, col)),
  ],
  buffers: [{ byteLength: bin.length, uri: `data:application/octet-stream;base64,${bin.toString('base64')}` }],
  bufferViews: [
    { buffer: 0, byteOffset: 0, byteLength: c.pos.byteLength, target: 34962 },
    { buffer: 0, byteOffset: c.pos.byteLength, byteLength: c.nrm.byteLength, target: 34962 },
    { buffer: 0, byteOffset: c.pos.byteLength + c.nrm.byteLength, byteLength: c.uv.byteLength, target: 34962 },
    { buffer: 0, byteOffset: c.pos.byteLength + c.nrm.byteLength + c.uv.byteLength, byteLength: c.idx.byteLength, target: 34963 },
  ],
  accessors: [
    { bufferView: 0, componentType: 5126, count: 24, type: 'VEC3', min: [-0.5, -0.5, -0.5], max: [0.5, 0.5, 0.5] },
    { bufferView: 1, componentType: 5126, count: 24, type: 'VEC3' },
    { bufferView: 2, componentType: 5126, count: 24, type: 'VEC2' },
    { bufferView: 3, componentType: 5123, count: 36, type: 'SCALAR' },
    ...FACE_COLOURS.map((_, f) => ({ bufferView: 3, byteOffset: f * 12, componentType: 5123, count: 6, type: 'SCALAR' })),
  ],
};
// Camera frames: 0 the start view, 1 another view (the page moves its camera there),
// 2 the start view shifted by -MODEL_SHIFT (what the page shows after moving the model by +MODEL_SHIFT).
const eye = [0.5, 2.6, 5.2], target = [0, 0.4, 0], shift = [0.6, 0, 0];
const loop = { fovY_deg: 40, frames: [
  { eye, target, up: [0, 1, 0] },
  { eye: [-3.6, 1.8, 3.9], target: [0.2, 0.3, -0.2], up: [0, 1, 0] },
  { eye: eye.map((v, i) => v - shift[i]), target: target.map((v, i) => v - shift[i]), up: [0, 1, 0] },
], model_shift: shift };
fs.writeFileSync(path.join(out, 'node-scene.gltf'), `${JSON.stringify(gltf, null, 1)}\n`);
fs.writeFileSync(path.join(out, 'node-camera-loop.json'), `${JSON.stringify(loop, null, 1)}\n`);
console.log(`wrote ${path.join(out, 'node-scene.gltf')} and node-camera-loop.json`);
