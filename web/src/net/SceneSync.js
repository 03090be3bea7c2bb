// Turns successive SceneDescriptions into protocol records: what changed since the last call
// (sets) and what disappeared (removes), keyed by the description's stable ids. Pure: no
// sockets, so it is unit-tested in Node.
import { RECORDS, sourceSize } from './Protocol.js';

const clamp = (v, lo, hi) => Math.min(Math.max(Number.isFinite(v) ? v : lo, lo), hi);
const nonNeg = (c) => c.map((v) => clamp(v, 0, 1e30));
const sig = (o) => JSON.stringify(o, (k, v) => (ArrayBuffer.isView(v) ? Array.from(v) : v));

export function wireMaterial(m) {
  return {
    type: 'material', id: m.id, model: m.model, alphaMask: !!m.alphaMask, doubleSided: m.doubleSided !== false,
    useVertexColor: !!m.useVertexColor,
    diffuseColor: nonNeg(m.diffuseColor), specularColor: nonNeg(m.specularColor), shininess: clamp(m.shininess, 0, 1e6),
    emissiveColor: nonNeg(m.emissiveColor), ambientIntensity: clamp(m.ambientIntensity, 0, 1e6), opacity: clamp(m.opacity, 0, 1),
    diffuseTexture: m.diffuseTexture || 0, specularTexture: m.specularTexture || 0, emissiveTexture: m.emissiveTexture || 0,
    reflection: clamp(m.reflectionCoefficient, 0, 1), refraction: clamp(m.refractionCoefficient, 0, 1),
    ior: clamp(m.refractionIndex, 1e-3, 100), alphaCutoff: clamp(m.alphaCutoff ?? 0.5, 0, 1),
  };
}

export function wireLight(l) {
  let direction = l.direction;
  if (!direction.some((v) => v !== 0)) direction = [0, 0, -1];
  let attenuation = nonNeg(l.attenuation);
  if (l.type !== 'directional' && !attenuation.some((v) => v > 0)) attenuation = [0, 0, 1];
  return {
    type: 'light', id: l.id, lightType: l.type, on: !!l.on, castShadow: !!l.castShadow, color: nonNeg(l.color), intensity: clamp(l.intensity ?? 1, 0, 1e30),
    position: l.position, direction, attenuation, cutoff: clamp(l.cutoff, 1e-4, Math.PI), softness: clamp(l.softness, 0, 1),
  };
}

// References (docs/protocol.md, "References"): what the node's decoder takes of a buffer_ref or
// texture_ref. A URL is absolute http(s), at most 4096 bytes (a longer one would be cut); a
// stride holds an element and is a multiple of the source's value size.
const field = (record, name) => RECORDS[record].fields.find((f) => f.name === name);
const URL_BYTES = field('buffer_ref', 'url').maxLength, MAX_STRIDE = field('buffer_ref', 'byte_stride').range.hi;
const referable = (url) => /^https?:\/\/./i.test(url || '') && new TextEncoder().encode(url).length <= URL_BYTES;

// A buffer_ref for buffer b when it has a source the node can load (null: upload it).
function bufferRef(b) {
  const s = b.source, size = s && sourceSize(s.source);
  if (!s || !referable(s.url) || s.components !== b.components || (s.source === 'f32') !== (b.type === 'f32')) return null;
  if (s.byteStride && (s.byteStride > MAX_STRIDE || s.byteStride < s.components * size || s.byteStride % size)) return null;
  return { type: 'buffer_ref', id: b.id, bufferType: b.type, components: b.components, source: s.source, values: s.values,
    byteStride: s.byteStride, byteOffset: s.byteOffset, url: s.url };
}

// A texture_ref for texture t when the node can load its file as it is: not for XML3D textures,
// which are flipped (flipY) before they are uploaded.
function textureRef(t) {
  if (t.flipY || !referable(t.url)) return null;
  return { type: 'texture_ref', id: t.id, wrapS: t.wrapS, wrapT: t.wrapT, filter: t.filter, srgb: !!t.srgb, url: t.url };
}

export function wireCamera(cam, width, height) {
  const aspect = width / height;
  const fovY = cam.fovX ? 2 * Math.atan(Math.tan(cam.fovX / 2) / aspect) : cam.fovY;
  return { type: 'camera', toWorld: cam.toWorld, fovY: clamp(fovY, 1e-3, Math.PI - 1e-3) };
}

export class SceneSync {
  // references: send buffer_ref and texture_ref records for what the node can load itself.
  constructor({ references = true } = {}) {
    this.references = references;
    this.reset();
  }

  // Forget what the server holds (a new session re-sends everything).
  reset() {
    this.sent = { buffers: new Map(), textures: new Map(), materials: new Set(), meshes: new Map(), lights: new Map() };
    this.camera = this.environment = this.resolution = null;
  }

  // Records that bring the server from what was sent to `scene`, in a safe order: removes
  // of meshes before what they use, data before the meshes that reference it. Texture sets
  // come as {type: 'texture', desc} for the caller to load and encode. A buffer_ref or
  // texture_ref carries `upload`, the buffer or texture record to send when the node refuses it
  // (the caller sends references first, and the rest after them without waiting for answers).
  diff(scene, { width, height, background = [0, 0, 0] }) {
    const out = [], s = this.sent;
    const removed = (map, cur, what) => {
      for (const id of [...map.keys ? map.keys() : map]) if (!cur.has(id)) { out.push({ type: 'remove', what, id }); map.delete(id); }
    };
    removed(s.meshes, scene.meshes, 'mesh');
    removed(s.lights, scene.lights, 'light');
    removed(s.materials, scene.materials, 'material');
    removed(s.textures, scene.textures, 'texture');
    removed(s.buffers, scene.buffers, 'buffer');
    for (const b of scene.buffers.values()) {
      if (s.buffers.get(b.id) === b.data) continue;
      s.buffers.set(b.id, b.data);
      const upload = { type: 'buffer', id: b.id, bufferType: b.type, components: b.components, data: b.data };
      const ref = this.references && bufferRef(b);
      out.push(ref ? { ...ref, upload } : upload);
    }
    for (const t of scene.textures.values()) {
      const k = `${t.url}|${t.wrapS}|${t.wrapT}|${t.filter}|${t.flipY}`;
      if (s.textures.get(t.id) === k) continue;
      s.textures.set(t.id, k);
      const upload = { type: 'texture', id: t.id, desc: t };
      const ref = this.references && textureRef(t);
      out.push(ref ? { ...ref, upload } : upload);
    }
    for (const m of scene.materials.values()) {
      if (s.materials.has(m.id)) continue;  // content-addressed: an id never changes meaning
      s.materials.add(m.id);
      out.push(wireMaterial(m));
    }
    for (const m of scene.meshes.values()) {
      const r = { type: 'mesh', id: m.id, positions: m.positions, normals: m.normals, texcoords: m.texcoords,
        colors: m.colors || 0, indices: m.indices, material: m.material, transform: m.transform, visible: m.visible };
      const k = sig(r);
      if (s.meshes.get(m.id) === k) continue;
      s.meshes.set(m.id, k);
      out.push(r);
    }
    for (const l of scene.lights.values()) {
      const r = wireLight(l);
      const k = sig(r);
      if (s.lights.get(l.id) === k) continue;
      s.lights.set(l.id, k);
      out.push(r);
    }
    const res = { type: 'resolution', width, height };
    if (sig(res) !== this.resolution) { this.resolution = sig(res); out.push(res); }
    if (scene.camera) {
      const c = wireCamera(scene.camera, width, height);
      if (sig(c) !== this.camera) { this.camera = sig(c); out.push(c); }
    }
    const env = { type: 'environment', ambient: scene.environment.ambient, background, exposure: scene.environment.exposure ?? 1, linear: false };
    if (sig(env) !== this.environment) { this.environment = sig(env); out.push(env); }
    return out;
  }
}
