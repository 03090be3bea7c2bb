// Figures of the web client against a real node, as JSON lines (then a summary line with the
// conditions; --markdown also prints the tables of docs/results/web.md):
//   node web/tools/web-figures.js --tessera build/app/tessera [--repeat 3] [--steps 15] [--markdown]
// 1. page load -> first server frame, and -> `load` (every resource uploaded, a frame drawn),
//    for each shared scene page (/demo/pavilion.html, kitchen.html, living-room.html);
// 2. bytes uploaded over the WebSocket with and without deflate (CompressionStream removed);
//    1 and 2 with `references=off`: everything uploaded;
// 3. input-to-frame latency: a synthesised mouse drag step (examine camera) -> the first frame
//    whose render request followed the camera record that the step produced;
// 4. references (docs/protocol.md "References"): connecting -> the first frame of the whole
//    scene for a first visitor (the node loads the files, its texture cache cold), a second
//    visitor (another fresh browser profile: the node's cache warm) and a visitor that uploads
//    everything (`references=off`), on a fresh node per repeat (--ref-pages, default the three).
//    That first frame may be a scaled one (the node's frame budget); the time to the same
//    scene at the element's full width is reported beside it, and each record says where the
//    time went (the last scene message sent, the frames drawn until then).
// 5. a drag and the still after it (issue 18's interactive targets), per --drag-pages page
//    (default pavilion; JPEG display; the page refines to --drag-refine samples, default 256):
//    the mouse held and moved 2 px right --drag-ms / 16 times, along a path fixed in time (moves
//    dispatched in the page every 16 ms, a late tick jumping to where the path is by then;
//    --drag-input cdp: page.mouse.move, a round trip per move, so the drag lasts longer on a
//    busy machine; moved_ms says how long, inputs how many moves the page got), then released.
//    Frames shown per second while it moved (from 500 ms after it started), and after the
//    release each
//    full-size frame's PSNR (RGB) against the last refined one, the node's converged still (an
//    n-sample frame against an N-sample average that contains it reads -10 log10(1 - n/N) dB
//    high: 0.28 dB at 16 of 256), with the time from the last mousemove to the first at 35 dB.
//    --profile DIR: for each second visitor, the page's CPU profile (DevTools protocol) in
//    DIR/<page>-second-<run>.cpuprofile and, with PERF=1, `perf record -g` of the node in
//    DIR/<page>-second-<run>.perf.data. Both use CLOCK_MONOTONIC: perf's seconds and the
//    profile's startTime (microseconds) line up.
// Uses playwright-core with /usr/bin/chromium (headless, software GL) and a fresh `tessera serve`.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { execFileSync, spawn } from 'node:child_process';
import { chromium } from 'playwright-core';
import { startNode } from './tessera-node.js';
import { decodeClient } from '../src/net/Protocol.js';

const argv = process.argv.slice(2);
const opt = (name, def) => { const i = argv.indexOf(name); return i >= 0 ? argv[i + 1] : def; };
const BIN = opt('--tessera');
const REPEAT = Number(opt('--repeat', 3)), STEPS = Number(opt('--steps', 15)), THREADS = Number(opt('--threads', 2));
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';
const PAGES = (opt('--pages', 'pavilion,kitchen,living-room')).split(',').filter(Boolean);
const LATENCY_PAGES = (opt('--latency-pages', 'basic,pavilion')).split(',').filter(Boolean);
const REF_PAGES = (opt('--ref-pages', 'kitchen,pavilion,living-room')).split(',').filter(Boolean);
const DRAG_PAGES = (opt('--drag-pages', 'pavilion')).split(',').filter(Boolean);
const DRAG_REFINE = Number(opt('--drag-refine', 256)), DRAG_MS = Number(opt('--drag-ms', 3000)), DRAG_QUERY = opt('--drag-query', '');
// --drag-input page (default): moves dispatched in the page at 60 Hz; cdp: page.mouse.move, a
// round trip to the browser per move (about 25 a second on the 2-core machine).
const DRAG_INPUT = opt('--drag-input', 'page');
if (!['page', 'cdp'].includes(DRAG_INPUT)) { console.error('--drag-input: page or cdp'); process.exit(2); }
const MARKDOWN = argv.includes('--markdown');
// --page-query "&A=B": appended to every demo page's URL (&sync-rate=30, say), before a section's own.
const PAGE_QUERY = opt('--page-query', '');
// --web-root DIR: serve another copy of web/ (an older client, say) to compare in one run.
const WEB_ROOT = opt('--web-root', '') || undefined;
const PROFILE = opt('--profile', '');
// --node-args "A B": more arguments for `tessera serve` (--tessera.denoise-below-db=0, say).
const NODE_ARGS = opt('--node-args', '').split(' ').filter(Boolean);
// --node-log FILE: the node's log lines of sections 1-3 (its events: frames, abandoned samples).
const NODE_LOG = opt('--node-log', '');
if (PROFILE) fs.mkdirSync(PROFILE, { recursive: true });
if (!BIN || !fs.existsSync(BIN)) { console.error('usage: node web/tools/web-figures.js --tessera PATH/TO/tessera [--repeat N] [--steps N] [--markdown]'); process.exit(2); }
if (!fs.existsSync(CHROMIUM)) { console.error(`${CHROMIUM} not found`); process.exit(2); }

const emit = (o) => console.log(JSON.stringify(o));
const median = (a) => { const s = [...a].sort((x, y) => x - y); return s.length ? (s.length % 2 ? s[s.length >> 1] : (s[s.length / 2 - 1] + s[s.length / 2]) / 2) : NaN; };
const pct = (a, p) => { const s = [...a].sort((x, y) => x - y); return s.length ? s[Math.min(s.length - 1, Math.floor(p * s.length))] : NaN; };

// In the page before anything else: frame, load and input times, and every protocol message sent.
function instrument(noDeflate) {
  window.__drawn = []; window.__sends = []; window.__inputs = []; window.__load = null; window.__connected = null;
  window.__answers = [];  // times of the messages that carry reference answers (0x85)
  if (noDeflate) { delete window.CompressionStream; }
  document.addEventListener('framedrawn', (e) => window.__drawn.push({ t: performance.now(), frame: e.detail.frame,
    rendering: e.detail.timings && e.detail.timings.rendering, pipeline: e.detail.timings && e.detail.timings.pipeline,
    width: e.detail.width }), true);
  document.addEventListener('load', (e) => { if (e.target.localName === 'xml3d' && window.__load === null) window.__load = performance.now(); }, true);
  // The mouse's own moves, not those the client passes on to the scene's elements.
  document.addEventListener('mousemove', (e) => { if (!(e.target.closest && e.target.closest('xml3d'))) window.__inputs.push(performance.now()); }, true);
  const send = WebSocket.prototype.send;
  WebSocket.prototype.send = function (data) {
    const b = data instanceof ArrayBuffer ? new Uint8Array(data) : new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
    const dv = new DataView(b.buffer, b.byteOffset, b.byteLength);
    let camera = false, render = null, scene = false, refs = false, o = 8;
    for (let i = 0, n = dv.getUint32(4, true); i < n && o + 8 <= b.length; i++) {
      if (b[o] === 0x04) camera = true;
      if (b[o] === 0x15 || b[o] === 0x16) refs = true;
      if (b[o] >= 0x10 && b[o] <= 0x16) scene = true;  // buffer .. light, buffer_ref, texture_ref
      if (b[o] === 0x20) render = dv.getUint32(o + 8, true);
      o += 8 + dv.getUint32(o + 4, true);
    }
    if (window.__connected === null) {  // the handshake, sent on open
      window.__connected = performance.now();
      this.addEventListener('message', (e) => {
        if (!(e.data instanceof ArrayBuffer) || e.data.byteLength < 9) return;
        const m = new Uint8Array(e.data), mv = new DataView(e.data);
        for (let i = 0, n = mv.getUint32(4, true), q = 8; i < n && q + 8 <= m.length; i++, q += 8 + mv.getUint32(q + 4, true)) {
          if (m[q] === 0x85) { window.__answers.push(performance.now()); break; }
        }
      });
    }
    window.__sends.push({ t: performance.now(), camera, render, scene, refs, bytes: b.length });
    return send.call(this, data);
  };
}

async function newContext() {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'tessera-figures-'));
  const context = await chromium.launchPersistentContext(dir, { executablePath: CHROMIUM, headless: true,
    args: ['--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update', '--disable-sync',
      '--no-first-run', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'], viewport: { width: 1280, height: 800 } });
  return { context, close: async () => { await context.close(); fs.rmSync(dir, { recursive: true, force: true }); } };
}

// Loads a demo page in server mode; resolves the timings and the upload byte breakdown.
// profile: a path prefix for the visit's CPU profile (and perf data with PERF=1), or ''.
async function loadPage(node, name, { noDeflate = false, display = 'jpeg', query = '', profile = '' } = {}) {
  const { context, close } = await newContext();
  const page = await context.newPage();
  await page.addInitScript(instrument, noDeflate);
  let cdp = null, perf = null;
  if (profile) {
    cdp = await context.newCDPSession(page);
    await cdp.send('Profiler.enable');
    await cdp.send('Profiler.setSamplingInterval', { interval: 200 });
    await cdp.send('Profiler.start');
    if (process.env.PERF) perf = spawn('perf', ['record', '-F', '999', '-g', '-p', String(node.proc.pid), '-o', `${profile}.perf.data`], { stdio: 'ignore' });
  }
  const up = { messages: 0, wire: 0, bufferRaw: 0, bufferWire: 0, buffersDeflated: 0, buffers: 0, texture: 0, refs: 0 };
  let lastSend = Date.now();
  page.on('websocket', (ws) => ws.on('framesent', (f) => {
    const bytes = typeof f.payload === 'string' ? Buffer.from(f.payload) : f.payload;
    up.messages++; up.wire += bytes.length; lastSend = Date.now();
    for (const r of decodeClient(new Uint8Array(bytes.buffer, bytes.byteOffset, bytes.length))) {
      if (r.type === 'buffer') { up.buffers++; up.bufferRaw += r.values * 4; up.bufferWire += r.payload.length; if (r.deflate) up.buffersDeflated++; }
      if (r.type === 'texture') up.texture += r.bytes.length;
      if (r.type === 'buffer_ref' || r.type === 'texture_ref') up.refs++;
    }
  }));
  await page.goto(`${node.base}/demo/${name}.html?server=${node.host}:${node.port}&display=${display}${PAGE_QUERY}${query}`);
  await page.waitForFunction(() => window.__load !== null, null, { timeout: 180000, polling: 100 });
  while (Date.now() - lastSend < 1500) await new Promise((r) => setTimeout(r, 250));  // upload finished
  await page.waitForFunction(() => {  // the first frame requested after the last scene upload is on screen
    const last = window.__sends.filter((s) => s.scene).pop();
    const req = last && window.__sends.find((s) => s.t >= last.t && s.render !== null);
    const d = req && window.__drawn.find((f) => f.frame >= req.render);
    // Within a frame budget that frame may be a scaled one: the first at the element's full
    // width (the still that follows it) is recorded too.
    const full = d && window.__drawn.find((f) => f.frame >= req.render && f.width >= document.querySelector('xml3d').tessera.width);
    if (d) { window.__complete = d.t; window.__lastScene = last.t; window.__completeRequest = req.t; window.__completeWidth = d.width; }
    if (full) window.__completeFull = full.t;
    return !!full;
  }, null, { timeout: 180000, polling: 100 });
  const t = await page.evaluate(() => ({ first: window.__drawn.length ? window.__drawn[0].t : null, load: window.__load, complete: window.__complete,
    nav: performance.getEntriesByType('navigation')[0].domContentLoadedEventEnd, frames: window.__drawn.length, connected: window.__connected,
    // Where the time after connecting goes: the last scene message sent, the render request of
    // the frame counted as complete, and every frame drawn until then (time, rendering ms).
    lastScene: window.__lastScene, completeRequest: window.__completeRequest, completeWidth: window.__completeWidth,
    completeFull: window.__completeFull,
    refsSent: (window.__sends.find((s) => s.refs) || {}).t, refsLast: (window.__sends.filter((s) => s.refs).pop() || {}).t,
    answered: window.__answers.length ? window.__answers[window.__answers.length - 1] : undefined,
    drawn: window.__drawn.filter((f) => f.t <= window.__complete).map((f) => [+f.t.toFixed(0), f.frame, f.rendering === undefined ? null : +(+f.rendering).toFixed(0)]) }));
  if (cdp) fs.writeFileSync(`${profile}.cpuprofile`, JSON.stringify((await cdp.send('Profiler.stop')).profile));
  if (perf) { perf.kill('SIGINT'); await new Promise((r) => perf.on('exit', r)); }
  return { page, close, t, up };
}

async function latency(node, name, display) {
  const { page, close } = await loadPage(node, name, { display });
  await new Promise((r) => setTimeout(r, 1000));
  const box = await page.evaluate(() => { const r = document.querySelector('.tessera-xml3d').getBoundingClientRect(); return [r.left + r.width / 2, r.top + r.height / 2]; });
  await page.mouse.move(box[0], box[1]);
  await page.mouse.down();
  const out = [];
  for (let i = 1; i <= STEPS; i++) {
    const tIn = await page.evaluate(() => performance.now());
    await page.mouse.move(box[0] + i * 6, box[1] + (i % 2 ? 3 : -3));
    const r = await page.waitForFunction((t0) => {
      const inp = window.__inputs.find((t) => t >= t0);
      if (inp === undefined) return null;
      const cam = window.__sends.find((s) => s.t >= inp && s.camera);
      if (!cam) return null;
      const req = window.__sends.find((s) => s.t >= cam.t && s.render !== null);
      if (!req) return null;
      const d = window.__drawn.find((f) => f.t >= req.t && f.frame >= req.render);
      return d ? { input: inp, camera: cam.t, request: req.t, drawn: d.t, rendering: d.rendering, pipeline: d.pipeline } : null;
    }, tIn, { timeout: 60000, polling: 'raf' }).catch(async (e) => {
      const st = await page.evaluate((t0) => ({ t0, inputs: window.__inputs.slice(-3), sends: window.__sends.slice(-5), drawn: window.__drawn.slice(-3),
        status: document.querySelector('.tessera-status').textContent, view: document.querySelector('view') && document.querySelector('view').outerHTML.slice(0, 200) }), tIn);
      throw new Error(`${name} ${display} step ${i}: no frame for the input: ${JSON.stringify(st)}\n${e.message}`);
    });
    const v = await r.jsonValue();
    out.push({ total: v.drawn - v.input, toSend: v.request - v.input, sendToFrame: v.drawn - v.request, rendering: v.rendering });
    await new Promise((res) => setTimeout(res, 250));
  }
  await page.mouse.up();
  const size = await page.evaluate(() => { const x = document.querySelector('xml3d'); return [x.tessera.width, x.tessera.height, x.getAttribute('ao-samples'), x.getAttribute('max-depth')]; });
  await close();
  return { out, size };
}

// Section 5: one drag over the page's centre, then the still converging.
async function drag(node, name) {
  const { page, close } = await loadPage(node, name, { query: `&refine-samples=${DRAG_REFINE}${DRAG_QUERY}` });
  await page.evaluate(() => {
    // Every frame shown: when, its size and samples; the JPEG bytes of those shown after the
    // release (window.__keepFrom), decoded at the end.
    window.__shown = [];
    window.__keepFrom = Infinity;
    const view = document.querySelector('xml3d').tessera.backend.frameView;
    const show = view.show.bind(view);
    view.show = async (f) => {
      const ok = await show(f);
      const t = performance.now();
      if (ok) window.__shown.push({ t, frame: f.frame, width: f.width, samples: f.samples ?? 1, refined: !!f.refined, converged: !!f.converged, payload: t >= window.__keepFrom ? f.payload.slice() : null });
      return ok;
    };
  });
  await new Promise((r) => setTimeout(r, 1000));
  const box = await page.evaluate(() => { const r = document.querySelector('.tessera-xml3d').getBoundingClientRect(); return [r.left + r.width / 2, r.top + r.height / 2]; });
  // A fixed path (2 px right a move, one move per 16 ms), so every run ends at the same view.
  const moves = Math.max(1, Math.round(DRAG_MS / 16));
  if (DRAG_INPUT === 'cdp') {
    // Each page.mouse.move is a round trip to the browser: about 25 moves a second here.
    await page.mouse.move(box[0] - moves, box[1]);
    await page.mouse.down();
    await page.evaluate(() => { window.__dragFrom = performance.now(); });
    const t0 = Date.now();
    for (let i = 1; i <= moves; i++) {
      await page.mouse.move(box[0] - moves + 2 * i, box[1] + (i % 2));
      await new Promise((r) => setTimeout(r, Math.max(0, t0 + 16 * i - Date.now())));
    }
    await page.evaluate(() => { window.__keepFrom = window.__inputs[window.__inputs.length - 1]; });
    await page.mouse.up();
  } else {
    // Dispatched in the page on a 16 ms clock, as a browser delivers a real mouse's moves: a
    // tick that comes late (the main thread busy) moves to where the path is by then, in one
    // event, as Chromium coalesces moves, so the drag takes DRAG_MS whatever the load.
    await page.evaluate(({ x0, y, moves }) => new Promise((resolve) => {
      const el = document.elementFromPoint(x0 + moves, y);
      const send = (type, i) => el.dispatchEvent(new MouseEvent(type, { bubbles: true, cancelable: true, view: window, clientX: x0 + 2 * i, clientY: y + (i % 2), button: 0, buttons: type === 'mouseup' ? 0 : 1 }));
      send('mousedown', 0);
      const t0 = window.__dragFrom = performance.now();
      let i = 0;
      const tick = () => {
        const next = Math.min(moves, Math.max(i + 1, Math.floor((performance.now() - t0) / 16)));
        i = next;
        send('mousemove', i);
        if (i < moves) { setTimeout(tick, Math.max(0, t0 + 16 * (i + 1) - performance.now())); return; }
        window.__keepFrom = window.__inputs[window.__inputs.length - 1];
        send('mouseup', i);
        resolve();
      };
      setTimeout(tick, 16);
    }), { x0: box[0] - moves, y: box[1], moves });
  }
  // Until the still is converged (a frame at the target), or nothing new for 5 s, or 120 s.
  const until = Date.now() + 120000;
  let last = -1, since = Date.now();
  for (;;) {
    const [n, done] = await page.evaluate((target) => [window.__shown.length, window.__shown.some((f) => f.t >= window.__keepFrom && (f.converged || f.samples >= target))], DRAG_REFINE);
    if (n !== last) { last = n; since = Date.now(); }
    if (done || Date.now() - since > 5000 || Date.now() > until) break;
    await new Promise((r) => setTimeout(r, 250));
  }
  const r = await page.evaluate(async () => {
    const x = document.querySelector('xml3d'), full = x.tessera.width;
    const down = window.__dragFrom;
    const stop = window.__keepFrom;
    const during = window.__shown.filter((f) => f.t >= down + 500 && f.t <= stop);
    const after = window.__shown.filter((f) => f.t >= stop && f.payload && f.width === full);
    const pixels = async (payload) => {
      const b = await createImageBitmap(new Blob([payload], { type: 'image/jpeg' }));
      const c = new OffscreenCanvas(b.width, b.height), g = c.getContext('2d');
      g.drawImage(b, 0, 0);
      return g.getImageData(0, 0, b.width, b.height).data;
    };
    const out = { moved_ms: stop - down, inputs: window.__inputs.filter((t) => t >= down && t <= stop).length, during: during.length, during_s: (stop - down - 500) / 1000, widths: during.map((f) => f.width), full, steps: [] };
    if (!after.length) return out;
    const ref = after[after.length - 1], refPx = await pixels(ref.payload);
    out.ref_samples = ref.samples;
    out.ref_ms = ref.t - stop;
    for (const f of after.slice(0, -1)) {
      const px = await pixels(f.payload);
      let se = 0;
      for (let i = 0; i < px.length; i += 4) for (let c = 0; c < 3; c++) { const d = px[i + c] - refPx[i + c]; se += d * d; }
      const mse = se / (px.length / 4 * 3);
      out.steps.push([+(f.t - stop).toFixed(1), f.samples, mse > 0 ? +(10 * Math.log10(255 * 255 / mse)).toFixed(2) : 99]);
    }
    return out;
  });
  const size = await page.evaluate(() => { const x = document.querySelector('xml3d'); return [x.tessera.width, x.tessera.height, x.getAttribute('ao-samples')]; });
  await close();
  const first35 = r.steps.find((s) => s[2] >= 35);
  return { drag: `/demo/${name}.html`, query: DRAG_QUERY, input: DRAG_INPUT, size, drag_ms: DRAG_MS, moved_ms: +r.moved_ms.toFixed(0), inputs: r.inputs, frames_during: r.during, fps_during: +(r.during / r.during_s).toFixed(1),
    median_width_during: median(r.widths), ref_samples: r.ref_samples ?? null, ref_ms: r.ref_ms === undefined ? null : +r.ref_ms.toFixed(0),
    first_35db_ms: first35 ? first35[0] : null, first_35db_samples: first35 ? first35[1] : null, steps: r.steps };
}

const node = await startNode(BIN, { threads: THREADS, webRoot: WEB_ROOT, args: NODE_ARGS });
const rows = { load: {}, loadRaw: {}, upload: {}, latency: {}, drag: [] };
try {
  for (const name of PAGES) {
    for (const noDeflate of [false, true]) {
      for (let k = 0; k < (noDeflate ? 1 : REPEAT); k++) {
        // Sections 1 and 2 measure uploads: the page sends no references (section 4 does).
        const { close, t, up } = await loadPage(node, name, { noDeflate, query: '&references=off' });
        await close();
        const rec = { page: `/demo/${name}.html`, deflate: !noDeflate, run: k, first_frame_ms: +(t.first ?? NaN).toFixed(0),
          load_ms: +t.load.toFixed(0), complete_frame_ms: +t.complete.toFixed(0), dom_ready_ms: +t.nav.toFixed(0), frames_until_load: t.frames, upload: up };
        emit(rec);
        (rows.upload[name] ||= {})[noDeflate ? 'raw' : 'deflate'] = up;
        if (!noDeflate) (rows.load[name] ||= []).push(rec); else (rows.loadRaw[name] ||= []).push(rec);
      }
    }
  }
  for (const name of LATENCY_PAGES) {
    for (const display of ['jpeg', 's3tc']) {
      const { out, size } = await latency(node, name, display);
      for (const [i, o] of out.entries()) emit({ latency: `/demo/${name}.html`, display, step: i, ...Object.fromEntries(Object.entries(o).map(([k, v]) => [k, +(+v).toFixed(1)])) });
      rows.latency[`${name} ${display}`] = { out, size };
    }
  }
  for (const name of DRAG_PAGES) {
    for (let k = 0; k < REPEAT; k++) {
      const rec = { ...(await drag(node, name)), run: k };
      emit(rec);
      rows.drag.push(rec);
    }
  }
} finally {
  await node.close();
  if (NODE_LOG) fs.writeFileSync(NODE_LOG, node.log.join('\n') + '\n');
}
for (let k = 0; k < (REF_PAGES.length ? REPEAT : 0); k++) {
  const fresh = await startNode(BIN, { threads: THREADS, webRoot: WEB_ROOT, args: NODE_ARGS });  // its texture cache cold
  try {
    for (const name of REF_PAGES) {
      for (const visitor of ['first', 'second', 'upload']) {
        const logFrom = fresh.log.length;
        const { close, t, up } = await loadPage(fresh, name, { query: visitor === 'upload' ? '&references=off' : '',
          profile: PROFILE && visitor === 'second' ? path.join(PROFILE, `${name}-second-${k}`) : '' });
        await close();
        // The node's side of it: how long each message's references took to load, and each
        // frame's width, kernel and rendering ms (rendering includes taking the scene's changes).
        const nodeEvents = fresh.log.slice(logFrom).filter((l) => l.startsWith('{')).map((l) => { try { return JSON.parse(l); } catch { return null; } }).filter(Boolean);
        const rec = { references: `/demo/${name}.html`, visitor, run: k, connected_ms: +t.connected.toFixed(0),
          complete_frame_ms: +t.complete.toFixed(0), connect_to_complete_ms: +(t.complete - t.connected).toFixed(0),
          refs: up.refs, wire_mb: +(up.wire / 1048576).toFixed(2),
          last_scene_ms: +(t.lastScene - t.connected).toFixed(0), complete_request_ms: +(t.completeRequest - t.connected).toFixed(0),
          complete_width: t.completeWidth, connect_to_full_ms: +(t.completeFull - t.connected).toFixed(0),
          // The references' round trip: the first and last message of references sent, the last
          // answer received (ms after connecting; absent without references).
          refs_sent_ms: t.refsSent === undefined ? null : +(t.refsSent - t.connected).toFixed(0),
          refs_last_ms: t.refsLast === undefined ? null : +(t.refsLast - t.connected).toFixed(0),
          answered_ms: t.answered === undefined ? null : +(t.answered - t.connected).toFixed(0),
          node_refs_ms: nodeEvents.filter((e) => 'references' in e && 'loaded' in e).map((e) => +(+e.ms).toFixed(0)),
          node_frames: nodeEvents.filter((e) => 'frame' in e && 'rendering_ms' in e).slice(0, 8).map((e) => [e.width, +(+e.kernel_ms).toFixed(0), +(+e.rendering_ms).toFixed(0)]),
          drawn: t.drawn.map(([at, frame, rendering]) => [at - Math.round(t.connected), frame, rendering]) };
        emit(rec);
        ((rows.refs ||= {})[`${name} ${visitor}`] ||= []).push(rec);
      }
    }
  } finally {
    await fresh.close();
  }
}
const chromiumVersion = execFileSync(CHROMIUM, ['--version'], { stdio: ['ignore', 'pipe', 'ignore'] }).toString().trim();
const summary = { summary: true, cpu: os.cpus()[0].model, cores: os.cpus().length, loadavg: os.loadavg().map((v) => +v.toFixed(2)),
  node_threads: THREADS, chromium: chromiumVersion, nodejs: process.version, repeat: REPEAT, steps: STEPS, tessera: node.info, page_query: PAGE_QUERY };
emit(summary);

if (MARKDOWN) {
  const ms = (a) => `${median(a).toFixed(0)} (${Math.min(...a).toFixed(0)}–${Math.max(...a).toFixed(0)})`;
  console.log('\n| page | DOM ready, ms | first server frame, ms | `load` event, ms | first frame of the whole scene, ms | the same without deflate, ms |\n| --- | --- | --- | --- | --- | --- |');
  for (const [name, recs] of Object.entries(rows.load)) {
    console.log(`| /demo/${name}.html | ${ms(recs.map((r) => r.dom_ready_ms))} | ${ms(recs.map((r) => r.first_frame_ms))} | ${ms(recs.map((r) => r.load_ms))} | ${ms(recs.map((r) => r.complete_frame_ms))} | ${ms((rows.loadRaw[name] || []).map((r) => r.complete_frame_ms))} |`);
  }
  const mb = (b) => (b / 1048576).toFixed(2);
  console.log('\n| page | buffers raw, MB | WebSocket bytes with deflate, MB | without deflate, MB | saved | textures, MB | messages |\n| --- | --- | --- | --- | --- | --- | --- |');
  for (const [name, u] of Object.entries(rows.upload)) {
    console.log(`| /demo/${name}.html | ${mb(u.raw.bufferRaw)} | ${mb(u.deflate.wire)} | ${mb(u.raw.wire)} | ${(100 * (1 - u.deflate.wire / u.raw.wire)).toFixed(1)} % | ${mb(u.deflate.texture)} | ${u.deflate.messages} / ${u.raw.messages} |`);
  }
  console.log('\n| page, display | size, ao-samples | input → frame, ms: median (p10–p90) | input → render request sent | request → frame shown | node rendering_ms |\n| --- | --- | --- | --- | --- | --- |');
  for (const [key, { out, size }] of Object.entries(rows.latency)) {
    const col = (k) => `${median(out.map((o) => o[k])).toFixed(1)} (${pct(out.map((o) => o[k]), 0.1).toFixed(1)}–${pct(out.map((o) => o[k]), 0.9).toFixed(1)})`;
    console.log(`| ${key} | ${size[0]}x${size[1]}, ${size[2] ?? 0} | ${col('total')} | ${col('toSend')} | ${col('sendToFrame')} | ${median(out.map((o) => o.rendering)).toFixed(1)} |`);
  }
  if (rows.drag.length) {
    console.log('\n| page | size, ao-samples | run | frames/s during the drag | median width during it | release → first frame at 35 dB, ms (samples) | release → converged still, ms (samples) |\n| --- | --- | --- | --- | --- | --- | --- |');
    for (const d of rows.drag)
      console.log(`| ${d.drag} | ${d.size[0]}x${d.size[1]}, ${d.size[2] ?? 0} | ${d.run} | ${d.fps_during} | ${d.median_width_during} | ${d.first_35db_ms === null ? 'not reached' : `${d.first_35db_ms.toFixed(0)} (${d.first_35db_samples})`} | ${d.ref_ms ?? '-'} (${d.ref_samples ?? '-'}) |`);
  }
  console.log('\n| page | visitor | connected → first frame of the whole scene, ms | its width | connected → that scene at full resolution, ms | page load → first frame of the whole scene, ms | references sent | WebSocket bytes sent, MB |\n| --- | --- | --- | --- | --- | --- | --- | --- |');
  for (const [key, recs] of Object.entries(rows.refs || {})) {
    const [name, visitor] = key.split(' ');
    console.log(`| /demo/${name}.html | ${visitor} | ${ms(recs.map((r) => r.connect_to_complete_ms))} | ${recs.map((r) => r.complete_width).join(', ')} | ${ms(recs.map((r) => r.connect_to_full_ms))} | ${ms(recs.map((r) => r.complete_frame_ms))} | ${median(recs.map((r) => r.refs))} | ${median(recs.map((r) => r.wire_mb)).toFixed(2)} |`);
  }
}
