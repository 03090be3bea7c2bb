// The node's rasterizer (renderer="rasterizer") draws the same page as the WebGL fallback:
// a real `tessera serve` (../build/app/tessera, or $TESSERA_BIN) renders pages/lit.html for a
// client that asks for the rasterizer, and its JPEG (quality 100) frame is compared with the
// fallback's canvas away from edges (the browser antialiases, the node does not): mean
// |difference| <= 4 levels, at most 3% of pixels over 24 (the rasterizer's unit test bound).
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { spawn } from 'node:child_process';
import { launch, open } from './browser.js';

const BIN = process.env.TESSERA_BIN || path.resolve('..', process.env.TESSERA_BUILD_DIR || 'build', 'app/tessera');
let env, node, port;

before(async () => {
  env = await launch();
  if (!fs.existsSync(BIN)) return;
  node = spawn(BIN, ['serve', '--host', '127.0.0.1', '--port', '0', '--web-root', '.'], { stdio: ['ignore', 'pipe', 'pipe'] });
  const line = await new Promise((resolve, reject) => {
    let out = '';
    node.stdout.on('data', (d) => { out += d; if (out.includes('\n')) resolve(out.split('\n')[0]); });
    node.on('exit', (c) => reject(new Error(`tessera serve exited with ${c}`)));
  });
  const info = JSON.parse(line);
  port = new URL(info.listening).port;
  node.rasterizer = info.rasterizer;
});
after(async () => { if (node) node.kill('SIGTERM'); await env.close(); });

// RGBA pixels of a canvas (WebGL with preserveDrawingBuffer, or a bitmaprenderer canvas).
async function grab(page, selector) {
  return page.evaluate((sel) => {
    const c = document.querySelector(sel);
    const o = new OffscreenCanvas(c.width, c.height);
    const g = o.getContext('2d');
    g.drawImage(c, 0, 0);
    return { w: c.width, h: c.height, data: [...g.getImageData(0, 0, c.width, c.height).data] };
  }, selector);
}

function step(img, x, y) {
  let m = 0;
  const at = (xx, yy, k) => img.data[(yy * img.w + xx) * 4 + k];
  for (let dy = -1; dy <= 1; dy++) for (let dx = -1; dx <= 1; dx++) {
    const xx = x + dx, yy = y + dy;
    if (xx < 0 || yy < 0 || xx >= img.w || yy >= img.h) continue;
    for (let k = 0; k < 3; k++) m = Math.max(m, Math.abs(at(xx, yy, k) - at(x, y, k)));
  }
  return m;
}

test('the node rasterizer matches the WebGL fallback on the same page', async (t) => {
  if (!node) { t.skip(`no tessera binary at ${BIN} (build it, or set TESSERA_BIN)`); return; }
  if (node.rasterizer !== 'available') { t.skip(`the node has no rasterizer: ${node.rasterizer}`); return; }
  const local = await open(env, '/test/browser/pages/lit.html');
  await local.waitForTimeout(300);
  const a = await grab(local, 'canvas.tessera-webgl');
  await local.close();
  const remote = await open(env, `/test/browser/pages/lit.html?server=127.0.0.1:${port}`, { waitLoad: false });
  await remote.waitForFunction(() => { const c = document.querySelector('canvas.tessera-display'); return c && c.width === 160; },
    null, { timeout: 20000 });
  // The frame shown is read again until it matches or 15 s have passed. In one full test run
  // here (other suites running beside it) the first full-size frame read differed by a mean of
  // 90 levels, where the same test alone reads 0.64. The cause was not found: the frame budget
  // shows a loaded node's interactive frame at a reduced scale, upscaled, before the still at
  // full resolution, and that is one way; the frames after it are the still's.
  const compare = (b) => {
    let n = 0, sum = 0, over = 0, drawn = 0;
    for (let y = 0; y < a.h; y++) for (let x = 0; x < a.w; x++) {
      const i = (y * a.w + x) * 4;
      if (a.data[i + 3] !== 255) continue;  // the fallback's canvas is transparent where nothing is drawn
      drawn++;
      if (step(a, x, y) > 48 || step(b, x, y) > 48) continue;
      let m = 0;
      for (let k = 0; k < 3; k++) { const e = Math.abs(a.data[i + k] - b.data[i + k]); sum += e; m = Math.max(m, e); }
      over += m > 24;
      n++;
    }
    const mean = sum / (3 * n);
    return { n, drawn, mean, over, msg: `compared ${n} of ${drawn} drawn pixels: mean ${mean.toFixed(2)}, over 24: ${(100 * over / n).toFixed(2)}%` };
  };
  const ok = (r) => r.n > 0.5 * r.drawn && r.mean <= 4 && r.over <= 0.03 * r.n;
  const deadline = Date.now() + 15000;
  let b, r;
  for (;;) {
    b = await grab(remote, 'canvas.tessera-display');
    r = b.w === a.w && b.h === a.h ? compare(b) : null;
    if ((r && ok(r)) || Date.now() > deadline) break;
    await remote.waitForTimeout(250);
  }
  const logs = remote.logs.join('\n');
  await remote.close();
  assert.equal(b.w, a.w, logs);
  assert.equal(b.h, a.h, logs);
  const { n, drawn, mean, over, msg } = r;
  console.log(msg);
  assert.ok(drawn > 0.15 * a.w * a.h, `the fallback drew too little: ${msg}`);
  assert.ok(n > 0.5 * drawn, msg);
  assert.ok(mean <= 4, msg);
  assert.ok(over <= 0.03 * n, msg);
});
