// Writes the small glTF scene of the real-node browser test (test/browser/node-e2e.test.js):
//   node tools/make-node-test-scene.js   ->  test/browser/pages/node-scene.gltf, node-camera-loop.json
// Everything the reference render (`tessera render`, glTF: linear colour space, sRGB output)
// and the page's server render (XML3D: colours as given) must agree on is unlit: emissive
// colours with components 0 or 1 and an emissive texture (sRGB decode, then encode, is the
// identity), no lights, ambient 0. A diffuse floor stays black there; pages that set
// ambient="..." see it lit, with ambient occlusion when ao-samples > 0.
import fs from 'node:fs';
import path from 'node:path';
import zlib from 'node:zlib';
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

const CRC = new Uint32Array(256).map((_, n) => { let c = n; for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1; return c; });
const crc32 = (buf) => { let c = 0xffffffff; for (const b of buf) c = CRC[(c ^ b) & 0xff] ^ (c >>> 8); return (c ^ 0xffffffff) >>> 0; };
function png(w, h, rgbAt) {
  const raw = Buffer.alloc(h * (1 + w * 3));
  for (let y = 0; y < h; y++) for (let x = 0; x < w; x++) raw.set(rgbAt(x, y), y * (1 + w * 3) + 1 + x * 3);
  const chunk = (type, data) => {
    const b = Buffer.alloc(12 + data.length);
    b.writeUInt32BE(data.length, 0); b.write(type, 4, 'latin1'); data.copy(b, 8);
    b.writeUInt32BE(crc32(b.subarray(4, 8 + data.length)), 8 + data.length);
    return b;
  };
  const ihdr = Buffer.alloc(13);
  ihdr.writeUInt32BE(w, 0); ihdr.writeUInt32BE(h, 4); ihdr[8] = 8; ihdr[9] = 2;  // 8-bit RGB
  return Buffer.concat([Buffer.from([137, 80, 78, 71, 13, 10, 26, 10]), chunk('IHDR', ihdr), chunk('IDAT', zlib.deflateSync(raw)), chunk('IEND', Buffer.alloc(0))]);
}

const c = cube();
const bin = Buffer.concat([c.pos, c.nrm, c.uv, c.idx].map((a) => Buffer.from(a.buffer)));
// 4x4 checker with a marked top-left quarter, so a flipped texture shows.
const tex = png(16, 16, (x, y) => (x < 8 && y < 8 ? [255, 255, 255] : ((x >> 2) + (y >> 2)) & 1 ? [255, 128, 0] : [64, 160, 255]));
const unlit = (name, emissive, extra = {}) => ({ name, pbrMetallicRoughness: { baseColorFactor: [0, 0, 0, 1], metallicFactor: 0, roughnessFactor: 1 },
  emissiveFactor: emissive, ...extra });
const q = (deg) => [0, Math.sin(deg * Math.PI / 360), 0, Math.cos(deg * Math.PI / 360)];
const gltf = {
  asset: { version: '2.0', generator: 'tessera web/tools/make-node-test-scene.js' },
  scene: 0,
  scenes: [{ nodes: [0, 1, 2, 3] }],
  nodes: [
    { name: 'floor', mesh: 0, translation: [0, -0.05, 0], scale: [6, 0.1, 6] },
    { name: 'red', mesh: 1, translation: [-1.5, 0.5, 0.3], rotation: q(-20) },
    { name: 'textured', mesh: 2, translation: [0, 0.6, 0], rotation: q(30), scale: [1.2, 1.2, 1.2] },
    { name: 'cyan', mesh: 3, translation: [1.6, 0.4, -0.6], scale: [0.8, 0.8, 0.8] },
  ],
  meshes: [0, 1, 2, 3].map((m) => ({ primitives: [{ attributes: { POSITION: 0, NORMAL: 1, TEXCOORD_0: 2 }, indices: 3, material: m }] })),
  materials: [
    { name: 'floor', pbrMetallicRoughness: { baseColorFactor: [0.8, 0.8, 0.8, 1], metallicFactor: 0, roughnessFactor: 1 } },
    unlit('red', [1, 0, 0]),
    unlit('checker', [1, 1, 1], { emissiveTexture: { index: 0 } }),
    unlit('cyan', [0, 1, 1]),
  ],
  textures: [{ source: 0, sampler: 0 }],
  samplers: [{ magFilter: 9728, minFilter: 9728, wrapS: 33071, wrapT: 33071 }],
  images: [{ uri: `data:image/png;base64,${tex.toString('base64')}` }],
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
