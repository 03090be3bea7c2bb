// The server path against a mock Tessera node: a WebSocket server in Node that checks the
// handshake and every record the page sends against the protocol (decoded with our own
// decoder, byte-checked against protocol/protocol.cpp in the unit tests) and answers render
// requests with a JPEG (or DXT1) frame (and, with `refine`, refines it as a node does: frames
// with the same number, refined, 2..target samples, the target from the page's refine record;
// with `frameSize`, its frames have that size instead of the page's, as within a frame budget).
// TODO(e2e): the same checks against a real node belong in web/test/browser/node-e2e.test.js
// (start app/tessera-node serving web/ and ../shared/scenes, open /demo/pavilion.html?server=...).
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import zlib from 'node:zlib';
import { WebSocketServer } from 'ws';
import { launch, open } from './browser.js';
import { decodeClient, encodeServer, dxt1Size } from '../../src/net/Protocol.js';

let env, jpeg;
const jpegs = {};  // 'WxH' -> a solid green JPEG of that size
before(async () => {
  env = await launch();
  // Solid green JPEGs (64x48, the page's size, and 32x24), made by the browser itself.
  const page = await env.context.newPage();
  for (const [w, h] of [[64, 48], [32, 24]]) {
    const b64 = await page.evaluate(async ([w, h]) => {
      const c = new OffscreenCanvas(w, h);
      const g = c.getContext('2d');
      g.fillStyle = 'rgb(0, 200, 0)';
      g.fillRect(0, 0, w, h);
      const blob = await c.convertToBlob({ type: 'image/jpeg', quality: 0.95 });
      const bytes = new Uint8Array(await blob.arrayBuffer());
      return btoa(String.fromCharCode(...bytes));
    }, [w, h]);
    jpegs[`${w}x${h}`] = new Uint8Array(Buffer.from(b64, 'base64'));
  }
  jpeg = jpegs['64x48'];
  await page.close();
});
after(async () => { await env.close(); });

class MockNode {
  constructor({ encoding = 'jpeg', refine = false, frameSize = [64, 48], answerReferences = false } = {}) {
    this.encoding = encoding;
    this.answerReferences = answerReferences;
    this.refine = refine;
    this.frameSize = frameSize;
    this.sessions = [];
    this.wss = new WebSocketServer({ host: '127.0.0.1', port: 0, path: '/ws' });
    this.wss.on('connection', (ws, req) => this.session(ws, req));
    this.waiters = [];
  }
  get port() { return this.wss.address().port; }
  session(ws, req) {
    const s = { ws, url: req.url, messages: [], records: [], renders: [], problems: [] };
    this.sessions.push(s);
    ws.on('message', (data) => {
      const bytes = new Uint8Array(data);
      let recs;
      try { recs = decodeClient(bytes); } catch (e) { s.problems.push(`undecodable message: ${e.message}`); return; }
      if (s.messages.length === 0) {
        if (recs.length !== 1 || recs[0].type !== 'handshake') s.problems.push('first message is not exactly one handshake');
        s.handshake = recs[0];
        ws.send(encodeServer([{ type: 'handshake_reply', renderer: 'raytracer', display: s.handshake.display, jpegQuality: 85, nodes: 2,
          width: s.handshake.width, height: s.handshake.height, maxMessageBytes: 1 << 20, maxBufferBytes: 1 << 28, serverVersion: 'mock 1' }]));
      } else if (recs.some((r) => r.type === 'handshake')) s.problems.push('handshake repeated');
      s.messages.push(bytes);
      for (const r of recs) {
        if (r.type === 'buffer' && r.deflate) {
          const raw = zlib.inflateSync(Buffer.from(r.payload));  // zlib format, as inflateInit2(15)
          if (raw.length !== r.values * 4) s.problems.push(`buffer ${r.id}: inflated ${raw.length} bytes, declared ${r.values * 4}`);
          const ab = raw.buffer.slice(raw.byteOffset, raw.byteOffset + raw.length);
          r.data = r.bufferType === 'f32' ? new Float32Array(ab) : new Uint32Array(ab);
        }
        if (r.type !== 'handshake') s.records.push(r);
        if (this.answerReferences && (r.type === 'buffer_ref' || r.type === 'texture_ref')) {
          ws.send(encodeServer([{ type: 'reference', what: r.type === 'buffer_ref' ? 'buffer' : 'texture', ok: true, id: r.id,
            bytes: 0, message: '' }]));
        }
        if (r.type === 'render') {
          s.renders.push(r.frame);
          const dxt = this.encoding === 'dxt1';
          const [width, height] = this.frameSize;
          let payload = jpegs[`${width}x${height}`];
          if (dxt) {  // DXT1 blocks: colour0 = colour1 = pure red (RGB565 0xf800), indices 0
            payload = new Uint8Array(dxt1Size(width, height));
            for (let i = 0; i < payload.length; i += 8) { payload[i] = 0x00; payload[i + 1] = 0xf8; payload[i + 2] = 0x00; payload[i + 3] = 0xf8; }
          }
          ws.send(encodeServer([{ type: 'frame', frame: r.frame, width, height, encoding: dxt ? 'dxt1' : 'jpeg',
            timings: { rendering: 5, pipeline: 7 }, payload }]));
          for (let k = 2; this.refine && k <= (s.refineSamples ?? 0); k++) {
            ws.send(encodeServer([{ type: 'frame', frame: r.frame, width, height, encoding: dxt ? 'dxt1' : 'jpeg',
              refined: true, samples: k, timings: { rendering: 5, pipeline: 7 }, payload }]));
          }
        }
        if (r.type === 'refine') {
          s.refineSamples = r.samples;
          s.refineAt = s.records.length - 1;
        }
      }
      for (const w of this.waiters.splice(0)) w();
    });
  }
  // Resolves when pred() holds after some message.
  until(pred, ms = 10000) {
    return new Promise((resolve, reject) => {
      const t = setTimeout(() => reject(new Error('timed out waiting for the page')), ms);
      const check = () => { if (pred()) { clearTimeout(t); resolve(); } else this.waiters.push(check); };
      check();
    });
  }
  close() { for (const s of this.sessions) s.ws.terminate(); this.wss.close(); }
}

async function displayPixel(page) {
  return page.evaluate(() => {
    const src = document.querySelector('.tessera-display');
    const c = new OffscreenCanvas(src.width, src.height);
    const g = c.getContext('2d');
    g.drawImage(src, 0, 0);
    return [...g.getImageData(32, 24, 1, 1).data];
  });
}

test('the page syncs its scene over the protocol and shows the JPEG frame that comes back', async () => {
  const node = new MockNode();
  await new Promise((r) => node.wss.on('listening', r));
  const page = await open(env, `/test/browser/pages/remote.html?server=127.0.0.1:${node.port}`);
  const s = node.sessions[0];
  assert.deepEqual(s.problems, []);
  assert.match(s.url, /^\/ws\?session=\w+/);
  assert.equal(s.handshake.renderer, 'raytracer');
  assert.equal(s.handshake.display, 'jpeg');
  assert.deepEqual([s.handshake.width, s.handshake.height], [64, 48]);
  const byType = (t) => s.records.filter((r) => r.type === t);
  const mesh = byType('mesh')[0];
  const pos = byType('buffer').find((b) => b.id === mesh.positions);
  assert.equal(pos.deflate, true, 'buffers of 256 bytes or more are deflated');
  assert.equal(pos.data.length, 36 * 3);
  assert.deepEqual([...pos.data.slice(0, 6)], [-1, -1, 0, 1, -1, 0]);
  assert.equal(mesh.transform[14], -5);
  const mat = byType('material').find((m) => m.id === mesh.material);
  assert.equal(mat.model, 'matte');
  assert.deepEqual(mat.diffuseColor, [1, 0, 0]);
  const light = byType('light')[0];
  assert.equal(light.lightType, 'point');
  assert.deepEqual(light.color, [1, 0.5, 0.25]);
  assert.deepEqual(byType('resolution')[0], { type: 'resolution', width: 64, height: 48 });
  const envRec = byType('environment')[0];
  assert.equal(envRec.linear, false);
  assert.deepEqual(envRec.background, [0, 0, 1]);
  assert.ok(Math.abs(byType('camera')[0].fovY - Math.PI / 4) < 1e-6);
  assert.ok(s.renders.length >= 1);
  // The render request comes after the scene it renders.
  assert.equal(s.records.findIndex((r) => r.type === 'render') > s.records.findIndex((r) => r.type === 'mesh'), true);
  const px = await displayPixel(page);
  assert.ok(px[0] < 30 && px[1] > 170 && px[2] < 30, `display shows the frame: ${px}`);

  // A DOM change sends just that change, then a render request.
  const before = s.records.length;
  await page.evaluate(() => document.getElementById('t').setAttribute('translation', '1 0 -5'));
  await node.until(() => s.records.slice(before).some((r) => r.type === 'render'));
  const changes = s.records.slice(before).map((r) => r.type);
  assert.deepEqual(changes, ['mesh', 'render']);
  assert.equal(s.records[before].transform[12], 1);
  await page.close();
  node.close();
});

test('connection loss is shown and the page reconnects and re-sends the scene', async () => {
  const node = new MockNode();
  await new Promise((r) => node.wss.on('listening', r));
  const page = await open(env, `/test/browser/pages/remote.html?server=127.0.0.1:${node.port}`);
  node.sessions[0].ws.terminate();
  await page.waitForFunction(() => document.querySelector('.tessera-xml3d').dataset.connection === 'disconnected');
  const status = await page.evaluate(() => document.querySelector('.tessera-status').textContent);
  assert.match(status, /connection to the Tessera node lost/);
  await node.until(() => node.sessions.length === 2 && node.sessions[1].renders.length > 0);
  const s2 = node.sessions[1];
  assert.deepEqual(s2.problems, []);
  assert.ok(s2.records.some((r) => r.type === 'mesh') && s2.records.some((r) => r.type === 'buffer'), 'scene re-sent');
  await page.waitForFunction(() => document.querySelector('.tessera-xml3d').dataset.connection === 'ready');
  await page.close();
  node.close();
});

// XML3D's load event needs a frame of the scene with everything loaded. With references, the
// node has a glTF's buffers before the browser does: the frame of the complete scene can come
// while the browser is still downloading them, and once they are in nothing is left to send, so
// no frame follows. The load event comes all the same.
test('the load event comes when the last download ends after the frame of the complete scene, with no frame after it', async () => {
  const node = new MockNode({ answerReferences: true });
  await new Promise((r) => node.wss.on('listening', r));
  // One triangle, its buffer in a file of its own.
  const positions = new Float32Array([-1, -1, 0, 1, -1, 0, 0, 1, 0]);
  const gltf = {
    asset: { version: '2.0' }, scene: 0, scenes: [{ nodes: [0] }], nodes: [{ mesh: 0 }],
    meshes: [{ primitives: [{ attributes: { POSITION: 0 } }] }],
    accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3', min: [-1, -1, 0], max: [1, 1, 0] }],
    bufferViews: [{ buffer: 0, byteLength: 36 }],
    buffers: [{ uri: 'model.bin', byteLength: 36 }],
  };
  let release;
  const held = new Promise((r) => (release = r));
  const page = await env.context.newPage();
  await page.route('**/held/model.gltf', (route) => route.fulfill({ status: 200, contentType: 'model/gltf+json', body: JSON.stringify(gltf) }));
  await page.route('**/held/model.bin', async (route) => {
    await held;
    await route.fulfill({ status: 200, contentType: 'application/octet-stream', body: Buffer.from(positions.buffer) });
  });
  await page.addInitScript(() => {
    window.__loaded = false;
    window.__frames = 0;
    document.addEventListener('load', (e) => { if (e.target.localName === 'xml3d') window.__loaded = true; }, true);
    document.addEventListener('framedrawn', () => window.__frames++, true);
  });
  try {
    await page.goto(`${env.base}/test/browser/pages/remote-model.html?server=127.0.0.1:${node.port}`);
    await page.waitForFunction(() => window.__frames > 0, null, { timeout: 10000 });
    const s = node.sessions[0];
    // In one full test run here the reference had not been sent by the first frame (the check
    // below failed; it passed in five runs alone): that frame can come before the model's
    // records. So wait for the model's reference, its mesh and a render request after the mesh,
    // then for that frame to be drawn.
    const isRef = (r) => r.type === 'buffer_ref' && /\/held\/model\.bin$/.test(r.url);
    const meshRendered = () => {
      const m = s.records.findIndex((r) => r.type === 'mesh');
      return m >= 0 && s.records.slice(m).some((r) => r.type === 'render');
    };
    await node.until(() => s.records.some(isRef) && meshRendered()).catch(() => {});
    await page.waitForTimeout(300);
    assert.deepEqual(s.problems, []);
    assert.ok(s.records.some(isRef), 'the buffer went as a reference');
    assert.equal(await page.evaluate(() => window.__loaded), false, 'no load event while the buffer is on its way');
    const renders = s.renders.length;
    release();
    await page.waitForFunction(() => window.__loaded, null, { timeout: 10000 });
    assert.equal(s.renders.length, renders, 'nothing was sent after the download: the frame shown was already complete');
  } finally {
    release();
    await page.close();
    node.close();
  }
});

test('display="s3tc" asks for DXT1 frames and draws them with WEBGL_compressed_texture_s3tc', async () => {
  const node = new MockNode({ encoding: 'dxt1' });
  await new Promise((r) => node.wss.on('listening', r));
  const page = await open(env, `/test/browser/pages/remote.html?server=127.0.0.1:${node.port}&display=s3tc`);
  assert.equal(node.sessions[0].handshake.display, 's3tc');
  const px = await page.evaluate(() => {
    const c = document.querySelector('.tessera-display');
    const gl = c.getContext('webgl2');
    const out = new Uint8Array(4);
    gl.readPixels(32, 24, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, out);
    return [...out];
  });
  assert.deepEqual(px, [255, 0, 0, 255]);
  await page.close();
  node.close();
});

test('refine-samples reaches the node as a refine record; refined frames are shown with "refining k/N", then "converged N"', async () => {
  const node = new MockNode({ refine: true });
  await new Promise((r) => node.wss.on('listening', r));
  const page = await open(env, `/test/browser/pages/remote.html?server=127.0.0.1:${node.port}&refine-samples=5`);
  const s = node.sessions[0];
  await node.until(() => s.renders.length >= 1);
  assert.deepEqual(s.problems, []);
  assert.deepEqual(s.records[s.refineAt], { type: 'refine', samples: 5 });
  assert.ok(s.refineAt < s.records.findIndex((r) => r.type === 'render'), 'before the first render request');
  const status = () => page.evaluate(() => document.querySelector('.tessera-status').textContent);
  await page.waitForFunction(() => /converged 5/.test(document.querySelector('.tessera-status').textContent), null, { timeout: 5000 });
  // The refined frames answered no request: no more requests than changes.
  const renders = s.renders.length;
  await new Promise((r) => setTimeout(r, 300));
  assert.equal(s.renders.length, renders, 'refined frames ask for nothing');

  // A change: "interactive" after the requested frame, then the refinements again.
  await page.evaluate(() => {
    window.__refine = [];
    document.getElementById('x').addEventListener('framedrawn', (e) => window.__refine.push([e.detail.refined, e.detail.samples,
      document.querySelector('.tessera-status').textContent]));
    document.getElementById('t').setAttribute('translation', '1 0 -5');
  });
  await page.waitForFunction(() => window.__refine.some(([, samples]) => samples === 5), null, { timeout: 5000 })
    .catch(async (e) => assert.fail(`${e.message}: ${JSON.stringify(await page.evaluate(() => window.__refine))}`));
  // Each frame shown with its status (a frame that decodes after a newer one is not shown).
  const seen = (await page.evaluate(() => window.__refine))
    .map(([refined, samples, text]) => [refined, samples, /interactive|refining \d+\/\d+|converged \d+/.exec(text)?.[0]]);
  const expect = [[false, 1, 'interactive'], [true, 2, 'refining 2/5'], [true, 3, 'refining 3/5'], [true, 4, 'refining 4/5'], [true, 5, 'converged 5']];
  console.log(`# refinement shown: ${seen.map((x) => x[2]).join(', ')}`);
  assert.deepEqual(seen.at(-1), expect.at(-1), JSON.stringify(seen));
  for (const x of seen) assert.ok(expect.some((y) => JSON.stringify(y) === JSON.stringify(x)), JSON.stringify(seen));

  // refine-samples="0": a refine record of 0, and no refinement status.
  const before = s.records.length;
  await page.evaluate(() => document.getElementById('x').setAttribute('refine-samples', '0'));
  await node.until(() => s.records.slice(before).some((r) => r.type === 'render'));
  assert.deepEqual(s.records.slice(before).map((r) => r.type), ['refine', 'render']);
  await page.waitForFunction(() => !/interactive|refining|converged/.test(document.querySelector('.tessera-status').textContent), null, { timeout: 5000 });
  assert.doesNotMatch(await status(), /refin|converged|interactive/);
  await page.close();
  node.close();
});

// The pixel at (x, y) of what the page shows (a screenshot), in CSS pixels.
async function screenPixel(page, x, y) {
  const png = (await page.screenshot({ clip: { x: 0, y: 0, width: 64, height: 48 } })).toString('base64');
  return page.evaluate(async ([png, x, y]) => {
    const bitmap = await createImageBitmap(new Blob([Uint8Array.from(atob(png), (c) => c.charCodeAt(0))], { type: 'image/png' }));
    const c = new OffscreenCanvas(bitmap.width, bitmap.height);
    const g = c.getContext('2d');
    g.drawImage(bitmap, 0, 0);
    const sx = bitmap.width / 64;  // the device pixel ratio
    return [...g.getImageData(Math.floor(x * sx), Math.floor(y * sx), 1, 1).data];
  }, [png, x, y]);
}

test('frame-budget reaches the node as a budget record (33 ms by default); a frame smaller than the element is shown scaled up to it', async () => {
  for (const display of ['jpeg', 's3tc']) {
    const node = new MockNode({ encoding: display === 's3tc' ? 'dxt1' : 'jpeg', frameSize: [32, 24] });
    await new Promise((r) => node.wss.on('listening', r));
    const page = await open(env, `/test/browser/pages/remote.html?server=127.0.0.1:${node.port}&display=${display}`);
    const s = node.sessions[0];
    await node.until(() => s.renders.length >= 1);
    assert.deepEqual(s.problems, []);
    const budgetAt = s.records.findIndex((r) => r.type === 'budget');
    assert.deepEqual(s.records[budgetAt], { type: 'budget', frameMs: 33 }, display);
    assert.ok(budgetAt < s.records.findIndex((r) => r.type === 'render'), 'before the first render request');
    // The display element: its pixels are the frame's, its displayed size the element's.
    await page.waitForFunction(() => document.querySelector('.tessera-display').width === 32, null, { timeout: 5000 });
    const size = await page.evaluate(() => {
      const c = document.querySelector('.tessera-display'), r = c.getBoundingClientRect();
      return { intrinsic: [c.width, c.height], shown: [r.width, r.height] };
    });
    assert.deepEqual(size, { intrinsic: [32, 24], shown: [64, 48] }, display);
    // On screen the frame fills the element: its colour at the far corner too, not the page's blue.
    const want = display === 's3tc' ? [255, 0, 0] : [0, 200, 0];
    for (const [x, y] of [[8, 6], [56, 8], [60, 16]]) {  // above the status line
      const px = await screenPixel(page, x, y);
      assert.ok(px.slice(0, 3).every((v, i) => Math.abs(v - want[i]) < 40), `${display} at (${x}, ${y}): ${px}`);
    }
    // A new budget: a budget record, then a render request.
    const before = s.records.length;
    await page.evaluate(() => document.getElementById('x').setAttribute('frame-budget', '0'));
    await node.until(() => s.records.slice(before).some((r) => r.type === 'render'));
    assert.deepEqual(s.records.slice(before).map((r) => r.type), ['budget', 'render']);
    assert.deepEqual(s.records[before], { type: 'budget', frameMs: 0 });
    await page.close();
    node.close();
  }
});
