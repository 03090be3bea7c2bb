// A tiny static file server for tests and local demos: web/ at /, and (when it exists)
// the shared scenes at /scenes/ — the same URL layout the Tessera node serves.
//   node tools/static-server.js [port] [scenes-dir]
import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const TYPES = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.json': 'application/json',
  '.gltf': 'model/gltf+json', '.bin': 'application/octet-stream', '.png': 'image/png', '.jpg': 'image/jpeg',
  '.jpeg': 'image/jpeg', '.xml': 'application/xml', '.xhtml': 'application/xhtml+xml', '.css': 'text/css', '.svg': 'image/svg+xml' };

export const WEB_ROOT = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..');

export function startStaticServer({ port = 0, root = WEB_ROOT, scenes = path.resolve(WEB_ROOT, '../../shared/scenes') } = {}) {
  const server = http.createServer((req, res) => {
    let p = decodeURIComponent(new URL(req.url, 'http://x').pathname);
    let base = root;
    if (p.startsWith('/scenes/')) { base = scenes; p = p.slice('/scenes'.length); }
    // As net/server.cpp: "/" is web/index.html, else web/demo/index.html.
    else if (p === '/' && !fs.existsSync(path.join(root, 'index.html'))) p = '/demo/index.html';
    const file = path.join(base, path.normalize(p).replace(/^(\.\.[/\\])+/, ''));
    if (!file.startsWith(base)) { res.writeHead(403).end(); return; }
    fs.stat(file, (err, st) => {
      let f = file;
      if (!err && st.isDirectory()) f = path.join(file, 'index.html');
      fs.readFile(f, (e, data) => {
        if (e) { res.writeHead(404, { 'content-type': 'text/plain' }).end('not found'); return; }
        res.writeHead(200, { 'content-type': TYPES[path.extname(f).toLowerCase()] || 'application/octet-stream' });
        res.end(data);
      });
    });
  });
  return new Promise((resolve) => server.listen(port, '127.0.0.1', () => resolve(server)));
}

if (process.argv[1] === fileURLToPath(import.meta.url)) {
  const port = Number(process.argv[2] || 8080);
  startStaticServer({ port, scenes: process.argv[3] ? path.resolve(process.argv[3]) : undefined })
    .then(() => console.log(`serving ${WEB_ROOT} at http://127.0.0.1:${port}/`));
}
