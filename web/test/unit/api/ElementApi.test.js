// XML3D element API (src/api/ElementApi.js) on a linkedom DOM: <transform> properties as
// XML3D types, round trips through the attributes, and the world matrices they give.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { page } from '../dom.js';
import { ensureElementApi } from '../../../src/api/ElementApi.js';
import { Vec3, AxisAngle, Mat4 } from '../../../src/api/MathTypes.js';
import { createXML3D } from '../../../src/api/XML3DGlobal.js';

const near = (a, b, eps = 1e-5) => assert.ok(Math.abs(a - b) < eps, `${a} != ${b}`);
const nearAll = (a, b, eps = 1e-5) => Array.from(a.data || a).forEach((v, i) => near(v, b[i], eps));

function scene() {
  const doc = page(`<xml3d id="x"><defs><transform id="t"></transform><transform id="u" translation="0 0 -5"></transform></defs>
    <group id="outer" transform="#u"><group id="g" transform="#t"><mesh id="m" style="transform: translateX(2px)">
      <float3 name="position">0 0 0 1 0 0 0 1 0</float3></mesh></group></group>
    <view id="v" transform="#u"></view></xml3d>`);
  for (const el of doc.querySelectorAll('xml3d, transform, group, mesh, view')) ensureElementApi(el);
  return doc;
}

test('<transform> properties read as XML3D types with the documented defaults', () => {
  const doc = scene();
  const t = doc.getElementById('t');
  assert.ok(t.translation instanceof Vec3);
  assert.ok(t.rotation instanceof AxisAngle);
  nearAll(t.translation, [0, 0, 0]);
  nearAll(t.scale, [1, 1, 1]);
  nearAll(t.center, [0, 0, 0]);
  nearAll(t.rotation, [0, 0, 1, 0]);
  nearAll(t.scaleOrientation, [0, 0, 1, 0]);
  nearAll(doc.getElementById('u').translation, [0, 0, -5]);
});

test('writing translation/rotation/scale sets the attributes and round-trips; the world matrix follows', () => {
  const doc = scene();
  const t = doc.getElementById('t'), g = doc.getElementById('g'), m = doc.getElementById('m');
  nearAll(g.getWorldMatrix(), new Mat4().translate(new Vec3(0, 0, -5)).data);
  t.translation = new Vec3(1, 2, 3);
  t.rotation = new AxisAngle(0, 1, 0, Math.PI / 2);
  t.scale = new Vec3(2, 2, 2);
  assert.equal(t.getAttribute('translation'), '1 2 3');
  assert.equal(t.getAttribute('scale'), '2 2 2');
  nearAll(t.translation, [1, 2, 3]);
  nearAll(t.rotation, [0, 1, 0, Math.PI / 2]);
  // group world = T(0,0,-5) · T(1,2,3) · R_y(90°) · S(2)
  const want = new Mat4().translate(new Vec3(0, 0, -5)).translate(new Vec3(1, 2, 3)).rotateY(Math.PI / 2).scale(new Vec3(2, 2, 2));
  nearAll(g.getWorldMatrix(), want.data);
  nearAll(g.getLocalMatrix(), new Mat4().translate(new Vec3(1, 2, 3)).rotateY(Math.PI / 2).scale(new Vec3(2, 2, 2)).data);
  // (1,0,0) in the group: scaled to (2,0,0), turned to (0,0,-2), moved to (1,2,1), then (1,2,-4).
  nearAll(new Vec3(1, 0, 0).mul(g.getWorldMatrix()), [1, 2, -4]);
  // The mesh adds its CSS translateX(2px): its origin is the group's (2,0,0), i.e. (1, 2, -6).
  nearAll(new Vec3(0, 0, 0).mul(m.getWorldMatrix()), [1, 2, -6]);
  // Arrays and strings are accepted too; null removes the attribute (default again).
  t.translation = [4, 5, 6];
  nearAll(t.translation, [4, 5, 6]);
  t.rotation = '1 0 0 0.5';
  nearAll(t.rotation, [1, 0, 0, 0.5]);
  t.translation = null;
  assert.equal(t.hasAttribute('translation'), false);
  nearAll(t.translation, [0, 0, 0]);
  // The returned objects are copies: changing one does not change the element (assign it back).
  const r = t.rotation;
  r.angle = 2;
  near(t.rotation.angle, 0.5);
  t.rotation = r;
  near(t.rotation.angle, 2);
});

test('view matrices; reflected attributes; members on the wrong element do not throw', () => {
  const doc = scene();
  const v = doc.getElementById('v');
  nearAll(new Vec3(0, 0, -5).mul(v.getViewMatrix()), [0, 0, 0]);
  nearAll(v.getViewMatrix().mul(v.getWorldMatrix()), new Mat4().data);
  const g = doc.getElementById('g');
  assert.equal(g.transform, '#t');
  g.transform = '#u';
  assert.equal(g.getAttribute('transform'), '#u');
  assert.equal(doc.getElementById('x').view, '');
  const warn = console.warn;
  const warnings = [];
  console.warn = (...a) => warnings.push(a.join(' '));
  try {
    assert.equal(doc.getElementById('t').getWorldMatrix(), null, '<transform> has no getWorldMatrix');
    assert.equal(doc.getElementById('m').getResult(['position']), null);
    assert.deepEqual(doc.getElementById('m').getOutputNames(), ['position']);
    // A transform property on another element is a plain expando, as before.
    g.rotation = 5;
    assert.equal(g.rotation, 5);
  } finally { console.warn = warn; }
  assert.ok(warnings.some((w) => /getWorldMatrix\(\) is not a method of <transform>/.test(w)), warnings.join('\n'));
  assert.ok(warnings.some((w) => /getResult\(\) is not supported/.test(w)), warnings.join('\n'));
});

test('the XML3D namespace: types, debug never throws, unknown members warn once', () => {
  const X = createXML3D({ version: 'test' });
  assert.equal(X.Vec3, Vec3);
  assert.equal(new X.AxisAngle().toDOMString(), '0 0 1 0');
  const warn = console.warn, error = console.error;
  const out = [];
  console.warn = (...a) => out.push(a.join(' '));
  console.error = (...a) => out.push(a.join(' '));
  try {
    X.debug.logError('boom', { a: 1 });
    X.debug.logDebug('hidden below the default level');
    X.materials.register('mine', {});
    X.materials.register('again', {});
    assert.equal(X.noSuchThing, undefined);
    assert.equal(X.noSuchThing, undefined);
    X.options.setValue('loglevel', 'error');
    X.debug.logWarning('dropped');
    assert.equal(X.options.getValue('renderer-faceculling'), 'none');
  } finally { console.warn = warn; console.error = error; }
  assert.equal(out.filter((l) => /boom/.test(l)).length, 1);
  assert.equal(out.filter((l) => /hidden|dropped/.test(l)).length, 0);
  assert.equal(out.filter((l) => /XML3D\.materials\.register\(\) is not supported/.test(l)).length, 1);
  assert.equal(out.filter((l) => /XML3D\.noSuchThing is not supported/.test(l)).length, 1);
});
