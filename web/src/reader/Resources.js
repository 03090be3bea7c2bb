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
  constructor({ fetch: fetchFn, parseXml, onLoad } = {}) {
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
    e = { state: 'loading', kind, data: null, error: null };
    this.entries.set(key, e);
    const k = `${kind} ${key}`;
    if (!this.shared.has(k)) this.shared.set(k, this.load(key, kind).catch((err) => { this.shared.delete(k); throw err; }));
    this.shared.get(k).then((data) => {
      e.state = 'loaded';
      e.data = data;
    }, (err) => {
      e.state = 'error';
      e.error = `${key}: ${err.message || err}`;
    }).then(() => this.onLoad(key, e));
    return e;
  }

  get pending() {
    let n = 0;
    for (const e of this.entries.values()) if (e.state === 'loading') n++;
    return n;
  }

  async fetchOk(url) {
    if (!this.fetch) throw new Error('no fetch available');
    const r = await this.fetch(url);
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    return r;
  }

  async load(url, kind) {
    const r = await this.fetchOk(url);
    if (kind === 'json') return parseXml3dJson(await r.json(), url, (u) => this.fetchOk(u).then((x) => x.arrayBuffer()));
    if (kind === 'gltf') {
      const isGlb = url.toLowerCase().split('?')[0].endsWith('.glb');
      const body = isGlb ? await r.arrayBuffer() : await r.json();
      return loadGltf(body, url, (u) => this.fetchOk(u).then((x) => x.arrayBuffer()));
    }
    const doc = this.parseXml(await r.text());
    if (!doc || !doc.documentElement || doc.getElementsByTagName('parsererror').length)
      throw new Error('not a well-formed XML document');
    DOCUMENT_URLS.set(doc, url);
    return doc;
  }

  urlOfDocument(doc) {
    return DOCUMENT_URLS.get(doc);
  }
}
