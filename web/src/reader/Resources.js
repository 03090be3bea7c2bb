// External resources referenced by the markup: XML3D JSON meshes ("xml3d-json"), glTF 2.0
// files (<model src>) and XML resource documents (file.xml#id). Each URL (without fragment)
// is fetched once; get() answers at once with the state, and onLoad is called when a
// pending resource settles so the page can be read again.
import { parseXml3dJson } from './JsonMesh.js';
import { loadGltf } from './GltfLoader.js';

// What every Resources of the page loaded or is loading, by fetch function, kind and URL: a
// handler that is rebuilt (an <xml3d> whose server attribute changes, say) or a second <xml3d>
// of the same scene does not fetch and parse the files again. A failed load is forgotten.
const SHARED = new WeakMap();  // fetch function -> Map(`${kind} ${url}` -> Promise of the data)
const DOCUMENT_URLS = new WeakMap();  // XML documents loaded -> their URLs

export class Resources {
  // deferBuffers: glTF files come as soon as their JSON is read, their buffers filled in later
  // (GltfLoader.js, "Deferred loads"): for a backend whose node loads the buffers itself. Set it
  // before the first get(). Such an entry is 'loaded' with its data, and `filling` until the
  // values are in; onLoad is called again then (or the entry turns to 'error').
  constructor({ fetch: fetchFn, parseXml, onLoad, deferBuffers = false } = {}) {
    this.deferBuffers = deferBuffers;
    // Deferred loads start their buffer downloads when this promise settles (null: at once): the
    // remote backend opens it once the node has answered the references, so that the download
    // does not compete with the scene's way to the node for the page's CPU and the node's.
    this.downloadGate = null;
    const base = fetchFn || globalThis.fetch;
    this.fetch = fetchFn || globalThis.fetch?.bind(globalThis);
    if (base && !SHARED.has(base)) SHARED.set(base, new Map());
    this.shared = base ? SHARED.get(base) : new Map();
    this.parseXml = parseXml || ((text) => new DOMParser().parseFromString(text, 'text/xml'));
    this.onLoad = onLoad || (() => {});
    this.entries = new Map();
  }

  static kindOf(url) {
    const path = url.split('#')[0].split('?')[0].toLowerCase();
    if (path.endsWith('.gltf') || path.endsWith('.glb')) return 'gltf';
    if (path.endsWith('.json')) return 'json';
    return 'xml';
  }

  // Returns {state: 'loading'|'loaded'|'error', data, error}.
  get(url, kind = Resources.kindOf(url)) {
    const key = url.split('#')[0];
    let e = this.entries.get(key);
    if (e) return e;
    e = { state: 'loading', kind, data: null, error: null, filling: false };
    this.entries.set(key, e);
    const defer = kind === 'gltf' && this.deferBuffers;
    const k = `${kind}${defer ? '+deferred' : ''} ${key}`;
    if (!this.shared.has(k)) this.shared.set(k, this.load(key, kind, defer).catch((err) => { this.shared.delete(k); throw err; }));
    const failed = (err) => {
      e.state = 'error';
      e.data = null;
      e.filling = false;
      e.error = `${key}: ${err.message || err}`;
    };
    this.shared.get(k).then((data) => {
      e.state = 'loaded';
      e.data = data;
      if (data && data.ready) {
        e.filling = true;
        data.ready.then(() => { e.filling = false; }, (err) => { this.shared.delete(k); failed(err); }).then(() => this.onLoad(key, e));
      }
    }, failed).then(() => this.onLoad(key, e));
    return e;
  }

  // Entries still loading, or whose values are still on their way (a deferred glTF).
  get pending() {
    let n = 0;
    for (const e of this.entries.values()) if (e.state === 'loading' || e.filling) n++;
    return n;
  }

  async fetchOk(url) {
    if (!this.fetch) throw new Error('no fetch available');
    const r = await this.fetch(url);
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    return r;
  }

  async load(url, kind, defer = false) {
    const r = await this.fetchOk(url);
    if (kind === 'json') return parseXml3dJson(await r.json(), url, (u) => this.fetchOk(u).then((x) => x.arrayBuffer()));
    if (kind === 'gltf') {
      const isGlb = url.toLowerCase().split('?')[0].endsWith('.glb');
      const body = isGlb ? await r.arrayBuffer() : await r.json();
      return loadGltf(body, url, (u) => this.binary(u, defer ? this.downloadGate : null), { defer });
    }
    const doc = this.parseXml(await r.text());
    if (!doc || !doc.documentElement || doc.getElementsByTagName('parsererror').length)
      throw new Error('not a well-formed XML document');
    DOCUMENT_URLS.set(doc, url);
    return doc;
  }

  // A file's bytes. Downloads in flight are shared: a deferred and a whole load of one glTF
  // (a handler rebuilt for the server while the WebGL one loads, say) fetch its buffers once.
  // Only while in flight, so that the page does not keep the bytes of every file it loaded.
  binary(url, gate = null) {
    const k = `binary ${url}`;
    if (!this.shared.has(k)) {
      const start = () => this.fetchOk(url).then((x) => x.arrayBuffer());
      const p = gate ? gate.then(start, start) : start();
      this.shared.set(k, p);
      p.then(() => this.shared.delete(k), () => this.shared.delete(k));
    }
    return this.shared.get(k);
  }

  urlOfDocument(doc) {
    return DOCUMENT_URLS.get(doc);
  }
}
