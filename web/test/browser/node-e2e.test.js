// The web client against a REAL Tessera node: `tessera serve` (path in TESSERA_BIN, passed by
// CTest) renders what the page in headless chromium sends. The page
// (pages/node.html) shows pages/node-scene.gltf from frame 0 of pages/node-camera-loop.json;
// its server frames must match `tessera render` of the same glTF and camera (PSNR bound) for
// each display method, and page scripts that move the camera or the model must produce frames
// matching the reference of the new view. The scene is unlit (see tools/make-node-test-scene.js)
// so that the glTF reference (linear colour space) and the XML3D page (colours as given) agree.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { launch } from './browser.js';
import { startNode, renderReference, WEB } from '../../tools/tessera-node.js';

const BIN = process.env.TESSERA_BIN;
const W = 160, H = 120;
// PSNR bound for "this frame shows that view", per display. Matching frames measure (jpeg q85 /
// mjpeg) ~27-36 dB and (DXT1) ~23-33 dB on this scene of saturated colours on black (4:2:0
// chroma and 4x4 blocks with three colours cost the most), a different view ~8-13 dB; each test
// also checks that the frame is far further from the other views' references. H.264 at the
// node's default 8 Mbit/s measures 28.8-29.0 dB (start view) and 26.5 dB (frame 1 of the loop)
// against JPEG's 28.4 and 27.1: both are at the ceiling of 4:2:0 chroma here (the references
// through a BT.709 4:2:0 round trip alone: 29.3 and 26.6 dB), so its bound is JPEG's plus one.
const MATCH_DB = { jpeg: 24, mjpeg: 24, s3tc: 19, h264: 25 };
const PAGES = path.join(WEB, 'test/browser/pages');

let env, node, tmp;
const refs = [];
before(async () => {
  if (!BIN) return;
  tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'tessera-node-e2e-'));
  for (const k of [0, 1, 2]) {
    const out = renderReference(BIN, { scene: path.join(PAGES, 'node-scene.gltf'), loop: path.join(PAGES, 'node-camera-loop.json'),
      frame: k, width: W, height: H, out: path.join(tmp, `ref${k}.png`) });
    refs.push(fs.readFileSync(out).toString('base64'));
  }
  node = await startNode(BIN, { threads: 2, args: ['--tessera.web-public=["test/browser/pages/"]'] });
  env = await launch();
});
after(async () => {
  if (env) await env.close();
  if (node) await node.close();
  if (tmp) fs.rmSync(tmp, { recursive: true, force: true });
});

// RGBA pixels of the frame display (JPEG canvas, S3TC WebGL canvas or MJPEG img), W x H.
const shown = (page) => page.evaluate(([w, h]) => {
  const src = document.querySelector('.tessera-display');
  if (!src || (src.localName === 'img' && !src.naturalWidth) || !src.width) return null;
  const c = new OffscreenCanvas(w, h), g = c.getContext('2d');
  g.drawImage(src, 0, 0, w, h);
  return btoa(String.fromCharCode(...g.getImageData(0, 0, w, h).data));
}, [W, H]);

// A reference PNG (base64) decoded by the browser to RGBA.
const decoded = new Map();
async function reference(page, k) {
  if (!decoded.has(k)) {
    decoded.set(k, await page.evaluate(async ([b64, w, h]) => {
      const bmp = await createImageBitmap(new Blob([Uint8Array.from(atob(b64), (ch) => ch.charCodeAt(0))], { type: 'image/png' }));
      if (bmp.width !== w || bmp.height !== h) throw new Error(`reference is ${bmp.width}x${bmp.height}`);
      const c = new OffscreenCanvas(w, h), g = c.getContext('2d');
      g.drawImage(bmp, 0, 0);
      return btoa(String.fromCharCode(...g.getImageData(0, 0, w, h).data));
    }, [refs[k], W, H]));
  }
  return Buffer.from(decoded.get(k), 'base64');
}

function psnr(a, b) {
  let se = 0;
  for (let i = 0; i < a.length; i += 4) for (let c = 0; c < 3; c++) { const d = a[i + c] - b[i + c]; se += d * d; }
  const mse = se / (a.length / 4 * 3);
  return mse === 0 ? 99 : 10 * Math.log10(255 * 255 / mse);
}

const frameCount = (page) => page.evaluate(() => (window.__frames || []).length);
const pageState = (page) => page.evaluate(() => ({
  status: document.querySelector('.tessera-status') && document.querySelector('.tessera-status').textContent,
  connection: document.querySelector('.tessera-xml3d') && document.querySelector('.tessera-xml3d').dataset.connection,
  frames: (window.__frames || []).length,
}));

// Waits until a server frame newer than `after` frames is shown and matches reference k.
async function untilMatches(page, k, bound, { after = 0, timeout = 20000 } = {}) {
  const t0 = Date.now();
  let last = null;
  while (Date.now() - t0 < timeout) {
    if (await frameCount(page) > after) {
      const img = await shown(page);
      if (img) {
        last = psnr(Buffer.from(img, 'base64'), await reference(page, k));
        if (last >= bound) return { psnr: last, image: Buffer.from(img, 'base64'), ms: Date.now() - t0 };
      }
    }
    await new Promise((r) => setTimeout(r, 50));
  }
  const st = await pageState(page);
  assert.fail(`no server frame matching reference ${k} within ${timeout} ms (last PSNR ${last && last.toFixed(1)} dB, `
    + `${st.frames} frames, connection ${st.connection}, status "${st.status}")\n${page.logs.join('\n')}\n`
    + `node log tail:\n${node.log.slice(-10).join('\n')}`);
}

// `init`: a script to run in the page before its own (page.addInitScript).
async function openNodePage(query, { init = null } = {}) {
  const page = await env.context.newPage();
  page.logs = [];
  page.on('console', (m) => page.logs.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => page.logs.push(`pageerror: ${e.message}`));
  if (init) await page.addInitScript(init);
  // The page comes from the node itself (same origin as its MJPEG stream, so the test can read
  // the shown pixels): a node serves only the client and demo files of its web root unless told
  // otherwise, so startNode below names the test pages' folder in tessera.web-public.
  await page.goto(`${node.base}/test/browser/pages/node.html?server=${node.host}:${node.port}&${query}`);
  return page;
}

for (const display of ['jpeg', 's3tc', 'mjpeg', 'h264']) {
  test(`display=${display}: real-node frames match tessera render; moving the camera or the model gives matching new frames`,
    { skip: !BIN && 'TESSERA_BIN not set (CTest passes the tessera binary)' }, async () => {
      const page = await openNodePage(`display=${display}`);
      const bound = MATCH_DB[display];
      const start = await untilMatches(page, 0, bound);
      const info = await page.evaluate(() => ({ display: document.getElementById('x').tessera.backend.display,
        element: document.querySelector('.tessera-display').localName, encodings: [...new Set(window.__frames.map((f) => f.encoding))] }));
      assert.equal(info.display, display, 'the page kept the display method it asked for');
      assert.equal(info.element, display === 'mjpeg' ? 'img' : 'canvas');
      if (display !== 'mjpeg') assert.deepEqual(info.encodings, [{ s3tc: 'dxt1', h264: 'h264' }[display] || 'jpeg']);
      const otherView = psnr(start.image, await reference(page, 1));
      assert.ok(otherView < Math.min(bound, start.psnr - 8), `views are told apart: ${otherView.toFixed(1)} dB against another view`);

      // A page script moves the camera to frame 1 of the loop.
      let n = await frameCount(page);
      await page.evaluate(() => window.setCameraFrame(1));
      const moved = await untilMatches(page, 1, bound, { after: n });
      // A page script moves the model (by model_shift): the same picture as the camera moved the other way.
      n = await frameCount(page);
      await page.evaluate(() => { window.setCameraFrame(0); window.shiftModel(); });
      const shifted = await untilMatches(page, 2, bound, { after: n });
      const unshifted = psnr(shifted.image, await reference(page, 0));
      assert.ok(unshifted < Math.min(bound, shifted.psnr - 6), `the moved model is not the start view: ${unshifted.toFixed(1)} dB`);
      console.log(`# ${display}: PSNR start ${start.psnr.toFixed(1)} dB (other view ${otherView.toFixed(1)}), camera moved ${moved.psnr.toFixed(1)} dB `
        + `after ${moved.ms} ms, model moved ${shifted.psnr.toFixed(1)} dB (start view ${unshifted.toFixed(1)}) after ${shifted.ms} ms`);
      const st = await pageState(page);
      assert.equal(st.connection, 'ready');
      assert.ok(!/server:/.test(st.status || ''), `no server errors: ${st.status}`);
      await page.close();
    });
}

const displayInfo = (page) => page.evaluate(() => ({ display: document.getElementById('x').tessera.backend.display,
  encodings: [...new Set(window.__frames.map((f) => f.encoding))] }));
const warnings = (page) => page.logs.filter((l) => l.startsWith('warning:'));

test('display=h264 without WebCodecs (VideoDecoder deleted before the page loads) shows JPEG frames after one warning; display=auto then picks JPEG silently',
  { skip: !BIN && 'TESSERA_BIN not set (CTest passes the tessera binary)' }, async () => {
    const noWebCodecs = () => { delete window.VideoDecoder; };
    for (const display of ['h264', 'auto']) {
      const page = await openNodePage(`display=${display}`, { init: noWebCodecs });
      const start = await untilMatches(page, 0, MATCH_DB.jpeg);
      assert.deepEqual(await displayInfo(page), { display: 'jpeg', encodings: ['jpeg'] });
      const warned = warnings(page);
      if (display === 'h264') {
        assert.equal(warned.length, 1, `exactly one warning:\n${page.logs.join('\n')}`);
        assert.match(warned[0], /no VideoDecoder.*display="h264" falls back to JPEG frames/);
      } else assert.deepEqual(warned, [], 'auto falls back without a warning');
      const st = await pageState(page);
      assert.equal(st.connection, 'ready');
      assert.ok(!/⚠/.test(st.status || ''), `no red status line: ${st.status}`);
      console.log(`# display=${display} without VideoDecoder: JPEG frames at ${start.psnr.toFixed(1)} dB, ${warned.length} warning(s)`);
      await page.close();
    }
  });

test('display=h264 shows H.264 where WebCodecs decodes it; after a decoder error the page asks for one keyframe and shows the node\'s next frames; video-kbps is accepted',
  { skip: !BIN && 'TESSERA_BIN not set (CTest passes the tessera binary)' }, async () => {
    const page = await openNodePage('display=h264');
    await untilMatches(page, 0, MATCH_DB.h264);
    assert.deepEqual(await displayInfo(page), { display: 'h264', encodings: ['h264'] });
    // From here on: whether each unit that comes is a keyframe (NAL type 5), and what the page sends.
    await page.evaluate(async () => {
      const { decodeClient } = await import('/src/net/Protocol.js');
      const { isKeyframe } = await import('/src/net/FrameDisplay.js');
      const ch = document.getElementById('x').tessera.backend.channel, onFrame = ch.onFrame, send = ch.send.bind(ch);
      window.__units = [];
      ch.onFrame = (r) => { window.__units.push(isKeyframe(r.payload)); onFrame(r); };
      window.__sent = [];
      ch.send = (bytes) => { window.__sent.push(decodeClient(bytes).map((r) => (r.type === 'video' ? `video ${r.bitrateKbps} ${r.keyframe}` : r.type))); send(bytes); };
    });
    // A decoder error (as a corrupt unit would cause): the display takes a fresh decoder, skips
    // delta units until a keyframe and asks for one, once; the node sends it with the frame that
    // the render request in the same message asks for.
    const n = await frameCount(page);
    await page.evaluate(() => { const v = document.getElementById('x').tessera.backend.frameView; v.failed(v.decoder, new Error('test: decoder broke')); });
    await page.evaluate(() => window.setCameraFrame(1));
    const moved = await untilMatches(page, 1, MATCH_DB.h264, { after: n });
    const { units, sent } = await page.evaluate(() => ({ units: window.__units, sent: window.__sent }));
    assert.deepEqual(sent[0], ['video 0 true', 'render'], JSON.stringify(sent));
    assert.equal(sent.flat().filter((r) => r === 'video 0 true').length, 1, `one keyframe request: ${JSON.stringify(sent)}`);
    assert.ok(units.includes(true), `a keyframe came after the request: ${JSON.stringify(units)}`);
    const warned = warnings(page);
    assert.equal(warned.length, 1, page.logs.join('\n'));
    assert.match(warned[0], /H\.264 decoder failed \(test: decoder broke\); asking the node for a keyframe/);
    // A bitrate from the page: a video record, which the node takes (no error); frames go on.
    const m = await frameCount(page);
    await page.evaluate(() => { document.getElementById('x').setAttribute('video-kbps', '2000'); window.setCameraFrame(0); });
    const back = await untilMatches(page, 0, MATCH_DB.h264, { after: m });
    assert.ok((await page.evaluate(() => window.__sent.flat())).includes('video 2000 false'));
    const st = await pageState(page);
    assert.equal(st.connection, 'ready');
    assert.ok(!/server:/.test(st.status || ''), `no server errors: ${st.status}`);
    console.log(`# h264 decoder error: units after it ${units.map((k) => (k ? 'K' : 'P')).join('')}, the new view at ${moved.psnr.toFixed(1)} dB `
      + `after ${moved.ms} ms; video-kbps=2000: ${back.psnr.toFixed(1)} dB`);
    await page.close();
  });

// The view moves (setCameraFrame 0, 1, 2, ...) every 40 ms for `ms`, as a page does while the
// user drags: the page asks for frames as fast as its run loop goes.
const moveFor = (page, ms) => page.evaluate(async (ms) => {
  for (let t0 = performance.now(), k = 0; performance.now() - t0 < ms; k++) {
    window.setCameraFrame(k % 3);
    await new Promise((r) => setTimeout(r, 40));
  }
}, ms);
const autoLines = (page) => page.logs.filter((l) => l.includes('display="auto"'));

test('display=auto starts with JPEG where WebCodecs decodes H.264, stays with it on a fast link saying nothing, and switches to H.264 with one console line when the link holds the JPEG frames back',
  { skip: !BIN && 'TESSERA_BIN not set (CTest passes the tessera binary)' }, async () => {
    const page = await openNodePage('display=auto');
    await untilMatches(page, 0, MATCH_DB.jpeg);
    assert.deepEqual(await displayInfo(page), { display: 'jpeg', encodings: ['jpeg'] });
    // Localhost: the node bounds the frames. The page measures (LinkProbe: a window is 2 s of
    // waiting for frames, which takes longer to gather here: on a quiet machine a 160x120 frame
    // comes about 3 ms after its request, so 30 s of moves gathered 1.6-1.8 s) and keeps JPEG.
    const probe = () => page.evaluate(() => { const b = document.getElementById('x').tessera.backend; return { display: b.display, windows: b.probe && b.probe.windows, frames: b.probe && b.probe.frames, waitMs: b.probe && Math.round(b.probe.waitMs) }; });
    const tf = Date.now();
    while (Date.now() - tf < 60000 && !((await probe()).windows >= 1)) await moveFor(page, 500);
    const fast = await probe();
    assert.equal(fast.display, 'jpeg');
    assert.ok(fast.windows >= 1, `measured: ${JSON.stringify(fast)}`);
    assert.deepEqual(autoLines(page), [], 'nothing said');
    // A slow link (chromium's network emulation: 24 KB/s down, 20 ms latency) while the view
    // moves: the JPEG frames come far slower than the node renders them.
    const cdp = await env.context.newCDPSession(page);
    await cdp.send('Network.enable');
    await cdp.send('Network.emulateNetworkConditions', { offline: false, latency: 20, downloadThroughput: 24000, uploadThroughput: 1000000 });
    const t0 = Date.now();
    while (Date.now() - t0 < 20000 && await page.evaluate(() => document.getElementById('x').tessera.backend.display) === 'jpeg') await moveFor(page, 500);
    const lines = autoLines(page);
    const switched = await page.evaluate(() => document.getElementById('x').tessera.backend.display);
    await cdp.send('Network.emulateNetworkConditions', { offline: false, latency: 0, downloadThroughput: -1, uploadThroughput: -1 });
    // (Debian's chromium 156 throttles WebSocket messages too; an emulation that did not would fail here.)
    assert.equal(switched, 'h264');
    assert.equal(lines.length, 1, page.logs.join('\n'));
    assert.match(lines[0], /^info: XML3D\/Tessera: display="auto": JPEG frames came at [\d.]+\/s \([\d.]+ Mbit\/s\) where the node gives [\d.]+\/s: the link bounds them, switching to H\.264$/);
    // The new session shows H.264 frames of the view. The view may be camera 0 already (the
    // moves cycle 0, 1, 2), and the new session's first frame may have come: move it away and
    // wait for that frame, so that setting camera 0 is a change whose frame comes after n.
    await page.evaluate(() => window.setCameraFrame(1));
    const away = await frameCount(page);
    for (const t1 = Date.now(); Date.now() - t1 < 20000 && await frameCount(page) <= away;) await new Promise((r) => setTimeout(r, 50));
    const n = await frameCount(page);
    await page.evaluate(() => window.setCameraFrame(0));
    const h = await untilMatches(page, 0, MATCH_DB.h264, { after: n });
    assert.equal((await displayInfo(page)).display, 'h264');
    console.log(`# display=auto: on localhost ${fast.windows} window(s) judged, JPEG kept; at 24 KB/s: ${lines[0].replace(/^info: XML3D\/Tessera: display="auto": /, '')} `
      + `after ${((Date.now() - t0) / 1000).toFixed(1)} s; H.264 at ${h.psnr.toFixed(1)} dB`);
    assert.deepEqual(warnings(page), []);
    await page.close();
  });

test('a mouse drag orbits the camera (examine controller) and the node\'s next frame shows the orbited view',
  { skip: !BIN && 'TESSERA_BIN not set (CTest passes the tessera binary)' }, async () => {
    const page = await openNodePage('display=jpeg&controller=examine');
    await untilMatches(page, 0, MATCH_DB.jpeg);
    const box = await page.evaluate(() => { const r = document.querySelector('.tessera-xml3d').getBoundingClientRect(); return [r.left + r.width / 2, r.top + r.height / 2]; });
    const n = await frameCount(page);
    await page.mouse.move(box[0], box[1]);
    await page.mouse.down();
    await page.mouse.move(box[0] + 30, box[1] + 6, { steps: 3 });
    await page.mouse.up();
    // The view the page now has (camera to world), as a camera loop for `tessera render`.
    await page.waitForFunction(() => document.getElementById('x').tessera.scene.camera.toWorld[12] !== 0.5, null, { timeout: 5000 });
    const m = await page.evaluate(() => [...document.getElementById('x').tessera.scene.camera.toWorld]);
    const eye = [m[12], m[13], m[14]], target = [m[12] - m[8], m[13] - m[9], m[14] - m[10]];
    const loop = JSON.parse(fs.readFileSync(path.join(PAGES, 'node-camera-loop.json'), 'utf8'));
    const centre = [0.05, 0.55, -0.15];  // roughly the scene's middle: an orbit keeps the distance to the examine point
    const dist = (p) => Math.hypot(p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]);
    assert.ok(Math.abs(dist(eye) - dist(loop.frames[0].eye)) < 0.5, `orbit, not a jump: eye ${eye.map((v) => v.toFixed(2))}`);
    fs.writeFileSync(path.join(tmp, 'orbit.json'), JSON.stringify({ fovY_deg: loop.fovY_deg, frames: [{ eye, target, up: [0, 1, 0] }] }));
    renderReference(BIN, { scene: path.join(PAGES, 'node-scene.gltf'), loop: path.join(tmp, 'orbit.json'), frame: 0, width: W, height: H,
      out: path.join(tmp, 'ref3.png') });
    refs[3] = fs.readFileSync(path.join(tmp, 'ref3.png')).toString('base64');
    const orbited = await untilMatches(page, 3, MATCH_DB.jpeg, { after: n });
    const before = psnr(orbited.image, await reference(page, 0));
    assert.ok(before < orbited.psnr - 3, `the frame changed with the drag: ${before.toFixed(1)} dB against the start view, ${orbited.psnr.toFixed(1)} against the orbited one`);
    console.log(`# drag: orbited view ${orbited.psnr.toFixed(1)} dB (start view ${before.toFixed(1)} dB)`);
    await page.close();
  });

const mean = (img) => { let s = 0; for (let i = 0; i < img.length; i += 4) s += img[i] + img[i + 1] + img[i + 2]; return s / (img.length / 4 * 3); };
async function untilImage(page, pred, { after = 0, timeout = 15000 } = {}, what = '') {
  const t0 = Date.now();
  while (Date.now() - t0 < timeout) {
    if (await frameCount(page) > after) {
      const b64 = await shown(page);
      if (b64) { const img = Buffer.from(b64, 'base64'); if (pred(img)) return img; }
    }
    await new Promise((r) => setTimeout(r, 50));
  }
  const st = await pageState(page);
  return assert.fail(`${what}: not within ${timeout} ms (${st.frames} frames, status "${st.status}")\n${page.logs.join('\n')}`);
}

test('ao-samples / max-depth on <xml3d> reach the node: AO darkens the ambient-lit floor, back off restores the frame, bad numbers warn',
  { skip: !BIN && 'TESSERA_BIN not set (CTest passes the tessera binary)' }, async () => {
    const page = await openNodePage(`display=jpeg&ambient=${encodeURIComponent('0.7 0.7 0.7')}`);
    await page.waitForFunction(() => document.getElementById('x').complete, null, { timeout: 20000 });
    await new Promise((r) => setTimeout(r, 300));  // frames requested while loading have come back
    const plain = Buffer.from(await shown(page), 'base64');
    let n = await frameCount(page);
    assert.ok(mean(plain) > 40, `the floor is lit by the ambient term (mean ${mean(plain).toFixed(1)})`);

    // AO on: the settings record makes the node trace occlusion rays; the floor around the boxes darkens.
    await page.evaluate(() => document.getElementById('x').setAttribute('ao-samples', '16'));
    const darker = (img) => { let d = 0; for (let i = 0; i < img.length; i += 4) if (plain[i] + plain[i + 1] + plain[i + 2] - img[i] - img[i + 1] - img[i + 2] > 45) d++; return d; };
    const ao = await untilImage(page, (img) => darker(img) > W * H * 0.03, { after: n }, 'a frame with ambient occlusion');
    assert.ok(mean(ao) < mean(plain) - 1, `AO only darkens: mean ${mean(plain).toFixed(1)} -> ${mean(ao).toFixed(1)}`);
    console.log(`# AO: ${darker(ao)} of ${W * H} pixels darker, mean ${mean(plain).toFixed(1)} -> ${mean(ao).toFixed(1)}`);

    // AO off again (attribute removed: the default, 0): the first picture comes back.
    n = await frameCount(page);
    await page.evaluate(() => document.getElementById('x').removeAttribute('ao-samples'));
    await untilImage(page, (img) => psnr(img, plain) >= 40, { after: n }, 'the AO-free frame again');

    // A depth change is a settings record too, accepted by the node (a new frame, no error).
    n = await frameCount(page);
    await page.evaluate(() => document.getElementById('x').setAttribute('max-depth', '2'));
    await page.waitForFunction((k) => window.__frames.length > k, n, { timeout: 10000 });

    // Bad numbers: a clear console warning and status line; the default is used (no AO, no error from the node).
    n = await frameCount(page);
    await page.evaluate(() => { const x = document.getElementById('x'); x.setAttribute('ao-samples', 'lots'); x.setAttribute('max-depth', '-3'); });
    await page.waitForFunction(() => /ao-samples="lots"/.test(document.querySelector('.tessera-status').textContent), null, { timeout: 5000 });
    const warnings = page.logs.filter((l) => l.startsWith('warning: XML3D: <xml3d'));
    assert.ok(warnings.some((w) => /ao-samples="lots">: not a whole number in 0\.\.256 .*using 0/.test(w)), warnings.join('\n'));
    assert.ok(warnings.some((w) => /max-depth="-3">: not a whole number in 1\.\.64 .*using 4/.test(w)), warnings.join('\n'));
    await page.waitForFunction((k) => window.__frames.length > k, n, { timeout: 10000 });  // depth 2 -> default 4
    assert.ok(psnr(Buffer.from(await shown(page), 'base64'), plain) >= 40, 'default settings: no AO');
    const st = await pageState(page);
    assert.equal(st.connection, 'ready');
    assert.ok(!/server:/.test(st.status), `no server errors: ${st.status}`);
    await page.close();
  });

// The pavilion demo page in server mode, once XML3D's load event came; its console lines in
// page.logs. No AO (its noise is seeded per session) and no refinement: two sessions of the
// same scene and view then give the same frame. `setup(page)` runs before it loads.
async function openPavilion(query, setup = async () => {}) {
  const page = await env.context.newPage();
  page.logs = [];
  page.on('console', (m) => page.logs.push(`${m.type()}: ${m.text()}`));
  await setup(page);
  await page.addInitScript(() => {
    window.__frames = [];
    document.addEventListener('framedrawn', (e) => window.__frames.push(e.detail.frame), true);
    window.__load = false;
    document.addEventListener('load', (e) => { if (e.target.localName === 'xml3d') window.__load = true; }, true);
  });
  await page.goto(`${node.base}/demo/pavilion.html?server=${node.host}:${node.port}&display=jpeg&ao-samples=0&refine-samples=1&frame-budget=0${query}`);
  await page.waitForFunction(() => window.__load, null, { timeout: 60000, polling: 100 });
  return page;
}

test('a demo page whose glTF lies in the node\'s own /scenes/ sends references: the node loads every one, and the picture equals the uploaded scene\'s',
  { skip: !BIN && 'TESSERA_BIN not set (CTest passes the tessera binary)' }, async () => {
    const openDemo = (query) => openPavilion(query);
    const events = () => node.log.filter((l) => l.includes('"references"')).map((l) => JSON.parse(l));
    const before = events().length;
    const refs = await openDemo('');
    // The references reach the node after the page's own loads (the load event may come first).
    const total = (list) => list.reduce((n, e) => n + e.loaded + e.refused, 0);
    for (const t0 = Date.now(); Date.now() - t0 < 60000 && total(events().slice(before)) < 366; ) await new Promise((r) => setTimeout(r, 200));
    await new Promise((r) => setTimeout(r, 500));
    const loaded = events().slice(before);
    assert.equal(total(loaded), 366, `the pavilion's 366 references reached the node: ${JSON.stringify(loaded)}`);
    assert.equal(loaded.reduce((n, e) => n + e.refused, 0), 0, `none refused: ${JSON.stringify(loaded)}`);
    assert.ok(loaded.reduce((n, e) => n + e.loaded, 0) > 100, 'the pavilion\'s buffers and textures went as references');
    assert.ok(!refs.logs.some((l) => /refused/.test(l)), refs.logs.join('\n'));
    const upload = await openDemo('&references=off');
    assert.equal(events().length, before + loaded.length, 'references="off" sends none');
    // XML3D's load event comes with the first frame after the page's own loads, before the node
    // has the whole scene: wait (on a loaded machine, seconds) until both pages show the same.
    let same = 0;
    for (const t0 = Date.now(); Date.now() - t0 < 60000 && same < 40; await new Promise((r) => setTimeout(r, 250))) {
      const [a, b] = [await shown(refs), await shown(upload)];
      if (a && b) same = psnr(Buffer.from(a, 'base64'), Buffer.from(b, 'base64'));
    }
    assert.ok(same >= 40, `the referenced scene looks as the uploaded one: ${same.toFixed(1)} dB`);
    console.log(`# references: ${loaded.reduce((n, e) => n + e.loaded, 0)} loaded in ${loaded.map((e) => e.ms).join(', ')} ms; `
      + `against the upload ${same.toFixed(1)} dB`);
    await refs.close();
    await upload.close();
  });

test('references the node refuses are uploaded after the rest of the scene went out, and the picture equals the uploaded scene\'s',
  { skip: !BIN && 'TESSERA_BIN not set (CTest passes the tessera binary)' }, async () => {
    // The page's glTF names its buffer and first image under /scenes/pavilion/refused/, where
    // the browser finds them (routed to the real files) and the node finds nothing: it refuses
    // those references, and the client uploads them behind the materials and meshes it sent.
    const openDemo = (query, refuse) => openPavilion(query, async (page) => {
      if (refuse) {
        await page.route('**/scenes/pavilion/scene.gltf', async (route) => {
          const gltf = await (await route.fetch()).json();
          gltf.buffers[0].uri = `refused/${gltf.buffers[0].uri}`;
          gltf.images[0].uri = `refused/${gltf.images[0].uri}`;
          await route.fulfill({ status: 200, contentType: 'model/gltf+json', body: JSON.stringify(gltf) });
        });
        await page.route('**/scenes/pavilion/refused/**', async (route) =>
          route.fulfill({ response: await route.fetch({ url: route.request().url().replace('/refused/', '/') }) }));
      }
    });
    const events = () => node.log.filter((l) => l.includes('"references"')).map((l) => JSON.parse(l));
    const before = events().length;
    const refused = await openDemo('', true);
    const total = (list) => list.reduce((n, e) => n + e.loaded + e.refused, 0);
    for (const t0 = Date.now(); Date.now() - t0 < 60000 && total(events().slice(before)) < 366; ) await new Promise((r) => setTimeout(r, 200));
    const answered = events().slice(before);
    const nRefused = answered.reduce((n, e) => n + e.refused, 0);
    assert.ok(nRefused > 100, `the buffer's references and the image's were refused: ${JSON.stringify(answered)}`);
    assert.ok(answered.some((e) => /no file of this node's \/scenes\/ at \/scenes\/pavilion\/refused\//.test(e.first_refusal || '')),
      JSON.stringify(answered));
    assert.equal(refused.logs.filter((l) => /refused \d+ references?/.test(l)).length, 1, refused.logs.join('\n'));
    const upload = await openDemo('&references=off', false);
    let same = 0;
    for (const t0 = Date.now(); Date.now() - t0 < 60000 && same < 40; await new Promise((r) => setTimeout(r, 250))) {
      const [a, b] = [await shown(refused), await shown(upload)];
      if (a && b) same = psnr(Buffer.from(a, 'base64'), Buffer.from(b, 'base64'));
    }
    assert.ok(same >= 40, `the scene with refused references looks as the uploaded one: ${same.toFixed(1)} dB`);
    console.log(`# references: ${nRefused} refused and uploaded; against the upload ${same.toFixed(1)} dB`);
    await refused.close();
    await upload.close();
  });

test('the references go out before the browser has downloaded the glTF\'s buffers; XML3D\'s load event waits for them',
  { skip: !BIN && 'TESSERA_BIN not set (CTest passes the tessera binary)' }, async () => {
    const page = await env.context.newPage();
    let release;
    const held = new Promise((r) => (release = r));
    let binRequested = false;
    await page.route('**/scenes/pavilion/*.bin', async (route) => { binRequested = true; await held; await route.continue(); });
    await page.addInitScript(() => {
      window.__load = false;
      document.addEventListener('load', (e) => { if (e.target.localName === 'xml3d') window.__load = true; }, true);
    });
    const events = () => node.log.filter((l) => l.includes('"references"')).map((l) => JSON.parse(l));
    const before = events().length;
    try {
      await page.goto(`${node.base}/demo/pavilion.html?server=${node.host}:${node.port}&display=jpeg&ao-samples=0`);
      const total = () => events().slice(before).reduce((n, e) => n + e.loaded + e.refused, 0);
      // The route's handler runs when Playwright hears of the request, which on a loaded
      // machine can be after the node has answered every reference: wait for both.
      for (const t0 = Date.now(); Date.now() - t0 < 60000 && (total() < 366 || !binRequested); ) await new Promise((r) => setTimeout(r, 200));
      assert.ok(binRequested, 'the page asked for the buffer');
      assert.equal(total(), 366, 'every reference reached the node while the buffer was held back');
      assert.equal(await page.evaluate(() => window.__load), false, 'no load event while the buffer is on its way');
    } finally {
      release();
    }
    await page.waitForFunction(() => window.__load, null, { timeout: 60000, polling: 100 });
    await page.close();
  });
