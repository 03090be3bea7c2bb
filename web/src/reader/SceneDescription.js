// The scene as both backends see it: entries keyed by stable numeric ids (from 1), mirroring
// the server's scene model (core/scene.h) plus what only the browser needs (elements for
// picking and events, vertex colours, texture image elements).
//
// buffers:   id -> {id, type: 'f32'|'u32', components, data: Float32Array|Uint32Array,
//                   source: where the data lies in an external file (GltfLoader.js sourceOf) or null}
// textures:  id -> {id, url, image, wrapS, wrapT: 'clamp'|'repeat', filter: 'linear'|'nearest', flipY, srgb}
// materials: id -> {id, model: 'matte'|'diffuse'|'phong', diffuseColor, specularColor, shininess,
//                   emissiveColor, ambientIntensity, opacity, diffuseTexture, specularTexture,
//                   emissiveTexture (texture ids, 0 = none), useVertexColor, reflectionCoefficient,
//                   refractionCoefficient, refractionIndex, alphaMask, alphaCutoff, doubleSided}
// meshes:    id -> {id, element, positions, normals, texcoords, colors, indices (buffer ids, 0 = none),
//                   material, transform (column-major Float32Array(16), object to world), visible}
// lights:    id -> {id, element, type: 'point'|'directional'|'spot', color, intensity, position,
//                   direction (world), attenuation [c, l, q], cutoff (rad), softness, on,
//                   castShadow (XML3D castShadow, default false; glTF lights true)}
// camera:    {element, toWorld, fovY, fovX|null, near|null, far|null}
// environment: {ambient, background, exposure, linear: false}  (XML3D: colours used as given)

import { sourceOf } from './GltfLoader.js';

export const MATERIAL_DEFAULTS = Object.freeze({
  model: 'phong',
  diffuseColor: [1, 1, 1],
  specularColor: [0, 0, 0],
  shininess: 0.2,            // xml3d.js code default (the spec text says 0.5); exponent = 128 * shininess
  emissiveColor: [0, 0, 0],
  ambientIntensity: 0,
  opacity: 1,
  diffuseTexture: null,
  specularTexture: null,
  emissiveTexture: null,
  useVertexColor: false,
  reflectionCoefficient: 0,  // Tessera extension (paper): mirror reflection 0..1
  refractionCoefficient: 0,  // Tessera extension: transmission 0..1
  refractionIndex: 1,        // Tessera extension: index of refraction of the inside
  alphaMask: false,
  alphaCutoff: 0.5,
  doubleSided: true,
});

// XML3D's default material: matte red.
export function defaultMaterial() {
  return { ...MATERIAL_DEFAULTS, model: 'matte', diffuseColor: [1, 0, 0] };
}

export class SceneDescription {
  constructor(xml3d = null) {
    this.xml3d = xml3d;
    this.buffers = new Map();
    this.textures = new Map();
    this.materials = new Map();
    this.meshes = new Map();
    this.lights = new Map();
    this.camera = null;
    this.environment = { ambient: [0, 0, 0], background: [0, 0, 0], exposure: 1, linear: false };
    this.errors = [];
    this.warnings = [];  // valid markup that is not supported (Xflow): {element, message}
    this.pending = 0;  // external resources still loading
  }

  addBuffer(data, components, ids) {
    const id = ids.ofArray(data);
    if (!this.buffers.has(id))
      this.buffers.set(id, { id, type: data instanceof Uint32Array ? 'u32' : 'f32', components, data, source: sourceOf(data) });
    return id;
  }

  addTexture(t, ids) {
    if (!t) return 0;
    const key = `tex:${t.url || ''}|${t.wrapS}|${t.wrapT}|${t.filter}|${t.flipY}`;
    const id = t.url ? ids.ofKey(key) : ids.of(t.image, key);
    if (!this.textures.has(id)) this.textures.set(id, { id, ...t });
    return id;
  }

  // Materials are content-addressed: equal parameters share an id, a change gets a new id.
  addMaterial(m, ids) {
    const desc = { ...m };
    for (const k of ['diffuseTexture', 'specularTexture', 'emissiveTexture'])
      desc[k] = typeof desc[k] === 'number' ? desc[k] : this.addTexture(desc[k], ids);
    const { name, ...rest } = desc;
    const sig = JSON.stringify(rest, (k, v) => (typeof v === 'number' ? Math.fround(v) : v));
    const id = ids.ofKey('mat:' + sig);
    if (!this.materials.has(id)) this.materials.set(id, { id, ...rest, name });
    return id;
  }

  triangleCount() {
    let n = 0;
    for (const m of this.meshes.values()) {
      if (!m.visible) continue;
      const b = this.buffers.get(m.indices || m.positions);
      n += m.indices ? b.data.length / 3 : b.data.length / 9;
    }
    return n;
  }
}
