// Reads XML3D 5 markup from a DOM into a SceneDescription: the model both backends (three.js
// and the Tessera sync channel) consume. Synchronous: external resources are requested from
// a Resources object and the page is read again when they arrive.
import * as M from '../math/Mat4.js';
import { parseCssTransform } from '../math/CssTransform.js';
import { parseValueElement, isValueElement, localName, first, vec3, numbersIn } from './Values.js';
import { SceneDescription, MATERIAL_DEFAULTS, defaultMaterial } from './SceneDescription.js';
import { pendingValues } from './GltfLoader.js';

// Elements that are never scene nodes (skipped while walking the scene tree).
const NON_SCENE = new Set(['defs', 'data', 'material', 'transform', 'asset', 'assetmesh', 'assetdata', 'dataflow',
  'texture', 'img', 'video', 'canvas', 'script', 'style', 'compute', 'shader', 'lightshader',
  'float', 'float2', 'float3', 'float4', 'float4x4', 'int', 'int4', 'bool', 'string']);

const MATERIAL_PARAMS = new Set(['diffuseColor', 'specularColor', 'shininess', 'emissiveColor', 'ambientIntensity',
  'opacity', 'diffuseTexture', 'specularTexture', 'emissiveTexture', 'useVertexColor', 'reflectionCoefficient',
  'refractionCoefficient', 'refractionIndex', 'alphaCutoff', 'transparency']);

const urnName = (urn, fallback) => (urn ? String(urn).trim().split(':').pop().toLowerCase() : fallback);

const XHTML_NS = 'http://www.w3.org/1999/xhtml';

// A minimal style reader for DOMs without getComputedStyle (unit tests): the style attribute.
function inlineStyle(el) {
  const out = {};
  const s = el.getAttribute && el.getAttribute('style');
  if (!s) return out;
  for (const decl of s.split(';')) {
    const i = decl.indexOf(':');
    if (i < 0) continue;
    out[decl.slice(0, i).trim().toLowerCase()] = decl.slice(i + 1).replace(/!\s*important\s*$/i, '').trim();
  }
  return out;
}

// Mesh types of XML3D that are not drawn (a warning, not an error).
const UNDRAWN_TYPES = new Set(['points', 'lines', 'linestrips']);
const PERSPECTIVE = 'urn:xml3d:view:perspective';
const PROJECTIVE = 'urn:xml3d:view:projective';

// The vertical field of view of a projective view's projectionMatrix (a float4x4 entry,
// column-major like every XML3D matrix) when it is a centred perspective projection, as
// gluPerspective and three.js make them: m[5] = 1 / tan(fovY / 2), no off-axis terms (m[8],
// m[9]), w = -z (m[11] = -1, m[15] = 0). Such a view is the perspective view with that fovY
// (the width follows the canvas, as for every view here). Otherwise null.
export function projectiveFovY(entry) {
  const m = entry && entry.value !== undefined ? entry.value : entry;
  if (!m || m.length !== 16) return null;
  const zero = (v) => Math.abs(v) < 1e-6;
  if (!(m[5] > 0 && m[0] > 0) || !zero(m[8]) || !zero(m[9]) || Math.abs(m[11] + 1) > 1e-6 || !zero(m[15])) return null;
  if (!zero(m[1]) || !zero(m[2]) || !zero(m[3]) || !zero(m[4]) || !zero(m[6]) || !zero(m[7]) || !zero(m[12]) || !zero(m[13])) return null;
  const fov = 2 * Math.atan(1 / m[5]);
  return fov > 0 && fov < Math.PI ? fov : null;
}

// XML3D 4.x's visible attribute (a bool, default true): "false" hides the element and its subtree.
const hiddenBy4x = (el) => (el.getAttribute('visible') || '').trim().toLowerCase() === 'false';

// XML3D 4.x's <view fieldOfView="rad"> (vertical; 5.x: <float name="fovVertical">), or null.
export function legacyFieldOfView(view) {
  const f = view.getAttribute('fieldOfView');
  const v = f === null || f.trim() === '' ? NaN : Number(f);
  return Number.isFinite(v) ? v : null;
}

const allFinite = (a) => {
  for (let i = 0; i < a.length; i++) if (!Number.isFinite(a[i])) return false;
  return true;
};
const maxValue = (a) => {
  let m = -1;
  for (let i = 0; i < a.length; i++) if (a[i] > m) m = a[i];
  return m;
};

export class MarkupReader {
  // resources: a Resources (or anything with get(url) and urlOfDocument(doc)).
  // computedStyle(el): optional, e.g. window.getComputedStyle.
  constructor({ resources = null, computedStyle = null, ids = null } = {}) {
    this.resources = resources;
    this.computedStyle = computedStyle;
    this.ids = ids || new IdRegistry();
    this.derived = new WeakMap();  // converted arrays, kept across reads (stable buffer identity)
    // What a scan of an array's values found (positions: all finite; indices: the largest), kept
    // across reads: a read then costs nothing per vertex. Not for arrays whose values are still
    // on their way (a deferred glTF): their zeros say nothing, and the node checks what it loads.
    this.scans = new WeakMap();
  }

  read(xml3d) {
    const scene = new SceneDescription(xml3d);
    this.scene = scene;
    this.views = [];
    this.warned = new Set();
    for (const df of xml3d.querySelectorAll('dataflow'))
      this.warn(df, `${this.describe(df)} is ignored: Xflow (dataflow, compute) is not supported`);
    this.walk(xml3d, M.identity(), null, true, 'visible');
    this.chooseView(xml3d);
    // Tessera extension: ambient="r g b" (a uniform sky on diffuse surfaces; XML3D has none).
    const amb = (xml3d.getAttribute('ambient') || '').trim().split(/[\s,]+/).map(Number);
    if (amb.length === 3 && amb.every((v) => Number.isFinite(v) && v >= 0)) scene.environment.ambient = amb;
    else if (xml3d.getAttribute('ambient')) this.error(xml3d, `xml3d ambient="${xml3d.getAttribute('ambient')}" is not three numbers >= 0`);
    return scene;
  }

  // ---- errors -------------------------------------------------------------------------
  error(element, message) {
    const key = message;
    if (this.warned.has(key)) return;
    this.warned.add(key);
    this.scene.errors.push({ element, message });
  }

  // Markup that is valid XML3D but not supported (Xflow): reported once, not an error.
  warn(element, message) {
    if (this.warned.has(message)) return;
    this.warned.add(message);
    this.scene.warnings.push({ element, message });
  }

  // <tag id="…"> (or name="…"), and the document's URL when it is not the page's.
  describe(el) {
    const id = el.getAttribute('id'), name = el.getAttribute('name');
    const attr = id ? ` id="${id}"` : name ? ` name="${name}"` : '';
    const url = this.resources && this.resources.urlOfDocument && this.resources.urlOfDocument(el.ownerDocument);
    return `<${localName(el)}${attr}>${url ? ` in ${url}` : ''}`;
  }

  // ---- style --------------------------------------------------------------------------
  // The computed style exists only for elements of the rendered page. In an external XML
  // document (file.xml#asset) getComputedStyle answers empty strings, so there, and for any
  // property the computed style leaves empty, the inline style attribute is used.
  style(el) {
    const inline = inlineStyle(el);
    const pageDoc = this.scene && this.scene.xml3d && this.scene.xml3d.ownerDocument;
    if (this.computedStyle && (!pageDoc || el.ownerDocument === pageDoc)) {
      try {
        const cs = this.computedStyle(el);
        // Elements of the XML3D namespace in an XHTML page (<xml3d xmlns="http://www.xml3d.org/2009/xml3d">,
        // as 4.x pages wrote them): the browser applies style sheets to them but not their style
        // attribute, so there what the attribute says wins.
        const own = el.namespaceURI && el.namespaceURI !== XHTML_NS ? inline : {};
        return {
          display: own.display || cs.display || inline.display, visibility: own.visibility || cs.visibility || inline.visibility,
          transform: own.transform || (cs.transform && cs.transform !== 'none' ? cs.transform : inline.transform),
          material: inline.material,
          shader: inline.shader,  // XML3D 4.x: style="shader: url(#id)"
          'z-index': cs.zIndex && cs.zIndex !== 'auto' ? cs.zIndex : inline['z-index'],
          computed: !!cs.visibility,  // computed visibility already holds what is inherited
        };
      } catch { /* fall through */ }
    }
    return inline;
  }

  // ---- references ---------------------------------------------------------------------
  // Resolves "#id" or "file.xml#id" or "file.json" relative to `context`. Returns
  // {element} | {data: Map} | {gltf} | {pending: true} | {error}.
  resolve(uri, context) {
    uri = String(uri).trim();
    const urlMatch = /^url\(\s*['"]?([^'")]*)['"]?\s*\)$/.exec(uri);
    if (urlMatch) uri = urlMatch[1];
    const doc = context.ownerDocument || context;
    if (uri.startsWith('#')) {
      const id = uri.slice(1);
      const el = doc.getElementById ? doc.getElementById(id) : null;
      const found = el || (doc.querySelector && doc.querySelector(`[id="${id.replace(/"/g, '\\"')}"]`));
      return found ? { element: found } : { error: `reference ${uri} not found` };
    }
    if (!this.resources) return { error: `external reference ${uri}: no resource loader` };
    const base = (this.resources.urlOfDocument && this.resources.urlOfDocument(doc)) || doc.baseURI ||
      (doc.location && doc.location.href) || 'http://localhost/';
    let abs;
    try { abs = new URL(uri, base).href; } catch { return { error: `bad URI ${uri}` }; }
    const r = this.resources.get(abs);
    if (r.state === 'loading') { this.scene.pending++; return { pending: true }; }
    if (r.state === 'error') return { error: r.error };
    if (r.kind === 'gltf') return { gltf: r.data, url: abs };
    if (r.kind === 'json') return { data: r.data, url: abs };
    const frag = abs.includes('#') ? abs.slice(abs.indexOf('#') + 1) : '';
    const d = r.data;
    if (!frag) return { element: d.documentElement };
    const el = (d.getElementById && d.getElementById(frag)) || (d.querySelector && d.querySelector(`[id="${frag}"]`));
    return el ? { element: el } : { error: `reference ${uri}: no element with id "${frag}"` };
  }

  // ---- data compositing ---------------------------------------------------------------
  // name -> {type, value, element}. src is an implicit first child, later siblings win,
  // outer values win over nested ones.
  collect(el, seen = new Set()) {
    if (seen.has(el)) { this.error(el, `cyclic data reference at <${localName(el)} id="${el.id}">`); return new Map(); }
    seen.add(el);
    const compute = el.getAttribute('compute');
    if (compute) {
      const c = compute.trim().replace(/\s+/g, ' ');
      this.warn(el, `${this.describe(el)} compute="${c.length > 60 ? c.slice(0, 57) + '...' : c}" is ignored: ` +
        'Xflow is not supported, the element\'s data is used without it');
    }
    const nested = new Map(), own = new Map();
    const src = el.getAttribute('src');
    if (src && localName(el) !== 'model') {
      const r = this.resolve(src, el);
      if (r.error) this.error(el, `<${localName(el)}${el.id ? ` id="${el.id}"` : ''}> src: ${r.error}`);
      else if (r.data) for (const [k, v] of r.data) nested.set(k, v);
      else if (r.element) for (const [k, v] of this.collect(r.element, seen)) nested.set(k, v);
    }
    for (const ch of el.children) {
      const tag = localName(ch);
      if (tag === 'data') {
        for (const [k, v] of this.collect(ch, seen)) nested.set(k, v);
      } else if (tag === 'texture') {
        const name = ch.getAttribute('name');
        if (name) own.set(name, { type: 'texture', value: [this.readTexture(ch)], element: ch });
      } else if (isValueElement(ch)) {
        const name = ch.getAttribute('name');
        if (!name) continue;
        const v = parseValueElement(ch);
        if (v.error) this.error(ch, v.error);
        own.set(name, { type: v.type, value: v.value, element: ch });
      }
    }
    seen.delete(el);
    for (const [k, v] of own) nested.set(k, v);
    return this.filter(el, nested);
  }

  // filter="keep(a, b)" / "remove(a, b)" / "rename({new: old, ...})" / "keep({new: old, ...})"
  // (XML3D spec, "Filters"): keep with a mapping keeps only the mapped entries, under their new
  // names; one entry may be given several new names.
  filter(el, map) {
    const f = el.getAttribute('filter');
    if (!f || localName(el) === 'texture') return map;
    const m = /^\s*(keep|remove|rename)\s*\((.*)\)\s*$/s.exec(f);
    if (!m) { this.error(el, `bad filter "${f}"`); return map; }
    const [, op, arg] = m;
    const unquote = (s) => s.trim().replace(/^['"]|['"]$/g, '');
    const body = arg.trim();
    const braced = body.startsWith('{');
    if (braced || op === 'rename') {  // a mapping {new: old, ...} (rename also takes it without braces)
      if ((braced && !body.endsWith('}')) || op === 'remove') { this.error(el, `bad filter "${f}"`); return map; }
      const pairs = [];
      for (const pair of (braced ? body.slice(1, -1) : body).split(',')) {
        if (!pair.trim()) continue;
        const parts = pair.split(':').map(unquote);
        if (parts.length !== 2 || !parts[0] || !parts[1]) { this.error(el, `bad filter "${f}"`); return map; }
        pairs.push(parts);
      }
      const out = new Map();
      if (op === 'rename') {
        const renamed = new Set(pairs.map(([, from]) => from));
        for (const [k, v] of map) if (!renamed.has(k)) out.set(k, v);
      }
      for (const [to, from] of pairs) if (map.has(from)) out.set(to, map.get(from));
      return out;
    }
    const names = new Set(body.split(/[\s,]+/).map(unquote).filter((s) => s));
    return new Map([...map].filter(([k]) => (op === 'keep') === names.has(k)));
  }

  readTexture(el) {
    const img = el.firstElementChild || [...el.children][0];
    // XML3D 4.x names (wrapS, wrapT, filterMin, filterMag) when the 5.x ones are absent.
    const wrap = (el.getAttribute('wrap') ||
      (el.hasAttribute('wrapS') || el.hasAttribute('wrapT') ? `${el.getAttribute('wrapS') || 'clamp'} ${el.getAttribute('wrapT') || 'clamp'}` : 'clamp'))
      .trim().toLowerCase().split(/\s+/);
    const filter = (el.getAttribute('filter') ||
      (el.hasAttribute('filterMin') || el.hasAttribute('filterMag') ? `${el.getAttribute('filterMin') || 'linear-mipmap-linear'} ${el.getAttribute('filterMag') || 'linear'}` : 'linear-mipmap-linear linear'))
      .trim().toLowerCase().split(/\s+/);
    const mag = filter[1] || filter[0];
    if (!img) { this.error(el, `<texture name="${el.getAttribute('name')}"> has no <img> child`); return null; }
    let url = img.getAttribute('src') || '';
    try {
      const doc = el.ownerDocument;
      const base = (this.resources && this.resources.urlOfDocument && this.resources.urlOfDocument(doc)) ||
        doc.baseURI || 'http://localhost/';
      if (url) url = new URL(url, base).href;
    } catch { /* keep as written */ }
    return {
      url, image: img,
      wrapS: wrap[0] === 'repeat' ? 'repeat' : 'clamp',
      wrapT: (wrap[1] || wrap[0]) === 'repeat' ? 'repeat' : 'clamp',
      filter: mag === 'nearest' ? 'nearest' : 'linear',
      flipY: true,   // XML3D uploads with UNPACK_FLIP_Y: texcoord (0,0) is the image's bottom-left
      srgb: false,
    };
  }

  // ---- transforms ---------------------------------------------------------------------
  // The element's own matrix (CSS transform over the transform attribute); for a <view>, the
  // XML3D 4.x pose attributes position="x y z" and orientation="x y z angle" come after it
  // (4.x: view to parent = T(position) * R(orientation); 5.x pages have neither). null = identity.
  localMatrix(el, style) {
    const m = this.ownMatrix(el, style);
    if (localName(el) !== 'view') return m;
    const pose = this.legacyViewPose(el);
    return pose ? (m ? M.multiply(m, pose) : pose) : m;
  }

  // The first n numbers of an attribute's text `s`; fewer: an error saying `what` needs n, and null.
  leadingNumbers(el, s, n, what) {
    const v = numbersIn(s);
    if (v.length < n) { this.error(el, `${what} needs ${n} numbers`); return null; }
    return v.slice(0, n);
  }

  legacyViewPose(el) {
    const pos = el.getAttribute('position'), ori = el.getAttribute('orientation');
    if (pos === null && ori === null) return null;
    // Too few numbers, or one that is not finite (1e999): an error, and that part left out.
    const part = (s, n, name, def) => {
      if (s === null) return def;
      const what = `${this.describe(el)} ${name}="${s}"`;
      const v = this.leadingNumbers(el, s, n, what);
      if (v && !allFinite(v)) { this.error(el, `${what} is not finite`); return def; }
      return v || def;
    };
    const p = part(pos, 3, 'position', [0, 0, 0]), o = part(ori, 4, 'orientation', [0, 0, 1, 0]);
    return M.multiply(M.translation(...p), M.axisAngle(...o));
  }

  ownMatrix(el, style) {
    if (style.transform && style.transform !== 'none') {
      try {
        const m = parseCssTransform(style.transform);
        if (m) return m;
      } catch (e) { this.error(el, `<${localName(el)}> CSS transform: ${e.message}`); }
    }
    const t = el.getAttribute('transform');
    if (!t) return null;
    const r = this.resolve(t, el);
    if (r.pending) return null;
    if (r.error) { this.error(el, `<${localName(el)}> transform: ${r.error}`); return null; }
    if (r.element) return this.transformOf(r.element);
    return null;
  }

  transformOf(el) {
    if (localName(el) === 'transform') {
      const v = (name, def) => {
        const s = el.getAttribute(name);
        return s ? this.leadingNumbers(el, s, def.length, `<transform ${name}="${s}">`) || def : def;
      };
      const t = v('translation', [0, 0, 0]), r = v('rotation', [0, 0, 1, 0]), s = v('scale', [1, 1, 1]);
      const c = v('center', [0, 0, 0]), so = v('scaleOrientation', [0, 0, 1, 0]);
      // T * C * R * SO * S * -SO * -C
      return M.multiplyAll(M.translation(...t), M.translation(...c), M.axisAngle(...r), M.axisAngle(...so),
        M.scaling(...s), M.axisAngle(so[0], so[1], so[2], -so[3]), M.translation(-c[0], -c[1], -c[2]));
    }
    const data = this.collect(el);
    const e = data.get('transform');
    if (e && e.value && e.value.length >= 16) return new Float32Array(e.value.slice(0, 16));
    this.error(el, `transform reference to <${localName(el)} id="${el.id}"> holds no float4x4 "transform"`);
    return null;
  }

  // ---- scene tree ---------------------------------------------------------------------
  walk(parent, world, materialRef, inheritVisible, inheritVisibility) {
    for (const el of parent.children) {
      const tag = localName(el);
      if (NON_SCENE.has(tag)) continue;
      if (tag.includes('-')) continue;  // web components are not expanded
      const style = this.style(el);
      const displayed = style.display !== 'none';
      const visibility = style.visibility || (style.computed ? 'visible' : inheritVisibility);
      if (!displayed && tag !== 'light') continue;
      const local = this.localMatrix(el, style);
      const w = local ? M.multiply(world, local) : world;
      // XML3D 4.x visible="false" on group, mesh, model, light and view (5.x: CSS display/visibility).
      const visible = inheritVisible && visibility !== 'hidden' && visibility !== 'collapse' && !hiddenBy4x(el);
      // XML3D 4.x names: shader="#id" and style="shader: url(#id)" (5.x: material).
      const mat = el.getAttribute('material') || style.material ||
        (tag !== 'light' && (el.getAttribute('shader') || style.shader)) || materialRef;
      const z = style['z-index'];
      if ((tag === 'mesh' || tag === 'model') && z && z !== 'auto')
        this.warn(el, `${this.describe(el)} z-index: ${z} is ignored: the scene is drawn in one depth order (no render bins)`);
      switch (tag) {
        case 'mesh': this.readMesh(el, w, mat, visible); break;
        case 'model': this.readModel(el, w, mat, visible); break;
        case 'light': this.readLight(el, w, displayed && visible, style); break;
        case 'view': this.views.push({ el, world: w }); break;
        default: this.walk(el, w, mat, visible, visibility); break;  // group and unknown elements
      }
    }
  }

  // ---- materials ----------------------------------------------------------------------
  materialParams(ref, context) {
    if (!ref) return null;
    const r = this.resolve(ref, context);
    if (r.pending) return null;
    if (r.error) { this.error(context, `<${localName(context)}> material: ${r.error}`); return null; }
    if (r.data) return { model: 'phong', data: r.data };
    const el = r.element;
    if (localName(el) !== 'material' && localName(el) !== 'shader') {
      this.error(context, `material reference ${ref} points at <${localName(el)}>, not <material>`);
      return null;
    }
    // <shader script="urn:xml3d:shader:phong"> is XML3D 4.x's <material model="urn:xml3d:material:phong">.
    const urn = el.getAttribute('model') || el.getAttribute('script');
    return { model: urnName(urn, 'phong'), urn, data: this.collect(el), element: el };
  }

  buildMaterial(params, overrides, element) {
    let model = params ? params.model : 'matte';
    if (model === 'flat') model = 'matte';
    if (model === 'phongvs') model = 'phong';  // early XML3D's per-vertex phong: the same parameters
    if (!['matte', 'diffuse', 'phong'].includes(model)) {
      // Valid XML3D that this library cannot draw as written: a material registered by the page's
      // script (XML3D.materials.register), a shade.js script (model="#id"), the point material.
      const el = (params && params.element) || element;
      this.warn(el, `${this.describe(el)} model="${(params && params.urn) || model}" is not supported ` +
        '(only urn:xml3d:material:matte, flat, diffuse and phong are): drawn as phong with its parameters');
      model = 'phong';
    }
    const m = params ? { ...MATERIAL_DEFAULTS, model } : defaultMaterial();
    const apply = (data) => {
      if (!data) return;
      for (const [name, e] of data) {
        const key = name === 'reflection' ? 'reflectionCoefficient' : name === 'refraction' ? 'refractionCoefficient'
          : name === 'ior' ? 'refractionIndex' : name;
        // XML3D 4.x's transparency (0 = opaque) is 1 - opacity.
        if (key === 'transparency') { const t = first(e, null); if (Number.isFinite(t)) m.opacity = Math.min(1, Math.max(0, 1 - t)); continue; }
        if (!MATERIAL_PARAMS.has(key)) continue;
        // useVertexColor first: it ends in "Color" but is a bool, not an RGB triple.
        if (key === 'useVertexColor') m[key] = !!first(e, 0);
        else if (e.type === 'texture') m[key] = e.value[0];
        else if (key.endsWith('Color')) m[key] = vec3(e, m[key]);
        else m[key] = first(e, m[key]);
      }
    };
    apply(params && params.data);
    apply(overrides);
    return m;
  }

  materialId(desc) {
    return this.scene.addMaterial(desc, this.ids);
  }

  // ---- meshes -------------------------------------------------------------------------
  readMesh(el, world, materialRef, visible) {
    const data = this.collect(el);
    const type = (el.getAttribute('type') || 'triangles').trim().toLowerCase();  // xml3d.js lower-cases it
    const overrides = new Map([...data].filter(([k]) => MATERIAL_PARAMS.has(k)));
    const params = this.materialParams(materialRef, el);
    const mat = this.buildMaterial(params, overrides, el);
    this.addGeometry(el, el, this.ids.of(el, 0), {
      positions: data.get('position'), normals: data.get('normal'), texcoords: data.get('texcoord'),
      colors: data.get('color'), indices: data.get('index'), vertexCount: data.get('vertexCount'),
      type: type === 'derived' ? String(first(data.get('type'), 'triangles')).trim().toLowerCase() : type,
    }, world, mat, visible);
  }

  // Adds one drawable with the given id; `el` is the element errors name, `pick` the one
  // events and picking report.
  addGeometry(el, pick, id, g, world, material, visible) {
    const what = `<${localName(el)}${el.id ? ` id="${el.id}"` : ''}>`;
    const val = (e) => (e && e.value !== undefined ? e.value : e);
    let positions = val(g.positions);
    if (!positions || positions.length === 0) {
      if (this.scene.pending === 0) this.error(el, `${what} has no position data`);
      return;
    }
    if (g.type !== 'triangles' && g.type !== 'tristrips') {
      // Points and lines are valid XML3D that this library does not draw: a warning. Any other
      // type is not XML3D at all: an error.
      if (UNDRAWN_TYPES.has(g.type)) this.warn(el, `${this.describe(el)} type="${g.type}" is not drawn: only triangles and tristrips are`);
      else this.error(el, `${what} type="${g.type}" is not drawn (triangles and tristrips are)`);
      return;
    }
    positions = this.floats(positions);
    const nv = positions.length / 3;
    if (positions.length % 3) { this.error(el, `${what} position count is not a multiple of 3`); return; }
    if (!this.scanned(positions, allFinite)) { this.error(el, `${what} positions hold NaN or Infinity`); return; }
    const check = (arr, comps, name) => {
      arr = val(arr);
      if (!arr || arr.length === 0) return null;
      if (arr.length !== nv * comps) {
        this.error(el, `${what} has ${arr.length / comps} ${name} values for ${nv} vertices: ${name} ignored`);
        return null;
      }
      return this.floats(arr);
    };
    const normals = check(g.normals, 3, 'normal');
    const texcoords = check(g.texcoords, 2, 'texcoord');
    const colors = check(g.colors, 3, 'color');
    let indices = this.indices(val(g.indices), g.type === 'tristrips' || g.strip, val(g.vertexCount), nv);
    if (indices) {
      const largest = this.scanned(indices, maxValue, -1);
      if (largest >= nv) {
        const bad = indices.find((x) => x >= nv);
        this.error(el, `${what} index ${bad} out of range (${nv} vertices)`);
        return;
      }
    } else if (nv % 3) {
      this.error(el, `${what} non-indexed triangles need a multiple of 3 vertices (has ${nv})`);
      return;
    }
    const s = this.scene;
    const mesh = {
      id,
      element: pick,
      positions: s.addBuffer(positions, 3, this.ids),
      normals: normals ? s.addBuffer(normals, 3, this.ids) : 0,
      texcoords: texcoords ? s.addBuffer(texcoords, 2, this.ids) : 0,
      colors: colors ? s.addBuffer(colors, 3, this.ids) : 0,
      indices: indices ? s.addBuffer(indices, 1, this.ids) : 0,
      material: this.materialId(material),
      transform: world,
      visible,
    };
    s.meshes.set(mesh.id, mesh);
  }

  // scan(array) for `array`, remembered; `pending` while its values are not in yet.
  scanned(array, scan, pending = true) {
    if (pendingValues(array)) return pending;
    let r = this.scans.get(array);
    if (r === undefined) { r = scan(array); this.scans.set(array, r); }
    return r;
  }

  floats(a) {
    if (a instanceof Float32Array) return a;
    let d = this.derived.get(a);
    if (!d) { d = Float32Array.from(a); this.derived.set(a, d); }
    return d;
  }

  // XML3D index (int) to uint32 triangles; triangle strips unrolled.
  indices(index, strip, vertexCount, nv) {
    const key = index || null;
    if (!strip) {
      if (!index || index.length === 0) return null;
      if (index instanceof Uint32Array) return index;
      let d = this.derived.get(index);
      if (!d) { d = Uint32Array.from(index, (x) => (x < 0 ? 0xffffffff : x)); this.derived.set(index, d); }
      return d;
    }
    const src = index && index.length ? index : null;
    const total = src ? src.length : nv;
    const counts = vertexCount && vertexCount.length ? Array.from(vertexCount) : [total];
    const cacheKey = src || vertexCount;
    if (cacheKey && this.derived.has(cacheKey)) return this.derived.get(cacheKey);
    const out = [];
    let base = 0;
    for (const n of counts) {
      for (let i = 0; i + 2 < n; i++) {
        const a = base + i, b = base + i + 1, c = base + i + 2;
        const ia = src ? src[a] : a, ib = src ? src[b] : b, ic = src ? src[c] : c;
        if (ia === ib || ib === ic || ia === ic) continue;  // degenerate (strip joins)
        if (i % 2 === 0) out.push(ia, ib, ic); else out.push(ib, ia, ic);
      }
      base += n;
    }
    const result = Uint32Array.from(out);
    if (cacheKey) this.derived.set(cacheKey, result);
    return result;
  }

  // ---- models -------------------------------------------------------------------------
  readModel(el, world, materialRef, visible) {
    const src = el.getAttribute('src');
    if (!src) { this.error(el, '<model> has no src'); return; }
    const r = this.resolve(src, el);
    if (r.pending) return;
    if (r.error) { this.error(el, `<model> src: ${r.error}`); return; }
    // Per-model overrides: <assetmesh name=... material=...> children.
    const overrides = new Map();
    for (const ch of el.children)
      if (localName(ch) === 'assetmesh' && ch.getAttribute('name')) overrides.set(ch.getAttribute('name'), ch);
    const fallback = this.materialParams(materialRef, el);
    if (r.gltf) {
      const g = r.gltf;
      if (g.undrawn > 0)
        this.warn(el, `${this.describe(el)} src="${src}": ${g.undrawn} glTF primitive${g.undrawn > 1 ? 's' : ''} of points or lines ` +
          `not drawn: only triangles, triangle strips and fans are`);
      for (const w of g.warnings || []) this.warn(el, `${this.describe(el)} src="${src}": ${w}`);
      if (g.badColors > 0)
        this.warn(el, `${this.describe(el)} src="${src}": COLOR_0 of ${g.badColors} glTF primitive${g.badColors > 1 ? 's' : ''} ` +
          'left out: not one RGB or RGBA colour per vertex');
      const pick = parsePick(el.getAttribute('pick'));
      g.meshes.forEach((p, i) => {
        if (pick && !pickSelects(pick, { name: p.name, classes: new Set() })) return;
        const o = overrides.get(p.name);
        let mat;
        if (o && o.getAttribute('material')) mat = this.buildMaterial(this.materialParams(o.getAttribute('material'), o), null, o);
        else if (p.material) mat = { ...MATERIAL_DEFAULTS, ...p.material };
        else mat = this.buildMaterial(fallback, null, el);
        if (p.colors) mat = { ...mat, useVertexColor: true };  // glTF: COLOR_0 multiplies the base colour
        const m = M.multiply(world, p.matrix);
        this.addGeometry(el, el, this.ids.of(el, `gltf:${i}`), { ...p, type: 'triangles' }, m, mat, visible);
      });
      g.lights.forEach((l, i) => this.addLight(el, `gltf:${i}`, l.type, M.multiply(world, l.matrix), {
        color: l.color, attenuation: l.attenuation, cutoff: l.cutoff, softness: l.softness,
        position: [0, 0, 0], direction: [0, 0, -1], on: visible, castShadow: true,  // glTF lights cast, as on the node
      }));
      if (g.camera) this.gltfCamera = { toWorld: M.multiply(world, g.camera.toWorld), fovY: g.camera.fovY };
      return;
    }
    if (r.element && ['asset', 'model'].includes(localName(r.element))) {
      this.drawAssetTable(el, this.assetTable(el, null, []), world, fallback, visible, new Set());
      return;
    }
    if (r.element) { this.error(el, `<model> src points at <${localName(r.element)}>, not <asset>, <model> or a glTF file`); return; }
    this.error(el, '<model> src is not an asset');
  }

  // ---- assets (XML3D spec "Assets"; docs/web-client.md "Assets") ------------------------
  // An <asset> or <model> is read into a table: its entries (<assetdata>/<assetmesh>; entries
  // of the same name are one entry, each element a later "post" that adds or overrides data,
  // material, transform or type), its sub-tables (nested <asset> elements; named ones are
  // merged by name) and its pick filter. A `src` naming another asset or model copies that
  // table first, so the element's own children extend and override it: a <model>'s
  // <assetmesh name=...> children are posts like any other. Returns the table; errors go to
  // the element that caused them.
  assetTable(el, parent, chain) {
    const t = newTable(el, parent);
    if (chain.includes(el) || chain.length > 16) {
      this.error(el, `<${localName(el)}${el.id ? ` id="${el.id}"` : ''}> src: cyclic asset reference`);
      return t;
    }
    chain = [...chain, el];
    let pick = parsePick(el.getAttribute('pick'));
    const src = el.getAttribute('src');
    if (src) {
      const r = this.resolve(src, el);
      if (r.error) this.error(el, `<${localName(el)}> src: ${r.error}`);
      else if (r.element && ['asset', 'model'].includes(localName(r.element))) {
        const from = this.assetTable(r.element, null, chain);
        copyTable(t, from);
        pick = pick && from.pick ? intersectPick(pick, from.pick) : (pick || from.pick);
      } else if (!r.pending) {
        this.error(el, `<${localName(el)}> src="${src}" is not an <asset> or <model>` +
          (r.gltf ? ' (a glTF file is instantiated by <model src> only)' : ''));
      }
    }
    t.pick = pick;
    if (el.getAttribute('material')) t.material = { ref: el.getAttribute('material'), el };
    if (localName(el) === 'asset') {
      const local = this.localMatrix(el, this.style(el));
      if (local) t.transform = local;
    }
    const matchPosts = [];
    for (const ch of el.children) {
      const tag = localName(ch);
      if (tag === 'asset') { mergeSubTable(t, this.assetTable(ch, t, chain)); continue; }
      if (tag !== 'assetdata' && tag !== 'assetmesh') continue;
      const name = ch.getAttribute('name');
      const match = ch.getAttribute('match');
      if (!name && match) { matchPosts.push({ filter: parsePick(match), post: ch, mesh: tag === 'assetmesh' }); continue; }
      if (name && match) this.warn(ch, `${this.describe(ch)} has both name and match: match is ignored`);
      let e = name ? t.named.get(name) : null;
      if (!e) {
        e = newEntry(name, t);
        t.entries.push(e);
        if (name) t.named.set(name, e);
      }
      addPost(e, ch);
    }
    // match="name, .class" elements are posts of every entry of their kind that they select.
    for (const m of matchPosts)
      for (const e of t.entries)
        if ((e.type !== null) === m.mesh && pickSelects(m.filter, e)) addPost(e, m.post);
    return t;
  }

  // The data of an entry: per post, in order, the entries its `includes` names (a name in the
  // same table; "parent.name", "sub.name", "parent.sub.name" through the tables), then the
  // post's own data; later wins.
  entryData(e, stack = []) {
    const out = new Map();
    if (stack.includes(e)) {
      this.error(e.posts[e.posts.length - 1], `includes: recursive include of "${e.name}"`);
      return out;
    }
    stack = [...stack, e];
    for (const post of e.posts) {
      for (const inc of (post.getAttribute('includes') || '').split(/[\s,]+/).filter((x) => x)) {
        const target = resolveInclude(e.table, inc);
        if (target.error) { this.error(post, `includes "${inc}": ${target.error}`); continue; }
        for (const [k, v] of this.entryData(target.entry, stack)) out.set(k, v);
      }
      for (const [k, v] of this.collect(post)) out.set(k, v);
    }
    return out;
  }

  // Draws the meshes of a table that its pick filter selects, then its sub-tables, each under
  // its own transform. `model` is the <model> element: events and picking report it, and mesh
  // ids are keyed by it and the entry's first element (a path when that repeats in the model).
  drawAssetTable(model, t, world, fallback, visible, used, path = '') {
    const w = t.transform ? M.multiply(world, t.transform) : world;
    t.entries.forEach((e, i) => {
      if (e.type === null || (t.pick && !pickSelects(t.pick, e))) return;
      const last = e.posts[e.posts.length - 1];
      if (this.style(last).display === 'none') return;
      let local = null;
      for (const post of e.posts) local = this.localMatrix(post, this.style(post)) || local;
      const data = this.entryData(e);
      let matPost = null;
      for (const post of e.posts) if (post.getAttribute('material')) matPost = post;
      let matRef = matPost && { ref: matPost.getAttribute('material'), el: matPost };
      for (let up = t; !matRef && up; up = up.parent) matRef = up.material;
      const params = matRef ? this.materialParams(matRef.ref, matRef.el) : fallback;
      const mat = this.buildMaterial(params, new Map([...data].filter(([k]) => MATERIAL_PARAMS.has(k))), last);
      const key = used.has(e.posts[0]) ? `${path}/${i}` : e.posts[0];
      used.add(e.posts[0]);
      this.addGeometry(last, model, this.ids.of(model, key), {
        positions: data.get('position'), normals: data.get('normal'), texcoords: data.get('texcoord'),
        colors: data.get('color'), indices: data.get('index'), vertexCount: data.get('vertexCount'),
        type: e.type,
      }, local ? M.multiply(w, local) : w, mat, visible);
    });
    t.subs.forEach((sub, i) => this.drawAssetTable(model, sub, w, fallback, visible, used, `${path}/${sub.name || ''}#${i}`));
  }

  // ---- lights -------------------------------------------------------------------------
  // XML3D 5: <light model="urn:xml3d:light:…"> with its parameters inline. XML3D 4.x: <light
  // shader="#ls"> (or style="shader: url(#ls)") naming a <lightshader
  // script="urn:xml3d:lightshader:point|directional|spot"> that holds the parameters (the light's
  // own values override them), a scalar intensity="k" attribute multiplying the float3
  // intensity, and the spot's falloffAngle for cutoffAngle.
  readLight(el, world, on, style = {}) {
    let urn = el.getAttribute('model'), d = this.collect(el), scale = 1;
    const shaderRef = !urn && (el.getAttribute('shader') || style.shader);
    if (shaderRef) {
      const r = this.resolve(shaderRef, el);
      if (r.pending) return;
      if (r.error) this.error(el, `${this.describe(el)} shader: ${r.error}`);
      else if (r.element && localName(r.element) === 'lightshader') {
        urn = r.element.getAttribute('script') || r.element.getAttribute('model') || '';
        d = new Map([...this.collect(r.element), ...d]);
      } else if (r.element) this.error(el, `${this.describe(el)} shader="${shaderRef}" points at <${localName(r.element)}>, not <lightshader>`);
      const k = el.getAttribute('intensity');
      if (k !== null && k.trim() !== '') {
        scale = Number(k);
        if (!Number.isFinite(scale)) { this.error(el, `${this.describe(el)} intensity="${k}" is not a number`); scale = 1; }
      }
    }
    const model = urnName(urn, 'directional');
    let type = model;
    if (!['point', 'directional', 'spot'].includes(model)) {
      this.error(el, `light model "${model}" unknown, directional used`);
      type = 'directional';
    }
    this.addLight(el, 0, type, world, {
      color: vec3(d.get('intensity'), [1, 1, 1]).map((c) => c * scale),
      position: vec3(d.get('position'), [0, 0, 0]),
      direction: vec3(d.get('direction'), [0, 0, -1]),
      attenuation: vec3(d.get('attenuation'), [0, 0, 1]),
      cutoff: first(d.get('cutoffAngle'), first(d.get('falloffAngle'), Math.PI / 4)),
      softness: first(d.get('softness'), 0),
      on: on && !!first(d.get('on'), 1),
      castShadow: !!first(d.get('castShadow'), 0),  // XML3D: false unless the light says so
    });
  }

  addLight(el, sub, type, world, p) {
    const cutoff = Math.min(Math.max(p.cutoff, 1e-4), Math.PI);
    const light = {
      id: this.ids.of(el, `light:${sub}`), element: el, type,
      color: p.color, intensity: 1,
      position: M.transformPoint(world, p.position),
      direction: M.normalize(M.transformDirection(world, p.direction)),
      attenuation: p.attenuation,
      cutoff,
      softness: spotSoftness(cutoff, p.softness),
      on: p.on,
      castShadow: !!p.castShadow,
    };
    this.scene.lights.set(light.id, light);
  }

  // ---- view ---------------------------------------------------------------------------
  chooseView(xml3d) {
    let active = null;
    // XML3D 4.x: activeView="#id" (a URI; 5.x: view, a selector). "#id" is both.
    const sel = xml3d.getAttribute('view') || xml3d.getAttribute('activeView') || xml3d.getAttribute('activeview');
    if (sel) {
      let el = null;
      try { el = xml3d.querySelector(sel); } catch { /* bad selector */ }
      if (!el && sel.startsWith('#')) { const r = this.resolve(sel, xml3d); el = r.element || null; }
      active = this.views.find((v) => v.el === el) || null;
      if (!active) this.error(xml3d, `xml3d view="${sel}" does not match a <view>`);
    }
    if (!active) active = this.views[0] || null;
    const cam = { element: active ? active.el : null, toWorld: M.identity(), fovY: Math.PI / 4, fovX: null, near: null, far: null };
    if (active) {
      cam.toWorld = active.world;
      const d = this.collect(active.el);
      cam.fovY = first(d.get('fovVertical'), legacyFieldOfView(active.el) ?? Math.PI / 4);
      const model = (active.el.getAttribute('model') || PERSPECTIVE).trim();
      if (model === PROJECTIVE) {
        const fov = projectiveFovY(d.get('projectionMatrix'));
        if (fov !== null) cam.fovY = fov;
        else this.warn(active.el, `${this.describe(active.el)} model="${PROJECTIVE}": its projectionMatrix is not a ` +
          `centred perspective projection (missing, off-axis or orthographic); drawn as a perspective view with fovVertical ${+cam.fovY.toFixed(4)}`);
      } else if (model !== PERSPECTIVE) {
        this.warn(active.el, `${this.describe(active.el)} model="${model}" is not a known view model; drawn as ${PERSPECTIVE}`);
      }
      const fx = d.get('fovHorizontal');
      if (fx && fx.value.length) cam.fovX = fx.value[0];
      cam.near = first(d.get('near'), null);
      cam.far = first(d.get('far'), null);
    } else if (this.gltfCamera) {
      cam.toWorld = this.gltfCamera.toWorld;
      cam.fovY = this.gltfCamera.fovY;
    }
    if (!(cam.fovY > 0 && cam.fovY < Math.PI)) { this.error(cam.element, `fovVertical ${cam.fovY} outside (0, pi)`); cam.fovY = Math.PI / 4; }
    this.scene.camera = cam;
  }
}

// A spot light's softness as the scene description holds it (0..1: 0 = hard edge, 1 = fading
// over the whole cone). XML3D's spot light is full inside the angle cutoff·(1 − softness) and
// fades out to cutoff, and xml3d.js takes the cosine of that angle without clamping softness,
// so softness 1.5 gives the inner angle cos(−cutoff/2) = cos(cutoff/2), i.e. softness 0.5, and
// an inner angle whose cosine is at or below cos(cutoff) gives a hard edge. This maps any value
// to the softness in 0..1 with the same inner cosine; 0..1 is kept as given.
export function spotSoftness(cutoff, softness) {
  if (!Number.isFinite(softness)) return 0;
  if (softness >= 0 && softness <= 1) return softness;
  const inner = Math.acos(Math.min(1, Math.max(-1, Math.cos(cutoff * (1 - softness)))));  // 0..pi
  return inner < cutoff ? 1 - inner / cutoff : 0;
}

// ---- asset tables (MarkupReader.assetTable) --------------------------------------------
const newTable = (el, parent) => ({
  el, name: el.getAttribute('name') || null, parent, entries: [], named: new Map(), subs: [], namedSubs: new Map(),
  pick: null, material: null, transform: null,
});
const newEntry = (name, table) => ({ name, table, posts: [], type: null, classes: new Set() });
function addPost(e, el) {
  e.posts.push(el);
  if (localName(el) === 'assetmesh') e.type = (el.getAttribute('type') || 'triangles').trim().toLowerCase();
  for (const c of (el.getAttribute('class') || '').split(/\s+/)) if (c) e.classes.add(c);
}
// A copy of entry `e` (its own post list and classes) becomes an entry of table `t`.
function addEntryCopy(t, e) {
  const c = { ...e, table: t, posts: [...e.posts], classes: new Set(e.classes) };
  t.entries.push(c);
  if (c.name) t.named.set(c.name, c);
}
// Copies `from` (a src asset's table) into the empty table `t`: entries and sub-tables become
// t's own (re-parented), the material and transform carry over.
function copyTable(t, from) {
  for (const e of from.entries) addEntryCopy(t, e);
  for (const sub of from.subs) mergeSubTable(t, cloneTable(sub, t));
  if (from.material) t.material = from.material;
  if (from.transform) t.transform = from.transform;
}
function cloneTable(from, parent) {
  const t = newTable(from.el, parent);
  t.name = from.name;
  t.pick = from.pick;
  copyTable(t, from);
  return t;
}
// A sub-table joins `t`; one with the name of an existing sub-table extends it instead (its
// entries' posts after the existing ones, so they override).
function mergeSubTable(t, sub) {
  const into = sub.name && t.namedSubs.get(sub.name);
  if (!into) {
    sub.parent = t;
    t.subs.push(sub);
    if (sub.name) t.namedSubs.set(sub.name, sub);
    return;
  }
  for (const e of sub.entries) {
    const have = e.name && into.named.get(e.name);
    if (have) for (const p of e.posts) addPost(have, p);
    else addEntryCopy(into, e);
  }
  for (const s of sub.subs) mergeSubTable(into, cloneTable(s, into));
  if (sub.material) into.material = sub.material;
  if (sub.transform) into.transform = sub.transform;
  if (sub.pick) into.pick = into.pick ? intersectPick(into.pick, sub.pick) : sub.pick;
}
// pick="a, b, .cls.other, *" (and match=...): entry names, class sets (an entry whose classes
// include all of one set) or everything. null when the attribute is absent.
export function parsePick(value) {
  if (value === null || value === undefined) return null;
  const f = { all: false, names: new Set(), classes: [] };
  for (const part of value.split(',').map((x) => x.trim()).filter((x) => x)) {
    if (part === '*') f.all = true;
    else if (part.startsWith('.')) f.classes.push(part.split('.').filter((x) => x));
    else f.names.add(part);
  }
  return f;
}
function pickSelects(f, e) {
  if (f.all) return true;
  if (e.classes.size && f.classes.some((set) => set.every((c) => e.classes.has(c)))) return true;
  return !!e.name && f.names.has(e.name);
}
function intersectPick(a, b) {
  const key = (set) => [...set].sort().join('.');
  const bClasses = new Set(b.classes.map(key));
  return {
    all: a.all && b.all,
    names: a.all ? new Set(b.names) : b.all ? new Set(a.names) : new Set([...a.names].filter((n) => b.names.has(n))),
    classes: a.all ? b.classes : b.all ? a.classes : a.classes.filter((set) => bClasses.has(key(set))),
  };
}
// "name", "parent.name", "sub.name", "parent.sub.name": the entry an includes names, from table t.
function resolveInclude(t, path) {
  const segs = path.split('.');
  for (const seg of segs.slice(0, -1)) {
    if (seg === 'parent') {
      if (!t.parent) return { error: 'the asset has no parent asset' };
      t = t.parent;
    } else {
      const sub = t.namedSubs.get(seg);
      if (!sub) return { error: `no nested asset named "${seg}"` };
      t = sub;
    }
  }
  const entry = t.named.get(segs[segs.length - 1]);
  return entry ? { entry } : { error: 'no assetdata with that name' };
}

// Stable numeric ids (from 1) for elements and their sub-parts, and for typed arrays. A sub-part
// key is a number, a string or another element (a model's instance of an asset mesh).
export class IdRegistry {
  constructor() {
    this.next = 1;
    this.byElement = new WeakMap();
    this.byArray = new WeakMap();
    this.byKey = new Map();
  }
  of(el, sub = 0) {
    let m = this.byElement.get(el);
    if (!m) { m = new Map(); this.byElement.set(el, m); }
    if (!m.has(sub)) m.set(sub, this.next++);
    return m.get(sub);
  }
  ofArray(a) {
    if (!this.byArray.has(a)) this.byArray.set(a, this.next++);
    return this.byArray.get(a);
  }
  ofKey(k) {
    if (!this.byKey.has(k)) this.byKey.set(k, this.next++);
    return this.byKey.get(k);
  }
}
