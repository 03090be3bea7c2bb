// XML3D.StandardCamera: the camera controller xml3d.js pages create with
//   new XML3D.StandardCamera(viewElement, {mode: "examine"|"fly", examinePoint, rotateSpeed: 3,
//                                          zoomSpeed: 20, useKeys: false})
// Our own implementation of the documented behaviour (docs: ../shared/XML3D.md §4; xml3d.js's
// tools/camera.js is GPL and was not read): it drives the view through a <transform> element
// (created when the view has none), left drag rotates (examine: around the examine point; fly:
// looks around), middle drag pans, right drag and the wheel dolly, W/S/A/D move when useKeys is
// set. Creating one replaces the <xml3d>'s built-in controller (controller attribute).
// Methods: translate(Vec3), rotate(Quat), lookAt(point), examine(element), setExaminePoint(p),
// attach(), detach(); properties position (Vec3) and orientation (Quat), readable and writable.
import * as M from '../math/Mat4.js';
import { Vec3, Quat, AxisAngle, Mat4 } from './MathTypes.js';
import { warnOnce } from './Debug.js';
import { handlerOf, worldMatrixOf } from './ElementApi.js';
import { CameraController } from '../ui/CameraController.js';

const xyz = (v) => (v && v.data ? Array.from(v.data).slice(0, 3) : Array.isArray(v) ? v.slice(0, 3) : v ? [v.x, v.y, v.z] : null);

export class StandardCamera {
  constructor(element, opts = {}) {
    this.element = element;
    this.mode = opts.mode === 'fly' ? 'fly' : 'examine';
    this.rotateSpeed = opts.rotateSpeed ?? 3;
    this.zoomSpeed = opts.zoomSpeed ?? 20;
    this.useKeys = !!opts.useKeys;
    this.examinePointValue = opts.examinePoint ? xyz(opts.examinePoint) : null;
    if (opts.touchTranslateMode) warnOnce('touchTranslateMode', 'StandardCamera option touchTranslateMode is ignored (no touch navigation)');
    this.controller = null;
    if (!element || element.localName !== 'view') warnOnce('StandardCamera-view', 'XML3D.StandardCamera needs a <view> element; the camera does nothing');
    else this.attach();
  }

  get handler() { return this.element ? handlerOf(this.element) : null; }

  /** Starts listening to mouse (and key) input; replaces the <xml3d>'s built-in controller. */
  attach() {
    if (this.controller) return this;
    const h = this.handler;
    if (!h) {
      // The <xml3d> is configured when the library starts; a camera made earlier waits for it.
      const win = this.element.ownerDocument.defaultView;
      if (!this.waiting && win) {
        this.waiting = true;
        win.addEventListener('load', () => { this.waiting = false; if (this.handler) this.attach(); else warnOnce('StandardCamera-xml3d', 'XML3D.StandardCamera: the view is not inside a rendered <xml3d>'); }, { once: true });
      }
      return this;
    }
    if (h.controller) h.controller.detach();
    this.controller = new CameraController(h, { mode: this.mode, rotateSpeed: this.rotateSpeed, zoomSpeed: this.zoomSpeed,
      view: this.element, examinePoint: this.examinePointValue, useKeys: this.useKeys }).attach();
    h.controller = this.controller;
    return this;
  }

  detach() {
    if (this.controller) {
      this.controller.detach();
      const h = this.handler;
      if (h && h.controller === this.controller) h.controller = null;
      this.controller = null;
    }
    return this;
  }

  pose() { return worldMatrixOf(this.element); }
  write(m) {
    const c = this.controller || (this.handler && new CameraController(this.handler, { view: this.element }));
    if (c) c.write(m);
  }

  /** Camera position in world space. */
  get position() { const m = this.pose(); return new Vec3(m[12], m[13], m[14]); }
  set position(p) { const m = this.pose(), v = xyz(p); m[12] = v[0]; m[13] = v[1]; m[14] = v[2]; this.write(m); }
  /** Camera orientation in world space (the view looks down its -Z). */
  get orientation() { const aa = M.toAxisAngle(this.pose()); return Quat.fromAxisAngle(new AxisAngle(...aa)); }
  set orientation(q) {
    const m = Mat4.fromQuat(q).data, p = this.pose();
    m[12] = p[12]; m[13] = p[13]; m[14] = p[14];
    this.write(m);
  }

  /** Moves the camera by a vector given in the camera's own frame (0 0 -1 is forward). */
  translate(v) {
    const m = this.pose(), d = M.transformDirection(m, xyz(v));
    m[12] += d[0]; m[13] += d[1]; m[14] += d[2];
    this.write(m);
  }

  /** Turns the camera by a quaternion applied in its own frame (orientation · q). */
  rotate(q) { this.orientation = this.orientation.mul(q); }

  /** Turns the camera to look at a world-space point (world +Y up), keeping its position. */
  lookAt(point) {
    const m = this.pose();
    this.write(M.lookAt([m[12], m[13], m[14]], xyz(point)));
  }

  setExaminePoint(p) {
    this.examinePointValue = xyz(p);
    if (this.controller) this.controller.fixedExaminePoint = this.examinePointValue;
  }

  getExaminePoint() {
    return new Vec3(...(this.examinePointValue || (this.controller ? this.controller.examinePoint() : [0, 0, 0])));
  }

  /** Frames an element: its world bounding box's centre becomes the examine point and the camera
   * moves along its current viewing direction until the box fits the vertical field of view. */
  examine(element) {
    const box = element && element.getWorldBoundingBox ? element.getWorldBoundingBox() : null;
    if (!box || box.isEmpty()) { warnOnce('examine-empty', 'StandardCamera.examine(): the element has no bounding box'); return; }
    const c = box.center(), r = box.size().length() / 2;
    const h = this.handler, fov = (h && h.scene && h.scene.camera && h.scene.camera.fovY) || Math.PI / 4;
    const dist = r / Math.sin(fov / 2);
    const m = this.pose(), back = M.normalize(M.transformDirection(m, [0, 0, 1]));
    m[12] = c.x + back[0] * dist; m[13] = c.y + back[1] * dist; m[14] = c.z + back[2] * dist;
    this.setExaminePoint(c);
    this.write(m);
  }
}
