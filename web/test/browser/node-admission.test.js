// Session admission in a real browser against a REAL Tessera node that asks for access tokens
// (docs/operations.md, "Admission"): the page gives the token in its URL fragment
// (#tessera-token=...), which the client takes out of the address bar and sends to the node; a
// token made by `tessera token` and one made here with node's crypto (as any web back-end
// would: docs/protocol.md) both get frames; a page without a token and one with an expired
// token get the node's reason as one console error and stop; the node's log holds neither
// token nor key.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import crypto from 'node:crypto';
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { launch, pollUntil } from './browser.js';
import { startNode } from '../../tools/tessera-node.js';

const BIN = process.env.TESSERA_BIN;
const skip = !BIN && 'TESSERA_BIN not set (CTest passes the tessera binary)';
const KEY = 'browser-admission-test-key-0123456789abcdef';

// A signed token as docs/protocol.md describes it.
const b64url = (buf) => Buffer.from(buf).toString('base64url');
function makeToken(key, expiry, subject) {
  const body = `tsr1.${expiry}.${b64url(subject)}`;
  return `${body}.${b64url(crypto.createHmac('sha256', key).update(body).digest())}`;
}

let env, node, tmp;
before(async () => {
  if (!BIN) return;
  tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'tessera-admission-'));
  fs.writeFileSync(path.join(tmp, 'token.key'), `${KEY}\n`, { mode: 0o600 });
  node = await startNode(BIN, { threads: 2, args: ['--tessera.web-public=["test/browser/pages/"]',
    `--tessera.token-key=${path.join(tmp, 'token.key')}`] });
  env = await launch();
});
after(async () => {
  if (env) await env.close();
  if (node) await node.close();
  if (tmp) fs.rmSync(tmp, { recursive: true, force: true });
});

async function openPage(fragment) {
  const page = await env.context.newPage();
  page.logs = [];
  page.on('console', (m) => page.logs.push({ type: m.type(), text: m.text() }));
  await page.goto(`${node.base}/test/browser/pages/node.html?server=${node.host}:${node.port}&display=jpeg${fragment}`);
  return page;
}

const state = (page) => page.evaluate(() => ({
  connection: document.querySelector('.tessera-xml3d') && document.querySelector('.tessera-xml3d').dataset.connection,
  frames: (window.__frames || []).length,
  status: document.querySelector('.tessera-status') && document.querySelector('.tessera-status').textContent,
  href: location.href,
}));

const until = (page, pred, what, timeout) => pollUntil(page, state, pred, what, timeout);

test('a token in the page URL fragment gets frames, and leaves the address bar', { skip }, async () => {
  const fromCommand = execFileSync(BIN, ['token', '--key', path.join(tmp, 'token.key'), '--ttl', '600', '--subject', 'browser'])
    .toString().trim();
  const fromBackend = makeToken(KEY, Math.floor(Date.now() / 1000) + 600, 'web back-end');
  for (const token of [fromCommand, fromBackend]) {
    const page = await openPage(`#tessera-token=${token}`);
    const st = await until(page, (s) => s.frames > 0, 'frames with a valid token');
    assert.equal(st.connection, 'ready');
    assert.ok(!st.href.includes('tessera-token') && !st.href.includes(token.slice(-20)), `address bar: ${st.href}`);
    assert.ok(!(st.status || '').includes(token.slice(-20)), 'the status line shows no token');
    await page.close();
  }
  for (const token of [fromCommand, fromBackend]) {
    assert.ok(!node.log.some((l) => l.includes(token.slice(token.lastIndexOf('.') + 1))), 'no token in the node log');
  }
});

test('without a token, or with an expired one, the page gets the node\'s reason as one console error', { skip }, async () => {
  const expired = makeToken(KEY, Math.floor(Date.now() / 1000) - 3600, 'late');
  for (const [fragment, reason] of [['', 'access token required'], [`#tessera-token=${expired}`, 'access token expired']]) {
    const page = await openPage(fragment);
    const st = await until(page, (s) => s.connection === 'failed', `refusal "${reason}"`);
    assert.equal(st.frames, 0);
    assert.ok(st.status.includes(reason), st.status);
    await new Promise((r) => setTimeout(r, 1200));  // past the first reconnect's back-off: none comes
    const errors = page.logs.filter((l) => l.type === 'error' && l.text.startsWith('Tessera:'));
    assert.deepEqual(errors.map((l) => l.text), [`Tessera: the node ${node.host}:${node.port} refused the session: ${reason}`]);
    await page.close();
  }
  assert.equal(node.log.filter((l) => l.includes('"rejected": "access token required"')).length, 1);
  assert.equal(node.log.filter((l) => l.includes('"rejected": "access token expired"') && l.includes('"subject": "late"')).length, 1);
  assert.ok(!node.log.some((l) => l.includes(expired.slice(expired.lastIndexOf('.') + 1)) || l.includes(KEY)));
});
