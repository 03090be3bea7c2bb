// Every link on the demo pages resolves when a Tessera node serves web/ (issue 20 item 11):
// the node answers "/" with web/demo/index.html (there is no web/index.html), so that page's
// relative links pointed at /basic.html and /demo.css, which are 404. The public part of the
// web root is what net/http.cpp's public_path allows (docs/operations.md, "Static files").
import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { parseHTML } from 'linkedom';

const web = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../../..');
const PUBLIC = ['src/', 'demo/', 'node_modules/three/build/'];
const ORIGIN = 'http://node.test:8080';

// The web-root file a same-origin URL is served from, or null (404). /scenes/ is the scenes
// root, not the web root; it is checked by prefix only.
function served(url) {
  const u = new URL(url);
  if (u.origin !== ORIGIN) return 'external';
  let rel = decodeURIComponent(u.pathname).replace(/^\/+/, '');
  if (rel.startsWith('scenes/')) return 'scenes';
  if (rel === '' || rel.endsWith('/')) rel += 'index.html';
  if (rel === 'index.html' && !fs.existsSync(path.join(web, rel))) rel = 'demo/index.html';  // net/server.cpp
  const isPublic = rel === 'index.html' || PUBLIC.some((p) => rel.startsWith(p) && rel.length > p.length);
  if (!isPublic || rel.split('/').some((s) => s.startsWith('.'))) return null;
  const file = path.join(web, rel);
  return fs.existsSync(file) && fs.statSync(file).isFile() ? file : null;
}

function links(file) {
  const { document } = parseHTML(fs.readFileSync(file, 'utf8'));
  const out = [];
  for (const el of document.querySelectorAll('a[href], link[href]')) out.push(el.getAttribute('href'));
  for (const el of document.querySelectorAll('script[src], img[src], model[src], mesh[src], data[src]')) out.push(el.getAttribute('src'));
  return out.filter((l) => !l.startsWith('#'));
}

const pages = fs.readdirSync(path.join(web, 'demo')).filter((f) => f.endsWith('.html'));
// Where the node serves each page: the index also at "/" and "/demo/".
const urlsOf = (f) => (f === 'index.html' ? ['/', '/demo/', '/demo/index.html'] : [`/demo/${f}`]);

for (const f of pages) {
  test(`demo/${f}: every link resolves from ${urlsOf(f).join(', ')}`, () => {
    const ls = links(path.join(web, 'demo', f));
    assert.ok(ls.length > 0);
    for (const at of urlsOf(f)) {
      assert.ok(served(ORIGIN + at), `${at} itself is served`);
      for (const l of ls) assert.ok(served(new URL(l, ORIGIN + at).href), `${l} on ${at} is 404 on a node`);
    }
  });
}

test('the root page is the demo index and links every demo page', () => {
  assert.equal(served(`${ORIGIN}/`), path.join(web, 'demo', 'index.html'));
  const ls = links(path.join(web, 'demo', 'index.html')).map((l) => new URL(l, `${ORIGIN}/`).pathname);
  for (const f of pages.filter((p) => p !== 'index.html')) assert.ok(ls.includes(`/demo/${f}`), `${f} is linked`);
});

test('over HTTP (tools/static-server.js, same "/" rule as the node): the root page and its links answer 200', async () => {
  const { startStaticServer } = await import('../../../tools/static-server.js');
  const server = await startStaticServer();
  const base = `http://127.0.0.1:${server.address().port}`;
  try {
    const root = await fetch(`${base}/`);
    assert.equal(root.status, 200);
    const { document } = parseHTML(await root.text());
    const urls = [...document.querySelectorAll('a[href], link[href]')].map((a) => new URL(a.getAttribute('href'), `${base}/`).href);
    assert.ok(urls.length >= 5);
    for (const u of urls) assert.equal((await fetch(u)).status, 200, u);
  } finally { server.close(); }
});
