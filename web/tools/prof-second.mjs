// Where a demo page's second visitor spends its time: loads the page twice on one fresh node
// (the second visit finds the node's caches warm) and, for the second visit, records the
// page's CPU profile (Chrome DevTools Protocol) and, with PERF=1, `perf record -g` of the node.
// Both use CLOCK_MONOTONIC, so their samples line up (perf script's seconds = the profile's
// startTime / 1e6 + offset).
//   node web/tools/prof-second.mjs build/app/tessera [page] [outdir]
//   -> one JSON line per visit (page times: connected, references sent, first answer, frames
//      drawn, resource fetches), outdir/page.cpuprofile, outdir/perf.data, outdir/node.log
import { chromium } from 'playwright-core';
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { startNode } from './tessera-node.js';
const [bin, pageName = 'kitchen', out = '/tmp/prof'] = process.argv.slice(2);
if (!bin) { console.error('usage: node web/tools/prof-second.mjs PATH/TO/tessera [page] [outdir]'); process.exit(2); }
fs.mkdirSync(out, { recursive: true });
const node = await startNode(bin, { threads: 2 });
const browser = await chromium.launch({ executablePath: process.env.CHROMIUM || '/usr/bin/chromium', headless: true,
  args: ['--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'] });
async function visit(profile) {
  const context = await browser.newContext({ viewport: { width: 1280, height: 800 } });
  const page = await context.newPage();
  await page.addInitScript(() => {
    window.__t = {}; window.__drawn = [];
    const send = WebSocket.prototype.send;
    WebSocket.prototype.send = function (d) {
      if (!window.__t.connected) { window.__t.connected = performance.now();
        this.addEventListener('message', (e) => { const m = new Uint8Array(e.data); if (m[8] === 0x85 && !window.__t.answer) window.__t.answer = performance.now(); }); }
      const b = new Uint8Array(d.buffer || d); if (b[8] === 0x15 && !window.__t.refs) window.__t.refs = performance.now();
      return send.call(this, d);
    };
    document.addEventListener('framedrawn', (e) => window.__drawn.push([performance.now(), e.detail.frame, e.detail.width]), true);
  });
  let cdp, perf;
  if (profile) {
    cdp = await context.newCDPSession(page);
    await cdp.send('Profiler.enable');
    await cdp.send('Profiler.setSamplingInterval', { interval: 200 });
    await cdp.send('Profiler.start');
    if (process.env.PERF) perf = spawn('perf', ['record', '-F', '999', '-g', '-p', String(node.proc.pid), '-o', path.join(out, 'perf.data')], { stdio: 'ignore' });
  }
  await page.goto(`${node.base}/demo/${pageName}.html?server=${node.host}:${node.port}&display=jpeg`);
  await page.waitForFunction(() => window.__drawn.length > 6, null, { timeout: 60000 });
  await new Promise((r) => setTimeout(r, 1500));
  const t = await page.evaluate(() => ({ ...window.__t, drawn: window.__drawn,
    res: performance.getEntriesByType('resource').filter((r) => /gltf|\.bin|xml3d\.js|three/.test(r.name)).map((r) => [r.name.split('/').pop(), +r.fetchStart.toFixed(0), +r.responseEnd.toFixed(0)]) }));
  if (profile) {
    const { profile: p } = await cdp.send('Profiler.stop');
    fs.writeFileSync(path.join(out, 'page.cpuprofile'), JSON.stringify(p));
    if (perf) { perf.kill('SIGINT'); await new Promise((r) => perf.on('exit', r)); }
  }
  await context.close();
  return t;
}
console.log(JSON.stringify(await visit(false)));
console.log(JSON.stringify(await visit(true)));
fs.writeFileSync(path.join(out, 'node.log'), node.log.join('\n'));
await browser.close();
await node.close();
