// Tessera's binary client protocol, the JavaScript twin of protocol/protocol.{h,cpp}: encoders
// and decoders for both directions (the browser encodes client records and decodes server
// records; tests and mock servers do the reverse).
//
//   message = "TS" u8 version u8 channel u32 record_count, record*
//   record  = u8 type u8 op u16 reserved(0) u32 body_length, body
// Everything is little endian.
//
// The constants (record types, enums, flags, body sizes, ranges, default limits) come from
// Wire.js, generated from protocol/wire.toml, the one place the wire format is declared. The
// decoders check what protocol.cpp checks, in the same order, and throw a ProtocolError whose
// `code` is the C++ ErrorCode's name and `record` the offending record's index: CTest
// protocol_crosscheck holds both codecs to the same bytes and the same error classes
// (docs/protocol.md, "Where the wire format is declared"). Two checks need what a browser does
// not have synchronously, and are done only when the caller passes them in `options`: a
// deflated buffer is inflated (and checked) with `options.inflate`, and a PNG or JPEG texture's
// header gives its size, but its pixels are not decoded here.
import {
  VERSION, MAGIC, MESSAGE_HEADER, RECORD_HEADER, NO_RECORD, REMOVE_BODY, LIMITS, ENUMS, FLAGS, RECORDS, RANGES,
  RecordType, Renderer, Display, FrameEncoding, TextureFormat, BufferType, Wrap, Filter, MaterialModel, LightType,
  SourceType, RefKind, Refinement, ErrorCode, MAX_ERROR_CODE, MESH_TRANSFORM, CAMERA_TRANSFORM, WORLD_LIMIT, UNIT_TOLERANCE,
} from './Wire.js';

export {
  VERSION, MAGIC, MESSAGE_HEADER, RECORD_HEADER, NO_RECORD, LIMITS, RECORDS, RecordType, Renderer, Display,
  FrameEncoding, TextureFormat, BufferType, Wrap, Filter, MaterialModel, LightType, SourceType, RefKind, ErrorCode,
};

export const Channel = Object.freeze(Object.fromEntries(ENUMS.channel.map((n, i) => [n, i])));
export const Op = Object.freeze(Object.fromEntries(ENUMS.op.map((n, i) => [n, i])));
export const BUFFER_DEFLATE = FLAGS.buffer.deflate;
export const MATERIAL_ALPHA_MASK = FLAGS.material.alpha_mask, MATERIAL_DOUBLE_SIDED = FLAGS.material.double_sided;
export const MATERIAL_USE_VERTEX_COLOR = FLAGS.material.use_vertex_color;
// The H.264 display's lowest bitrate (kbit/s); a video record's 0 leaves the bitrate unchanged (protocol.h kMinVideoKbps).
export const MIN_VIDEO_KBPS = 100;
const TYPE_NAME = Object.fromEntries(Object.entries(RecordType).map(([k, v]) => [v, k]));

// `code`: the C++ ErrorCode's name ('truncated', 'bad_enum', ...) for a decoding error, null for
// an encoder given a record it cannot write; `record`: the record's index in its message.
export class ProtocolError extends Error {
  constructor(message, code = null, record = NO_RECORD) {
    super(message);
    this.code = code;
    this.record = record;
  }
}

const index = (list, v, what) => {
  const i = typeof v === 'number' ? v : list.indexOf(v);
  if (i < 0 || i >= list.length) throw new ProtocolError(`${what}: "${v}" is not one of ${list.join(', ')}`);
  return i;
};

// ---- writing ---------------------------------------------------------------------------
class Writer {
  constructor(size = 1024) { this.buf = new Uint8Array(size); this.dv = new DataView(this.buf.buffer); this.n = 0; }
  reserve(k) {
    if (this.n + k <= this.buf.length) return;
    const b = new Uint8Array(Math.max(this.buf.length * 2, this.n + k));
    b.set(this.buf.subarray(0, this.n));
    this.buf = b; this.dv = new DataView(b.buffer);
  }
  u8(v) { this.reserve(1); this.dv.setUint8(this.n, v); this.n += 1; }
  u16(v) { this.reserve(2); this.dv.setUint16(this.n, v, true); this.n += 2; }
  u32(v) { this.reserve(4); this.dv.setUint32(this.n, v >>> 0, true); this.n += 4; }
  u64(v) { this.reserve(8); this.dv.setBigUint64(this.n, BigInt(v), true); this.n += 8; }
  f32(v) { this.reserve(4); this.dv.setFloat32(this.n, v, true); this.n += 4; }
  vec3(v) { this.f32(v[0]); this.f32(v[1]); this.f32(v[2]); }
  mat4(m) { for (let i = 0; i < 16; i++) this.f32(m[i]); }
  bytes(b) {
    const u = b instanceof Uint8Array ? b : new Uint8Array(b.buffer, b.byteOffset, b.byteLength);
    this.reserve(u.length); this.buf.set(u, this.n); this.n += u.length;
  }
  begin(type, op = Op.set) { this.u8(type); this.u8(op); this.u16(0); const at = this.n; this.u32(0); return at; }
  end(at) { this.dv.setUint32(at, this.n - at - 4, true); }
  result() { return this.buf.slice(0, this.n); }
}

function header(w, channel, count) {
  w.u8(MAGIC[0]); w.u8(MAGIC[1]); w.u8(VERSION); w.u8(channel); w.u32(count);
}

// UTF-8 of `s`, cut to the field's longest encoding (as the C++ encoder cuts it).
const textEncoder = new TextEncoder();
const utf8 = (s, max) => textEncoder.encode(s ?? '').subarray(0, max);
const maxLength = (record, field) => RECORDS[record].fields.find((f) => f.name === field).maxLength;
// Bytes of one value of a buffer reference's source type (protocol.h source_size).
export const sourceSize = (s) => (s === 'u16' ? 2 : s === 'u8' ? 1 : 4);

function encodeClientRecord(w, r) {
  let at;
  switch (r.type) {
    case 'handshake':
      at = w.begin(RecordType.handshake);
      w.u8(index(Renderer, r.renderer ?? 'raytracer', 'renderer')); w.u8(index(Display, r.display ?? 'jpeg', 'display'));
      w.u8(r.jpegQuality ?? 85); w.u8(0); w.u32(r.maxNodes ?? 0); w.u32(r.width); w.u32(r.height);
      break;
    case 'settings':
      at = w.begin(RecordType.settings); w.u32(r.aoSamples ?? 0); w.u32(r.maxDepth ?? 4); break;
    case 'refine':
      at = w.begin(RecordType.refine); w.u32(r.samples ?? 0); break;
    case 'budget':
      at = w.begin(RecordType.budget); w.u32(r.frameMs ?? 0); break;
    case 'video':
      at = w.begin(RecordType.video); w.u32(r.bitrateKbps ?? 0); w.u8(r.keyframe ? 1 : 0); w.u8(0); w.u8(0); w.u8(0); break;
    case 'resolution':
      at = w.begin(RecordType.resolution); w.u32(r.width); w.u32(r.height); break;
    case 'camera':
      at = w.begin(RecordType.camera); w.mat4(r.toWorld); w.f32(r.fovY); break;
    case 'environment':
      at = w.begin(RecordType.environment);
      w.vec3(r.ambient ?? [0, 0, 0]); w.vec3(r.background ?? [0, 0, 0]); w.f32(r.exposure ?? 1);
      w.u8(r.linear ? 1 : 0); w.u8(0); w.u8(0); w.u8(0);
      break;
    case 'buffer': {
      at = w.begin(RecordType.buffer);
      const values = r.data.length;
      w.u32(r.id); w.u8(index(BufferType, r.bufferType, 'buffer type')); w.u8(r.components);
      w.u8(r.deflated ? BUFFER_DEFLATE : 0); w.u8(0); w.u32(values);
      w.bytes(r.deflated || r.data);
      break;
    }
    case 'texture':
      at = w.begin(RecordType.texture);
      w.u32(r.id); w.u8(index(TextureFormat, r.format, 'texture format'));
      w.u8(index(Wrap, r.wrapS ?? 'repeat', 'wrap')); w.u8(index(Wrap, r.wrapT ?? 'repeat', 'wrap'));
      w.u8(index(Filter, r.filter ?? 'linear', 'filter')); w.u8(r.srgb ? 1 : 0); w.u8(0); w.u8(0); w.u8(0);
      w.u32(r.width); w.u32(r.height); w.bytes(r.bytes);
      break;
    case 'material':
      at = w.begin(RecordType.material);
      w.u32(r.id); w.u8(index(MaterialModel, r.model, 'material model'));
      w.u8((r.alphaMask ? MATERIAL_ALPHA_MASK : 0) | (r.doubleSided !== false ? MATERIAL_DOUBLE_SIDED : 0) |
        (r.useVertexColor ? MATERIAL_USE_VERTEX_COLOR : 0)); w.u16(0);
      w.vec3(r.diffuseColor); w.vec3(r.specularColor); w.f32(r.shininess); w.vec3(r.emissiveColor);
      w.f32(r.ambientIntensity); w.f32(r.opacity);
      w.u32(r.diffuseTexture || 0); w.u32(r.specularTexture || 0); w.u32(r.emissiveTexture || 0);
      w.f32(r.reflection); w.f32(r.refraction); w.f32(r.ior); w.f32(r.alphaCutoff ?? 0.5);
      break;
    case 'mesh':
      at = w.begin(RecordType.mesh);
      w.u32(r.id); w.u32(r.positions); w.u32(r.normals || 0); w.u32(r.texcoords || 0); w.u32(r.colors || 0);
      w.u32(r.indices || 0);
      w.u32(r.material || 0); w.mat4(r.transform); w.u8(r.visible === false ? 0 : 1); w.u8(0); w.u8(0); w.u8(0);
      break;
    case 'light':
      at = w.begin(RecordType.light);
      w.u32(r.id); w.u8(index(LightType, r.lightType, 'light type')); w.u8(r.on === false ? 0 : 1);
      w.u8(r.castShadow === false ? 0 : 1); w.u8(0);
      w.vec3(r.color); w.f32(r.intensity ?? 1); w.vec3(r.position); w.vec3(r.direction); w.vec3(r.attenuation);
      w.f32(r.cutoff); w.f32(r.softness);
      break;
    case 'buffer_ref':
      at = w.begin(RecordType.buffer_ref);
      w.u32(r.id); w.u8(index(BufferType, r.bufferType, 'buffer type')); w.u8(r.components);
      w.u8(index(SourceType, r.source, 'source')); w.u8(0); w.u32(r.values); w.u32(r.byteStride ?? 0);
      w.u64(r.byteOffset ?? 0); w.bytes(utf8(r.url, maxLength('buffer_ref', 'url')));
      break;
    case 'texture_ref':
      at = w.begin(RecordType.texture_ref);
      w.u32(r.id); w.u8(index(Wrap, r.wrapS ?? 'repeat', 'wrap')); w.u8(index(Wrap, r.wrapT ?? 'repeat', 'wrap'));
      w.u8(index(Filter, r.filter ?? 'linear', 'filter')); w.u8(r.srgb ? 1 : 0);
      w.bytes(utf8(r.url, maxLength('texture_ref', 'url')));
      break;
    case 'remove':
      at = w.begin(RecordType[r.what], Op.remove); w.u32(r.id); break;
    case 'render':
      at = w.begin(RecordType.render); w.u32(r.frame); break;
    default: throw new ProtocolError(`unknown client record type ${r.type}`);
  }
  w.end(at);
}

function encodeServerRecord(w, r) {
  let at;
  switch (r.type) {
    case 'handshake_reply': {
      at = w.begin(RecordType.handshake_reply);
      const v = utf8(r.serverVersion, maxLength('handshake_reply', 'server_version'));
      w.u8(index(Renderer, r.renderer ?? 'raytracer', 'renderer')); w.u8(index(Display, r.display ?? 'jpeg', 'display'));
      w.u8(r.jpegQuality ?? 85); w.u8(v.length); w.u32(r.nodes ?? 1); w.u32(r.width); w.u32(r.height);
      w.u32(r.maxMessageBytes ?? 0); w.u64(r.maxBufferBytes ?? 0); w.bytes(v);
      break;
    }
    case 'frame': {
      at = w.begin(RecordType.frame);
      const t = r.timings || {};
      w.u32(r.frame); w.u32(r.width); w.u32(r.height); w.u8(index(FrameEncoding, r.encoding ?? 'jpeg', 'encoding'));
      w.u8(index(Refinement, r.refinement ?? (r.refined ? (r.converged ? 'converged' : 'refined') : 'requested'), 'refined'));
      w.u16(Math.max(1, Math.min(0xffff, r.samples ?? 1)));
      for (const k of ['kernel', 'rendering', 'sat', 'tiling', 'pipeline', 'encode']) w.f32(t[k] ?? 0);
      w.bytes(r.payload ?? new Uint8Array(0));
      break;
    }
    case 'error':
      at = w.begin(RecordType.error);
      w.u16(typeof r.code === 'number' ? r.code : index(ErrorCode, r.code, 'error code')); w.u8(r.fatal ? 1 : 0); w.u8(0);
      w.u32(r.record ?? NO_RECORD); w.bytes(utf8(r.message, maxLength('error', 'message')));
      break;
    case 'reference':
      at = w.begin(RecordType.reference);
      w.u8(index(RefKind, r.what, 'reference kind')); w.u8(r.ok ? 1 : 0); w.u16(0); w.u32(r.id); w.u64(r.bytes ?? 0);
      w.bytes(utf8(r.message, maxLength('reference', 'message')));
      break;
    case 'stats':
      at = w.begin(RecordType.stats);
      w.u32(r.frames ?? 0); w.u32(r.dropped ?? 0); w.u64(r.bytesSent ?? 0); w.u64(r.sceneBytes ?? 0);
      w.u64(r.triangles ?? 0); w.u32(r.nodes ?? 1); w.f32(r.fps ?? 0); w.f32(r.meanPipelineMs ?? 0);
      break;
    default: throw new ProtocolError(`unknown server record type ${r.type}`);
  }
  w.end(at);
}

export function encodeClient(records) {
  const w = new Writer(256);
  header(w, Channel.client, records.length);
  for (const r of records) encodeClientRecord(w, r);
  return w.result();
}

export function encodeServer(records) {
  const w = new Writer(256);
  header(w, Channel.server, records.length);
  for (const r of records) encodeServerRecord(w, r);
  return w.result();
}

// Size of one client record on the wire (for packing messages).
export function clientRecordSize(r) {
  if (r.type === 'remove') return RECORD_HEADER + REMOVE_BODY;
  const spec = RECORDS[r.type];
  if (!spec || spec.channel !== 'client') throw new ProtocolError(`unknown client record type ${r.type}`);
  if (r.type === 'buffer') return RECORD_HEADER + spec.fixed + (r.deflated ? r.deflated.length : r.data.byteLength);
  if (r.type === 'texture') return RECORD_HEADER + spec.fixed + r.bytes.byteLength;
  if (r.type === 'buffer_ref' || r.type === 'texture_ref') return RECORD_HEADER + spec.fixed + utf8(r.url, maxLength(r.type, 'url')).length;
  return RECORD_HEADER + spec.fixed;
}

// ---- reading ---------------------------------------------------------------------------
// Reads a record body whose length was checked first (as protocol.cpp's Reader).
class Reader {
  constructor(bytes, off, len) { this.dv = new DataView(bytes.buffer, bytes.byteOffset + off, len); this.bytes = bytes; this.base = off; this.p = 0; this.len = len; }
  u8() { return this.dv.getUint8(this.p++); }
  u16() { const v = this.dv.getUint16(this.p, true); this.p += 2; return v; }
  u32() { const v = this.dv.getUint32(this.p, true); this.p += 4; return v; }
  // A Number while exact, else a BigInt (so that every u64 decodes and re-encodes exactly).
  u64() {
    const v = this.dv.getBigUint64(this.p, true); this.p += 8;
    return v <= BigInt(Number.MAX_SAFE_INTEGER) ? Number(v) : v;
  }
  f32() { const v = this.dv.getFloat32(this.p, true); this.p += 4; return v; }
  vec3() { return [this.f32(), this.f32(), this.f32()]; }
  mat4() { const m = new Float32Array(16); for (let i = 0; i < 16; i++) m[i] = this.f32(); return m; }
  reserved3() { return this.u8() | (this.u8() << 8) | (this.u8() << 16); }
  rest() { const b = this.bytes.slice(this.base + this.p, this.base + this.len); this.p = this.len; return b; }
  left() { return this.len - this.p; }
}

// The checks of core/validate.h (transform_figures, check_transform, check_point,
// check_direction), in the same arithmetic: double for the 3x3 figures, float (Math.fround
// after every operation) for normalising a direction.
function transformProblem(m, lim) {
  const a = [0, 1, 2].map((r) => [0, 1, 2].map((c) => m[c * 4 + r]));
  const adj = [
    [a[1][1] * a[2][2] - a[1][2] * a[2][1], a[0][2] * a[2][1] - a[0][1] * a[2][2], a[0][1] * a[1][2] - a[0][2] * a[1][1]],
    [a[1][2] * a[2][0] - a[1][0] * a[2][2], a[0][0] * a[2][2] - a[0][2] * a[2][0], a[0][2] * a[1][0] - a[0][0] * a[1][2]],
    [a[1][0] * a[2][1] - a[1][1] * a[2][0], a[0][1] * a[2][0] - a[0][0] * a[2][1], a[0][0] * a[1][1] - a[0][1] * a[1][0]],
  ];
  const det = a[0][0] * adj[0][0] + a[0][1] * adj[1][0] + a[0][2] * adj[2][0];
  let norm = 0, adjNorm = 0, translation = 0;
  for (let r = 0; r < 3; r++) {
    let row = 0, rowAdj = 0;
    for (let c = 0; c < 3; c++) { row += Math.abs(a[r][c]); rowAdj += Math.abs(adj[r][c]); }
    norm = Math.max(norm, row); adjNorm = Math.max(adjNorm, rowAdj);
    translation = Math.max(translation, Math.abs(m[12 + r]));
  }
  const normInverse = det !== 0 ? adjNorm / Math.abs(det) : Infinity;
  const condition = det !== 0 ? norm * normInverse : Infinity;
  if (norm > lim.maxNorm) return `scale too large: the upper 3x3's norm (max row sum) is ${norm}, at most ${lim.maxNorm}`;
  if (translation > lim.maxTranslation) return `translation ${translation} beyond ${lim.maxTranslation}`;
  if (det === 0) return 'the upper 3x3 is singular (determinant 0)';
  if (normInverse > lim.maxInverseNorm) return `nearly singular: the inverse's norm is ${normInverse}, at most ${lim.maxInverseNorm}`;
  if (condition > lim.maxCondition) return `ill-conditioned: condition number ${condition}, at most ${lim.maxCondition}`;
  return '';
}
const f = Math.fround;
const dotf = (v) => f(f(f(v[0] * v[0]) + f(v[1] * v[1])) + f(v[2] * v[2]));
function pointProblem(p) {
  const m = Math.max(Math.abs(p[0]), Math.abs(p[1]), Math.abs(p[2]));
  return m > WORLD_LIMIT ? `component ${m} beyond the world limit ${WORLD_LIMIT}` : '';
}
function directionProblem(d) {
  const l = f(Math.sqrt(dotf(d)));
  const n = l > 0 ? d.map((x) => f(x / l)) : [0, 0, 0];
  const ln = f(Math.sqrt(dotf(n)));
  return Math.abs(f(ln - 1)) < UNIT_TOLERANCE ? '' : 'cannot be normalised (zero, or too large or small for float)';
}
const finite = (v) => Array.prototype.every.call(typeof v === 'number' ? [v] : v, Number.isFinite);

// One record's checks, failing as protocol.cpp's Check does: the first failure throws.
class Check {
  constructor(index, name, lim) { this.index = index; this.name = name; this.lim = lim; }
  fail(code, what) { throw new ProtocolError(`record ${this.index} (${this.name}): ${what}`, code, this.index); }
  finite(v, field) { if (!finite(v)) this.fail('not_finite', `${field} is not finite`); }
  // Finite and within the field's declared range (Wire.js RANGES: closed, open, above, int).
  range(v, field, range = RANGES[this.name][field]) {
    if (range.kind !== 'int') this.finite(v, field);
    const ok = range.kind === 'open' ? v > range.lo && v < range.hi
      : range.kind === 'above' ? v > range.lo : v >= range.lo && v <= range.hi;
    if (!ok) this.fail(range.kind === 'int' ? this.fieldError(field) : 'out_of_range', `${field} = ${v} outside its range`);
  }
  fieldError(field) { return RECORDS[this.name].fields.find((x) => x.name === field).error ?? 'out_of_range'; }
  nonNegative(v, field) {
    this.finite(v, field);
    if (v[0] < 0 || v[1] < 0 || v[2] < 0) this.fail('out_of_range', `${field} is negative`);
  }
  enumeration(v, field) {
    const list = ENUMS[RECORDS[this.name].fields.find((x) => x.name === field).enum];
    if (v >= list.length) this.fail('bad_enum', `${field} = ${v} (valid: 0..${list.length - 1})`);
    return list[v];
  }
  flag(v, field) { if (v > 1) this.fail('bad_enum', `${field} = ${v} (valid: 0..1)`); return v !== 0; }
  flags(v, group) { if (v & ~Object.values(FLAGS[group]).reduce((x, y) => x | y, 0)) this.fail('bad_reserved', `unknown ${group} flags`); }
  reserved(v) { if (v !== 0) this.fail('bad_reserved', 'reserved field is not zero'); }
  id(v, field) { if (v === 0) this.fail('bad_id', `${field} is 0 (reserved)`); }
  length(got, want) { if (got !== want) this.fail('bad_length', `body length ${got}, expected ${want}`); }
  minLength(got, want) { if (got < want) this.fail('bad_length', `body length ${got}, at least ${want} expected`); }
  limit(v, name, field) { if (v > this.lim[name]) this.fail('limit_exceeded', `${field} ${v} exceeds the limit ${this.lim[name]}`); }
  // Width and height: each at least its minimum (out_of_range), then within the limits.
  size(w, h, wLimit, hLimit, what = 'resolution') {
    const spec = RECORDS[this.name].fields;
    const min = (n) => spec.find((x) => x.name === n).min;
    if (w < min('width') || h < min('height')) this.fail('out_of_range', `${what} ${w}x${h} is empty`);
    if (w > this.lim[wLimit] || h > this.lim[hLimit]) this.fail('limit_exceeded', `${what} ${w}x${h} exceeds the limit`);
  }
  resolution(w, h) { this.size(w, h, 'max_width', 'max_height'); }
  transform(m, field, lim) { const why = transformProblem(m, lim); if (why) this.fail('out_of_range', `${field}: ${why}`); }
  // A reference's URL: the rest of the body, 1..max_length bytes (which URLs a node loads is
  // its own business).
  url(r) {
    const max = RECORDS[this.name].fields.find((x) => x.name === 'url').maxLength;
    if (r.left() === 0 || r.left() > max) this.fail('bad_length', `url of ${r.left()} bytes (1..${max})`);
    return new TextDecoder().decode(r.rest());
  }
}

// PNG: the signature, then IHDR with the big-endian width and height.
function pngSize(b) {
  const sig = [0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a];
  if (b.length < 24 || sig.some((x, i) => b[i] !== x) || String.fromCharCode(...b.subarray(12, 16)) !== 'IHDR') return null;
  const dv = new DataView(b.buffer, b.byteOffset, b.byteLength);
  return [dv.getUint32(16), dv.getUint32(20)];
}
// JPEG: SOI, then markers up to the first start-of-frame (SOF0..SOF15 but DHT, JPG, DAC).
function jpegSize(b) {
  if (b.length < 4 || b[0] !== 0xff || b[1] !== 0xd8) return null;
  let p = 2;
  while (p + 4 <= b.length) {
    if (b[p] !== 0xff) return null;
    const m = b[p + 1];
    if (m === 0xff) { p++; continue; }
    if (m === 0xd8 || m === 0x01 || (m >= 0xd0 && m <= 0xd7)) { p += 2; continue; }
    if (m === 0xd9 || m === 0xda) return null;  // end of image, or scan data before any frame
    const len = (b[p + 2] << 8) | b[p + 3];
    if (len < 2) return null;
    if (m >= 0xc0 && m <= 0xcf && m !== 0xc4 && m !== 0xc8 && m !== 0xcc) {
      if (p + 9 > b.length) return null;
      const h = (b[p + 5] << 8) | b[p + 6], w = (b[p + 7] << 8) | b[p + 8];
      return w && h ? [w, h] : null;
    }
    p += 2 + len;
  }
  return null;
}

function decodeClientRecord(c, op, r, state) {
  const name = c.name, spec = RECORDS[name], lim = c.lim;
  if (op === Op.remove) {
    if (!spec.removable) c.fail('bad_op', 'remove is only defined for buffer, texture, material, mesh and light');
    c.length(r.left(), REMOVE_BODY);
    const id = r.u32();
    c.id(id, 'id');
    return { type: 'remove', what: name, id };
  }
  switch (name) {
    case 'handshake': {
      c.length(r.left(), spec.fixed);
      const renderer = r.u8(), display = r.u8(), jpegQuality = r.u8(), res = r.u8();
      const maxNodes = r.u32(), width = r.u32(), height = r.u32();
      const rec = { type: name, renderer: c.enumeration(renderer, 'renderer'), display: c.enumeration(display, 'display') };
      c.reserved(res);
      c.range(jpegQuality, 'jpeg_quality');
      c.limit(maxNodes, 'max_nodes', 'max_nodes');
      c.resolution(width, height);
      return Object.assign(rec, { jpegQuality, maxNodes, width, height });
    }
    case 'settings': {
      c.length(r.left(), spec.fixed);
      const aoSamples = r.u32(), maxDepth = r.u32();
      c.limit(aoSamples, 'max_ao_samples', 'ao_samples');
      c.limit(maxDepth, 'max_depth', 'max_depth');
      return { type: name, aoSamples, maxDepth };
    }
    case 'refine': {
      c.length(r.left(), spec.fixed);
      const samples = r.u32();
      c.limit(samples, 'max_refine_samples', 'samples');
      return { type: name, samples };
    }
    case 'video': {
      c.length(r.left(), spec.fixed);
      const bitrateKbps = r.u32(), key = r.u8(), res = r.reserved3();
      c.range(bitrateKbps, 'bitrate_kbps'); c.flag(key, 'keyframe'); c.reserved(res);
      if (bitrateKbps !== 0 && bitrateKbps < MIN_VIDEO_KBPS) {
        c.fail('out_of_range', `bitrate_kbps = ${bitrateKbps} outside ${MIN_VIDEO_KBPS}..${RANGES.video.bitrate_kbps.hi} (0: unchanged)`);
      }
      return { type: name, bitrateKbps, keyframe: key !== 0 };
    }
    case 'budget': {
      c.length(r.left(), spec.fixed);
      const frameMs = r.u32();
      c.limit(frameMs, 'max_frame_budget_ms', 'frame_ms');
      return { type: name, frameMs };
    }
    case 'resolution': {
      c.length(r.left(), spec.fixed);
      const width = r.u32(), height = r.u32();
      c.resolution(width, height);
      return { type: name, width, height };
    }
    case 'camera': {
      c.length(r.left(), spec.fixed);
      const toWorld = r.mat4(), fovY = r.f32();
      c.finite(toWorld, 'to_world');
      c.range(fovY, 'fov_y');
      c.transform(toWorld, 'to_world', CAMERA_TRANSFORM);
      return { type: name, toWorld, fovY };
    }
    case 'environment': {
      c.length(r.left(), spec.fixed);
      const ambient = r.vec3(), background = r.vec3(), exposure = r.f32(), linear = r.u8(), res = r.reserved3();
      c.nonNegative(ambient, 'ambient'); c.nonNegative(background, 'background'); c.finite(exposure, 'exposure');
      c.flag(linear, 'linear'); c.reserved(res);
      c.range(exposure, 'exposure');
      return { type: name, ambient, background, exposure, linear: linear !== 0 };
    }
    case 'buffer': {
      const body = r.left();
      c.minLength(body, spec.fixed);
      const id = r.u32(), type = r.u8(), components = r.u8(), flags = r.u8(), res = r.u8(), values = r.u32();
      c.id(id, 'id');
      const bufferType = c.enumeration(type, 'type');
      c.reserved(res);
      c.flags(flags, 'buffer');
      c.range(components, 'components');
      if (values % components) c.fail('bad_components', `${values} values are not a multiple of ${components} components`);
      const bytes = values * 4;
      if (bytes > lim.max_buffer_bytes) c.fail('limit_exceeded', `buffer of ${bytes} bytes exceeds the limit of ${lim.max_buffer_bytes}`);
      if (Math.floor(values / components) > lim.max_vertices) c.fail('limit_exceeded', `${Math.floor(values / components)} elements exceed the limit of ${lim.max_vertices}`);
      const deflate = (flags & BUFFER_DEFLATE) !== 0;
      if (!deflate) c.length(body, spec.fixed + bytes);
      state.charge(c, bytes);
      const payload = r.rest();
      const rec = { type: name, id, bufferType, components, values, deflate, payload };
      let raw = deflate ? null : payload;
      if (deflate) {
        rec.deflated = payload;
        if (state.inflate) {
          try { raw = state.inflate(payload, bytes); } catch (e) { c.fail('bad_payload', `deflate: ${e.message}`); }
          if (raw.length !== bytes) c.fail('bad_payload', `deflate: inflated ${raw.length} bytes, declared ${bytes}`);
        }
      }
      if (raw) {
        const copy = raw.slice();  // aligned for the typed array
        rec.data = bufferType === 'f32' ? new Float32Array(copy.buffer, 0, values) : new Uint32Array(copy.buffer, 0, values);
      }
      return rec;
    }
    case 'texture': {
      const body = r.left();
      c.minLength(body, spec.fixed);
      const id = r.u32(), format = r.u8(), wrapS = r.u8(), wrapT = r.u8(), filter = r.u8(), srgb = r.u8(), res = r.reserved3();
      const width = r.u32(), height = r.u32();
      c.id(id, 'id');
      const rec = { type: name, id, format: c.enumeration(format, 'format'), wrapS: c.enumeration(wrapS, 'wrap_s'),
        wrapT: c.enumeration(wrapT, 'wrap_t'), filter: c.enumeration(filter, 'filter'), srgb: c.flag(srgb, 'srgb') };
      c.reserved(res);
      c.size(width, height, 'max_texture_size', 'max_texture_size', 'texture size');
      const bytes = width * height * 4;
      if (rec.format === 'rgba8') c.length(body, spec.fixed + bytes);
      state.charge(c, bytes);
      Object.assign(rec, { width, height, bytes: r.rest() });
      if (rec.format !== 'rgba8') {
        const size = rec.format === 'png' ? pngSize(rec.bytes) : jpegSize(rec.bytes);
        if (!size) c.fail('bad_texture', rec.format === 'png' ? 'not a PNG file' : 'not a JPEG file');
        if (size[0] !== width || size[1] !== height) c.fail('bad_texture', `encoded image is ${size[0]}x${size[1]}, declared ${width}x${height}`);
      }
      return rec;
    }
    case 'buffer_ref': {
      c.minLength(r.left(), spec.fixed);
      const id = r.u32(), type = r.u8(), components = r.u8(), src = r.u8(), res = r.u8();
      const values = r.u32(), byteStride = r.u32(), byteOffset = r.u64();
      c.id(id, 'id');
      const bufferType = c.enumeration(type, 'type'), source = c.enumeration(src, 'source');
      c.reserved(res);
      c.range(components, 'components');
      if ((bufferType === 'f32') !== (source === 'f32'))
        c.fail('bad_enum', `source ${source === 'f32' ? 'f32' : 'integer'} does not fit a buffer of type ${bufferType}`);
      if (values % components) c.fail('bad_components', `${values} values are not a multiple of ${components} components`);
      const bytes = values * 4;
      if (bytes > lim.max_buffer_bytes) c.fail('limit_exceeded', `buffer of ${bytes} bytes exceeds the limit of ${lim.max_buffer_bytes}`);
      if (Math.floor(values / components) > lim.max_vertices) c.fail('limit_exceeded', `${Math.floor(values / components)} elements exceed the limit of ${lim.max_vertices}`);
      c.range(byteStride, 'byte_stride');
      const size = sourceSize(source);
      if (byteStride && (byteStride < components * size || byteStride % size))
        c.fail('out_of_range', `byte_stride ${byteStride} does not hold ${components} values of ${size} bytes, or is not a multiple of ${size}`);
      return { type: name, id, bufferType, components, source, values, byteStride, byteOffset, url: c.url(r) };
    }
    case 'texture_ref': {
      c.minLength(r.left(), spec.fixed);
      const id = r.u32(), wrapS = r.u8(), wrapT = r.u8(), filter = r.u8(), srgb = r.u8();
      c.id(id, 'id');
      return { type: name, id, wrapS: c.enumeration(wrapS, 'wrap_s'), wrapT: c.enumeration(wrapT, 'wrap_t'),
        filter: c.enumeration(filter, 'filter'), srgb: c.flag(srgb, 'srgb'), url: c.url(r) };
    }
    case 'material': {
      c.length(r.left(), spec.fixed);
      const id = r.u32(), model = r.u8(), flags = r.u8(), res = r.u16();
      const rec = { type: name, id, model: null, alphaMask: (flags & MATERIAL_ALPHA_MASK) !== 0, doubleSided: (flags & MATERIAL_DOUBLE_SIDED) !== 0,
        useVertexColor: (flags & MATERIAL_USE_VERTEX_COLOR) !== 0,
        diffuseColor: r.vec3(), specularColor: r.vec3(), shininess: r.f32(), emissiveColor: r.vec3(),
        ambientIntensity: r.f32(), opacity: r.f32(), diffuseTexture: r.u32(), specularTexture: r.u32(),
        emissiveTexture: r.u32(), reflection: r.f32(), refraction: r.f32(), ior: r.f32(), alphaCutoff: r.f32() };
      c.id(id, 'id');
      rec.model = c.enumeration(model, 'model');
      c.reserved(res);
      c.flags(flags, 'material');
      c.nonNegative(rec.diffuseColor, 'diffuse_color'); c.nonNegative(rec.specularColor, 'specular_color');
      c.range(rec.shininess, 'shininess'); c.nonNegative(rec.emissiveColor, 'emissive_color');
      c.range(rec.ambientIntensity, 'ambient_intensity'); c.range(rec.opacity, 'opacity');
      c.range(rec.reflection, 'reflection'); c.range(rec.refraction, 'refraction'); c.range(rec.ior, 'ior');
      c.range(rec.alphaCutoff, 'alpha_cutoff');
      return rec;
    }
    case 'mesh': {
      c.length(r.left(), spec.fixed);
      const rec = { type: name, id: r.u32(), positions: r.u32(), normals: r.u32(), texcoords: r.u32(), colors: r.u32(),
        indices: r.u32(), material: r.u32(), transform: r.mat4(), visible: null };
      const visible = r.u8(), res = r.reserved3();
      c.id(rec.id, 'id'); c.id(rec.positions, 'positions'); c.finite(rec.transform, 'transform');
      rec.visible = c.flag(visible, 'visible');
      c.reserved(res);
      c.transform(rec.transform, 'transform', MESH_TRANSFORM);
      return rec;
    }
    case 'light': {
      c.length(r.left(), spec.fixed);
      const id = r.u32(), type = r.u8(), on = r.u8(), castShadow = r.u8(), res = r.u8();
      const rec = { type: name, id, lightType: null, on: null, castShadow: null, color: r.vec3(), intensity: r.f32(), position: r.vec3(),
        direction: r.vec3(), attenuation: r.vec3(), cutoff: r.f32(), softness: r.f32() };
      c.id(id, 'id');
      rec.lightType = c.enumeration(type, 'type');
      rec.on = c.flag(on, 'on');
      rec.castShadow = c.flag(castShadow, 'cast_shadow');
      c.reserved(res);
      c.nonNegative(rec.color, 'color'); c.range(rec.intensity, 'intensity'); c.finite(rec.position, 'position');
      c.finite(rec.direction, 'direction'); c.nonNegative(rec.attenuation, 'attenuation');
      c.range(rec.cutoff, 'cutoff'); c.range(rec.softness, 'softness');
      const t = rec.lightType;
      if (t !== 'point' && dotf(rec.direction) === 0) c.fail('out_of_range', 'direction is zero');
      let why;
      if (t !== 'directional' && (why = pointProblem(rec.position))) c.fail('out_of_range', `position ${why}`);
      if (t !== 'point' && (why = directionProblem(rec.direction))) c.fail('out_of_range', `direction ${why}`);
      if (t !== 'directional' && rec.attenuation.every((x) => x === 0)) c.fail('out_of_range', 'attenuation is all zero');
      if (t === 'spot' && rec.cutoff === 0) c.fail('out_of_range', 'cutoff is zero');
      return rec;
    }
    case 'render':
      c.length(r.left(), spec.fixed);
      return { type: name, frame: r.u32() };
    default: return c.fail('unknown_record', 'not a client record');
  }
}

function decodeServerRecord(c, op, r) {
  const name = c.name, spec = RECORDS[name];
  switch (name) {
    case 'handshake_reply': {
      const body = r.left();
      c.minLength(body, spec.fixed);
      const renderer = r.u8(), display = r.u8(), jpegQuality = r.u8(), n = r.u8();
      const rec = { type: name, renderer: null, display: null, jpegQuality, nodes: r.u32(), width: r.u32(), height: r.u32(),
        maxMessageBytes: r.u32(), maxBufferBytes: r.u64() };
      c.length(body, spec.fixed + n);
      rec.serverVersion = new TextDecoder().decode(r.rest());
      rec.renderer = c.enumeration(renderer, 'renderer');
      rec.display = c.enumeration(display, 'display');
      c.range(jpegQuality, 'jpeg_quality');
      c.resolution(rec.width, rec.height);
      return rec;
    }
    case 'frame': {
      const body = r.left();
      c.minLength(body, spec.fixed);
      const rec = { type: name, frame: r.u32(), width: r.u32(), height: r.u32(), encoding: null };
      const encoding = r.u8(), refined = r.u8();
      rec.samples = r.u16();
      rec.timings = {};
      for (const k of ['kernel', 'rendering', 'sat', 'tiling', 'pipeline', 'encode']) rec.timings[k] = r.f32();
      rec.encoding = c.enumeration(encoding, 'encoding');
      rec.refinement = c.enumeration(refined, 'refined');  // requested, refined or converged (the still's last)
      rec.refined = rec.refinement !== 'requested';
      rec.converged = rec.refinement === 'converged';
      c.resolution(rec.width, rec.height);
      if (rec.encoding === 'dxt1') c.length(body, spec.fixed + dxt1Size(rec.width, rec.height));
      rec.payload = r.rest();
      return rec;
    }
    case 'error': {
      c.minLength(r.left(), spec.fixed);
      const code = r.u16(), fatal = r.u8(), res = r.u8(), record = r.u32();
      if (code > MAX_ERROR_CODE) c.fail('bad_enum', `error code ${code}`);
      const rec = { type: name, code, codeName: ErrorCode[code], fatal: c.flag(fatal, 'fatal'), record };
      c.reserved(res);
      rec.message = new TextDecoder().decode(r.rest());
      return rec;
    }
    case 'reference': {
      c.minLength(r.left(), spec.fixed);
      const what = r.u8(), ok = r.u8(), res = r.u16(), id = r.u32(), bytes = r.u64();
      const rec = { type: name, what: c.enumeration(what, 'what'), ok: c.flag(ok, 'ok'), id, bytes };
      c.reserved(res);
      c.id(id, 'id');
      rec.message = new TextDecoder().decode(r.rest());
      return rec;
    }
    case 'stats':
      c.length(r.left(), spec.fixed);
      return { type: name, frames: r.u32(), dropped: r.u32(), bytesSent: r.u64(), sceneBytes: r.u64(), triangles: r.u64(),
        nodes: r.u32(), fps: r.f32(), meanPipelineMs: r.f32() };
    default: return c.fail('unknown_record', 'not a server record');
  }
}

// Walks a message's framing as protocol.cpp's walk() does, in the same order of checks.
function decode(bytes, channel, decodeRecord, options = {}) {
  if (!(bytes instanceof Uint8Array)) bytes = new Uint8Array(bytes);
  const lim = { ...LIMITS, ...(options.limits || {}) };
  const fail = (code, message, record = NO_RECORD) => { throw new ProtocolError(message, code, record); };
  const size = bytes.length;
  if (size > lim.max_message_bytes) fail('too_large', `message of ${size} bytes exceeds the limit of ${lim.max_message_bytes}`);
  if (size < MESSAGE_HEADER) fail('truncated', `message of ${size} bytes is shorter than its header (truncated)`);
  if (bytes[0] !== MAGIC[0] || bytes[1] !== MAGIC[1]) fail('bad_magic', 'bad magic (not "TS")');
  if (bytes[2] !== VERSION) fail('bad_version', `protocol version ${bytes[2]} not supported (expected ${VERSION})`);
  if (bytes[3] !== channel) fail('bad_channel', `channel ${bytes[3]} (expected ${channel})`);
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const count = dv.getUint32(4, true);
  if (count === 0) fail('bad_length', 'message holds no records');
  if (count > lim.max_records) fail('too_large', `${count} records exceed the limit of ${lim.max_records}`);
  if (count > Math.floor((size - MESSAGE_HEADER) / RECORD_HEADER)) fail('truncated', `${count} records cannot fit in ${size} bytes (truncated)`);
  let payload = 0;
  const state = {
    inflate: options.inflate,
    charge(c, n) {  // decoded bytes of the message's buffers and textures
      if (n > lim.max_message_payload_bytes - payload) c.fail('limit_exceeded', `buffers and textures in this message exceed the limit of ${lim.max_message_payload_bytes} bytes`);
      payload += n;
    },
  };
  const records = [];
  let at = MESSAGE_HEADER, handshake = false;
  for (let i = 0; i < count; i++) {
    if (size - at < RECORD_HEADER) fail('truncated', `record ${i}: header truncated`, i);
    const type = bytes[at], op = bytes[at + 1], res = dv.getUint16(at + 2, true), len = dv.getUint32(at + 4, true);
    at += RECORD_HEADER;
    if (len > size - at) fail('truncated', `record ${i}: body of ${len} bytes, only ${size - at} left (truncated)`, i);
    const name = TYPE_NAME[type];
    if (!name || RECORDS[name].channel !== ENUMS.channel[channel]) fail('unknown_record', `record ${i}: unknown record type ${type}`, i);
    if (op > Op.remove) fail('bad_op', `record ${i}: unknown op ${op}`, i);
    if (channel === Channel.server && op !== Op.set) fail('bad_op', `record ${i}: server records have op 0`, i);
    if (res !== 0) fail('bad_reserved', `record ${i}: reserved header field is not zero`, i);
    if (name === 'handshake') handshake = true;
    records.push(decodeRecord(new Check(i, name, lim), op, new Reader(bytes, at, len), state));
    at += len;
  }
  if (at !== size) fail('bad_length', `${size - at} bytes after the last record`);
  if (handshake && count !== 1) fail('bad_handshake', 'a handshake must be the only record in its message');
  return records;
}

// options: { limits: overrides of LIMITS (C++ names), inflate: (zlib bytes, declared size) => bytes }
export const decodeClient = (bytes, options) => decode(bytes, Channel.client, decodeClientRecord, options);
export const decodeServer = (bytes, options) => decode(bytes, Channel.server, decodeServerRecord, options);

// Size in bytes of DXT1 data for a frame (4x4 blocks of 8 bytes).
export const dxt1Size = (w, h) => Math.ceil(w / 4) * Math.ceil(h / 4) * 8;
