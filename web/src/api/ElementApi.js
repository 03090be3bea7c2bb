// XML3D 5's element interfaces (specification, "The … element" IDL blocks), on plain DOM
// elements:
//   <transform>: translation, scale, center (XML3D.Vec3) and rotation, scaleOrientation
//     (XML3D.AxisAngle), read from and written to the attributes, so a write updates the scene;
//   group, mesh, model, view, light: getWorldMatrix(), getLocalMatrix() (XML3D.Mat4);
//   group, mesh, model (and xml3d): getWorldBoundingBox(), getLocalBoundingBox() (XML3D.Box);
//   view: getViewMatrix() (world to view), getProjectionMatrix();
//   mesh, data: getOutputNames(); getResult() warns (not supported);
//   string attributes reflected as properties (mesh.src, group.transform, view.model, …).
// In HTML documents XML3D elements are HTMLUnknownElements (<data>: HTMLDataElement), so the
// members are defined once on those prototypes, each checking the element's tag (an element created by script has them before
// it is inserted). Elements of other prototypes (the XHTML namespace) get them per element
// (ensureElementApi). A member used on an element it does not belong to keeps ordinary expando
// behaviour (properties) or warns once and returns null (methods).
import * as M from '../math/Mat4.js';
import { Vec3, AxisAngle, Mat4, Box } from './MathTypes.js';
import { warnOnce } from './Debug.js';
import { MarkupReader, legacyFieldOfView } from '../reader/MarkupReader.js';
import { SceneDescription } from '../reader/SceneDescription.js';
import { localName, numbersIn } from '../reader/Values.js';
import { meshWorldBox, emptyBox, clippingPlanes } from '../scene/Bounds.js';

const tags = (s) => new Set(s.split(' '));
const TRANSFORMABLE = tags('group mesh model view light');
const BOXED = tags('group mesh model xml3d');
const VALUES = 'float float2 float3 float4 float4x4 int int4 bool string';

// <transform> properties: name -> [attribute, type, default]
const TRANSFORM_PROPS = {
  translation: ['translation', Vec3, [0, 0, 0]],
  scale: ['scale', Vec3, [1, 1, 1]],
  center: ['center', Vec3, [0, 0, 0]],
  rotation: ['rotation', AxisAngle, [0, 0, 1, 0]],
  scaleOrientation: ['scaleOrientation', AxisAngle, [0, 0, 1, 0]],
  scaleorientation: ['scaleOrientation', AxisAngle, [0, 0, 1, 0]],
};

// Reflected string attributes: property -> tags that have it.
const STRING_PROPS = {
  src: tags('mesh model data asset assetmesh assetdata dataflow material'),
  type: tags('mesh assetmesh texture'),
  material: tags('group mesh model assetmesh'),
  transform: tags('group mesh model view light assetmesh'),
  model: tags('view light material'),
  view: tags('xml3d'),
  name: tags(`${VALUES} texture asset assetmesh assetdata`),
  key: tags(VALUES),
  includes: tags('assetmesh assetdata'),
  compute: tags('data mesh assetmesh assetdata'),
  filter: tags('data mesh assetmesh assetdata texture'),
  wrap: tags('texture'),
};

const expando = new WeakMap();
const ownValue = (el, k) => { const m = expando.get(el); return m ? m[k] : undefined; };
const setOwnValue = (el, k, v) => { let m = expando.get(el); if (!m) expando.set(el, (m = {})); m[k] = v; };

// The handler of the <xml3d> an element belongs to (set by XML3DHandler as xml3d.tessera).
export function handlerOf(el) {
  const x = localName(el) === 'xml3d' ? el : el.closest && el.closest('xml3d');
  return (x && x.tessera) || null;
}

const readers = new WeakMap();
function readerFor(el) {
  const h = handlerOf(el);
  if (h) return h.reader;
  const win = el.ownerDocument && el.ownerDocument.defaultView;
  let r = readers.get(el.ownerDocument);
  if (!r) {
    r = new MarkupReader({ computedStyle: win && win.getComputedStyle ? (e) => win.getComputedStyle(e) : null });
    readers.set(el.ownerDocument, r);
  }
  return r;
}

// Runs `fn(reader)` on a scratch scene so that errors and pending counts of this query do not
// touch the scene the handler last read.
function withReader(el, fn) {
  const r = readerFor(el);
  const saved = [r.scene, r.warned];
  const x = el.closest && el.closest('xml3d');
  r.scene = new SceneDescription(x || null);
  r.warned = new Set();
  try { return fn(r); } finally { [r.scene, r.warned] = saved; }
}

/** Local matrix of a transformable element (CSS transform over the transform attribute). */
export function localMatrixOf(el) {
  return withReader(el, (r) => r.localMatrix(el, r.style(el)) || M.identity());
}

/** World matrix of the element's parent (the product of its ancestors' local matrices). */
export function parentWorldOf(el) {
  const chain = [];
  for (let p = el.parentElement; p && localName(p) !== 'xml3d'; p = p.parentElement) chain.unshift(p);
  let m = M.identity();
  for (const p of chain) m = M.multiply(m, localMatrixOf(p));
  return m;
}

/** Object-to-world matrix (Float32Array) of a scene element, read from the DOM as it is now. */
export function worldMatrixOf(el) {
  if (localName(el) === 'xml3d') return M.identity();
  return M.multiply(parentWorldOf(el), localMatrixOf(el));
}

// The scene description with every DOM change made so far (XML3DHandler.sceneNow).
function sceneOf(el) {
  const h = handlerOf(el);
  return h ? h.sceneNow() : null;
}

// Box of the meshes picked as `el` or inside it, in the space given by `toSpace` (world to it).
function boxOf(el, toSpace) {
  const scene = sceneOf(el);
  const box = new Box();
  if (!scene) return box;
  const b = emptyBox();
  const all = localName(el) === 'xml3d';
  for (const m of scene.meshes.values()) {
    if (!m.visible || !(all || m.element === el || el.contains(m.element))) continue;
    meshWorldBox(scene, toSpace ? { ...m, transform: M.multiply(toSpace, m.transform) } : m, b);
  }
  if (b.min[0] <= b.max[0]) { box.min = b.min; box.max = b.max; }
  return box;
}

/** Camera parameters of a <view> element: {toWorld, fovY, fovX, near, far}. */
function cameraOf(view) {
  const scene = sceneOf(view);
  if (scene && scene.camera && scene.camera.element === view) return { ...scene.camera, toWorld: worldMatrixOf(view) };
  const d = withReader(view, (r) => r.collect(view));
  const num = (k) => { const e = d.get(k); return e && e.value && e.value.length ? Number(e.value[0]) : null; };
  return { toWorld: worldMatrixOf(view), fovY: num('fovVertical') ?? legacyFieldOfView(view) ?? Math.PI / 4, fovX: num('fovHorizontal'), near: num('near'), far: num('far') };
}

// ---- member definitions ------------------------------------------------------------------
function transformProp(prop, [attr, Type, def]) {
  return {
    configurable: true,
    get() {
      if (localName(this) !== 'transform') return ownValue(this, prop);
      const s = this.getAttribute(attr);
      const n = s ? numbersIn(s) : [];
      return new Type(...(n.length >= def.length ? n.slice(0, def.length) : def));
    },
    set(v) {
      if (localName(this) !== 'transform') { setOwnValue(this, prop, v); return; }
      if (v == null) { this.removeAttribute(attr); return; }
      let text;
      if (typeof v === 'string') text = v;
      else if (v.data || ArrayBuffer.isView(v) || Array.isArray(v)) text = Array.from(v.data || v).slice(0, def.length).join(' ');
      else if (Type === AxisAngle && v.axis) text = [v.axis.x, v.axis.y, v.axis.z, v.angle].join(' ');
      else if ('x' in v) text = [v.x, v.y, v.z].join(' ');
      else { warnOnce(`set-${prop}`, `<transform>.${prop} = ${String(v)}: expected an XML3D.${Type.name}; ignored`); return; }
      this.setAttribute(attr, text);
    },
  };
}

function stringProp(prop, owners) {
  return {
    configurable: true,
    get() {
      if (!owners.has(localName(this))) return ownValue(this, prop);
      return this.getAttribute(prop) ?? '';
    },
    set(v) {
      if (!owners.has(localName(this))) { setOwnValue(this, prop, v); return; }
      if (v == null) this.removeAttribute(prop); else this.setAttribute(prop, String(v));
    },
  };
}

function method(name, owners, fn) {
  return {
    configurable: true, writable: true,
    value: function xml3dMethod(...args) {
      if (!owners.has(localName(this))) {
        warnOnce(`${name}@${localName(this)}`, `${name}() is not a method of <${localName(this)}>; returned null`);
        return null;
      }
      try { return fn.apply(this, args); } catch (e) {
        warnOnce(`${name}-failed`, `<${localName(this)}>.${name}() failed (${e.message}); returned null`);
        return null;
      }
    },
  };
}

const MEMBERS = {
  getWorldMatrix: method('getWorldMatrix', TRANSFORMABLE, function () { return Mat4.wrap(worldMatrixOf(this)); }),
  getLocalMatrix: method('getLocalMatrix', TRANSFORMABLE, function () { return Mat4.wrap(localMatrixOf(this)); }),
  getWorldBoundingBox: method('getWorldBoundingBox', BOXED, function () { return boxOf(this, null); }),
  // mesh: object space; group and model: without parent transformations; xml3d: world space.
  getLocalBoundingBox: method('getLocalBoundingBox', BOXED, function () {
    const tag = localName(this);
    if (tag === 'xml3d') return boxOf(this, null);
    const ref = tag === 'mesh' ? worldMatrixOf(this) : parentWorldOf(this);
    return boxOf(this, M.invert(ref) || M.identity());
  }),
  getViewMatrix: method('getViewMatrix', tags('view'), function () { return Mat4.wrap(M.invert(worldMatrixOf(this)) || M.identity()); }),
  // Perspective for the canvas' aspect ratio; near/far as the renderer chooses them when not given.
  getProjectionMatrix: method('getProjectionMatrix', tags('view'), function () {
    const h = handlerOf(this), cam = cameraOf(this);
    const aspect = h ? h.width / h.height : 4 / 3;
    const fovY = cam.fovX ? 2 * Math.atan(Math.tan(cam.fovX / 2) / aspect) : cam.fovY;
    const scene = h ? h.sceneNow() : new SceneDescription();
    const { near, far } = clippingPlanes(scene, cam.toWorld, cam.near, cam.far);
    return Mat4.perspective(fovY, aspect, near, far);
  }),
  getOutputNames: method('getOutputNames', tags('mesh data'), function () { return [...withReader(this, (r) => r.collect(this)).keys()]; }),
  getResult: method('getResult', tags('mesh data'), function () {
    warnOnce('getResult', `<${localName(this)}>.getResult() is not supported by Tessera (no Xflow); returned null`);
    return null;
  }),
};

function descriptors() {
  const d = { ...MEMBERS };
  for (const [k, spec] of Object.entries(TRANSFORM_PROPS)) d[k] = transformProp(k, spec);
  for (const [k, owners] of Object.entries(STRING_PROPS)) d[k] = stringProp(k, owners);
  return d;
}

const installed = new WeakSet();
/** Defines the element members on HTMLUnknownElement.prototype of `win` (XML3D's tags in HTML)
 * and HTMLDataElement.prototype (<data>), once each; native members are left alone. */
export function installElementApi(win) {
  for (const C of [win && win.HTMLUnknownElement, win && win.HTMLDataElement]) {
    const proto = C && C.prototype;
    if (!proto || installed.has(proto)) continue;
    installed.add(proto);
    for (const [k, desc] of Object.entries(descriptors())) if (!(k in proto)) Object.defineProperty(proto, k, desc);
  }
}

/** Gives an element the members when its prototype lacks them (e.g. XHTML-namespace elements). */
export function ensureElementApi(el) {
  if ('getWorldMatrix' in el) return;
  const d = descriptors();
  for (const [k, desc] of Object.entries(d)) {
    const own = Object.prototype.hasOwnProperty.call(el, k);
    if (k in el && !own) continue;  // a member of the element's own interface
    // A value a script stored before the element had the members goes through the setter.
    const v = own ? el[k] : undefined;
    if (own) delete el[k];
    Object.defineProperty(el, k, desc);
    if (own && v !== undefined) el[k] = v;
  }
}
