// A simple examine / fly camera for XML3D views (our own; xml3d.js's StandardCamera is GPL).
// Like StandardCamera it drives the view through a <transform> element, creating one (and a
// view, if the page has none) when needed. Examine: left drag orbits the examine point (centre
// of the scene's bounding box), right drag or wheel dollies, middle drag pans. Fly: left drag
// looks around, W/S/A/D move (always on in fly mode, unless useKeys is false).
// XML3D.StandardCamera (src/api/StandardCamera.js) drives a given <view> through this class.
import * as M from '../math/Mat4.js';
import { worldBox, isEmpty } from '../scene/Bounds.js';
import { worldMatrixOf, parentWorldOf } from '../api/ElementApi.js';

let generated = 0;

export class CameraController {
  // view: the <view> to drive (default: the active view); examinePoint: [x, y, z] to orbit
  // (default: the centre of the scene's bounding box); useKeys: WASD (default: in fly mode).
  constructor(handler, { mode = 'examine', rotateSpeed = 3, zoomSpeed = 20, view = null, examinePoint = null, useKeys = null } = {}) {
    this.handler = handler;
    this.mode = mode;
    this.view = view;
    this.fixedExaminePoint = examinePoint;
    this.useKeys = useKeys ?? (mode === 'fly');
    this.rotateSpeed = rotateSpeed;
    this.zoomSpeed = zoomSpeed;
    this.drag = null;
    this.listeners = [];
  }

  on(target, type, fn, opts) {
    target.addEventListener(type, fn, opts);
    this.listeners.push(() => target.removeEventListener(type, fn, opts));
  }

  attach() {
    const el = this.handler.inputElement;
    this.on(el, 'mousedown', (e) => { this.drag = { x: e.clientX, y: e.clientY, button: e.button, moved: false }; });
    this.on(window, 'mouseup', () => { this.drag = null; });
    this.on(window, 'mousemove', (e) => this.move(e));
    this.on(el, 'wheel', (e) => { e.preventDefault(); this.dolly(Math.sign(e.deltaY) * 0.1); }, { passive: false });
    this.on(el, 'contextmenu', (e) => e.preventDefault());
    this.on(window, 'keydown', (e) => this.key(e));
    return this;
  }

  detach() {
    for (const off of this.listeners) off();
    this.listeners = [];
  }

  pose() {
    if (this.view) return worldMatrixOf(this.view);
    const scene = this.handler.scene;
    return scene && scene.camera ? new Float32Array(scene.camera.toWorld) : M.identity();
  }

  examinePoint() {
    if (this.fixedExaminePoint) return this.fixedExaminePoint;
    const box = worldBox(this.handler.scene);
    if (isEmpty(box)) return [0, 0, 0];
    return [0, 1, 2].map((k) => (box.min[k] + box.max[k]) / 2);
  }

  sceneSize() {
    const box = worldBox(this.handler.scene);
    return isEmpty(box) ? 10 : Math.hypot(box.max[0] - box.min[0], box.max[1] - box.min[1], box.max[2] - box.min[2]);
  }

  move(e) {
    if (!this.drag) return;
    const dx = e.clientX - this.drag.x, dy = e.clientY - this.drag.y;
    if (!dx && !dy) return;
    this.drag.x = e.clientX; this.drag.y = e.clientY;
    const h = this.handler.height || 600;
    const m = this.pose();
    const eye = [m[12], m[13], m[14]];
    if (this.drag.button === 0) {
      const yaw = -dx / h * this.rotateSpeed, pitch = -dy / h * this.rotateSpeed;
      const right = M.normalize([m[0], m[1], m[2]]);
      const rot = M.multiply(M.axisAngle(0, 1, 0, yaw), M.axisAngle(...right, pitch));
      if (this.mode === 'examine') {
        const c = this.examinePoint();
        const t = M.multiplyAll(M.translation(...c), rot, M.translation(-c[0], -c[1], -c[2]));
        this.write(M.multiply(t, m));
      } else {
        const r = M.multiply(rot, m);
        r[12] = eye[0]; r[13] = eye[1]; r[14] = eye[2];
        this.write(r);
      }
    } else if (this.drag.button === 2) {
      this.dolly(dy / h);
    } else {
      const s = this.sceneSize() / h;
      const t = M.transformDirection(m, [-dx * s, dy * s, 0]);
      m[12] += t[0]; m[13] += t[1]; m[14] += t[2];
      this.write(m);
    }
  }

  dolly(amount) {
    const m = this.pose();
    const d = this.sceneSize() * amount * this.zoomSpeed / 20;
    const fwd = M.transformDirection(m, [0, 0, 1]);
    m[12] += fwd[0] * d; m[13] += fwd[1] * d; m[14] += fwd[2] * d;
    this.write(m);
  }

  key(e) {
    if (!this.useKeys) return;
    const step = this.sceneSize() * 0.01;
    const dir = { w: [0, 0, -1], s: [0, 0, 1], a: [-1, 0, 0], d: [1, 0, 0] }[e.key && e.key.toLowerCase()];
    if (!dir) return;
    const m = this.pose();
    const t = M.transformDirection(m, dir);
    m[12] += t[0] * step; m[13] += t[1] * step; m[14] += t[2] * step;
    this.write(m);
  }

  // Writes a camera-to-world matrix into the view's <transform> (translation + axis-angle).
  // The matrix is taken into the space of the view's parent.
  write(m) {
    const xml3d = this.handler.xml3d, doc = xml3d.ownerDocument;
    let view = this.view || (this.handler.scene && this.handler.scene.camera && this.handler.scene.camera.element);
    if (!view) {
      view = doc.createElement('view');
      view.id = `Generated_View_${++generated}`;
      xml3d.appendChild(view);
      xml3d.setAttribute('view', `#${view.id}`);
    }
    let t = null;
    const ref = view.getAttribute('transform');
    if (ref && ref.startsWith('#')) t = doc.getElementById(ref.slice(1));
    if (!t || t.localName !== 'transform') {
      t = doc.createElement('transform');
      t.id = `${view.id || 'view'}_transform_${++generated}`;
      xml3d.appendChild(t);
      view.setAttribute('transform', `#${t.id}`);
      if (view.style) view.style.transform = '';
    }
    const parent = M.invert(parentWorldOf(view));
    if (parent) m = M.multiply(parent, m);
    // An XML3D 4.x pose (position, orientation) is now part of the <transform>.
    view.removeAttribute('position');
    view.removeAttribute('orientation');
    const aa = M.toAxisAngle(m);
    t.setAttribute('translation', `${m[12]} ${m[13]} ${m[14]}`);
    t.setAttribute('rotation', aa.join(' '));
  }
}
