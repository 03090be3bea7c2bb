// The demo page over HTTPS and WSS in a real browser against a REAL Tessera node with a
// self-signed certificate (scripts/tls-cert.sh; chromium started with
// --ignore-certificate-errors, as for any self-signed node in a test): the page, its scripts
// and the scene come over HTTPS, the session over WSS (the page is https, so the client picks
// wss:// for a bare server="host:port"), and frames arrive for the JPEG and the MJPEG display
// (the <img> on https://.../mjpeg/). Plain http:// to the same port gets no page.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { launch, pollUntil } from './browser.js';
import { startNode, WEB } from '../../tools/tessera-node.js';

const BIN = process.env.TESSERA_BIN;
const skip = !BIN && 'TESSERA_BIN not set (CTest passes the tessera binary)';

let env, node, tmp;
before(async () => {
  if (!BIN) return;
  tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'tessera-tls-'));
  execFileSync(path.resolve(WEB, '../scripts/tls-cert.sh'), [tmp], { stdio: 'ignore' });
  node = await startNode(BIN, { threads: 2, args: ['--tessera.web-public=["test/browser/pages/"]',
    `--tessera.tls-cert=${path.join(tmp, 'node.crt')}`, `--tessera.tls-key=${path.join(tmp, 'node.key')}`] });
  env = await launch({ args: ['--ignore-certificate-errors'] });
});
after(async () => {
  if (env) await env.close();
  if (node) await node.close();
  if (tmp) fs.rmSync(tmp, { recursive: true, force: true });
});

const state = (page) => page.evaluate(() => ({
  connection: document.querySelector('.tessera-xml3d') && document.querySelector('.tessera-xml3d').dataset.connection,
  frames: (window.__frames || []).length,
  mjpeg: (() => { const img = document.querySelector('img.tessera-display'); return img ? { src: img.src, w: img.naturalWidth } : null; })(),
  protocol: location.protocol,
}));

const until = (page, pred, what, timeout) => pollUntil(page, state, pred, what, timeout);

test('the node serves https:// and wss:// only', { skip }, async () => {
  assert.equal(node.info.listening.slice(0, 8), 'https://');
  assert.equal(node.info.websocket.slice(0, 6), 'wss://');
  assert.equal(node.base.slice(0, 8), 'https://');
});

for (const display of ['jpeg', 'mjpeg']) {
  test(`the page over HTTPS gets ${display} frames over WSS`, { skip }, async () => {
    const page = await env.context.newPage();
    page.logs = [];
    page.on('console', (m) => page.logs.push(`${m.type()}: ${m.text()}`));
    const sockets = [];
    page.on('websocket', (ws) => sockets.push(ws.url()));
    await page.goto(`${node.base}/test/browser/pages/node.html?server=${node.host}:${node.port}&display=${display}`);
    const st = display === 'jpeg'
      ? await until(page, (s) => s.frames > 0, 'JPEG frames over WSS')
      : await until(page, (s) => s.mjpeg && s.mjpeg.w > 0, 'an MJPEG frame over HTTPS');
    assert.equal(st.protocol, 'https:');
    assert.equal(st.connection, 'ready');
    assert.ok(sockets.length > 0 && sockets.every((u) => u.startsWith(`wss://${node.host}:${node.port}/ws`)), sockets.join(' '));
    if (display === 'mjpeg') assert.ok(st.mjpeg.src.startsWith(`https://${node.host}:${node.port}/mjpeg/`), st.mjpeg.src);
    await page.close();
  });
}

test('plain http:// to the TLS port gets no page', { skip }, async () => {
  const page = await env.context.newPage();
  let failed = null;
  try {
    await page.goto(`http://${node.host}:${node.port}/test/browser/pages/node.html`, { timeout: 10000 });
  } catch (e) {
    failed = e.message;
  }
  assert.ok(failed && /ERR_EMPTY_RESPONSE|ERR_CONNECTION|ERR_INVALID_HTTP_RESPONSE/.test(failed), String(failed));
  await page.close();
  assert.ok(node.log.some((l) => l.includes('"rejected": "TLS handshake failed"')));
});
