// Local rendering backend: a WebGL canvas drawn by ThreeRenderer.
import { ThreeRenderer } from './ThreeRenderer.js';

export class WebGLBackend {
  constructor(handler) {
    const doc = handler.container.ownerDocument;
    this.handler = handler;
    this.element = doc.createElement('canvas');
    this.element.className = '_xml3d tessera-webgl';
    handler.container.appendChild(this.element);
    this.renderer = new ThreeRenderer(this.element, {
      onError: (el, msg) => handler.setStatus(`tex:${msg}`, `⚠ ${msg}`, true),
      onTextureLoad: () => handler.invalidate(),
    });
  }
  update(scene) { this.renderer.update(scene); }
  draw(scene, w, h) { return this.renderer.render(scene, w, h); }
  dispose() { this.renderer.dispose(); this.element.remove(); }
}
