// XML3D's math types (XML3D 5 specification, "Datatypes"): Vec2, Vec3, Vec4, AxisAngle, Quat,
// Mat2, Mat3, Mat4, Box and Ray. Written for Tessera from the specification's interface text.
//
// As documented: each type wraps a Float32Array `data`; component accessors (x, y, m12, …) are
// mutable; every other method of the vector, quaternion and matrix types returns a new object
// (the types are "immutable"), while Box and Ray methods change the object and return it.
// Matrices are column-major (as XML3D's float4x4 and CSS matrix3d), and `mNM` is row N,
// column M. Where the specification is silent or garbled, these choices are made (and
// documented in docs/web-client.md):
//   - vector × matrix (`v.mul(m)`) is the matrix applied to the column vector, M·v; for a Vec3
//     and a Mat4 the fourth component is 1 and the result is divided by w (projective point);
//   - `a.mul(b)` of matrices is a·b (b applied first); `q.mul(r)` of quaternions is the
//     Hamilton product q·r (the spec's "component wise" would not compose rotations);
//   - Mat4.perspective takes (fovy, aspect, near, far); with six numbers it is a frustum;
//   - Box/Ray `intersects(…, opt)` write the ray parameter of the entry point to opt.dist
//     (0 when the origin is inside the box, Infinity on a miss).

const EPS = 1e-6;
const numbers = (str) => (String(str).match(/[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|NaN|[+-]?Infinity/g) || []).map(Number);
const fmt = (a) => Array.from(a, (v) => String(v)).join(' ');

// The array behind an argument that is one of our types, a typed array or a plain array.
function arr(v) {
  if (v == null) return null;
  if (v.data instanceof Float32Array) return v.data;
  if (ArrayBuffer.isView(v) || Array.isArray(v)) return v;
  return null;
}

// A vector class with N components named by `names`.
function defineVector(n, names, zero) {
  class V {
    constructor(...args) {
      this.data = new Float32Array(n);
      const a = args.length === 1 ? arr(args[0]) : null;
      if (a) for (let i = 0; i < n; i++) this.data[i] = a[i] ?? 0;
      else if (args.length >= n) for (let i = 0; i < n; i++) this.data[i] = +args[i];
      else this.data.set(zero);
    }
    static wrap(data) { const v = Object.create(V.prototype); v.data = data; return v; }
    static fromDOMString(str) { return new V(Float32Array.from(numbers(str).slice(0, n).concat(zero.slice(numbers(str).length)))); }
    static random(scale = 1) {
      const v = new V();
      for (let i = 0; i < n; i++) v.data[i] = Math.random() * 2 - 1;
      const l = v.length() || 1;
      for (let i = 0; i < n; i++) v.data[i] *= scale / l;
      return v;
    }
    toDOMString() { return fmt(this.data); }
    toString() { return `${V.name}(${Array.from(this.data).join(', ')})`; }
    clone() { return new V(this.data); }
    map(f) { const r = new V(); for (let i = 0; i < n; i++) r.data[i] = f(this.data[i], i); return r; }
    add(o) { const b = arr(o); return this.map((v, i) => v + b[i]); }
    sub(o) { const b = arr(o); return this.map((v, i) => v - b[i]); }
    divide(o) { const b = arr(o); return this.map((v, i) => v / b[i]); }
    scale(s) { return this.map((v) => v * s); }
    negate() { return this.map((v) => -v); }
    min(o) { const b = arr(o); return this.map((v, i) => Math.min(v, b[i])); }
    max(o) { const b = arr(o); return this.map((v, i) => Math.max(v, b[i])); }
    lerp(o, t) { const b = arr(o); return this.map((v, i) => v + (b[i] - v) * t); }
    dot(o) { const b = arr(o); let s = 0; for (let i = 0; i < n; i++) s += this.data[i] * b[i]; return s; }
    length() { return Math.sqrt(this.dot(this)); }
    dist(o) { return this.sub(o).length(); }
    normalize() { const l = this.length(); return l > 0 ? this.scale(1 / l) : this.clone(); }
  }
  names.forEach((name, i) => Object.defineProperty(V.prototype, name, {
    get() { return this.data[i]; }, set(v) { this.data[i] = v; }, enumerable: true,
  }));
  return V;
}

export const Vec2 = defineVector(2, ['x', 'y'], [0, 0]);
Object.defineProperty(Vec2, 'name', { value: 'Vec2' });
export const Vec3 = defineVector(3, ['x', 'y', 'z'], [0, 0, 0]);
Object.defineProperty(Vec3, 'name', { value: 'Vec3' });
export const Vec4 = defineVector(4, ['x', 'y', 'z', 'w'], [0, 0, 0, 0]);
Object.defineProperty(Vec4, 'name', { value: 'Vec4' });

// Column-major matrix × column vector (the first `rows` results), with the vector padded by `pad`.
function matVec(m, size, v, pad) {
  const full = [...Array.from(v).slice(0, size), ...pad].slice(0, size);
  const r = new Array(size).fill(0);
  for (let row = 0; row < size; row++) for (let c = 0; c < size; c++) r[row] += m[c * size + row] * full[c];
  return r;
}

Vec2.prototype.mul = function mul(o) {
  if (o instanceof Mat2) return new Vec2(...matVec(o.data, 2, this.data, []));
  if (o instanceof Mat3) return new Vec2(...matVec(o.data, 3, this.data, [1]).slice(0, 2));
  if (o instanceof Mat4) return new Vec2(...matVec(o.data, 4, this.data, [0, 1]).slice(0, 2));
  const b = arr(o); return this.map((v, i) => v * b[i]);
};

Vec3.prototype.mul = function mul(o) {
  if (o instanceof Quat) return rotateByQuat(this.data, o.data);
  if (o instanceof Mat3) return new Vec3(...matVec(o.data, 3, this.data, []));
  if (o instanceof Mat4 || (ArrayBuffer.isView(o) && o.length === 16)) {
    const r = matVec(arr(o), 4, this.data, [1]);
    const w = r[3] || 1;
    return new Vec3(r[0] / w, r[1] / w, r[2] / w);
  }
  const b = arr(o); return this.map((v, i) => v * b[i]);
};
Vec3.prototype.cross = function cross(o) {
  const a = this.data, b = arr(o);
  return new Vec3(a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]);
};
Vec3.prototype.reciprocal = function reciprocal() { return this.map((v) => 1 / v); };
Vec3.prototype.transformDirection = function transformDirection(m) {
  return new Vec3(...matVec(arr(m), 4, this.data, [0]).slice(0, 3));
};

Vec4.prototype.mul = function mul(o) {
  if (o instanceof Mat4) return new Vec4(...matVec(o.data, 4, this.data, []));
  const b = arr(o); return this.map((v, i) => v * b[i]);
};
Vec4.prototype.transformQuat = function transformQuat(q) {
  const r = rotateByQuat(this.data, arr(q));
  return new Vec4(r.x, r.y, r.z, this.data[3]);
};

function rotateByQuat(v, q) {
  const [x, y, z] = v, [qx, qy, qz, qw] = q;
  // t = 2 q.xyz × v; v' = v + w t + q.xyz × t
  const tx = 2 * (qy * z - qz * y), ty = 2 * (qz * x - qx * z), tz = 2 * (qx * y - qy * x);
  return new Vec3(x + qw * tx + (qy * tz - qz * ty), y + qw * ty + (qz * tx - qx * tz), z + qw * tz + (qx * ty - qy * tx));
}

// ---- Quat [x, y, z, w] ------------------------------------------------------------------
export class Quat {
  constructor(...args) {
    this.data = new Float32Array([0, 0, 0, 1]);
    const a = args.length === 1 ? arr(args[0]) : null;
    if (a) this.data.set(Array.from(a).slice(0, 4));
    else if (args.length >= 4) this.data.set(args.slice(0, 4).map(Number));
  }
  static wrap(data) { const q = Object.create(Quat.prototype); q.data = data; return q; }
  static fromDOMString(str) { const n = numbers(str); return n.length >= 4 ? new Quat(...n.slice(0, 4)) : new Quat(); }
  /** Normalized quaternion of an AxisAngle (the axis is normalized; a zero axis gives identity). */
  static fromAxisAngle(aa) {
    const d = arr(aa);
    const l = Math.hypot(d[0], d[1], d[2]);
    if (!l) return new Quat();
    const s = Math.sin(d[3] / 2) / l;
    return new Quat(d[0] * s, d[1] * s, d[2] * s, Math.cos(d[3] / 2));
  }
  /** Rotation whose columns are the basis vectors x, y, z (the basis' space to the standard space). */
  static fromBasis(x, y, z) {
    const a = arr(x), b = arr(y), c = arr(z);
    return Quat.fromMat3(new Mat3(new Float32Array([a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]]))).normalize();
  }
  static fromMat3(m) {
    const d = arr(m);
    const m00 = d[0], m10 = d[1], m20 = d[2], m01 = d[3], m11 = d[4], m21 = d[5], m02 = d[6], m12 = d[7], m22 = d[8];
    const tr = m00 + m11 + m22;
    let x, y, z, w;
    if (tr > 0) {
      const s = Math.sqrt(tr + 1) * 2;
      w = s / 4; x = (m21 - m12) / s; y = (m02 - m20) / s; z = (m10 - m01) / s;
    } else if (m00 > m11 && m00 > m22) {
      const s = Math.sqrt(1 + m00 - m11 - m22) * 2;
      w = (m21 - m12) / s; x = s / 4; y = (m01 + m10) / s; z = (m02 + m20) / s;
    } else if (m11 > m22) {
      const s = Math.sqrt(1 + m11 - m00 - m22) * 2;
      w = (m02 - m20) / s; x = (m01 + m10) / s; y = s / 4; z = (m12 + m21) / s;
    } else {
      const s = Math.sqrt(1 + m22 - m00 - m11) * 2;
      w = (m10 - m01) / s; x = (m02 + m20) / s; y = (m12 + m21) / s; z = s / 4;
    }
    return new Quat(x, y, z, w).normalize();
  }
  /** The shortest rotation taking direction `from` to direction `to`. */
  static fromRotationTo(from, to) {
    const a = new Vec3(from).normalize(), b = new Vec3(to).normalize();
    const d = a.dot(b);
    if (d < -1 + EPS) {
      let axis = new Vec3(1, 0, 0).cross(a);
      if (axis.length() < EPS) axis = new Vec3(0, 1, 0).cross(a);
      return Quat.fromAxisAngle(new AxisAngle(axis, Math.PI));
    }
    const c = a.cross(b);
    return new Quat(c.x, c.y, c.z, 1 + d).normalize();
  }
  toDOMString() { return fmt(this.data); }
  toString() { return `Quat(${Array.from(this.data).join(', ')})`; }
  clone() { return new Quat(this.data); }
  add(o) { const b = arr(o); return new Quat(...this.data.map((v, i) => v + b[i])); }
  scale(s) { return new Quat(...this.data.map((v) => v * s)); }
  dot(o) { const b = arr(o); return this.data[0] * b[0] + this.data[1] * b[1] + this.data[2] * b[2] + this.data[3] * b[3]; }
  length() { return Math.sqrt(this.dot(this)); }
  normalize() { const l = this.length(); return l > 0 ? this.scale(1 / l) : new Quat(); }
  conjugate() { const [x, y, z, w] = this.data; return new Quat(-x, -y, -z, w); }
  invert() { const d = this.dot(this); return d ? this.conjugate().scale(1 / d) : new Quat(0, 0, 0, 0); }
  calculateW() { const [x, y, z] = this.data; return new Quat(x, y, z, -Math.sqrt(Math.abs(1 - x * x - y * y - z * z))); }
  /** Hamilton product this·other: the rotation `other` followed by this one. */
  mul(o) {
    const [ax, ay, az, aw] = this.data, [bx, by, bz, bw] = arr(o);
    return new Quat(ax * bw + aw * bx + ay * bz - az * by, ay * bw + aw * by + az * bx - ax * bz,
      az * bw + aw * bz + ax * by - ay * bx, aw * bw - ax * bx - ay * by - az * bz);
  }
  rotateX(a) { return this.mul(new Quat(Math.sin(a / 2), 0, 0, Math.cos(a / 2))); }
  rotateY(a) { return this.mul(new Quat(0, Math.sin(a / 2), 0, Math.cos(a / 2))); }
  rotateZ(a) { return this.mul(new Quat(0, 0, Math.sin(a / 2), Math.cos(a / 2))); }
  lerp(o, t) { const b = arr(o); return new Quat(...this.data.map((v, i) => v + (b[i] - v) * t)); }
  /** Spherical interpolation along the shorter arc. */
  slerp(o, t) {
    let b = Array.from(arr(o));
    let cos = this.dot(b);
    if (cos < 0) { cos = -cos; b = b.map((v) => -v); }
    let s0 = 1 - t, s1 = t;
    if (1 - cos > EPS) {
      const om = Math.acos(cos), sin = Math.sin(om);
      s0 = Math.sin((1 - t) * om) / sin; s1 = Math.sin(t * om) / sin;
    }
    return new Quat(...this.data.map((v, i) => s0 * v + s1 * b[i]));
  }
}
['x', 'y', 'z', 'w'].forEach((name, i) => Object.defineProperty(Quat.prototype, name, {
  get() { return this.data[i]; }, set(v) { this.data[i] = v; }, enumerable: true,
}));

// ---- AxisAngle [x, y, z, angle] ---------------------------------------------------------
export class AxisAngle {
  /** (), (x, y, z, angle), (Float32Array|AxisAngle), and (Vec3 axis, angle). */
  constructor(...args) {
    this.data = new Float32Array([0, 0, 1, 0]);
    const a = args.length === 1 ? arr(args[0]) : null;
    if (a) this.data.set(Array.from(a).slice(0, 4));
    else if (args.length === 2 && arr(args[0])) { const v = arr(args[0]); this.data.set([v[0], v[1], v[2], +args[1]]); }
    else if (args.length >= 4) this.data.set(args.slice(0, 4).map(Number));
  }
  static wrap(data) { const q = Object.create(AxisAngle.prototype); q.data = data; return q; }
  static fromDOMString(str) { const n = numbers(str); return n.length >= 4 ? new AxisAngle(...n.slice(0, 4)) : new AxisAngle(); }
  /** Axis-angle of a quaternion's rotation; angle in [0, 2π), identity gives 0 0 1 0. */
  static fromQuat(q) {
    const [x, y, z, w0] = arr(q);
    const l = Math.hypot(x, y, z, w0) || 1;
    const w = Math.max(-1, Math.min(1, w0 / l));
    const angle = 2 * Math.acos(w);
    const s = Math.sqrt(1 - w * w);
    if (s < EPS) return new AxisAngle(0, 0, 1, 0);
    return new AxisAngle(x / l / s, y / l / s, z / l / s, angle);
  }
  get axis() { return Vec3.wrap(this.data.subarray(0, 3)); }
  set axis(v) { const a = arr(v); this.data[0] = a[0]; this.data[1] = a[1]; this.data[2] = a[2]; }
  get angle() { return this.data[3]; }
  set angle(v) { this.data[3] = v; }
  toQuat() { return Quat.fromAxisAngle(this); }
  clone() { return new AxisAngle(this.data); }
  toDOMString() { return fmt(this.data); }
  toString() { return `AxisAngle(${Array.from(this.data).join(', ')})`; }
}

// ---- matrices ---------------------------------------------------------------------------
function matMul(a, b, n) {
  const r = new Float32Array(n * n);
  for (let c = 0; c < n; c++) for (let row = 0; row < n; row++) {
    let s = 0;
    for (let k = 0; k < n; k++) s += a[k * n + row] * b[c * n + k];
    r[c * n + row] = s;
  }
  return r;
}
function transpose(a, n) {
  const r = new Float32Array(n * n);
  for (let c = 0; c < n; c++) for (let row = 0; row < n; row++) r[row * n + c] = a[c * n + row];
  return r;
}
// Determinant and adjugate by cofactors (n <= 4), in double precision.
function minor(a, n, skipRow, skipCol) {
  const r = [];
  for (let c = 0; c < n; c++) if (c !== skipCol) for (let row = 0; row < n; row++) if (row !== skipRow) r.push(a[c * n + row]);
  return r;
}
function det(a, n) {
  if (n === 1) return a[0];
  if (n === 2) return a[0] * a[3] - a[2] * a[1];
  let s = 0;
  for (let c = 0; c < n; c++) s += (c % 2 ? -1 : 1) * a[c * n] * det(minor(a, n, 0, c), n - 1);
  return s;
}
function adjugate(a, n) {
  const r = new Float64Array(n * n);
  // adj[row][col] = cofactor[col][row]
  for (let row = 0; row < n; row++) for (let col = 0; col < n; col++)
    r[col * n + row] = ((row + col) % 2 ? -1 : 1) * det(minor(a, n, col, row), n - 1);
  return r;
}

function defineMatrix(n) {
  class M {
    constructor(other) {
      this.data = new Float32Array(n * n);
      const a = arr(other);
      if (a) this.data.set(Array.from(a).slice(0, n * n));
      else for (let i = 0; i < n; i++) this.data[i * n + i] = 1;
    }
    static wrap(data) { const m = Object.create(M.prototype); m.data = data; return m; }
    static fromDOMString(str) { const v = numbers(str); return v.length >= n * n ? new M(v.slice(0, n * n)) : new M(); }
    toDOMString() { return fmt(this.data); }
    toString() { return `Mat${n}(${Array.from(this.data).join(', ')})`; }
    clone() { return new M(this.data); }
    mul(o) { return M.wrap(matMul(this.data, arr(o), n)); }
    transpose() { return M.wrap(transpose(this.data, n)); }
    determinant() { return det(Array.from(this.data), n); }
    adjoint() { return new M(adjugate(Array.from(this.data), n)); }
    /** The inverse, or null when the matrix is singular. */
    invert() {
      const d = this.determinant();
      if (!d || !Number.isFinite(d)) return null;
      return new M(adjugate(Array.from(this.data), n).map((v) => v / d));
    }
  }
  for (let row = 1; row <= n; row++) for (let col = 1; col <= n; col++) {
    const i = (col - 1) * n + (row - 1);
    Object.defineProperty(M.prototype, `m${row}${col}`, { get() { return this.data[i]; }, set(v) { this.data[i] = v; } });
  }
  return M;
}

export const Mat2 = defineMatrix(2);
Object.defineProperty(Mat2, 'name', { value: 'Mat2' });
export const Mat3 = defineMatrix(3);
Object.defineProperty(Mat3, 'name', { value: 'Mat3' });
export const Mat4 = defineMatrix(4);
Object.defineProperty(Mat4, 'name', { value: 'Mat4' });

Mat2.prototype.rotate = function rotate(a) {
  const c = Math.cos(a), s = Math.sin(a);
  return this.mul(new Mat2([c, s, -s, c]));
};
Mat2.prototype.scale = function scale(v) { const b = arr(v); return this.mul(new Mat2([b[0], 0, 0, b[1]])); };

// Mat3 rotate/scale/translate act on 2D homogeneous coordinates (x, y, 1); scale and translate
// use the x and y of the given vector.
Mat3.prototype.rotate = function rotate(a) {
  const c = Math.cos(a), s = Math.sin(a);
  return this.mul(new Mat3([c, s, 0, -s, c, 0, 0, 0, 1]));
};
Mat3.prototype.scale = function scale(v) { const b = arr(v); return this.mul(new Mat3([b[0], 0, 0, 0, b[1], 0, 0, 0, 1])); };
Mat3.prototype.translate = function translate(v) { const b = arr(v); return this.mul(new Mat3([1, 0, 0, 0, 1, 0, b[0], b[1], 1])); };
Mat3.fromMat4 = (m) => { const d = arr(m); return new Mat3([d[0], d[1], d[2], d[4], d[5], d[6], d[8], d[9], d[10]]); };
Mat3.fromQuat = (q) => Mat3.fromMat4(Mat4.fromQuat(q));
Mat3.normalFromMat4 = (m) => { const inv = Mat3.fromMat4(m).invert(); return inv ? inv.transpose() : null; };

Mat4.fromQuat = (q) => {
  const [x, y, z, w] = arr(q);
  return new Mat4([1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w), 0,
    2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w), 0,
    2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y), 0, 0, 0, 0, 1]);
};
Mat4.fromRotationTranslation = (q, t) => {
  const m = Mat4.fromQuat(q), v = arr(t);
  m.data[12] = v[0]; m.data[13] = v[1]; m.data[14] = v[2];
  return m;
};
Mat4.translation = (v) => { const b = arr(v), m = new Mat4(); m.data[12] = b[0]; m.data[13] = b[1]; m.data[14] = b[2]; return m; };
Mat4.prototype.translate = function translate(v) { return this.mul(Mat4.translation(v)); };
Mat4.prototype.scale = function scale(v) { const b = arr(v); return this.mul(new Mat4([b[0], 0, 0, 0, 0, b[1], 0, 0, 0, 0, b[2], 0, 0, 0, 0, 1])); };
Mat4.prototype.rotate = function rotate(angle, axis) { return this.mul(Mat4.fromQuat(Quat.fromAxisAngle(new AxisAngle(axis, angle)))); };
Mat4.prototype.rotateX = function rotateX(a) { return this.rotate(a, [1, 0, 0]); };
Mat4.prototype.rotateY = function rotateY(a) { return this.rotate(a, [0, 1, 0]); };
Mat4.prototype.rotateZ = function rotateZ(a) { return this.rotate(a, [0, 0, 1]); };
Mat4.frustum = (l, r, b, t, n, f) => new Mat4([2 * n / (r - l), 0, 0, 0, 0, 2 * n / (t - b), 0, 0,
  (r + l) / (r - l), (t + b) / (t - b), -(f + n) / (f - n), -1, 0, 0, -2 * f * n / (f - n), 0]);
Mat4.ortho = (l, r, b, t, n, f) => new Mat4([2 / (r - l), 0, 0, 0, 0, 2 / (t - b), 0, 0, 0, 0, -2 / (f - n), 0,
  -(r + l) / (r - l), -(t + b) / (t - b), -(f + n) / (f - n), 1]);
/** perspective(fovy, aspect, near, far) (radians); with six numbers, frustum(l, r, b, t, n, f). */
Mat4.perspective = (...a) => {
  if (a.length >= 6) return Mat4.frustum(...a);
  const [fovy, aspect, n, f] = a, t = n * Math.tan(fovy / 2);
  return Mat4.frustum(-t * aspect, t * aspect, -t, t, n, f);
};
/** The view matrix (world to eye) of an eye at `eye` looking at `center` with `up`. */
Mat4.lookAt = (eye, center, up) => {
  const e = new Vec3(eye), z = e.sub(center).normalize();
  let x = new Vec3(up).cross(z).normalize();
  if (x.length() < EPS) x = new Vec3(0, 0, 1).cross(z).normalize();
  const y = z.cross(x);
  return new Mat4([x.x, y.x, z.x, 0, x.y, y.y, z.y, 0, x.z, y.z, z.z, 0, -x.dot(e), -y.dot(e), -z.dot(e), 1]);
};

// The longer names xml3d.js 5 gives the same methods (those of gl-matrix under it), which
// pages call: xml3d-examples' shaderOverrides turns its camera with
// `new XML3D.Vec3(0, 1, 0).multiply(rot)`, a TypeError here while only `mul` existed.
for (const C of [Vec2, Vec3, Vec4, Quat, Mat2, Mat3, Mat4]) C.prototype.multiply = function multiply(o) { return this.mul(o); };
for (const C of [Vec2, Vec3, Vec4]) {
  C.prototype.subtract = function subtract(o) { return this.sub(o); };
  C.prototype.distance = function distance(o) { return this.dist(o); };
}
for (const C of [Vec2, Vec3, Vec4, Quat]) C.prototype.len = function len() { return this.length(); };

// ---- Box (mutable) ----------------------------------------------------------------------
export class Box {
  /** (), (Box other), or (Vec3 min, Vec3 max). The empty box has min > max. */
  constructor(a, b) {
    this.data = new Float32Array([Infinity, Infinity, Infinity, -Infinity, -Infinity, -Infinity]);
    if (a instanceof Box) this.data.set(a.data);
    else if (arr(a) && arr(b)) { this.data.set(Array.from(arr(a)).slice(0, 3), 0); this.data.set(Array.from(arr(b)).slice(0, 3), 3); }
  }
  get min() { return Vec3.wrap(this.data.subarray(0, 3)); }
  set min(v) { this.data.set(Array.from(arr(v)).slice(0, 3), 0); }
  get max() { return Vec3.wrap(this.data.subarray(3, 6)); }
  set max(v) { this.data.set(Array.from(arr(v)).slice(0, 3), 3); }
  clone() { return new Box(this); }
  copy(o) { this.data.set(o.data); return this; }
  copyMin(o) { this.data.set(o.data.subarray(0, 3), 0); return this; }
  copyMax(o) { this.data.set(o.data.subarray(3, 6), 3); return this; }
  setEmpty() { this.data.set([Infinity, Infinity, Infinity, -Infinity, -Infinity, -Infinity]); return this; }
  isEmpty() { const d = this.data; return !(d[0] <= d[3] && d[1] <= d[4] && d[2] <= d[5]); }
  /** Grows the box to enclose a Box or a point (Vec3). */
  extend(o) {
    const d = this.data;
    if (o instanceof Box) {
      if (o.isEmpty()) return this;
      for (let k = 0; k < 3; k++) { d[k] = Math.min(d[k], o.data[k]); d[k + 3] = Math.max(d[k + 3], o.data[k + 3]); }
    } else {
      const p = arr(o);
      for (let k = 0; k < 3; k++) { d[k] = Math.min(d[k], p[k]); d[k + 3] = Math.max(d[k + 3], p[k]); }
    }
    return this;
  }
  center() { return this.min.add(this.max).scale(0.5); }
  size() { return this.isEmpty() ? new Vec3() : this.max.sub(this.min); }
  extent() { return this.size().scale(0.5); }
  longestSide() { const s = this.size(); return Math.max(s.x, s.y, s.z); }
  contains(p) { const v = arr(p), d = this.data; return v[0] >= d[0] && v[0] <= d[3] && v[1] >= d[1] && v[1] <= d[4] && v[2] >= d[2] && v[2] <= d[5]; }
  /** Transforms the eight corners with a Mat4 and encloses them (the box stays axis-aligned). */
  transformAxisAligned(m) {
    if (this.isEmpty()) return this;
    const d = Array.from(this.data);
    this.setEmpty();
    for (let c = 0; c < 8; c++) this.extend(new Vec3(c & 1 ? d[3] : d[0], c & 2 ? d[4] : d[1], c & 4 ? d[5] : d[2]).mul(Mat4.wrap(arr(m))));
    return this;
  }
  /** As transformAxisAligned: this Box type stores no orientation. */
  transform(m) { return this.transformAxisAligned(m); }
  intersects(ray, opt) { return rayBox(ray, this, opt); }
  toString() { return `Box(min: ${this.min.toDOMString()}, max: ${this.max.toDOMString()})`; }
  toDOMString() { return fmt(this.data); }
}

// ---- Ray (mutable) ----------------------------------------------------------------------
export class Ray {
  /** (), (Ray other), or (Vec3 origin, Vec3 direction). Default: origin 0 0 0, direction 0 0 -1. */
  constructor(a, b) {
    this.data = new Float32Array([0, 0, 0, 0, 0, -1]);
    if (a instanceof Ray) this.data.set(a.data);
    else if (arr(a) && arr(b)) this.setFromOriginDirection(a, b);
  }
  get origin() { return Vec3.wrap(this.data.subarray(0, 3)); }
  set origin(v) { this.data.set(Array.from(arr(v)).slice(0, 3), 0); }
  get direction() { return Vec3.wrap(this.data.subarray(3, 6)); }
  set direction(v) { this.data.set(Array.from(arr(v)).slice(0, 3), 3); }
  clone() { return new Ray(this); }
  copy(o) { this.data.set(o.data); return this; }
  copyOrigin(o) { this.data.set(o.data.subarray(0, 3), 0); return this; }
  copyDirection(o) { this.data.set(o.data.subarray(3, 6), 3); return this; }
  /** The specification's name for copyDirection. */
  copyMax(o) { return this.copyDirection(o); }
  setFromOriginDirection(origin, direction) { this.origin = origin; this.direction = direction; return this; }
  intersects(box, opt) { return rayBox(this, box, opt); }
  toString() { return `Ray(origin: ${this.origin.toDOMString()}, direction: ${this.direction.toDOMString()})`; }
}

// Slab test. opt.dist: ray parameter of the entry point (0 when the origin is inside), Infinity on a miss.
function rayBox(ray, box, opt) {
  const o = ray.data, b = box.data;
  let tmin = -Infinity, tmax = Infinity, miss = box.isEmpty();
  for (let k = 0; k < 3 && !miss; k++) {
    const d = o[3 + k];
    if (Math.abs(d) < 1e-12) {
      if (o[k] < b[k] || o[k] > b[k + 3]) miss = true;  // parallel to the slab and outside it
      continue;
    }
    let t1 = (b[k] - o[k]) / d, t2 = (b[k + 3] - o[k]) / d;
    if (t1 > t2) [t1, t2] = [t2, t1];
    tmin = Math.max(tmin, t1); tmax = Math.min(tmax, t2);
  }
  const hit = !miss && tmin <= tmax && tmax >= 0;
  if (opt && typeof opt === 'object') opt.dist = hit ? Math.max(tmin, 0) : Infinity;
  return hit;
}
