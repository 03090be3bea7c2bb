// window.XML3D: the namespace xml3d.js 5 pages script against (XML3D 5 specification,
// "Datatypes"; ../shared/XML3D.md §4 for the rest). Members Tessera cannot provide are still
// there when a page commonly calls them at start-up (XML3D.materials.register,
// Xflow.registerOperator, …): they warn once, naming themselves, and do nothing, so the page's
// script goes on. Reading any other member that xml3d.js has and Tessera lacks warns once too.
import { Vec2, Vec3, Vec4, AxisAngle, Quat, Mat2, Mat3, Mat4, Box, Ray } from './MathTypes.js';
import { debug, warnOnce } from './Debug.js';
import { StandardCamera } from './StandardCamera.js';
import { installElementApi } from './ElementApi.js';

// XML3D.options: the documented keys and defaults; only loglevel has an effect here.
const OPTION_DEFAULTS = {
  loglevel: 'warning',
  'resource-crossorigin-attribute': 'anonymous',
  'renderer-faceculling': 'none',
  'renderer-frontface': 'ccw',
  'renderer-frustum-culling': true,
  'renderer-mousemove-picking': true,
  'renderer-movement-aware-click-handler': false,
  'renderer-continuous': false,
  'renderer-ssao': false,
  'renderer-sort-opaque-objects': false,
};

function makeOptions() {
  const values = { ...OPTION_DEFAULTS };
  const observers = new Set();
  const options = {
    getKeys: () => Object.keys(values),
    getValue: (k) => values[k],
    setValue(k, v) {
      if (typeof k === 'object' && k) { for (const [kk, vv] of Object.entries(k)) options.setValue(kk, vv); return; }
      values[k] = v;
      if (k === 'loglevel') debug.setLogLevel(v);
      else warnOnce(`option:${k}`, `option "${k}" is stored but has no effect in Tessera`);
      for (const o of observers) { try { o(k, v); } catch (e) { debug.logException(e); } }
    },
    resetValue(k) { if (k in OPTION_DEFAULTS) options.setValue(k, OPTION_DEFAULTS[k]); },
    addObserver: (fn) => { observers.add(fn); },
    removeObserver: (fn) => { observers.delete(fn); },
    /** ?xml3d-<key>=value in the page URL. */
    setOptionsFromQuery(search = (globalThis.location && globalThis.location.search) || '') {
      for (const [k, v] of new URLSearchParams(search)) {
        if (!k.startsWith('xml3d-')) continue;
        const key = k.slice(6);
        options.setValue(key, v === 'true' ? true : v === 'false' ? false : v);
      }
    },
  };
  return options;
}

const unsupported = (name, ret) => (...args) => {
  warnOnce(name, `${name}() is not supported by Tessera and does nothing`);
  return typeof ret === 'function' ? ret(...args) : ret;
};

// Names xml3d.js defines that are only warned about when read (nothing to stub sensibly).
const PASS = new Set(['then', 'toJSON', 'constructor', 'prototype', 'length', 'name', 'nodeType', 'valueOf', 'toString',
  'inspect', 'asymmetricMatch', '$$typeof', '@@__IMMUTABLE_ITERABLE__@@', '_']);

/**
 * Builds the XML3D namespace. handlers(): the XML3DHandlers of the page (for flushDOMChanges).
 */
export function createXML3D({ version, handlers = () => [] } = {}) {
  const ns = {
    version,
    Vec2, Vec3, Vec4, AxisAngle, Quat, Mat2, Mat3, Mat4, Box, Ray,
    debug,
    options: makeOptions(),
    StandardCamera,
    util: {},
    /** document.createElement for XML3D tags (4.x pages; v5 elements are plain elements). */
    createElement: (tag) => globalThis.document.createElement(tag),
    /** Applies pending DOM changes to the scene the element API answers from. */
    flushDOMChanges() { for (const h of handlers()) h.sceneNow(); },
    materials: { register: unsupported('XML3D.materials.register'), getScript: unsupported('XML3D.materials.getScript', null) },
    resource: {
      registerFormatHandler: unsupported('XML3D.resource.registerFormatHandler'),
      onRequest: unsupported('XML3D.resource.onRequest'),
      fetch: (uri, opt) => globalThis.fetch(uri, opt),
      getAbsoluteURI: (base, uri) => new URL(uri, base || globalThis.location.href).href,
      FormatHandler: class FormatHandler {
        constructor() { warnOnce('XML3D.resource.FormatHandler', 'XML3D.resource.FormatHandler: format plugins are not supported by Tessera'); }
      },
    },
    registerComponent: unsupported('XML3D.registerComponent', () => Promise.resolve()),
  };
  return new Proxy(ns, {
    get(t, k, r) {
      if (typeof k === 'string' && !(k in t) && !PASS.has(k))
        warnOnce(`XML3D.${k}`, `XML3D.${k} is not supported by Tessera (undefined)`);
      return Reflect.get(t, k, r);
    },
  });
}

/** Installs window.XML3D (unless the page already has one) and a warning Xflow stub. */
export function installGlobal(win, opts) {
  if (!win) return null;
  installElementApi(win);
  if (win.XML3D) {
    warnOnce('XML3D-exists', 'window.XML3D already exists (another XML3D library on the page?); Tessera\'s is not installed');
    return win.XML3D;
  }
  win.XML3D = createXML3D(opts);
  if (!win.Xflow) {
    win.Xflow = {
      registerOperator: (name) => warnOnce(`Xflow.registerOperator(${name})`, `Xflow.registerOperator("${name}") is ignored: Xflow is not supported by Tessera`),
    };
  }
  win.XML3D.options.setOptionsFromQuery(win.location ? win.location.search : '');
  return win.XML3D;
}
