// One <xml3d> element on the page: reads its markup into a SceneDescription whenever the DOM
// changes, hands it to a backend (three.js locally, or the Tessera node when the element has
// a `server` attribute), and provides XML3D's element API and events.
import { MarkupReader, IdRegistry } from '../reader/MarkupReader.js';
import { Resources } from '../reader/Resources.js';
import { setScriptValue, isValueElement } from '../reader/Values.js';
import { generateRay, pick, unbuiltPickTrees } from '../scene/Picker.js';
import { CameraController } from './CameraController.js';
import { Vec3, Ray } from '../api/MathTypes.js';
import { installElementApi, ensureElementApi } from '../api/ElementApi.js';

// Above this many triangles a mousemove is not picked (clicks and the API still are).
const MOUSEMOVE_PICK_LIMIT = 300000;

const STYLE_ID = 'tessera-xml3d-style';
const CSS = `
xml3d.tessera-hidden { display: none !important; }
.tessera-xml3d { position: relative; display: inline-block; overflow: hidden; }
.tessera-xml3d > canvas, .tessera-xml3d > img.tessera-display { position: absolute; left: 0; top: 0; width: 100%; height: 100%; }
.tessera-status { position: absolute; left: 4px; bottom: 4px; right: 4px; font: 12px/1.4 sans-serif; color: #fff;
  pointer-events: none; white-space: pre-wrap; }
.tessera-status > div { background: rgba(0,0,0,0.6); padding: 2px 6px; margin-top: 2px; border-radius: 3px; display: inline-block; }
.tessera-status .tessera-error { background: rgba(160,0,0,0.85); }
`;

function injectStyle(doc) {
  if (doc.getElementById(STYLE_ID)) return;
  const s = doc.createElement('style');
  s.id = STYLE_ID;
  s.textContent = CSS;
  doc.head.appendChild(s);
}

const vec = (a) => (a ? new Vec3(a[0], a[1], a[2]) : null);
function fill(out, a) {
  if (!out) return;
  const v = a || [NaN, NaN, NaN];
  if (out.data instanceof Float32Array && out.data.length >= 3) out.data.set(v);
  else if (typeof out.set === 'function') out.set(v[0], v[1], v[2]);
  else { out.x = v[0]; out.y = v[1]; out.z = v[2]; }
}

export class XML3DHandler {
  // createBackend(handler) -> backend {element, inputElement?, update(scene), draw(scene, w, h), dispose()}
  constructor(xml3d, createBackend) {
    const doc = xml3d.ownerDocument;
    injectStyle(doc);
    this.xml3d = xml3d;
    this.complete = false;
    this.scene = null;
    this.shownErrors = new Set();
    this.ids = new IdRegistry();
    this.resources = new Resources({ onLoad: () => { this.dirty = true; this.invalidate(); } });
    this.reader = new MarkupReader({ resources: this.resources, ids: this.ids,
      computedStyle: (el) => doc.defaultView.getComputedStyle(el) });

    // Container in place of the xml3d element; it takes the element's class and style.
    const c = this.container = doc.createElement('div');
    c.className = `tessera-xml3d _xml3d ${xml3d.getAttribute('class') || ''}`.trim();
    c.style.cssText = xml3d.getAttribute('style') || '';
    if (!c.style.width) c.style.width = `${parseInt(xml3d.getAttribute('width') || '800', 10)}px`;
    if (!c.style.height) c.style.height = `${parseInt(xml3d.getAttribute('height') || '600', 10)}px`;
    xml3d.parentNode.insertBefore(c, xml3d);
    xml3d.classList.add('tessera-hidden');

    this.status = doc.createElement('div');
    this.status.className = 'tessera-status';
    this.messages = new Map();  // key -> {text, error}
    this.backend = createBackend(this);
    // A node that loads the page's glTF buffers itself needs only their URLs: the scene is sent
    // before the browser has downloaded them (Resources.js, deferBuffers).
    this.resources.deferBuffers = !!this.backend.defersBuffers;
    this.resources.downloadGate = this.backend.downloadGate || null;
    this.inputElement = this.backend.inputElement || this.backend.element;
    c.appendChild(this.status);  // above the display and input elements

    this.installApi();
    this.installEvents();
    this.observer = new MutationObserver((records) => {
      if (records.some((r) => !(r.type === 'attributes' && r.target === xml3d && r.attributeName === 'class'))) { this.dirty = true; this.invalidate(); }
    });
    this.observer.observe(xml3d, { attributes: true, childList: true, characterData: true, subtree: true });
    this.onResize = () => this.invalidate();
    doc.defaultView.addEventListener('resize', this.onResize);
    const mode = xml3d.getAttribute('controller') || 'examine';
    if (mode !== 'none') this.controller = new CameraController(this, { mode }).attach();
    this.invalidate();
  }

  get width() { return Math.max(1, this.container.clientWidth | 0); }
  get height() { return Math.max(1, this.container.clientHeight | 0); }

  invalidate() {
    if (this.frameRequested || this.disposed) return;
    this.frameRequested = true;
    this.xml3d.ownerDocument.defaultView.requestAnimationFrame(() => { this.frameRequested = false; this.frame(); });
  }

  // Sets (or clears, with text null) a status line; errors are shown in red.
  setStatus(key, text, error = false) {
    if (text == null) this.messages.delete(key); else this.messages.set(key, { text, error });
    this.status.replaceChildren(...[...this.messages.values()].map((m) => {
      const d = this.xml3d.ownerDocument.createElement('div');
      d.textContent = m.text;
      if (m.error) d.className = 'tessera-error';
      return d;
    }));
  }

  reportErrors(errors) {
    for (const e of errors) {
      if (this.shownErrors.has(e.message)) continue;
      this.shownErrors.add(e.message);
      console.warn(`XML3D: ${e.message}`, e.element || '');
    }
    this.errors = errors.map((e) => e.message);
    const n = errors.length;
    this.setStatus('errors', n ? `⚠ ${n} problem${n > 1 ? 's' : ''} in the scene: ${errors.slice(0, 3).map((e) => e.message).join('; ')}${n > 3 ? ' …' : ''}` : null, true);
  }

  // Valid XML3D that is not supported (Xflow): one console warning each, naming the element;
  // no status line, as nothing in the markup is wrong.
  reportWarnings(warnings = []) {
    for (const w of warnings) {
      const key = `warning:${w.message}`;
      if (this.shownErrors.has(key)) continue;
      this.shownErrors.add(key);
      console.warn(`XML3D: ${w.message}`, w.element || '');
    }
    this.warnings = warnings.map((w) => w.message);
  }

  frame() {
    const t0 = performance.now();
    const scene = this.reader.read(this.xml3d);
    this.scene = scene;
    this.dirty = false;
    this.installElementApi(scene);
    this.reportErrors(scene.errors);
    this.reportWarnings(scene.warnings);
    this.setStatus('loading', scene.pending ? `loading ${scene.pending} resource${scene.pending > 1 ? 's' : ''}…` : null);
    this.backend.update(scene);
    const detail = this.backend.draw(scene, this.width, this.height);
    if (detail) this.frameDrawn({ ...detail, timeStart: t0 });
    this.preparePicking(scene);
  }

  // Every mousemove over a scene below MOUSEMOVE_PICK_LIMIT is picked (for the events on its
  // elements) before the camera controller sees it. The picking trees (scene/PickBvh.js) are
  // built in idle time once the scene has loaded, so that the first move does not wait for
  // them (the pavilion's: about 200 ms for all, 48 ms for those along one ray).
  preparePicking(scene) {
    this.pickScene = scene;
    const win = this.xml3d.ownerDocument.defaultView;
    if (this.pickPrep || scene.pending || !win.requestIdleCallback || scene.triangleCount() >= MOUSEMOVE_PICK_LIMIT) return;
    const step = (deadline) => {
      this.pickPrep = null;
      if (this.disposed) return;
      const left = unbuiltPickTrees(this.pickScene);
      while (left.length && deadline.timeRemaining() > 0) left.pop().build();
      if (left.length) this.pickPrep = win.requestIdleCallback(step);
    };
    this.pickPrep = win.requestIdleCallback(step);
  }

  // Called by backends when a frame is on screen.
  frameDrawn(detail) {
    this.xml3d.dispatchEvent(new CustomEvent('framedrawn', { detail }));
    this.sceneShown();
  }

  // XML3D's load event: once, when a frame shows the scene with every resource loaded. A
  // remote backend also calls this when the node has answered everything it was sent and that
  // frame is on screen: a frame can come before the page is read again with its last resource
  // in, and no change (so no frame) may follow.
  sceneShown() {
    if (!this.complete && !this.dirty && this.scene && this.scene.pending === 0 && this.resources.pending === 0) {
      this.complete = true;
      this.xml3d.dispatchEvent(new Event('load'));
    }
  }

  // The scene description with every DOM change made so far: pending mutation records are
  // taken and the page is read again now (the next frame draws it), so that the element API
  // answers for what a script has just written (XML3D.flushDOMChanges()).
  sceneNow() {
    if (this.disposed) return this.scene;
    const pending = this.observer.takeRecords().some((r) => !(r.type === 'attributes' && r.target === this.xml3d && r.attributeName === 'class'));
    if (pending || this.dirty || !this.scene) {
      this.scene = this.reader.read(this.xml3d);
      this.dirty = false;
      this.invalidate();
    }
    return this.scene;
  }

  // ---- API on the xml3d element (XML3D 5) ----------------------------------------------
  // Matrices, bounding boxes and <transform> properties: src/api/ElementApi.js.
  installApi() {
    const x = this.xml3d, h = this;
    installElementApi(x.ownerDocument.defaultView);
    ensureElementApi(x);
    Object.defineProperty(x, 'complete', { configurable: true, get: () => h.complete });
    x.getElementByPoint = (px, py, hitPoint, hitNormal) => h.getElementByPoint(px, py, hitPoint, hitNormal);
    x.getElementByRay = (ray, hitPoint, hitNormal) => h.getElementByRay(ray, hitPoint, hitNormal);
    x.generateRay = (px, py) => {
      const r = h.rayAt(px, py, h.sceneNow());
      return r ? new Ray(vec(r.origin), vec(r.direction)) : new Ray();
    };
    x.getRenderInterface = () => ({ handler: h, backend: h.backend });
    // As xml3d.js: the hidden element's size and position are those of what is drawn in its place.
    x.getBoundingClientRect = () => h.container.getBoundingClientRect();
    x.getClientRects = () => h.container.getClientRects();
    for (const k of ['clientWidth', 'clientHeight', 'clientLeft', 'clientTop', 'offsetWidth', 'offsetHeight', 'offsetLeft', 'offsetTop', 'offsetParent'])
      Object.defineProperty(x, k, { configurable: true, get: () => h.container[k] });
    x.tessera = this;
  }

  // Elements that are not HTMLUnknownElements (XHTML namespace) get the element API one by one.
  installElementApi(scene) {
    const win = this.xml3d.ownerDocument.defaultView;
    if (!(win && win.HTMLUnknownElement && this.xml3d instanceof win.HTMLUnknownElement)) {
      for (const m of scene.meshes.values()) {
        ensureElementApi(m.element);
        for (let p = m.element.parentElement; p && p !== this.xml3d; p = p.parentElement) ensureElementApi(p);
      }
      for (const el of this.xml3d.querySelectorAll('transform,view,light,group,mesh,model,data')) ensureElementApi(el);
    }
    for (const v of this.xml3d.querySelectorAll('float,float2,float3,float4,float4x4,int,int4,bool,string')) {
      if (!v.setScriptValue && isValueElement(v)) v.setScriptValue = (value) => setScriptValue(v, value);
    }
  }

  // Page coordinates (as xml3d.js) to a world ray through that pixel.
  rayAt(px, py, scene = this.scene) {
    if (!scene) return null;
    const win = this.xml3d.ownerDocument.defaultView;
    const r = this.container.getBoundingClientRect();
    const x = px - (r.left + win.scrollX), y = py - (r.top + win.scrollY);
    return generateRay(scene.camera, x, y, this.width, this.height);
  }

  pickAt(px, py, scene = this.scene) {
    const ray = this.rayAt(px, py, scene);
    return ray ? pick(scene, ray) : null;
  }

  // XML3D.Ray (or {origin, direction} with x/y/z or arrays) to the first element it hits.
  getElementByRay(ray, hitPoint, hitNormal) {
    const xyz = (v) => (v && v.data ? Array.from(v.data).slice(0, 3) : Array.isArray(v) ? v : v ? [v.x, v.y, v.z] : null);
    const origin = ray && xyz(ray.origin), dir = ray && xyz(ray.direction);
    let hit = null;
    if (origin && dir && dir.every(Number.isFinite) && Math.hypot(...dir) > 0) {
      const l = Math.hypot(...dir);
      hit = pick(this.sceneNow(), { origin, direction: dir.map((d) => d / l) });
    }
    fill(hitPoint, hit && hit.point);
    fill(hitNormal, hit && hit.normal);
    return hit ? hit.element : null;
  }

  getElementByPoint(px, py, hitPoint, hitNormal) {
    const hit = this.pickAt(px, py, this.sceneNow());
    fill(hitPoint, hit && hit.point);
    fill(hitNormal, hit && hit.normal);
    return hit ? hit.element : null;
  }

  // Mouse events are re-dispatched on the picked mesh or model and bubble up to xml3d.
  installEvents() {
    const el = this.inputElement, win = this.xml3d.ownerDocument.defaultView;
    let hovered = null;
    const redispatch = (e, type, target, hit) => {
      const ev = new win.MouseEvent(type, e);
      if (hit) { ev.position = vec(hit.point); ev.normal = vec(hit.normal); }
      target.dispatchEvent(ev);
    };
    const handle = (e) => {
      const hit = this.pickAt(e.pageX, e.pageY);
      const target = hit ? hit.element : this.xml3d;
      if (e.type === 'mousemove') {
        if (target !== hovered) {
          if (hovered) redispatch(e, 'mouseout', hovered, null);
          hovered = target;
          redispatch(e, 'mouseover', target, hit);
        }
      }
      redispatch(e, e.type, target, hit);
    };
    for (const type of ['click', 'dblclick', 'mousedown', 'mouseup']) el.addEventListener(type, handle);
    el.addEventListener('mousemove', (e) => {
      if (this.scene && this.scene.triangleCount() < MOUSEMOVE_PICK_LIMIT) handle(e);
    });
  }

  dispose() {
    this.disposed = true;
    if (this.pickPrep) this.xml3d.ownerDocument.defaultView.cancelIdleCallback(this.pickPrep);
    this.observer.disconnect();
    if (this.controller) this.controller.detach();
    this.xml3d.ownerDocument.defaultView.removeEventListener('resize', this.onResize);
    this.backend.dispose();
    this.container.remove();
    this.xml3d.classList.remove('tessera-hidden');
  }
}
