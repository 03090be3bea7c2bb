// Turns successive SceneDescriptions into protocol records: what changed since the last call
// (sets) and what disappeared (removes), keyed by the description's stable ids. Pure: no
// sockets, so it is unit-tested in Node.
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

export function wireCamera(cam, width, height) {
  const aspect = width / height;
  const fovY = cam.fovX ? 2 * Math.atan(Math.tan(cam.fovX / 2) / aspect) : cam.fovY;
  return { type: 'camera', toWorld: cam.toWorld, fovY: clamp(fovY, 1e-3, Math.PI - 1e-3) };
}

export class SceneSync {
  constructor() { this.reset(); }

  // Forget what the server holds (a new session re-sends everything).
  reset() {
    this.sent = { buffers: new Map(), textures: new Map(), materials: new Set(), meshes: new Map(), lights: new Map() };
    this.camera = this.environment = this.resolution = null;
  }

  // Records that bring the server from what was sent to `scene`, in a safe order: removes
  // of meshes before what they use, data before the meshes that reference it. Texture sets
  // come as {type: 'texture', desc} for the caller to load and encode.
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
      out.push({ type: 'buffer', id: b.id, bufferType: b.type, components: b.components, data: b.data });
    }
    for (const t of scene.textures.values()) {
      const k = `${t.url}|${t.wrapS}|${t.wrapT}|${t.filter}|${t.flipY}`;
      if (s.textures.get(t.id) === k) continue;
      s.textures.set(t.id, k);
      out.push({ type: 'texture', id: t.id, desc: t });
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
