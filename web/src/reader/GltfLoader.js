// glTF 2.0 (JSON + external or data: buffers, or .glb) for <model src="x.gltf">. Produces
// flat primitives with their node's world matrix baked into `matrix`, XML3D-style material
// parameters, KHR_lights_punctual lights and the first camera.
import { identity, multiply, translation, scaling, fromQuaternion } from '../math/Mat4.js';

const COMPONENTS = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4, MAT4: 16 };
const TYPES = { 5120: Int8Array, 5121: Uint8Array, 5122: Int16Array, 5123: Uint16Array, 5125: Uint32Array, 5126: Float32Array };
const WRAP = { 33071: 'clamp', 33648: 'repeat', 10497: 'repeat' };  // mirrored repeat read as repeat
const SOURCE = { 5126: 'f32', 5125: 'u32', 5123: 'u16', 5121: 'u8' };  // a buffer_ref's source, by componentType

// Where an array the loader returned lies in an external file, so that a node can load it
// itself (a buffer_ref, docs/protocol.md "References"): {url, byteOffset, byteStride (0:
// packed), source, components, values}. Only for arrays that hold exactly the file's values:
// never for data: URIs or GLB chunks, normalised or sparse accessors, or what is converted
// (an array made from another has no entry, so conversions later on need not say so).
const sources = new WeakMap();
export const sourceOf = (array) => sources.get(array) ?? null;

// Deferred loads ({defer: true}: a page whose buffers the node loads itself): the result comes
// as soon as the JSON is read, its arrays views of zero-filled buffers that the download fills
// in place later. This registry gives, for such an array, the promise of its values while they
// are on their way (null once they are in, and for every other array): whatever reads values
// (an upload the node refused, bounds, picking) waits for it or does not keep what it read.
const deferred = new WeakMap();  // array -> {ready: Promise, done: boolean}
export const pendingValues = (array) => {
  const d = deferred.get(array);
  return d && !d.done ? d.ready : null;
};

// Whether every array a deferred load would make from an external buffer is a view of the
// file's bytes as they are (or u16/u8 indices widened, which a node widens too): those need
// no values until the download is in. Anything converted from the values (normalised, strided,
// sparse, RGBA colours, strips unrolled) needs them at once, so such files load whole first.
function deferrable(json, bufferUrls) {
  const external = (a) => a.bufferView !== undefined && json.bufferViews[a.bufferView] &&
    !!bufferUrls[json.bufferViews[a.bufferView].buffer];
  if ((json.buffers || []).some((b, i) => bufferUrls[i] && !(Number.isInteger(b.byteLength) && b.byteLength > 0 && b.byteLength < 2 ** 31)))
    return false;
  for (const mesh of json.meshes || []) {
    for (const p of mesh.primitives || []) {
      const mode = p.mode ?? 4;
      if (mode !== 4 && mode !== 5) continue;
      const uses = Object.entries(p.attributes || {}).filter(([k]) => ['POSITION', 'NORMAL', 'TEXCOORD_0', 'COLOR_0'].includes(k));
      if (p.indices !== undefined) uses.push(['indices', p.indices]);
      for (const [k, i] of uses) {
        const a = json.accessors && json.accessors[i];
        if (!a) return false;
        if (!external(a)) continue;  // zeros, a data: URI or the GLB chunk: its values are here
        const T = TYPES[a.componentType], n = COMPONENTS[a.type];
        if (!T || !n || mode === 5 || a.sparse || a.normalized) return false;
        const v = json.bufferViews[a.bufferView], elem = n * T.BYTES_PER_ELEMENT;
        if ((v.byteStride || elem) !== elem || ((v.byteOffset || 0) + (a.byteOffset || 0)) % T.BYTES_PER_ELEMENT) return false;
        if (k === 'indices' ? ![5125, 5123, 5121].includes(a.componentType) : a.componentType !== 5126) return false;
        if (k === 'COLOR_0' && n !== 3) return false;
      }
    }
  }
  return true;
}

function parseGlb(buf) {
  const dv = new DataView(buf);
  if (dv.getUint32(0, true) !== 0x46546c67) throw new Error('not a GLB file');
  let off = 12, json, bin;
  while (off < buf.byteLength) {
    const len = dv.getUint32(off, true), type = dv.getUint32(off + 4, true);
    const chunk = buf.slice(off + 8, off + 8 + len);
    if (type === 0x4e4f534a) json = JSON.parse(new TextDecoder().decode(chunk));
    else if (type === 0x004e4942) bin = chunk;
    off += 8 + len;
  }
  return { json, bin };
}

function decodeDataUri(uri) {
  const b64 = uri.slice(uri.indexOf(',') + 1);
  const s = atob(b64);
  const out = new Uint8Array(s.length);
  for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
  return out.buffer;
}

// defer: return before the external buffers are in, where the file allows it (deferrable());
// the result's `ready` is then the promise of their values (else null), and its `deferred`
// says so.
export async function loadGltf(body, url, fetchBinary, { defer = false } = {}) {
  let json = body, glbBin = null;
  if (body instanceof ArrayBuffer) ({ json, bin: glbBin } = parseGlb(body));
  if (!json.asset || !String(json.asset.version).startsWith('2')) throw new Error('only glTF 2.0 is supported');
  // The absolute URL of each external buffer (null for data: URIs and the GLB chunk).
  const bufferUrls = (json.buffers || []).map((b) => (b.uri === undefined || b.uri.startsWith('data:') ? null : new URL(b.uri, url).href));
  const later = defer && bufferUrls.some(Boolean) && deferrable(json, bufferUrls);
  const downloads = [];  // deferred: [index, promise of the file]
  const load = (b, i) => {
    if (b.uri === undefined) {
      if (!glbBin) throw new Error(`buffer ${i} has no uri`);
      return glbBin;
    }
    if (b.uri.startsWith('data:')) return decodeDataUri(b.uri);
    if (!later) return fetchBinary(bufferUrls[i]);
    downloads.push([i, fetchBinary(bufferUrls[i])]);
    return new ArrayBuffer(b.byteLength);  // filled in place when the download is in
  };
  const buffers = later ? (json.buffers || []).map(load) : await Promise.all((json.buffers || []).map(load));
  // Deferred: what must be redone once the values are in (indices widened), and the promise.
  const fixups = [];
  const state = { ready: null, done: false };
  const isLater = (i) => {
    const a = json.accessors[i];
    return later && a.bufferView !== undefined && !!bufferUrls[json.bufferViews[a.bufferView].buffer];
  };

  // Records that `array` holds accessor i's values as they lie in an external file.
  function remember(array, i) {
    const a = json.accessors[i], n = COMPONENTS[a.type];
    if (a.bufferView === undefined || a.sparse || a.normalized || n > 4) return;
    const v = json.bufferViews[a.bufferView];
    if (!bufferUrls[v.buffer]) return;
    sources.set(array, { url: bufferUrls[v.buffer], byteOffset: (v.byteOffset || 0) + (a.byteOffset || 0),
      byteStride: v.byteStride || 0, source: SOURCE[a.componentType], components: n, values: a.count * n });
  }

  const accessorCache = new Map();
  function accessor(i) {
    if (accessorCache.has(i)) return accessorCache.get(i);
    const a = json.accessors[i];
    const T = TYPES[a.componentType];
    const n = COMPONENTS[a.type];
    if (!T || !n) throw new Error(`accessor ${i}: unsupported type`);
    let out;
    if (a.bufferView === undefined) out = new T(a.count * n);
    else {
      const v = json.bufferViews[a.bufferView];
      const buf = buffers[v.buffer];
      const base = (v.byteOffset || 0) + (a.byteOffset || 0);
      const elem = n * T.BYTES_PER_ELEMENT;
      const stride = v.byteStride || elem;
      if (stride === elem && base % T.BYTES_PER_ELEMENT === 0) {
        out = new T(buf, base, a.count * n);
      } else {  // strided or unaligned: copy element by element
        out = new T(a.count * n);
        const bytes = new Uint8Array(buf);
        const tmp = new Uint8Array(out.buffer);
        for (let k = 0; k < a.count; k++) tmp.set(bytes.subarray(base + k * stride, base + k * stride + elem), k * elem);
      }
    }
    if (a.normalized && T !== Float32Array) {
      const max = { 5120: 127, 5121: 255, 5122: 32767, 5123: 65535 }[a.componentType] || 1;
      out = Float32Array.from(out, (x) => Math.max(x / max, -1));
    } else if (T === Float32Array || T === Uint32Array) remember(out, i);  // used as they are
    accessorCache.set(i, out);
    return out;
  }
  // Indices as Uint32Array, widened once per accessor: primitives that share an accessor share
  // the array (one buffer), and a widened u16 or u8 one still names its source.
  const indexCache = new Map();
  function indexAccessor(i) {
    if (!indexCache.has(i)) {
      const a = accessor(i);
      let out = a;
      if (!(a instanceof Uint32Array)) {
        out = new Uint32Array(a.length);
        if (!isLater(i)) out.set(a);  // widened natively (Uint32Array.from iterates); a later one is zeros until its fixup
        if (a instanceof Uint16Array || a instanceof Uint8Array) remember(out, i);  // widened, value for value
        if (isLater(i)) fixups.push(() => out.set(a));
      }
      if (isLater(i)) deferred.set(out, state);
      indexCache.set(i, out);
    }
    return indexCache.get(i);
  }
  const asFloat = (a) => (a instanceof Float32Array ? a : Float32Array.from(a));

  function texture(info) {
    if (!info) return null;
    const t = json.textures[info.index];
    const img = t && json.images[t.source];
    if (!img || !img.uri) return null;
    const s = (t.sampler !== undefined && json.samplers[t.sampler]) || {};
    return {
      url: new URL(img.uri, url).href,
      wrapS: WRAP[s.wrapS ?? 10497], wrapT: WRAP[s.wrapT ?? 10497],
      filter: s.magFilter === 9728 ? 'nearest' : 'linear',
      flipY: false, srgb: true,
    };
  }

  const materials = (json.materials || []).map((m) => {
    const pbr = m.pbrMetallicRoughness || {};
    const base = pbr.baseColorFactor || [1, 1, 1, 1];
    const metallic = pbr.metallicFactor ?? 1, rough = pbr.roughnessFactor ?? 1;
    const ext = m.extensions || {};
    const transmission = ext.KHR_materials_transmission ? ext.KHR_materials_transmission.transmissionFactor ?? 0 : 0;
    const spec = 0.04 * (1 - metallic);
    return {
      name: m.name,
      model: 'phong',
      diffuseColor: [base[0] * (1 - metallic), base[1] * (1 - metallic), base[2] * (1 - metallic)],
      specularColor: [spec + base[0] * metallic, spec + base[1] * metallic, spec + base[2] * metallic],
      shininess: Math.max(0.01, (1 - rough) * (1 - rough)),
      emissiveColor: m.emissiveFactor ? [...m.emissiveFactor] : [0, 0, 0],
      opacity: m.alphaMode === 'BLEND' ? base[3] : 1,
      diffuseTexture: texture(pbr.baseColorTexture),
      emissiveTexture: texture(m.emissiveTexture),
      reflectionCoefficient: metallic * (1 - rough),
      refractionCoefficient: transmission,
      refractionIndex: ext.KHR_materials_ior ? ext.KHR_materials_ior.ior ?? 1.5 : (transmission ? 1.5 : 1),
      alphaMask: m.alphaMode === 'MASK',
      alphaCutoff: m.alphaCutoff ?? 0.5,
      doubleSided: !!m.doubleSided,
    };
  });

  // undrawn: primitives that are not drawn (points and lines), counted for one warning;
  // badColors: COLOR_0 attributes left out because they do not give one colour per vertex.
  const result = { meshes: [], lights: [], camera: null, url, undrawn: 0, badColors: 0 };
  // COLOR_0 as RGB floats (VEC3, or VEC4 with its alpha dropped; normalised integers are scaled
  // by accessor()), or null. glTF multiplies the base colour by it.
  function vertexColors(at) {
    if (at.COLOR_0 === undefined) return null;
    const a = json.accessors[at.COLOR_0], n = COMPONENTS[a.type];
    const c = asFloat(accessor(at.COLOR_0));
    if ((n !== 3 && n !== 4) || a.count !== json.accessors[at.POSITION].count) { result.badColors++; return null; }
    if (n === 3) return c;
    const rgb = new Float32Array(a.count * 3);
    for (let v = 0; v < a.count; v++) for (let j = 0; j < 3; j++) rgb[v * 3 + j] = c[v * 4 + j];
    return rgb;
  }
  const lightDefs = (json.extensions && json.extensions.KHR_lights_punctual && json.extensions.KHR_lights_punctual.lights) || [];
  function visit(ni, parent) {
    const node = json.nodes[ni];
    let local;
    if (node.matrix) local = new Float32Array(node.matrix);
    else {
      const t = node.translation || [0, 0, 0], r = node.rotation || [0, 0, 0, 1], s = node.scale || [1, 1, 1];
      local = multiply(multiply(translation(...t), fromQuaternion(...r)), scaling(...s));
    }
    const world = multiply(parent, local);
    if (node.mesh !== undefined) {
      const mesh = json.meshes[node.mesh];
      mesh.primitives.forEach((p, k) => {
        const mode = p.mode ?? 4;
        if (mode !== 4 && mode !== 5) { result.undrawn++; return; }  // points, lines and fans are not drawn
        const at = p.attributes;
        if (at.POSITION === undefined) return;
        const indices = p.indices !== undefined ? indexAccessor(p.indices) : null;
        result.meshes.push({
          name: `${node.name ?? ni}${k}`,
          nodeName: node.name, meshName: mesh.name,
          positions: asFloat(accessor(at.POSITION)),
          normals: at.NORMAL !== undefined ? asFloat(accessor(at.NORMAL)) : null,
          texcoords: at.TEXCOORD_0 !== undefined ? asFloat(accessor(at.TEXCOORD_0)) : null,
          colors: vertexColors(at),
          indices, strip: mode === 5,  // unrolled by MarkupReader (a new array, without a source)
          material: p.material !== undefined ? materials[p.material] : null,
          matrix: world,
        });
      });
    }
    const lx = node.extensions && node.extensions.KHR_lights_punctual;
    if (lx && lightDefs[lx.light]) {
      const l = lightDefs[lx.light];
      const c = l.color || [1, 1, 1], i = l.intensity ?? 1;
      result.lights.push({
        type: l.type === 'spot' ? 'spot' : l.type === 'point' ? 'point' : 'directional',
        color: [c[0] * i, c[1] * i, c[2] * i],
        cutoff: l.spot ? l.spot.outerConeAngle ?? Math.PI / 4 : Math.PI / 4,
        softness: l.spot ? 1 - (l.spot.innerConeAngle ?? 0) / (l.spot.outerConeAngle ?? Math.PI / 4) : 0,
        attenuation: l.type === 'directional' ? [1, 0, 0] : [1, 0, 1],
        matrix: world,
      });
    }
    if (node.camera !== undefined && !result.camera) {
      const c = json.cameras[node.camera];
      if (c.type === 'perspective') result.camera = { toWorld: world, fovY: c.perspective.yfov };
    }
    for (const ch of node.children || []) visit(ch, world);
  }
  const sceneIndex = json.scene ?? 0;
  const scene = json.scenes ? json.scenes[sceneIndex] : { nodes: json.nodes.map((_, i) => i) };
  for (const n of scene.nodes || []) visit(n, identity());
  result.environment = scene.extras && scene.extras.environment;
  result.deferred = later;
  result.ready = null;
  if (later) {
    for (const i of accessorCache.keys()) if (isLater(i)) deferred.set(accessorCache.get(i), state);
    state.ready = result.ready = Promise.all(downloads.map(([i, p]) => p.then((got) => {
      const want = json.buffers[i].byteLength;
      if (!(got.byteLength >= want)) throw new Error(`${bufferUrls[i]}: ${got.byteLength} bytes, the glTF says ${want}`);
      new Uint8Array(buffers[i]).set(new Uint8Array(got, 0, want));
    }))).then(() => {
      for (const f of fixups) f();
      state.done = true;
    });
    state.ready.catch(() => {});  // the caller handles it; no unhandled rejection here
  }
  return result;
}
