// The WebGL fallback: draws a SceneDescription with three.js. Entries are synced by id, so a
// re-read page only touches what changed.
import * as THREE from './three.js';
import { createLightUniforms, updateLightUniforms, createMaterial } from './XML3DMaterial.js';
import { clippingPlanes } from '../scene/Bounds.js';

export class ThreeRenderer {
  constructor(canvas, { onError = () => {}, onTextureLoad = () => {} } = {}) {
    this.canvas = canvas;
    this.onError = onError;
    this.onTextureLoad = onTextureLoad;
    // XML3D context: alpha, non-premultiplied, antialias, preserveDrawingBuffer (for picking/screenshots).
    this.renderer = new THREE.WebGLRenderer({ canvas, alpha: true, antialias: true, premultipliedAlpha: false, preserveDrawingBuffer: true });
    this.renderer.setClearColor(0x000000, 0);
    this.renderer.outputColorSpace = THREE.LinearSRGBColorSpace;  // XML3D: colours written as given
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera();
    this.camera.matrixAutoUpdate = false;
    this.lightUniforms = createLightUniforms();
    this.counts = { point: 0, directional: 0, spot: 0 };
    this.attributes = new Map();  // buffer id -> {data, attr}
    this.geometries = new Map();  // key -> BufferGeometry
    this.materials = new Map();   // key -> ShaderMaterial
    this.textures = new Map();    // texture id -> THREE.Texture
    this.objects = new Map();     // mesh id -> THREE.Mesh
  }

  static isSupported(canvas) {
    try { return !!(canvas.getContext('webgl2')); } catch { return false; }
  }

  texture(desc) {
    let t = this.textures.get(desc.id);
    if (t) return t;
    t = new THREE.Texture();
    t.flipY = desc.flipY;
    t.wrapS = desc.wrapS === 'repeat' ? THREE.RepeatWrapping : THREE.ClampToEdgeWrapping;
    t.wrapT = desc.wrapT === 'repeat' ? THREE.RepeatWrapping : THREE.ClampToEdgeWrapping;
    t.magFilter = desc.filter === 'nearest' ? THREE.NearestFilter : THREE.LinearFilter;
    t.minFilter = desc.filter === 'nearest' ? THREE.NearestFilter : THREE.LinearMipmapLinearFilter;
    t.colorSpace = THREE.NoColorSpace;
    const img = new Image();
    img.crossOrigin = 'anonymous';
    img.onload = () => { t.image = img; t.needsUpdate = true; this.onTextureLoad(); };
    img.onerror = () => this.onError(null, `texture ${desc.url} could not be loaded`);
    img.src = desc.url;
    this.textures.set(desc.id, t);
    return t;
  }

  attribute(scene, id) {
    const b = scene.buffers.get(id);
    let e = this.attributes.get(id);
    if (e && e.data === b.data) return e.attr;
    const attr = new THREE.BufferAttribute(b.data, b.components);
    this.attributes.set(id, { data: b.data, attr });
    return attr;
  }

  geometry(scene, m) {
    const key = `${m.positions}/${m.normals}/${m.texcoords}/${m.colors}/${m.indices}`;
    let g = this.geometries.get(key);
    if (g && g.userData.positions === scene.buffers.get(m.positions).data) return g;
    g = new THREE.BufferGeometry();
    g.userData.positions = scene.buffers.get(m.positions).data;
    g.setAttribute('position', this.attribute(scene, m.positions));
    if (m.indices) g.setIndex(this.attribute(scene, m.indices));
    if (m.normals) g.setAttribute('normal', this.attribute(scene, m.normals));
    else g.computeVertexNormals();
    if (m.texcoords) g.setAttribute('uv', this.attribute(scene, m.texcoords));
    if (m.colors) g.setAttribute('color', this.attribute(scene, m.colors));
    this.geometries.set(key, g);
    return g;
  }

  material(scene, m) {
    const d = scene.materials.get(m.material);
    const flags = { uv: !!m.texcoords, color: !!m.colors };
    const c = this.counts;
    const key = `${m.material}/${flags.uv}/${flags.color}/${c.point}/${c.directional}/${c.spot}`;
    let mat = this.materials.get(key);
    if (!mat) {
      mat = createMaterial(d, (id) => this.texture(scene.textures.get(id)), this.lightUniforms, c, flags);
      this.materials.set(key, mat);
    }
    return mat;
  }

  // Syncs three's scene with the description.
  update(scene) {
    this.desc = scene;
    this.counts = updateLightUniforms(this.lightUniforms, scene.lights.values(), scene.environment.ambient);
    for (const [id, o] of this.objects)
      if (!scene.meshes.has(id)) { this.scene.remove(o); this.objects.delete(id); }
    for (const m of scene.meshes.values()) {
      let o = this.objects.get(m.id);
      const g = this.geometry(scene, m), mat = this.material(scene, m);
      if (!o) {
        o = new THREE.Mesh(g, mat);
        o.matrixAutoUpdate = false;
        this.objects.set(m.id, o);
        this.scene.add(o);
      }
      o.geometry = g;
      o.material = mat;
      o.visible = m.visible;
      o.matrix.fromArray(m.transform);
      o.matrixWorldNeedsUpdate = true;
      o.userData.element = m.element;
    }
    // Drop cached materials/geometries nothing uses any more.
    const used = new Set([...this.objects.values()].flatMap((o) => [o.material, o.geometry]));
    for (const [k, v] of this.materials) if (!used.has(v)) { v.dispose(); this.materials.delete(k); }
    for (const [k, v] of this.geometries) if (!used.has(v)) { v.dispose(); this.geometries.delete(k); }
  }

  setSize(w, h) {
    if (this.canvas.width !== w || this.canvas.height !== h) this.renderer.setSize(w, h, false);
  }

  // Camera from the description; near/far from the scene bounding box when not given.
  updateCamera(desc, w, h) {
    const cam = desc.camera, c = this.camera;
    const aspect = w / h;
    c.aspect = aspect;
    const fovY = cam.fovX ? 2 * Math.atan(Math.tan(cam.fovX / 2) / aspect) : cam.fovY;
    c.fov = fovY * 180 / Math.PI;
    const { near, far } = clippingPlanes(desc, cam.toWorld, cam.near, cam.far);
    c.near = near; c.far = far;
    c.updateProjectionMatrix();
    c.matrix.fromArray(cam.toWorld);
    c.matrixWorld.copy(c.matrix);
    c.matrixWorldInverse.copy(c.matrixWorld).invert();
  }

  render(desc, w, h) {
    this.setSize(w, h);
    this.updateCamera(desc, w, h);
    const t0 = performance.now();
    this.renderer.render(this.scene, this.camera);
    const info = this.renderer.info.render;
    return { timeStart: t0, timeEnd: performance.now(), renderTimeInMilliseconds: performance.now() - t0,
      count: { objects: info.calls, primitives: info.triangles } };
  }

  dispose() {
    for (const g of this.geometries.values()) g.dispose();
    for (const m of this.materials.values()) m.dispose();
    for (const t of this.textures.values()) t.dispose();
    this.renderer.dispose();
  }
}
