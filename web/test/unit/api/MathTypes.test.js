// XML3D namespace math types (src/api/MathTypes.js) against known values.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Vec2, Vec3, Vec4, AxisAngle, Quat, Mat2, Mat3, Mat4, Box, Ray } from '../../../src/api/MathTypes.js';

const near = (a, b, eps = 1e-5, what = '') => assert.ok(Math.abs(a - b) < eps, `${what} ${a} != ${b}`);
const nearAll = (a, b, eps = 1e-5) => {
  const x = Array.from(a.data || a), y = Array.from(b.data || b);
  assert.equal(x.length, y.length);
  x.forEach((v, i) => near(v, y[i], eps, `[${i}]`));
};
const S = Math.SQRT1_2;

test('Vec3: constructors, accessors, add/sub/scale/dot/cross/length/normalize, immutability', () => {
  assert.deepEqual(Array.from(new Vec3().data), [0, 0, 0]);
  const a = new Vec3(1, 2, 3), b = new Vec3(new Float32Array([4, 5, 6]));
  nearAll(a.add(b), [5, 7, 9]);
  nearAll(b.sub(a), [3, 3, 3]);
  nearAll(a.scale(2), [2, 4, 6]);
  assert.equal(a.dot(b), 32);
  nearAll(new Vec3(1, 0, 0).cross(new Vec3(0, 1, 0)), [0, 0, 1]);
  near(new Vec3(3, 4, 0).length(), 5);
  nearAll(new Vec3(0, 3, 4).normalize(), [0, 0.6, 0.8]);
  near(a.dist(b), Math.sqrt(27));
  nearAll(a.mul(b), [4, 10, 18]);
  nearAll(a.negate(), [-1, -2, -3]);
  nearAll(a.lerp(b, 0.5), [2.5, 3.5, 4.5]);
  nearAll(a.min(new Vec3(0, 5, 0)), [0, 2, 0]);
  nearAll(new Vec3(2, 4, 8).reciprocal(), [0.5, 0.25, 0.125]);
  assert.deepEqual(Array.from(a.data), [1, 2, 3], 'methods return new vectors');
  a.x = 7;
  assert.equal(a.data[0], 7, 'x is a mutable accessor');
  const c = new Vec3(a);
  c.y = 9;
  assert.equal(a.y, 2, 'the copy constructor copies');
  const raw = new Float32Array([1, 1, 1]);
  Vec3.wrap(raw).z = 5;
  assert.equal(raw[2], 5, 'wrap shares the array');
  assert.equal(new Vec3(1, 2.5, -3).toDOMString(), '1 2.5 -3');
  nearAll(Vec3.fromDOMString(' 1  2\n3 '), [1, 2, 3]);
  near(Vec3.random(2).length(), 2);
  nearAll(new Vec2(3, 4).normalize(), [0.6, 0.8]);
  near(new Vec4(1, 2, 3, 4).dot(new Vec4(1, 1, 1, 1)), 10);
});

test('Quat.fromAxisAngle: known values; identity; axis normalised', () => {
  nearAll(Quat.fromAxisAngle(new AxisAngle(0, 1, 0, Math.PI / 2)), [0, S, 0, S]);
  nearAll(Quat.fromAxisAngle(new AxisAngle(1, 0, 0, Math.PI)), [1, 0, 0, 0]);
  nearAll(Quat.fromAxisAngle(new AxisAngle(0, 0, 5, Math.PI / 3)), [0, 0, 0.5, Math.sqrt(3) / 2]);
  nearAll(Quat.fromAxisAngle(new AxisAngle()), [0, 0, 0, 1]);
  nearAll(new Quat(), [0, 0, 0, 1]);
  nearAll(new AxisAngle(0, 1, 0, 1).toQuat(), [0, Math.sin(0.5), 0, Math.cos(0.5)]);
});

test('AxisAngle round trip through Quat; accessors; DOM strings', () => {
  for (const [x, y, z, a] of [[0, 1, 0, 0.5], [1, 2, 3, 2.5], [-1, 0, 0, 3], [0.3, -0.4, 0.5, 0.01]]) {
    const l = Math.hypot(x, y, z);
    const back = AxisAngle.fromQuat(Quat.fromAxisAngle(new AxisAngle(x, y, z, a)));
    nearAll(back, [x / l, y / l, z / l, a], 1e-4);
  }
  nearAll(AxisAngle.fromQuat(new Quat()), [0, 0, 1, 0]);
  const aa = new AxisAngle(new Vec3(1, 0, 0), 2);
  nearAll(aa, [1, 0, 0, 2]);
  assert.ok(aa.axis instanceof Vec3);
  aa.axis.y = 1;             // the axis accessor is mutable
  aa.angle = 1.5;
  nearAll(aa, [1, 1, 0, 1.5]);
  nearAll(AxisAngle.fromDOMString('0 1 0 1.5707963'), [0, 1, 0, 1.5707963]);
  assert.equal(new AxisAngle(0, 0, 1, 0.5).toDOMString(), '0 0 1 0.5');
});

test('Quat: mul composes rotations, rotates vectors, slerp, conjugate/invert, fromBasis, fromRotationTo', () => {
  const qy = Quat.fromAxisAngle(new AxisAngle(0, 1, 0, Math.PI / 2));
  nearAll(new Vec3(1, 0, 0).mul(qy), [0, 0, -1]);
  const qx = Quat.fromAxisAngle(new AxisAngle(1, 0, 0, Math.PI / 2));
  // (qy·qx) applies qx first: z -> -y under qx, then -y stays under qy.
  nearAll(new Vec3(0, 0, 1).mul(qy.mul(qx)), [0, -1, 0]);
  nearAll(qy.mul(qy.conjugate()), [0, 0, 0, 1]);
  nearAll(qy.scale(2).invert().mul(qy.scale(2)), [0, 0, 0, 1]);
  nearAll(new Quat().slerp(Quat.fromAxisAngle(new AxisAngle(0, 0, 1, 2)), 0.25), Quat.fromAxisAngle(new AxisAngle(0, 0, 1, 0.5)));
  nearAll(new Quat().rotateY(Math.PI / 2), qy);
  // Basis: x' = (0,0,-1), y' = (0,1,0), z' = (1,0,0) is the +90° turn about Y.
  nearAll(Quat.fromBasis(new Vec3(0, 0, -1), new Vec3(0, 1, 0), new Vec3(1, 0, 0)), qy);
  nearAll(new Vec3(1, 0, 0).mul(Quat.fromRotationTo(new Vec3(1, 0, 0), new Vec3(0, 2, 0))), [0, 1, 0]);
  nearAll(new Vec3(1, 0, 0).mul(Quat.fromRotationTo(new Vec3(1, 0, 0), new Vec3(-1, 0, 0))), [-1, 0, 0]);
  nearAll(Mat3.fromQuat(qy).mul(Mat3.fromQuat(qy).transpose()), new Mat3());
  nearAll(Quat.fromMat3(Mat3.fromQuat(qy)), qy);
});

test('Mat4: inverse × matrix = identity, singular gives null, accessors mRC, transpose, determinant', () => {
  const m = new Mat4().translate(new Vec3(1, 2, 3)).rotate(0.7, new Vec3(1, 1, 0)).scale(new Vec3(2, 3, 4));
  nearAll(m.invert().mul(m), new Mat4());
  nearAll(m.mul(m.invert()), new Mat4());
  near(m.determinant(), 24, 1e-4);
  assert.equal(new Mat4(new Float32Array(16)).invert(), null);
  const t = new Mat4().translate(new Vec3(5, 6, 7));
  assert.deepEqual([t.m14, t.m24, t.m34, t.m44], [5, 6, 7, 1], 'mRC: row R, column C (column-major data[12..14] is the translation)');
  assert.equal(t.data[12], 5);
  assert.equal(t.transpose().m41, 5);
  nearAll(t.adjoint(), t.invert().data.map((v) => v * t.determinant()));
  const h = new Mat4([1, 2, 3, 4, 5, 6, 7, 8, 2, 6, 4, 8, 3, 1, 1, 2]);
  near(h.determinant(), 72, 1e-3);
  nearAll(h.invert().mul(h), new Mat4(), 1e-4);
});

test('transformPoint: Vec3.mul(Mat4) is M·(v,1); transformDirection ignores translation', () => {
  const m = new Mat4().translate(new Vec3(10, 0, 0)).rotateZ(Math.PI / 2);
  nearAll(new Vec3(1, 0, 0).mul(m), [10, 1, 0]);
  nearAll(new Vec3(1, 0, 0).transformDirection(m), [0, 1, 0]);
  nearAll(new Vec3(1, 2, 3).mul(new Mat3()), [1, 2, 3]);
  nearAll(new Vec4(1, 0, 0, 1).mul(m), [10, 1, 0, 1]);
  // A projective matrix: the point is divided by w.
  const p = Mat4.perspective(Math.PI / 2, 1, 1, 100);
  nearAll(new Vec3(0, 0, -1).mul(p), [0, 0, -1]);
  nearAll(new Vec3(0, 0, -100).mul(p), [0, 0, 1], 1e-4);
  const v = Mat4.lookAt(new Vec3(0, 0, 5), new Vec3(0, 0, 0), new Vec3(0, 1, 0));
  nearAll(new Vec3(0, 0, 0).mul(v), [0, 0, -5]);
  nearAll(Mat4.fromRotationTranslation(Quat.fromAxisAngle(new AxisAngle(0, 0, 1, Math.PI / 2)), new Vec3(1, 1, 1)),
    new Mat4().translate(new Vec3(1, 1, 1)).rotateZ(Math.PI / 2));
});

test('Ray against a Box: hit and miss, distances, inside, parallel', () => {
  const box = new Box(new Vec3(-1, -1, -1), new Vec3(1, 1, 1));
  const opt = {};
  assert.equal(new Ray(new Vec3(0, 0, 5), new Vec3(0, 0, -1)).intersects(box, opt), true);
  near(opt.dist, 4);
  assert.equal(box.intersects(new Ray(new Vec3(-6, 0.5, 0), new Vec3(1, 0, 0)), opt), true);
  near(opt.dist, 5);
  const d = new Vec3(1, 1, 0).normalize();
  assert.equal(new Ray(new Vec3(-3, -3, 0), d).intersects(box, opt), true);
  near(opt.dist, 2 * Math.SQRT2, 1e-5);
  assert.equal(new Ray(new Vec3(0, 0, 5), new Vec3(0, 0, 1)).intersects(box, opt), false, 'box behind the ray');
  assert.equal(opt.dist, Infinity);
  assert.equal(new Ray(new Vec3(0, 3, 5), new Vec3(0, 0, -1)).intersects(box, opt), false, 'passes above');
  assert.equal(new Ray(new Vec3(1, 0, 5), new Vec3(0, 0, -1)).intersects(box, opt), true, 'grazes a face');
  assert.equal(new Ray().intersects(box, opt), true, 'origin inside');
  assert.equal(opt.dist, 0);
  assert.equal(new Ray(new Vec3(0, 0, 5), new Vec3(0, 0, -1)).intersects(new Box(), opt), false, 'empty box');
  const r = new Ray();
  nearAll(r.origin, [0, 0, 0]);
  nearAll(r.direction, [0, 0, -1]);
  r.origin.x = 3;  // mutable accessor
  assert.equal(r.data[0], 3);
});

test('Box: empty, extend, center/size/extent, contains, transformAxisAligned', () => {
  const b = new Box();
  assert.ok(b.isEmpty());
  b.extend(new Vec3(1, 2, 3)).extend(new Vec3(-1, 0, 1));
  assert.ok(!b.isEmpty());
  nearAll(b.center(), [0, 1, 2]);
  nearAll(b.size(), [2, 2, 2]);
  nearAll(b.extent(), [1, 1, 1]);
  assert.equal(b.longestSide(), 2);
  assert.ok(b.contains(new Vec3(0, 1, 2)) && !b.contains(new Vec3(5, 1, 2)));
  const c = b.clone().transformAxisAligned(new Mat4().translate(new Vec3(10, 0, 0)).rotateZ(Math.PI / 2));
  nearAll(c.min, [8, -1, 1]);
  nearAll(c.max, [10, 1, 3]);
  nearAll(b.min, [-1, 0, 1], 1e-6);
  assert.ok(b.setEmpty().isEmpty());
});

// xml3d.js 5 (gl-matrix underneath) gives the same methods long names as well, and pages call
// them: xml3d-examples' shaderOverrides does `new XML3D.Vec3(0, 1, 0).multiply(rot)` (a
// TypeError while only `mul` existed, so its camera never turned).
test('long method names of xml3d.js: multiply, subtract, distance, len act as mul, sub, dist, length', () => {
  const q = Quat.fromAxisAngle(new AxisAngle(0, 0, 1, Math.PI / 2));
  nearAll(new Vec3(1, 0, 0).multiply(q), new Vec3(1, 0, 0).mul(q));
  nearAll(new Vec3(1, 0, 0).multiply(q), [0, 1, 0]);
  nearAll(new Vec3(1, 2, 3).multiply(new Vec3(2, 2, 2)), [2, 4, 6]);
  nearAll(new Vec2(1, 2).multiply(new Vec2(3, 4)), [3, 8]);
  nearAll(new Vec4(1, 2, 3, 4).multiply(Mat4.translation([1, 0, 0])), new Vec4(1, 2, 3, 4).mul(Mat4.translation([1, 0, 0])));
  nearAll(q.multiply(q), q.mul(q));
  const m = new Mat4().rotateZ(0.3).translate([1, 2, 3]);
  nearAll(m.multiply(m.invert()), new Mat4());
  nearAll(new Mat3([2, 0, 0, 0, 2, 0, 0, 0, 2]).multiply(new Mat3()), [2, 0, 0, 0, 2, 0, 0, 0, 2]);
  nearAll(new Mat2([1, 2, 3, 4]).multiply(new Mat2()), [1, 2, 3, 4]);
  for (const V of [Vec2, Vec3, Vec4]) {
    const a = new V(3, 4, 0, 0), b = new V(0, 0, 0, 0);
    nearAll(a.subtract(new V(1, 1, 1, 1)), a.sub(new V(1, 1, 1, 1)));
    near(a.distance(b), 5);
    near(a.len(), 5);
  }
  near(new Quat(0, 0, 0, 2).len(), 2);
});
