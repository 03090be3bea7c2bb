// Writes web/test/pages/gltf-features.glb, the model of the conformance page gltf-features.html:
// three unit quads at z = -3 that each show one glTF feature by its colour (docs/web-client.md,
// "Conformance pages"). Deterministic: the same bytes on every run.
//   node web/tools/make-gltf-features.js
// - left (x = -1.5): unlit, a .glb-embedded 2x1 PNG (red | blue, nearest) through
//   KHR_texture_transform (offset [0.5, 0], scale [0.5, 1]): blue all over (red on its left
//   half without the transform; white without the embedded image);
// - middle (x = 0): an unlit green triangle fan whose third vertex comes from a sparse accessor
//   (without it the base values put that vertex at the centre: no top-right corner);
// - right (x = 1.5): positions as normalized shorts (KHR_mesh_quantization) scaled by its node,
//   texture coordinates from TEXCOORD_1 (the blue texel; TEXCOORD_0 points at the red one).
// The file also lists KHR_materials_clearcoat as used: one warning names it.
import fs from 'node:fs';
import path from 'node:path';
import zlib from 'node:zlib';
import { fileURLToPath } from 'node:url';

const OUT = path.join(path.dirname(fileURLToPath(import.meta.url)), '..', 'test', 'pages', 'gltf-features.glb');

function crc32(bytes) {
  let c = ~0;
  for (const b of bytes) {
    c ^= b;
    for (let k = 0; k < 8; k++) c = (c >>> 1) ^ (0xedb88320 & -(c & 1));
  }
  return ~c >>> 0;
}
function png(w, h, rgba) {
  const chunk = (type, data) => {
    const body = Buffer.concat([Buffer.from(type, 'ascii'), data]);
    const out = Buffer.alloc(12 + data.length);
    out.writeUInt32BE(data.length, 0);
    body.copy(out, 4);
    out.writeUInt32BE(crc32(body), 8 + data.length);
    return out;
  };
  const ihdr = Buffer.alloc(13);
  ihdr.writeUInt32BE(w, 0); ihdr.writeUInt32BE(h, 4);
  ihdr[8] = 8; ihdr[9] = 6;  // 8 bits, RGBA
  const rows = [];
  for (let y = 0; y < h; y++) rows.push(Buffer.from([0]), Buffer.from(rgba.slice(y * w * 4, (y + 1) * w * 4)));
  return Buffer.concat([Buffer.from([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a]), chunk('IHDR', ihdr),
    chunk('IDAT', zlib.deflateSync(Buffer.concat(rows), { level: 9 })), chunk('IEND', Buffer.alloc(0))]);
}

// The binary chunk, view by view (each 4-byte aligned).
const parts = [], bufferViews = [];
let at = 0;
function view(bytes, extra = {}) {
  const b = Buffer.from(bytes.buffer ? new Uint8Array(bytes.buffer, bytes.byteOffset, bytes.byteLength) : bytes);
  bufferViews.push({ buffer: 0, byteOffset: at, byteLength: b.length, ...extra });
  parts.push(b);
  at += b.length;
  const pad = (4 - (at % 4)) % 4;
  if (pad) { parts.push(Buffer.alloc(pad)); at += pad; }
  return bufferViews.length - 1;
}

const quad = (cx) => new Float32Array([cx - 0.5, -0.5, -3, cx + 0.5, -0.5, -3, cx + 0.5, 0.5, -3, cx - 0.5, 0.5, -3]);
const vLeft = view(quad(-1.5));
const vUv = view(new Float32Array([0, 1, 1, 1, 1, 0, 0, 0]));
const vQuadIdx = view(new Uint16Array([0, 1, 2, 0, 2, 3]));
const middle = quad(0);
middle.set([0, 0, -3], 6);  // the base values: vertex 2 at the centre
const vMid = view(middle);
const vSparseIdx = view(new Uint8Array([2]));
const vSparseVal = view(new Float32Array([0.5, 0.5, -3]));
const vRight = view(new Int16Array([-32767, -32767, 0, 0, 32767, -32767, 0, 0, 32767, 32767, 0, 0, -32767, 32767, 0, 0]), { byteStride: 8 });
const vRed = view(new Float32Array([0.25, 0.5, 0.25, 0.5, 0.25, 0.5, 0.25, 0.5]));
const vBlue = view(new Float32Array([0.75, 0.5, 0.75, 0.5, 0.75, 0.5, 0.75, 0.5]));
const vImage = view(png(2, 1, [255, 0, 0, 255, 0, 0, 255, 255]));
const bin = Buffer.concat(parts);

const json = {
  asset: { version: '2.0', generator: 'web/tools/make-gltf-features.js' },
  extensionsUsed: ['KHR_texture_transform', 'KHR_materials_unlit', 'KHR_mesh_quantization', 'KHR_materials_clearcoat'],
  extensionsRequired: ['KHR_mesh_quantization'],
  scene: 0,
  scenes: [{ nodes: [0, 1, 2] }],
  nodes: [{ mesh: 0, name: 'transformed' }, { mesh: 1, name: 'sparse-fan' }, { mesh: 2, name: 'quantized', translation: [1.5, 0, -3], scale: [0.5, 0.5, 0.5] }],
  meshes: [
    { primitives: [{ attributes: { POSITION: 0, TEXCOORD_0: 1 }, indices: 2, material: 0 }] },
    { primitives: [{ attributes: { POSITION: 3 }, mode: 6, material: 1 }] },
    { primitives: [{ attributes: { POSITION: 4, TEXCOORD_0: 5, TEXCOORD_1: 6 }, indices: 2, material: 2 }] },
  ],
  materials: [
    { name: 'transformed', pbrMetallicRoughness: { baseColorTexture: { index: 0, extensions: { KHR_texture_transform: { offset: [0.5, 0], scale: [0.5, 1] } } } },
      extensions: { KHR_materials_unlit: {}, KHR_materials_clearcoat: { clearcoatFactor: 1 } } },
    { name: 'green', pbrMetallicRoughness: { baseColorFactor: [0, 1, 0, 1] }, extensions: { KHR_materials_unlit: {} } },
    { name: 'second-set', pbrMetallicRoughness: { baseColorTexture: { index: 0, texCoord: 1 } }, extensions: { KHR_materials_unlit: {} } },
  ],
  textures: [{ source: 0, sampler: 0 }],
  samplers: [{ magFilter: 9728, minFilter: 9728, wrapS: 33071, wrapT: 33071 }],
  images: [{ bufferView: vImage, mimeType: 'image/png' }],
  accessors: [
    { bufferView: vLeft, componentType: 5126, count: 4, type: 'VEC3', min: [-2, -0.5, -3], max: [-1, 0.5, -3] },
    { bufferView: vUv, componentType: 5126, count: 4, type: 'VEC2' },
    { bufferView: vQuadIdx, componentType: 5123, count: 6, type: 'SCALAR' },
    { bufferView: vMid, componentType: 5126, count: 4, type: 'VEC3', min: [-0.5, -0.5, -3], max: [0.5, 0.5, -3],
      sparse: { count: 1, indices: { bufferView: vSparseIdx, componentType: 5121 }, values: { bufferView: vSparseVal } } },
    { bufferView: vRight, componentType: 5122, normalized: true, count: 4, type: 'VEC3', min: [-1, -1, 0], max: [1, 1, 0] },
    { bufferView: vRed, componentType: 5126, count: 4, type: 'VEC2' },
    { bufferView: vBlue, componentType: 5126, count: 4, type: 'VEC2' },
  ],
  bufferViews,
  buffers: [{ byteLength: bin.length }],
};

let text = Buffer.from(JSON.stringify(json), 'utf8');
text = Buffer.concat([text, Buffer.alloc((4 - (text.length % 4)) % 4, 0x20)]);
const header = Buffer.alloc(12), jsonHead = Buffer.alloc(8), binHead = Buffer.alloc(8);
header.write('glTF', 0, 'ascii'); header.writeUInt32LE(2, 4); header.writeUInt32LE(12 + 8 + text.length + 8 + bin.length, 8);
jsonHead.writeUInt32LE(text.length, 0); jsonHead.write('JSON', 4, 'ascii');
binHead.writeUInt32LE(bin.length, 0); binHead.writeUInt32LE(0x004e4942, 4);
fs.writeFileSync(OUT, Buffer.concat([header, jsonHead, text, binHead, bin]));
console.log(`wrote ${OUT}`);
