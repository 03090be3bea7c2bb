import { test } from 'node:test';
import assert from 'node:assert/strict';
import { parseCssTransform } from '../../../src/math/CssTransform.js';
import { multiply, axisAngle, invert, identity } from '../../../src/math/Mat4.js';

test('CSS none and empty give no matrix', () => {
  assert.equal(parseCssTransform('none'), null);
  assert.equal(parseCssTransform(''), null);
});

test('matrix3d is column-major with translation in 12..14', () => {
  const m = parseCssTransform('matrix3d(1,0,0,0,0,1,0,0,0,0,1,0,4,5,6,1)');
  assert.deepEqual([m[12], m[13], m[14]], [4, 5, 6]);
});

test('functions compose left to right (translate then rotate)', () => {
  const m = parseCssTransform('translateX(2px) rotateY(90deg) scale3d(2, 2, 2)');
  const ref = multiply(multiply(parseCssTransform('translate3d(2px,0,0)'), axisAngle(0, 1, 0, Math.PI / 2)),
    parseCssTransform('scale(2) scaleZ(2)'));
  m.forEach((v, i) => assert.ok(Math.abs(v - ref[i]) < 1e-6));
});

test('unsupported functions throw with their name', () => {
  assert.throws(() => parseCssTransform('skew(10deg)'), /skew/);
});

test('invert gives the identity back', () => {
  const m = parseCssTransform('translate3d(1px,2px,3px) rotate3d(1,1,0,33deg) scale(3)');
  const p = multiply(m, invert(m));
  identity().forEach((v, i) => assert.ok(Math.abs(p[i] - v) < 1e-5));
});
