// The XML3D global API driven from a page script (web/test/pages/xml3d-api.html), WebGL mode.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { launch, open, pixel } from './browser.js';

let env;
before(async () => { env = await launch(); });
after(async () => { await env.close(); });

const RED = [255, 0, 0, 255], BLUE = [0, 0, 255, 255];
// Canvas pixels (200x100, fovVertical pi/4, squares at z = -5): x = 100 + X * 24.14, y = 50 - Y * 24.14.
const px = (X, Y) => [Math.round(100 + X * 24.142), Math.round(50 - Y * 24.142)];
const frame = (page) => page.evaluate(() => new Promise((r) => {
  document.getElementById('x').addEventListener('framedrawn', () => r(), { once: true });
  document.getElementById('x').tessera.invalidate();
}));

test('the markup alone (?still): an upright red square and the blue square at y = 0', async () => {
  const page = await open(env, '/test/pages/xml3d-api.html?still');
  await page.waitForFunction(() => window.apiDone, null, { timeout: 10000 });
  assert.deepEqual(await pixel(page, ...px(-1.2 + 0.42, 0.42)), RED, 'square corner');
  assert.equal((await pixel(page, ...px(-1.2 + 0.62, 0)))[3], 0, 'no tip right of the square');
  assert.deepEqual(await pixel(page, ...px(1.2, -0.4)), BLUE);
  await page.close();
});

test('a page script rotates a <transform> with XML3D.AxisAngle, moves one with XML3D.Vec3, and picks', async () => {
  const page = await open(env, '/test/pages/xml3d-api.html');
  await page.waitForFunction(() => window.apiDone || window.apiError, null, { timeout: 10000 });
  const { results, error } = await page.evaluate(() => ({ results: window.apiResults, error: window.apiError }));
  assert.equal(error, undefined, error);
  const errors = page.logs.filter((l) => /^(error|pageerror):/.test(l));
  assert.deepEqual(errors, [], page.logs.join('\n'));
  const warnings = page.logs.filter((l) => /^warning: XML3D/.test(l));
  assert.deepEqual(warnings, ['warning: XML3D: XML3D.materials.register() is not supported by Tessera and does nothing'], page.logs.join('\n'));

  // The script's own findings.
  assert.equal(results.pickTip, 'a', JSON.stringify(results));
  assert.ok(Math.abs(results.hitPoint[0] + 0.55) < 0.05 && Math.abs(results.hitPoint[2] + 5) < 1e-3, String(results.hitPoint));
  assert.deepEqual(results.hitNormal.map(Math.round), [0, 0, 1]);
  assert.deepEqual(results.blueCentre.map((v) => Math.round(v * 100) / 100), [1.2, 0.3, -5]);
  assert.equal(results.pickBlue, 'b');
  assert.equal(results.rayCorner, null);
  assert.equal(results.rayCentre, 'a');
  const h = Math.SQRT1_2;
  [-1.2 - h, -h, -1.2 + h, h].forEach((v, i) => assert.ok(Math.abs(results.boxA[i] - v) < 1e-4, `boxA ${results.boxA}`));
  assert.equal(results.rotation, `0 0 1 ${Math.fround(Math.PI / 4)}`);

  // The picture: a diamond (tip out past the square, corner gone) and the blue square moved up.
  await frame(page);
  assert.deepEqual(await pixel(page, ...px(-1.2 + 0.62, 0)), RED, 'diamond tip');
  assert.equal((await pixel(page, ...px(-1.2 + 0.42, 0.42)))[3], 0, 'the square corner is gone');
  assert.deepEqual(await pixel(page, ...px(-1.2, 0)), RED, 'centre');
  assert.deepEqual(await pixel(page, ...px(1.2, 0.7)), BLUE, 'blue moved up');
  assert.equal((await pixel(page, ...px(1.2, -0.4)))[3], 0, 'blue no longer reaches y = -0.4');
  await page.close();
});

test('XML3D.StandardCamera drives the view through a <transform>: translate, lookAt, examine, mouse drag', async () => {
  const page = await open(env, '/test/pages/xml3d-api.html?still');
  await page.waitForFunction(() => window.apiDone, null, { timeout: 10000 });
  const r = await page.evaluate(() => {
    const v = document.getElementById('v');
    const cam = new XML3D.StandardCamera(v, { mode: 'examine' });
    const pos = () => { const p = cam.position; return [p.x, p.y, p.z].map((n) => Math.round(n * 1000) / 1000); };
    const out = { start: pos() };
    cam.translate(new XML3D.Vec3(0, 0, 2));        // backwards in the view's frame
    out.moved = pos();
    out.transformRef = v.getAttribute('transform');
    cam.lookAt(new XML3D.Vec3(1.2, 0, -5));
    const fwd = new XML3D.Vec3(0, 0, -1).transformDirection(v.getWorldMatrix());
    out.forward = [fwd.x, fwd.y, fwd.z];
    cam.examine(document.getElementById('b'));
    out.examined = pos();
    out.examinePoint = cam.getExaminePoint().toDOMString();
    return out;
  });
  assert.deepEqual(r.start, [0, 0, 0]);
  assert.deepEqual(r.moved, [0, 0, 2]);
  assert.match(r.transformRef, /^#/);
  const d = [1.2, 0, -7], l = Math.hypot(...d);
  r.forward.forEach((v, i) => assert.ok(Math.abs(v - d[i] / l) < 1e-4, String(r.forward)));
  // Framed: along the viewing direction from the blue square's centre (1.2, 0, -5).
  assert.ok(Math.hypot(r.examined[0] - 1.2, r.examined[1], r.examined[2] + 5) > 1, String(r.examined));
  const before = await page.evaluate(() => Array.from(document.getElementById('v').getWorldMatrix().data));
  const box = await page.evaluate(() => { const b = document.getElementById('x').getBoundingClientRect(); return [b.left, b.top]; });
  await page.mouse.move(box[0] + 100, box[1] + 50);
  await page.mouse.down();
  await page.mouse.move(box[0] + 130, box[1] + 50, { steps: 3 });
  await page.mouse.up();
  const after = await page.evaluate(() => Array.from(document.getElementById('v').getWorldMatrix().data));
  assert.ok(after.some((v, i) => Math.abs(v - before[i]) > 1e-3), 'a left drag orbits the view');
  await page.close();
});
