// Tessera's XML3D client. Import this module on a page: every <xml3d> element is rendered
// locally with WebGL (three.js), or, with server="host:port", by a Tessera node. It also
// installs window.XML3D (src/api/), the namespace xml3d.js pages script against.
//   <script type="module" src="/src/xml3d.js"></script>
import { XML3DHandler } from './ui/XML3DHandler.js';
import { WebGLBackend } from './render/WebGLBackend.js';
import { RemoteBackend } from './net/RemoteBackend.js';
import { installGlobal } from './api/XML3DGlobal.js';

export const version = '0.1.0-tessera';
const handlers = new Map();

function backendFor(xml3d) {
  return xml3d.hasAttribute('server') && xml3d.getAttribute('server')
    ? (h) => new RemoteBackend(h, xml3d.getAttribute('server'))
    : (h) => new WebGLBackend(h);
}

export function configure(xml3d) {
  if (handlers.has(xml3d)) return handlers.get(xml3d);
  let h;
  try {
    h = new XML3DHandler(xml3d, backendFor(xml3d));
  } catch (e) {
    console.error('XML3D: could not configure <xml3d>', e);
    const ev = new Event('unsupported', { cancelable: true });
    if (xml3d.dispatchEvent(ev)) {
      const d = xml3d.ownerDocument.createElement('div');
      d.style.cssText = 'color:#fff;background:#a00;padding:8px;font:14px sans-serif';
      d.textContent = `This 3D scene cannot be shown: ${e.message}`;
      xml3d.parentNode.insertBefore(d, xml3d);
    }
    return null;
  }
  handlers.set(xml3d, h);
  return h;
}

// Re-creates the handler (e.g. after the server attribute changed).
export function reconfigure(xml3d) {
  const h = handlers.get(xml3d);
  if (h) { h.dispose(); handlers.delete(xml3d); }
  return configure(xml3d);
}

function scan(root) {
  for (const x of root.querySelectorAll('xml3d')) configure(x);
}

function start() {
  scan(document);
  new MutationObserver((records) => {
    for (const r of records) {
      for (const n of r.addedNodes) if (n.nodeType === 1) {
        if (n.localName === 'xml3d') configure(n); else if (n.querySelectorAll) scan(n);
      }
      for (const n of r.removedNodes) if (n.nodeType === 1) {
        for (const [x, h] of handlers) if (!x.isConnected) { h.dispose(); handlers.delete(x); }
      }
      if (r.type === 'attributes' && r.target.localName === 'xml3d' && handlers.has(r.target)) reconfigure(r.target);
    }
  }).observe(document.documentElement, { childList: true, subtree: true, attributes: true, attributeFilter: ['server', 'renderer', 'display', 'nodes', 'token'] });
}

if (typeof window !== 'undefined') installGlobal(window, { version, handlers: () => [...handlers.values()] });

// Configuration starts at DOMContentLoaded, as xml3d.js's does: a module script of the parser
// runs before that event but after parsing ('interactive'), so starting at once would read the
// scene, and fire its load event, before the page's module scripts after ours had defined
// what the page's onload names. Once that event has begun (this module appended or imported
// later), or where the navigation entry does not say, it starts at once.
function contentLoaded() {
  if (document.readyState === 'loading') return false;
  if (document.readyState === 'complete') return true;
  const nav = typeof performance !== 'undefined' && performance.getEntriesByType
    ? performance.getEntriesByType('navigation')[0] : undefined;
  return !nav || nav.domContentLoadedEventStart > 0;
}

if (typeof document !== 'undefined') {
  if (contentLoaded()) start(); else document.addEventListener('DOMContentLoaded', start, { once: true });
}

export { XML3DHandler };
