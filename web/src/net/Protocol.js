// Tessera's binary client protocol (protocol/protocol.h in the repository, byte for byte): every
// constant of the wire format lives here, with encoders and decoders for both directions
// (the browser encodes client records and decodes server records; tests and mock servers
// do the reverse).
//
//   message = "TS" u8 version u8 channel u32 record_count, record*
//   record  = u8 type u8 op u16 reserved(0) u32 body_length, body
// Everything is little endian.

export const VERSION = 1;
export const MAGIC = [0x54, 0x53];  // "TS"
export const MESSAGE_HEADER = 8;
export const RECORD_HEADER = 8;
export const NO_RECORD = 0xffffffff;

export const Channel = { client: 0, server: 1 };
export const Op = { set: 0, remove: 1 };
export const RecordType = {
  handshake: 0x01, settings: 0x02, resolution: 0x03, camera: 0x04, environment: 0x05,
  buffer: 0x10, texture: 0x11, material: 0x12, mesh: 0x13, light: 0x14, render: 0x20,
  handshake_reply: 0x81, frame: 0x82, error: 0x83, stats: 0x84,
};
const TYPE_NAME = Object.fromEntries(Object.entries(RecordType).map(([k, v]) => [v, k]));

export const Renderer = ['raytracer', 'rasterizer'];
export const Display = ['jpeg', 's3tc', 'mjpeg'];
export const FrameEncoding = ['jpeg', 'dxt1'];
export const TextureFormat = ['rgba8', 'png', 'jpeg'];
export const BufferType = ['f32', 'u32'];
export const Wrap = ['clamp', 'repeat'];
export const Filter = ['nearest', 'linear'];
export const MaterialModel = ['matte', 'diffuse', 'phong'];
export const LightType = ['point', 'directional', 'spot'];
export const BUFFER_DEFLATE = 1;
export const MATERIAL_ALPHA_MASK = 1, MATERIAL_DOUBLE_SIDED = 2;

export const ErrorCode = ['ok', 'truncated', 'bad_magic', 'bad_version', 'bad_channel', 'too_large', 'unknown_record',
  'bad_op', 'bad_length', 'bad_reserved', 'bad_id', 'bad_enum', 'bad_components', 'not_finite', 'out_of_range',
  'limit_exceeded', 'bad_payload', 'bad_texture', 'bad_mesh', 'unknown_id', 'bad_handshake', 'not_scene_update',
  'internal'];

export class ProtocolError extends Error {}

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
      w.u8((r.alphaMask ? MATERIAL_ALPHA_MASK : 0) | (r.doubleSided !== false ? MATERIAL_DOUBLE_SIDED : 0)); w.u16(0);
      w.vec3(r.diffuseColor); w.vec3(r.specularColor); w.f32(r.shininess); w.vec3(r.emissiveColor);
      w.f32(r.ambientIntensity); w.f32(r.opacity);
      w.u32(r.diffuseTexture || 0); w.u32(r.specularTexture || 0); w.u32(r.emissiveTexture || 0);
      w.f32(r.reflection); w.f32(r.refraction); w.f32(r.ior); w.f32(r.alphaCutoff ?? 0.5);
      break;
    case 'mesh':
      at = w.begin(RecordType.mesh);
      w.u32(r.id); w.u32(r.positions); w.u32(r.normals || 0); w.u32(r.texcoords || 0); w.u32(r.indices || 0);
      w.u32(r.material || 0); w.mat4(r.transform); w.u8(r.visible === false ? 0 : 1); w.u8(0); w.u8(0); w.u8(0);
      break;
    case 'light':
      at = w.begin(RecordType.light);
      w.u32(r.id); w.u8(index(LightType, r.lightType, 'light type')); w.u8(r.on === false ? 0 : 1); w.u16(0);
      w.vec3(r.color); w.f32(r.intensity ?? 1); w.vec3(r.position); w.vec3(r.direction); w.vec3(r.attenuation);
      w.f32(r.cutoff); w.f32(r.softness);
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
      const v = new TextEncoder().encode(r.serverVersion ?? '').slice(0, 255);
      w.u8(index(Renderer, r.renderer ?? 'raytracer', 'renderer')); w.u8(index(Display, r.display ?? 'jpeg', 'display'));
      w.u8(r.jpegQuality ?? 85); w.u8(v.length); w.u32(r.nodes ?? 1); w.u32(r.width); w.u32(r.height);
      w.u32(r.maxMessageBytes ?? 0); w.u64(r.maxBufferBytes ?? 0); w.bytes(v);
      break;
    }
    case 'frame': {
      at = w.begin(RecordType.frame);
      const t = r.timings || {};
      w.u32(r.frame); w.u32(r.width); w.u32(r.height); w.u8(index(FrameEncoding, r.encoding ?? 'jpeg', 'encoding'));
      w.u8(0); w.u8(0); w.u8(0);
      for (const k of ['kernel', 'rendering', 'sat', 'tiling', 'pipeline', 'encode']) w.f32(t[k] ?? 0);
      w.bytes(r.payload ?? new Uint8Array(0));
      break;
    }
    case 'error':
      at = w.begin(RecordType.error);
      w.u16(typeof r.code === 'number' ? r.code : index(ErrorCode, r.code, 'error code')); w.u8(r.fatal ? 1 : 0); w.u8(0);
      w.u32(r.record ?? NO_RECORD); w.bytes(new TextEncoder().encode(r.message ?? '').slice(0, 65535));
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
  const fixed = { handshake: 16, settings: 8, resolution: 8, camera: 68, environment: 32, material: 84, mesh: 92,
    light: 68, remove: 4, render: 4 }[r.type];
  if (fixed !== undefined) return RECORD_HEADER + fixed;
  if (r.type === 'buffer') return RECORD_HEADER + 12 + (r.deflated ? r.deflated.length : r.data.byteLength);
  if (r.type === 'texture') return RECORD_HEADER + 20 + r.bytes.byteLength;
  throw new ProtocolError(`unknown client record type ${r.type}`);
}

// ---- reading ---------------------------------------------------------------------------
class Reader {
  constructor(bytes, off, len) { this.dv = new DataView(bytes.buffer, bytes.byteOffset + off, len); this.bytes = bytes; this.base = off; this.p = 0; this.len = len; }
  need(k) { if (this.p + k > this.len) throw new ProtocolError('record body truncated'); }
  u8() { this.need(1); return this.dv.getUint8(this.p++); }
  u16() { this.need(2); const v = this.dv.getUint16(this.p, true); this.p += 2; return v; }
  u32() { this.need(4); const v = this.dv.getUint32(this.p, true); this.p += 4; return v; }
  u64() { this.need(8); const v = this.dv.getBigUint64(this.p, true); this.p += 8; return Number(v); }
  f32() { this.need(4); const v = this.dv.getFloat32(this.p, true); this.p += 4; return v; }
  vec3() { return [this.f32(), this.f32(), this.f32()]; }
  mat4() { const m = new Float32Array(16); for (let i = 0; i < 16; i++) m[i] = this.f32(); return m; }
  rest() { const b = this.bytes.slice(this.base + this.p, this.base + this.len); this.p = this.len; return b; }
  left() { return this.len - this.p; }
  done(what) { if (this.p !== this.len) throw new ProtocolError(`${what}: body length ${this.len}, expected ${this.p}`); }
  zero(v) { if (v !== 0) throw new ProtocolError('reserved field is not zero'); }
}

function enumAt(list, i, what) {
  if (i >= list.length) throw new ProtocolError(`${what} = ${i} (valid: 0..${list.length - 1})`);
  return list[i];
}

function decodeClientRecord(type, op, r) {
  const name = TYPE_NAME[type];
  if (op === Op.remove) {
    if (!['buffer', 'texture', 'material', 'mesh', 'light'].includes(name)) throw new ProtocolError('remove on a record without id');
    const rec = { type: 'remove', what: name, id: r.u32() };
    r.done('remove');
    return rec;
  }
  if (op !== Op.set) throw new ProtocolError(`op ${op} not defined`);
  let rec;
  switch (name) {
    case 'handshake': {
      const renderer = enumAt(Renderer, r.u8(), 'renderer'), display = enumAt(Display, r.u8(), 'display');
      const jpegQuality = r.u8(); r.zero(r.u8());
      rec = { type: name, renderer, display, jpegQuality, maxNodes: r.u32(), width: r.u32(), height: r.u32() };
      break;
    }
    case 'settings': rec = { type: name, aoSamples: r.u32(), maxDepth: r.u32() }; break;
    case 'resolution': rec = { type: name, width: r.u32(), height: r.u32() }; break;
    case 'camera': rec = { type: name, toWorld: r.mat4(), fovY: r.f32() }; break;
    case 'environment': {
      rec = { type: name, ambient: r.vec3(), background: r.vec3(), exposure: r.f32(), linear: !!r.u8() };
      r.zero(r.u8() | r.u8() | r.u8());
      break;
    }
    case 'buffer': {
      const id = r.u32(), bufferType = enumAt(BufferType, r.u8(), 'buffer type'), components = r.u8(), flags = r.u8();
      r.zero(r.u8());
      const values = r.u32();
      if (flags & ~BUFFER_DEFLATE) throw new ProtocolError('unknown buffer flags');
      if (components < 1 || components > 4 || values % components) throw new ProtocolError('bad components');
      const payload = r.rest();
      rec = { type: name, id, bufferType, components, values, deflate: !!(flags & BUFFER_DEFLATE), payload };
      if (!rec.deflate) {
        if (payload.length !== values * 4) throw new ProtocolError(`buffer body ${payload.length} bytes, expected ${values * 4}`);
        rec.data = bufferType === 'f32' ? new Float32Array(payload.buffer, payload.byteOffset, values) : new Uint32Array(payload.buffer, payload.byteOffset, values);
      }
      break;
    }
    case 'texture': {
      const id = r.u32(), format = enumAt(TextureFormat, r.u8(), 'format');
      const wrapS = enumAt(Wrap, r.u8(), 'wrap_s'), wrapT = enumAt(Wrap, r.u8(), 'wrap_t'), filter = enumAt(Filter, r.u8(), 'filter');
      const srgb = !!r.u8(); r.zero(r.u8() | r.u8() | r.u8());
      rec = { type: name, id, format, wrapS, wrapT, filter, srgb, width: r.u32(), height: r.u32() };
      rec.bytes = r.rest();
      if (format === 'rgba8' && rec.bytes.length !== rec.width * rec.height * 4) throw new ProtocolError('texture size mismatch');
      break;
    }
    case 'material': {
      const id = r.u32(), model = enumAt(MaterialModel, r.u8(), 'model'), flags = r.u8();
      r.zero(r.u16());
      rec = { type: name, id, model, alphaMask: !!(flags & MATERIAL_ALPHA_MASK), doubleSided: !!(flags & MATERIAL_DOUBLE_SIDED),
        diffuseColor: r.vec3(), specularColor: r.vec3(), shininess: r.f32(), emissiveColor: r.vec3(),
        ambientIntensity: r.f32(), opacity: r.f32(), diffuseTexture: r.u32(), specularTexture: r.u32(),
        emissiveTexture: r.u32(), reflection: r.f32(), refraction: r.f32(), ior: r.f32(), alphaCutoff: r.f32() };
      break;
    }
    case 'mesh':
      rec = { type: name, id: r.u32(), positions: r.u32(), normals: r.u32(), texcoords: r.u32(), indices: r.u32(),
        material: r.u32(), transform: r.mat4(), visible: !!r.u8() };
      r.zero(r.u8() | r.u8() | r.u8());
      break;
    case 'light': {
      const id = r.u32(), lightType = enumAt(LightType, r.u8(), 'light type'), on = !!r.u8();
      r.zero(r.u16());
      rec = { type: name, id, lightType, on, color: r.vec3(), intensity: r.f32(), position: r.vec3(), direction: r.vec3(),
        attenuation: r.vec3(), cutoff: r.f32(), softness: r.f32() };
      break;
    }
    case 'render': rec = { type: name, frame: r.u32() }; break;
    default: throw new ProtocolError(`record type 0x${type.toString(16)} is not a client record`);
  }
  r.done(name);
  return rec;
}

function decodeServerRecord(type, op, r) {
  const name = TYPE_NAME[type];
  if (op !== Op.set) throw new ProtocolError(`op ${op} not defined for server records`);
  let rec;
  switch (name) {
    case 'handshake_reply': {
      const renderer = enumAt(Renderer, r.u8(), 'renderer'), display = enumAt(Display, r.u8(), 'display');
      const jpegQuality = r.u8(), n = r.u8();
      rec = { type: name, renderer, display, jpegQuality, nodes: r.u32(), width: r.u32(), height: r.u32(),
        maxMessageBytes: r.u32(), maxBufferBytes: r.u64() };
      if (r.left() !== n) throw new ProtocolError('handshake reply: version length mismatch');
      rec.serverVersion = new TextDecoder().decode(r.rest());
      break;
    }
    case 'frame': {
      rec = { type: name, frame: r.u32(), width: r.u32(), height: r.u32(), encoding: enumAt(FrameEncoding, r.u8(), 'encoding') };
      r.zero(r.u8() | r.u8() | r.u8());
      rec.timings = {};
      for (const k of ['kernel', 'rendering', 'sat', 'tiling', 'pipeline', 'encode']) rec.timings[k] = r.f32();
      rec.payload = r.rest();
      break;
    }
    case 'error': {
      const code = r.u16(), fatal = !!r.u8();
      r.zero(r.u8());
      rec = { type: name, code, codeName: ErrorCode[code] || `code ${code}`, fatal, record: r.u32() };
      rec.message = new TextDecoder().decode(r.rest());
      break;
    }
    case 'stats':
      rec = { type: name, frames: r.u32(), dropped: r.u32(), bytesSent: r.u64(), sceneBytes: r.u64(), triangles: r.u64(),
        nodes: r.u32(), fps: r.f32(), meanPipelineMs: r.f32() };
      break;
    default: throw new ProtocolError(`record type 0x${type.toString(16)} is not a server record`);
  }
  r.done(name);
  return rec;
}

function decode(bytes, channel, decodeRecord) {
  if (!(bytes instanceof Uint8Array)) bytes = new Uint8Array(bytes);
  if (bytes.length < MESSAGE_HEADER) throw new ProtocolError('message shorter than its header');
  if (bytes[0] !== MAGIC[0] || bytes[1] !== MAGIC[1]) throw new ProtocolError('bad magic (not "TS")');
  if (bytes[2] !== VERSION) throw new ProtocolError(`protocol version ${bytes[2]} (expected ${VERSION})`);
  if (bytes[3] !== channel) throw new ProtocolError(`channel ${bytes[3]} (expected ${channel})`);
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const count = dv.getUint32(4, true);
  const records = [];
  let p = MESSAGE_HEADER;
  for (let i = 0; i < count; i++) {
    if (p + RECORD_HEADER > bytes.length) throw new ProtocolError(`record ${i}: header truncated`);
    const type = bytes[p], op = bytes[p + 1], res = dv.getUint16(p + 2, true), len = dv.getUint32(p + 4, true);
    if (res) throw new ProtocolError(`record ${i}: reserved field is not zero`);
    if (p + RECORD_HEADER + len > bytes.length) throw new ProtocolError(`record ${i}: body truncated`);
    try {
      records.push(decodeRecord(type, op, new Reader(bytes, p + RECORD_HEADER, len)));
    } catch (e) {
      throw new ProtocolError(`record ${i}: ${e.message}`);
    }
    p += RECORD_HEADER + len;
  }
  if (p !== bytes.length) throw new ProtocolError(`${bytes.length - p} bytes after the last record`);
  return records;
}

export const decodeClient = (bytes) => decode(bytes, Channel.client, decodeClientRecord);
export const decodeServer = (bytes) => decode(bytes, Channel.server, decodeServerRecord);

// Size in bytes of DXT1 data for a frame (4x4 blocks of 8 bytes).
export const dxt1Size = (w, h) => Math.ceil(w / 4) * Math.ceil(h / 4) * 8;
