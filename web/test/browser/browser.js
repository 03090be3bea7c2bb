// Shared setup for browser tests: headless Debian chromium through playwright-core (never a
// downloaded browser), a fresh profile, and the static server.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { chromium } from 'playwright-core';
import { startStaticServer } from '../../tools/static-server.js';

export const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';
export const hasChromium = () => fs.existsSync(CHROMIUM);

// `args`: further chromium switches (e.g. --ignore-certificate-errors for a node with a
// self-signed certificate).
export async function launch({ args = [] } = {}) {
  const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'tessera-chromium-'));
  const context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: CHROMIUM, headless: true,
    args: ['--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update',
      '--disable-sync', '--no-first-run', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', ...args],
    viewport: { width: 400, height: 300 },
  });
  const server = await startStaticServer();
  const base = `http://127.0.0.1:${server.address().port}`;
  return {
    context, base, server,
    async close() {
      await context.close();
      server.close();
      fs.rmSync(userDataDir, { recursive: true, force: true });
    },
  };
}

// Opens a page, collects console output, waits for the xml3d load event (or a timeout). The
// browser's own request for /favicon.ico, a 404 here, is not the page's error: whether its
// console line comes before a test reads the logs depends on timing (seen failing the
// xml3d-api test once in a full run).
export async function open(env, url, { waitLoad = true } = {}) {
  const page = await env.context.newPage();
  page.logs = [];
  page.on('console', (m) => {
    if (m.type() === 'error' && /\/favicon\.ico$/.test(m.location().url || '')) return;
    page.logs.push(`${m.type()}: ${m.text()}`);
  });
  page.on('pageerror', (e) => page.logs.push(`pageerror: ${e.message}`));
  await page.addInitScript(() => {
    window.__loaded = false;
    document.addEventListener('load', (e) => { if (e.target.localName === 'xml3d') window.__loaded = true; }, true);
  });
  await page.goto(env.base + url);
  if (waitLoad) await page.waitForFunction(() => window.__loaded, null, { timeout: 15000 });
  return page;
}

// RGBA of the drawn canvas at (x, y) in canvas pixels.
export async function pixel(page, x, y, selector = 'canvas.tessera-webgl') {
  return page.evaluate(([sel, x, y]) => {
    const c = document.querySelector(sel);
    const gl = c.getContext('webgl2');
    const out = new Uint8Array(4);
    gl.readPixels(x, c.height - 1 - y, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, out);
    return [...out];
  }, [selector, x, y]);
}

// Polls `read(page)` every 50 ms until `pred` holds for what it returns, which it then returns;
// fails with `what`, the last value and the page's console lines after `timeout` ms.
export async function pollUntil(page, read, pred, what, timeout = 20000) {
  const t0 = Date.now();
  let st;
  while (Date.now() - t0 < timeout) {
    st = await read(page);
    if (pred(st)) return st;
    await new Promise((r) => setTimeout(r, 50));
  }
  const logs = (page.logs || []).map((l) => (typeof l === 'string' ? l : `${l.type}: ${l.text}`));
  throw new Error(`${what}: not within ${timeout} ms: ${JSON.stringify(st)}\n${logs.join('\n')}`);
}
