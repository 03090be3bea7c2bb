import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { launch, open, pixel } from './browser.js';

let env;
before(async () => { env = await launch(); });
after(async () => { await env.close(); });

test('the WebGL fallback draws a red box in the centre, transparent elsewhere', async () => {
  const page = await open(env, '/test/browser/pages/redbox.html');
  const centre = await pixel(page, 100, 75);
  assert.deepEqual(centre, [255, 0, 0, 255], page.logs.join('\n'));
  const corner = await pixel(page, 5, 5);
  assert.equal(corner[3], 0);
  await page.close();
});

test('picking returns the mesh under the point, with position and normal', async () => {
  const page = await open(env, '/test/browser/pages/picking.html');
  const r = await page.evaluate(() => {
    const x = document.getElementById('x');
    const rect = x.tessera.container.getBoundingClientRect();
    const at = (px, py) => {
      const p = {}, n = {};
      const el = x.getElementByPoint(rect.left + px, rect.top + py, p, n);
      return { id: el && el.id, p, n };
    };
    return { left: at(60, 75), right: at(140, 75), none: at(100, 140), top: at(100, 10) };
  });
  assert.equal(r.left.id, 'a');
  assert.equal(r.right.id, 'b');
  assert.equal(r.none.id, null);
  assert.ok(Number.isNaN(r.none.p.x));
  assert.equal(r.top.id, 'c');
  assert.ok(Math.abs(r.left.p.z + 6) < 1e-3);
  assert.deepEqual([r.left.n.x, r.left.n.y, Math.round(r.left.n.z)], [0, 0, 1]);
  // Drawn colours: default red matte, blue matte, lit phong green (n.l = 1).
  assert.deepEqual(await pixel(page, 60, 75), [255, 0, 0, 255]);
  assert.deepEqual(await pixel(page, 140, 75), [0, 0, 255, 255]);
  assert.deepEqual(await pixel(page, 100, 10), [0, 255, 0, 255]);
  await page.close();
});

test('picking trees are built in idle time, and a mesh whose positions change is picked where it is now', async () => {
  const page = await open(env, '/test/browser/pages/picking.html');
  // Before any pick: the client builds them once the scene has loaded (XML3DHandler.preparePicking).
  await page.evaluate(async () => { window.picker = await import('/src/scene/Picker.js'); });
  await page.waitForFunction(() => {
    const x = document.getElementById('x');
    return x.tessera.scene && x.tessera.scene.meshes.size === 3 && window.picker.unbuiltPickTrees(x.tessera.scene).length === 0;
  }, null, { timeout: 10000, polling: 100 });
  const at = (px, py) => page.evaluate(([px, py]) => {
    const x = document.getElementById('x'), r = x.tessera.container.getBoundingClientRect();
    const el = x.getElementByPoint(r.left + px, r.top + py);
    return el && el.id;
  }, [px, py]);
  assert.equal(await at(60, 75), 'a');
  assert.equal(await at(100, 140), null);
  // The quad's positions moved down by 1.4 (a new array): the old tree must not answer.
  await page.evaluate(() => { document.querySelector('#quad float3').textContent = '-1 -2.4 0 1 -2.4 0 1 -0.4 0 -1 -0.4 0'; });
  assert.equal(await at(60, 40), null);
  assert.equal(await at(60, 110), 'a');
  await page.close();
});

test('clicks are re-dispatched on the picked mesh and bubble through its group', async () => {
  const page = await open(env, '/test/browser/pages/picking.html');
  await page.evaluate(() => {
    window.clicks = [];
    document.getElementById('left').addEventListener('click', (e) => window.clicks.push([e.target.id, e.position && e.position.z]));
  });
  const box = await page.evaluate(() => { const r = document.getElementById('x').tessera.container.getBoundingClientRect(); return [r.left, r.top]; });
  await page.mouse.click(box[0] + 60, box[1] + 75);
  const clicks = await page.evaluate(() => window.clicks);
  assert.equal(clicks.length, 1);
  assert.equal(clicks[0][0], 'a');
  assert.ok(Math.abs(clicks[0][1] + 6) < 1e-3);
  await page.close();
});

test('DOM changes are picked up: attributes, value text, setScriptValue, added and removed elements', async () => {
  const page = await open(env, '/test/browser/pages/picking.html');
  const frame = () => page.evaluate(() => new Promise((r) => document.getElementById('x').addEventListener('framedrawn', () => r(), { once: true })));
  let f = frame();
  await page.evaluate(() => { document.getElementById('b').setAttribute('material', '#lit'); });
  await f;
  assert.deepEqual(await pixel(page, 140, 75), [0, 255, 0, 255]);
  f = frame();
  await page.evaluate(() => { document.querySelector('#blue float3').textContent = '1 1 0'; document.getElementById('b').setAttribute('material', '#blue'); });
  await f;
  assert.deepEqual(await pixel(page, 140, 75), [255, 255, 0, 255]);
  f = frame();
  await page.evaluate(() => document.querySelector('#blue float3').setScriptValue(new Float32Array([0, 1, 1])));
  await f;
  assert.deepEqual(await pixel(page, 140, 75), [0, 255, 255, 255]);
  f = frame();
  await page.evaluate(() => { document.getElementById('right').remove(); });
  await f;
  assert.equal((await pixel(page, 140, 75))[3], 0);
  f = frame();
  await page.evaluate(() => { document.getElementById('left').style.display = 'none'; });
  await f;
  assert.equal((await pixel(page, 60, 75))[3], 0);
  const box = await page.evaluate(() => { const b = document.getElementById('x').getWorldBoundingBox(); return [b.min.y, b.max.y]; });
  assert.ok(Math.abs(box[0] - 1.9) < 1e-4 && Math.abs(box[1] - 2.5) < 1e-4, String(box));
  await page.close();
});

test('a page module after ours finds XML3D, and <xml3d> is configured at DOMContentLoaded after it, as xml3d.js does', async () => {
  // Before: the module configured <xml3d> as soon as it ran, before the page's module below it,
  // so the scene's onload called a function that did not exist yet.
  const page = await open(env, '/test/browser/pages/late-module.html');
  await page.waitForFunction(() => window.sceneLoaded, null, { timeout: 10000 });
  const seen = await page.evaluate(() => ({ before: window.configuredBeforePageModule, global: window.xml3dGlobalInPageModule }));
  assert.deepEqual(seen, { before: false, global: true });
  assert.deepEqual(page.logs.filter((l) => /^(error|pageerror):/.test(l)), [], page.logs.join('\n'));
  await page.close();
});

test('a broken page shows a clear error and still renders what it can', async () => {
  const page = await open(env, '/test/browser/pages/broken.html');
  const status = await page.evaluate(() => document.querySelector('.tessera-status').textContent);
  assert.match(status, /does-not-exist\.json: HTTP 404/);
  assert.match(status, /#no-such-material not found/);
  const errors = await page.evaluate(() => document.getElementById('x').tessera.errors.join('\n'));
  assert.match(errors, /not a number/);
  assert.match(errors, /index 99 out of range/);
  // The mesh with the wrong material reference is drawn with the default red material.
  assert.deepEqual(await pixel(page, 100, 75), [255, 0, 0, 255]);
  await page.close();
});
