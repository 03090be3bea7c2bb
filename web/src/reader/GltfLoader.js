// glTF 2.0 (JSON + external or data: buffers, or .glb) for <model src="x.gltf">. Produces
// flat primitives with their node's world matrix baked into `matrix`, XML3D-style material
// parameters, KHR_lights_punctual lights and the first camera.
import { identity, multiply, translation, scaling, fromQuaternion } from '../math/Mat4.js';

const COMPONENTS = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4, MAT4: 16 };
const TYPES = { 5120: Int8Array, 5121: Uint8Array, 5122: Int16Array, 5123: Uint16Array, 5125: Uint32Array, 5126: Float32Array };
const WRAP = { 33071: 'clamp', 33648: 'repeat', 10497: 'repeat' };  // mirrored repeat read as repeat
const SOURCE = { 5126: 'f32', 5125: 'u32', 5123: 'u16', 5121: 'u8' };  // a buffer_ref's source, by componentType
// The glTF extensions read here (as the node's loader, core/gltf_loader.cpp): a file that
// requires another one is refused by name; one it only uses is named in a warning.
export const SUPPORTED_EXTENSIONS = Object.freeze(['KHR_lights_punctual', 'KHR_materials_emissive_strength',
  'KHR_materials_ior', 'KHR_materials_pbrSpecularGlossiness', 'KHR_materials_transmission', 'KHR_materials_unlit',
  'KHR_mesh_quantization', 'KHR_texture_transform']);

// The texture coordinates a textureInfo reads: its set (texCoord, or KHR_texture_transform's)
// and that extension's affine map, u' = m[0] u + m[1] v + m[2], v' = m[3] u + m[4] v + m[5]
// (offset + R(rotation) (scale * uv), R's columns (cos, -sin) and (sin, cos): counter-clockwise
// in glTF's UV space, whose v axis points down, as three.js, Babylon.js and the
// TextureTransformTest sample model have it; the extension's GLSL listing has the transpose, a
// known error in it, KhronosGroup/glTF issue 1563), or m null. As on the node.
function uvMapping(info) {
  const u = { set: info && Number.isInteger(info.texCoord) ? info.texCoord : 0, m: null };
  const t = info && info.extensions && info.extensions.KHR_texture_transform;
  if (!t || typeof t !== 'object') return u;
  if (Number.isInteger(t.texCoord)) u.set = t.texCoord;
  const pair = (v, d) => (Array.isArray(v) && v.length === 2 && v.every(Number.isFinite) ? v : d);
  const [ou, ov] = pair(t.offset, [0, 0]), [su, sv] = pair(t.scale, [1, 1]);
  const r = Number.isFinite(t.rotation) ? t.rotation : 0, c = Math.cos(r), sn = Math.sin(r);
  u.m = [c * su, sn * sv, ou, -sn * su, c * sv, ov];
  return u;
}
const sameMapping = (a, b) => a.set === b.set && JSON.stringify(a.m) === JSON.stringify(b.m);

// At most this many elements in an accessor without a bufferView (zeros, or a sparse one's
// base): a count alone cannot allocate gigabytes. The node's loader has the same bound.
const MAX_ZERO_ELEMENTS = 2 ** 24;

// glTF's emission: emissiveFactor (default black) times KHR_materials_emissive_strength's
// emissiveStrength (default 1), as on the node.
const emission = (m) => {
  const k = (m.extensions && m.extensions.KHR_materials_emissive_strength || {}).emissiveStrength;
  const f = Array.isArray(m.emissiveFactor) ? m.emissiveFactor : [0, 0, 0];
  return f.slice(0, 3).map((v) => v * (Number.isFinite(k) ? k : 1));
};
// The fields every glTF material gives, whatever its model.
const MATERIAL_BASE = (m, base) => ({
  name: m.name, specularColor: [0, 0, 0], shininess: 0.01, emissiveColor: emission(m),
  opacity: m.alphaMode === 'BLEND' ? base[3] : 1, reflectionCoefficient: 0, refractionCoefficient: 0, refractionIndex: 1,
  alphaMask: m.alphaMode === 'MASK', alphaCutoff: m.alphaCutoff ?? 0.5, doubleSided: !!m.doubleSided,
});

// A triangle fan's vertex order as a triangle list (glTF 2.0: triangle i is v_i+1, v_i+2, v_0).
function fanToList(v) {
  const out = new Uint32Array(Math.max(0, v.length - 2) * 3);
  for (let i = 0; i + 2 < v.length; i++) out.set([v[i + 1], v[i + 2], v[0]], 3 * i);
  return out;
}

// A material's base colour textureInfo: pbrMetallicRoughness's, or the diffuse texture's under
// KHR_materials_pbrSpecularGlossiness (as the node's base_color_texture); undefined: none.
const baseTexture = (m) => {
  const sg = m.extensions && m.extensions.KHR_materials_pbrSpecularGlossiness;
  return sg ? sg.diffuseTexture : (m.pbrMetallicRoughness || {}).baseColorTexture;
};

// Per material, the texture coordinates its textures read: the base colour texture's, else
// the emissive's.
const materialMappings = (json) => (json.materials || []).map((m) => uvMapping(baseTexture(m) || m.emissiveTexture));

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
  const uvOf = materialMappings(json);
  for (const mesh of json.meshes || []) {
    for (const p of mesh.primitives || []) {
      const mode = p.mode ?? 4;
      if (mode !== 4 && mode !== 5 && mode !== 6) continue;
      const uv = uvOf[p.material] || { set: 0, m: null };
      const set = `TEXCOORD_${uv.set}`;
      const uses = Object.entries(p.attributes || {}).filter(([k]) => ['POSITION', 'NORMAL', set, 'COLOR_0'].includes(k));
      if (uv.m && (p.attributes || {})[set] !== undefined) uses.push(['transformed', p.attributes[set]]);
      if (p.indices !== undefined) uses.push(['indices', p.indices]);
      for (const [k, i] of uses) {
        const a = json.accessors && json.accessors[i];
        if (!a) return false;
        if (!external(a)) continue;  // zeros, a data: URI or the GLB chunk: its values are here
        const T = TYPES[a.componentType], n = COMPONENTS[a.type];
        if (!T || !n || mode !== 4 || a.sparse || a.normalized || k === 'transformed') return false;
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

// The glTF structure the reader walks, checked before it walks it: the top-level lists are
// arrays, nodes' transforms arrays of numbers of the right length, primitives have attributes,
// the scene exists. What else a malformed file gets wrong still ends as an Error saying the
// file is malformed (below), never as an exception of another kind.
const LISTS = ['accessors', 'bufferViews', 'buffers', 'meshes', 'nodes', 'materials', 'textures', 'images', 'samplers', 'scenes', 'cameras'];
function checkStructure(json) {
  if (!json || typeof json !== 'object') throw new Error('not a glTF file: no JSON object');
  for (const k of LISTS)
    if (json[k] !== undefined && !Array.isArray(json[k])) throw new Error(`"${k}" is not an array`);
  const numbers = (v, n) => Array.isArray(v) && v.length === n && v.every(Number.isFinite);
  (json.nodes || []).forEach((node, i) => {
    if (!node || typeof node !== 'object') throw new Error(`node ${i} is not an object`);
    for (const [k, n] of [['matrix', 16], ['translation', 3], ['rotation', 4], ['scale', 3]])
      if (node[k] !== undefined && !numbers(node[k], n)) throw new Error(`node ${i}: "${k}" is not ${n} finite numbers`);
    if (node.children !== undefined && !Array.isArray(node.children)) throw new Error(`node ${i}: "children" is not an array`);
  });
  (json.meshes || []).forEach((mesh, i) => {
    if (!mesh || !Array.isArray(mesh.primitives)) throw new Error(`mesh ${i} has no primitives`);
    mesh.primitives.forEach((p, k) => {
      if (!p || !p.attributes || typeof p.attributes !== 'object') throw new Error(`mesh ${i} primitive ${k} has no attributes`);
    });
  });
  if (json.scenes && json.scenes.length && !(json.scenes[json.scene ?? 0] && typeof json.scenes[json.scene ?? 0] === 'object'))
    throw new Error(`scene ${json.scene} does not exist`);
}

// defer: return before the external buffers are in, where the file allows it (deferrable());
// the result's `ready` is then the promise of their values (else null), and its `deferred`
// says so.
export async function loadGltf(body, url, fetchBinary, options = {}) {
  try {
    return await load(body, url, fetchBinary, options);
  } catch (e) {
    if (e instanceof TypeError || e instanceof RangeError) throw new Error(`malformed glTF: ${e.message}`);
    throw e;
  }
}

async function load(body, url, fetchBinary, { defer = false } = {}) {
  let json = body, glbBin = null;
  if (body instanceof ArrayBuffer) ({ json, bin: glbBin } = parseGlb(body));
  if (!json || !json.asset || !String(json.asset.version).startsWith('2')) throw new Error('only glTF 2.0 is supported');
  checkStructure(json);
  const unsupported = (list) => (Array.isArray(list) ? list : []).filter((e) => !SUPPORTED_EXTENSIONS.includes(e));
  const required = unsupported(json.extensionsRequired);
  if (required.length)  // Draco or meshopt geometry would otherwise load as nothing, or as garbage
    throw new Error(`requires glTF extensions this loader does not implement: ${required.join(', ')}`);
  const warnings = [];
  const ignored = unsupported(json.extensionsUsed);
  if (ignored.length) warnings.push(`glTF extensions ignored: ${ignored.join(', ')}`);
  // What a glTF viewer would play that this reader does not (as on the node): said once.
  const count = (list) => (Array.isArray(list) ? list.length : 0);
  const morphed = (Array.isArray(json.meshes) ? json.meshes : []).reduce((n, m) => n + (m && Array.isArray(m.primitives)
    ? m.primitives.filter((p) => p && Array.isArray(p.targets) && p.targets.length).length : 0), 0);
  const still = [[count(json.animations), 'animation', 'animations'], [count(json.skins), 'skin', 'skins'],
    [morphed, 'primitive with morph targets', 'primitives with morph targets']]
    .filter(([n]) => n > 0).map(([n, one, many]) => `${n} ${n === 1 ? one : many}`);
  if (still.length) warnings.push(`${still.join(', ')} not played: the meshes are drawn in the file's rest pose`);
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

  // A sparse accessor's substitutions (glTF 2.0, "Sparse Accessors") on `out`, its base values:
  // increasing indices below the count, and the values that replace those elements. Errors name
  // the accessor.
  function applySparse(a, out, T, n, i) {
    const sp = a.sparse, count = sp.count;
    const IT = { 5121: Uint8Array, 5123: Uint16Array, 5125: Uint32Array }[sp.indices && sp.indices.componentType];
    if (!IT || !Number.isInteger(count) || count < 1 || count > a.count)
      throw new Error(`accessor ${i}: sparse accessor with bad indices or ${count} substitutions for ${a.count} elements`);
    const view = (ref, size) => {
      const v = json.bufferViews[ref.bufferView];
      if (!v) throw new Error(`accessor ${i}: sparse arrays name no bufferView`);
      const start = (v.byteOffset || 0) + (ref.byteOffset || 0), bytes = count * size;
      if ((ref.byteOffset || 0) + bytes > v.byteLength) throw new Error(`accessor ${i}: sparse arrays read past the end of bufferView ${ref.bufferView}`);
      return new Uint8Array(buffers[v.buffer], start, bytes).slice().buffer;  // aligned copies
    };
    const idx = new IT(view(sp.indices, IT.BYTES_PER_ELEMENT));
    const val = new T(view(sp.values, n * T.BYTES_PER_ELEMENT));
    for (let k = 0; k < count; k++) {
      if (idx[k] >= a.count || (k > 0 && idx[k] <= idx[k - 1])) throw new Error(`accessor ${i}: sparse index ${idx[k]} out of range or not increasing`);
      out.set(val.subarray(k * n, k * n + n), idx[k] * n);
    }
    return out;
  }

  const accessorCache = new Map();
  // Accessors are checked against their bufferView, and the view against its buffer, before
  // anything is read or allocated (as the node's loader does): a bad file is an error naming
  // what is wrong, never a read past the end, zeros in silence, or gigabytes allocated.
  function accessor(i) {
    if (accessorCache.has(i)) return accessorCache.get(i);
    const a = json.accessors && json.accessors[i];
    if (!a) throw new Error(`accessor ${i} does not exist`);
    const T = TYPES[a.componentType];
    const n = COMPONENTS[a.type];
    if (!T || !n) throw new Error(`accessor ${i}: unsupported type`);
    if (!Number.isInteger(a.count) || a.count < 0) throw new Error(`accessor ${i}: count ${a.count} is not a count`);
    let out;
    if (a.bufferView === undefined) {
      if (a.count > MAX_ZERO_ELEMENTS) throw new Error(`accessor ${i} without a bufferView has ${a.count} elements (at most ${MAX_ZERO_ELEMENTS})`);
      out = new T(a.count * n);
    } else {
      const v = json.bufferViews && json.bufferViews[a.bufferView];
      const buf = v && buffers[v.buffer];
      if (!buf) throw new Error(`accessor ${i}: bufferView ${a.bufferView} or its buffer does not exist`);
      const vo = v.byteOffset || 0, ao = a.byteOffset || 0;
      if (!Number.isInteger(v.byteLength) || !Number.isInteger(vo) || vo < 0 || vo + v.byteLength > buf.byteLength)
        throw new Error(`bufferView ${a.bufferView} (byteOffset ${vo}, byteLength ${v.byteLength}) exceeds buffer ${v.buffer} (${buf.byteLength} bytes)`);
      const base = vo + ao;
      const elem = n * T.BYTES_PER_ELEMENT;
      const stride = v.byteStride || elem;
      if (!Number.isInteger(ao) || ao < 0 || !(stride >= elem) || (a.count > 0 && ao + (a.count - 1) * stride + elem > v.byteLength))
        throw new Error(`accessor ${i}: ${a.count} elements (stride ${stride}, byteOffset ${ao}) read past the end of bufferView ${a.bufferView} (${v.byteLength} bytes)`);
      if (stride === elem && base % T.BYTES_PER_ELEMENT === 0) {
        out = new T(buf, base, a.count * n);
      } else {  // strided or unaligned: copy element by element
        out = new T(a.count * n);
        const bytes = new Uint8Array(buf);
        const tmp = new Uint8Array(out.buffer);
        for (let k = 0; k < a.count; k++) tmp.set(bytes.subarray(base + k * stride, base + k * stride + elem), k * elem);
      }
    }
    if (a.sparse) out = applySparse(a, out.slice(), T, n, i);  // on a copy: never the file's bytes
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

  // An image in a bufferView (a .glb's own images) becomes a blob: URL of its bytes, once per image.
  const imageUrls = new Map();
  function imageUrl(k) {
    const img = json.images[k];
    if (!img) return null;
    if (img.uri) return new URL(img.uri, url).href;
    if (img.bufferView === undefined || !json.bufferViews[img.bufferView]) return null;
    if (!imageUrls.has(k)) {
      const v = json.bufferViews[img.bufferView];
      const bytes = new Uint8Array(buffers[v.buffer], v.byteOffset || 0, v.byteLength);
      imageUrls.set(k, URL.createObjectURL(new Blob([bytes.slice()], { type: img.mimeType || 'image/png' })));
    }
    return imageUrls.get(k);
  }
  function texture(info) {
    if (!info) return null;
    const t = json.textures[info.index];
    const src = t && imageUrl(t.source);
    if (!src) return null;
    const s = (t.sampler !== undefined && json.samplers[t.sampler]) || {};
    return {
      url: src,
      wrapS: WRAP[s.wrapS ?? 10497], wrapT: WRAP[s.wrapT ?? 10497],
      filter: s.magFilter === 9728 ? 'nearest' : 'linear',
      flipY: false, srgb: true,
    };
  }

  // glTF materials as XML3D ones, by the node loader's rules (core/gltf_loader.cpp,
  // convert_material; both are pinned to tests/data/gltf-materials.json): so one file has the
  // same materials as the node's --scene and as a page's <model>.
  const materials = (json.materials || []).map((m) => {
    const pbr = m.pbrMetallicRoughness || {};
    const ext = m.extensions || {};
    // KHR_materials_pbrSpecularGlossiness: the diffuse colour and texture as the base colour,
    // 1 - glossiness as the roughness, a dielectric.
    const sg = ext.KHR_materials_pbrSpecularGlossiness;
    const base = (sg ? sg.diffuseFactor : pbr.baseColorFactor) || [1, 1, 1, 1];
    const metallic = sg ? 0 : pbr.metallicFactor ?? 1, rough = sg ? 1 - (sg.glossinessFactor ?? 1) : pbr.roughnessFactor ?? 1;
    const rgb = [base[0], base[1], base[2]], times = (v, k) => v.map((x) => x * k);
    const out = { ...MATERIAL_BASE(m, base), model: 'phong', diffuseTexture: texture(baseTexture(m)), emissiveTexture: texture(m.emissiveTexture) };
    if (m.alphaMode === 'MASK') out.opacity = base[3];  // the cut-out compares texture alpha x opacity with the cutoff
    if (ext.KHR_materials_unlit) return { ...out, model: 'matte', diffuseColor: rgb };  // XML3D's matte: the base colour as it is
    // The specular lobe: Phong exponent 2 / a^2 - 2 with a = roughness^2, within 1..128.
    const a = Math.max(rough * rough, 1e-3);
    out.shininess = Math.max(Math.min(2 / (a * a) - 2, 128), 1) / 128;
    const transmission = ext.KHR_materials_transmission ? ext.KHR_materials_transmission.transmissionFactor ?? 0 : 0;
    if (transmission > 0) {  // a dielectric: refraction, with Fresnel reflection
      const ior = ext.KHR_materials_ior ? ext.KHR_materials_ior.ior ?? 1.5 : 1.5;
      return { ...out, diffuseColor: times(rgb, 1 - transmission), specularColor: [0.04, 0.04, 0.04], refractionCoefficient: transmission,
        refractionIndex: ior };
    }
    if (metallic >= 0.5) {  // a conductor: a mirror tinted by the base colour
      const gloss = 1 - Math.min(rough * 2, 0.9);
      return { ...out, diffuseColor: times(rgb, 1 - gloss), specularColor: rgb, reflectionCoefficient: Math.min(Math.max(...rgb), 1) * gloss };
    }
    const spec = rough < 0.5 ? 0.04 * (1 - rough) * 4 : 0;
    return { ...out, diffuseColor: rgb, specularColor: [spec, spec, spec] };
  });

  // undrawn: primitives that are not drawn (points and lines), counted for one warning;
  // badColors: COLOR_0 attributes left out because they do not give one colour per vertex.
  const result = { meshes: [], lights: [], camera: null, url, undrawn: 0, badColors: 0, warnings };
  const uvOf = materialMappings(json);
  (json.materials || []).forEach((m, k) => {
    if (baseTexture(m) && m.emissiveTexture && !sameMapping(uvMapping(m.emissiveTexture), uvOf[k]))
      warnings.push(`material '${m.name ?? k}': its emissive texture reads other texture coordinates than its base colour texture; both read the base colour's`);
  });
  // A primitive's texture coordinates: its material's set, through its transform (a new array).
  function texcoords(at, material) {
    const uv = uvOf[material] || { set: 0, m: null };
    const i = at[`TEXCOORD_${uv.set}`];
    if (i === undefined) return null;
    const t = asFloat(accessor(i));
    if (!uv.m) return t;
    const m = uv.m, out = new Float32Array(t.length);
    for (let k = 0; k + 1 < t.length; k += 2) {
      out[k] = m[0] * t[k] + m[1] * t[k + 1] + m[2];
      out[k + 1] = m[3] * t[k] + m[4] * t[k + 1] + m[5];
    }
    return out;
  }
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
  // glTF's nodes form disjoint trees: a node reached a second time (a second parent, a cycle, a
  // root listed twice) is an error, as on the node. Without the check a file of 64 nodes each
  // listing the next one twice would be walked 2^64 times (the page would hang), and a cycle
  // would recurse until the stack ran out.
  const reached = new Set();
  function visit(ni, parent) {
    const node = json.nodes && json.nodes[ni];
    if (!node) throw new Error(`node ${ni} does not exist`);
    if (reached.has(ni)) throw new Error(`node ${ni} is reached twice (a second parent, a cycle or a root listed twice)`);
    reached.add(ni);
    let local;
    if (node.matrix) local = new Float32Array(node.matrix);
    else {
      const t = node.translation || [0, 0, 0], r = node.rotation || [0, 0, 0, 1], s = node.scale || [1, 1, 1];
      local = multiply(multiply(translation(...t), fromQuaternion(...r)), scaling(...s));
    }
    const world = multiply(parent, local);
    if (node.mesh !== undefined) {
      const mesh = json.meshes && json.meshes[node.mesh];
      if (!mesh || !Array.isArray(mesh.primitives)) throw new Error(`node ${ni} names mesh ${node.mesh}, which does not exist or has no primitives`);
      mesh.primitives.forEach((p, k) => {
        const mode = p.mode ?? 4;
        if (mode !== 4 && mode !== 5 && mode !== 6) { result.undrawn++; return; }  // points and lines are not drawn
        const at = p.attributes;
        if (at.POSITION === undefined) return;
        const positions = asFloat(accessor(at.POSITION));  // checked before its count sizes anything
        let indices = p.indices !== undefined ? indexAccessor(p.indices) : null;
        if (mode === 6) {  // a fan becomes a triangle list (a new array, without a source)
          const order = indices || Uint32Array.from({ length: positions.length / 3 }, (_, k) => k);
          indices = fanToList(order);
        }
        result.meshes.push({
          name: `${node.name ?? ni}${k}`,
          nodeName: node.name, meshName: mesh.name,
          positions,
          normals: at.NORMAL !== undefined ? asFloat(accessor(at.NORMAL)) : null,
          texcoords: texcoords(at, p.material),
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
      const c = json.cameras && json.cameras[node.camera];  // one that does not exist is ignored, as on the node
      if (c && c.type === 'perspective' && c.perspective) result.camera = { toWorld: world, fovY: c.perspective.yfov };
    }
    for (const ch of node.children || []) visit(ch, world);
  }
  const sceneIndex = json.scene ?? 0;
  // A file without scenes: every node tree, its roots the nodes that are no node's child (as on
  // the node); listing every node would reach each child twice.
  const children = new Set((json.nodes || []).flatMap((n) => n.children || []));
  const scene = json.scenes && json.scenes.length ? json.scenes[sceneIndex]
    : { nodes: (json.nodes || []).map((_, i) => i).filter((i) => !children.has(i)) };
  if (scene.nodes !== undefined && !Array.isArray(scene.nodes)) throw new Error(`scene ${sceneIndex}: "nodes" is not an array`);
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
