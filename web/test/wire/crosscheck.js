// The JavaScript half of CTest protocol_crosscheck (docs/testing.md): holds web/src/net/Protocol.js
// to what protocol/protocol.cpp made of the same inputs, as tests/wire/protocol_golden.cpp wrote
// it (build/tests/wire/protocol_golden.json, written by the build). Fails on any difference:
//   - valid messages: Protocol.js must encode the same records to the same bytes, decode those
//     bytes to the same records and re-encode them to the same bytes again; the fields it reads
//     must sit where protocol/wire.toml declares them (via Wire.js), and every field of every
//     record type must take a value other than 0 in some message;
//   - malformed messages: Protocol.js must refuse each with the error class and record index the
//     C++ decoder gave, and the C++ decoder must have given the class the message was made for;
//     every class the C++ decoder tells apart must be among them, on each channel it applies to;
//   - the error code names and the default limits must be the C++ ones.
//
//   node test/wire/crosscheck.js GOLDEN.json              the cross-check
//   node test/wire/crosscheck.js --self-test GOLDEN.json  checks that the cross-check fails on a
//     changed byte, a changed error class, a changed limit, and a decoder that reads one field
//     wrong or reports one class as another
import fs from 'node:fs';
import zlib from 'node:zlib';
import * as Protocol from '../../src/net/Protocol.js';
import { ENUMS } from '../../src/net/Wire.js';

const { RECORDS, ErrorCode, LIMITS, MESSAGE_HEADER, RECORD_HEADER, ProtocolError } = Protocol;

// The classes protocol.cpp's decoders report. Not here: ok, and what only `apply` (bad_mesh,
// unknown_id, not_scene_update) or only a server (internal, no_effect) reports.
const DECODER_CLASSES = ErrorCode.filter((c) => !['ok', 'bad_mesh', 'unknown_id', 'not_scene_update', 'internal', 'no_effect'].includes(c));
const SERVER_CLASSES = ['too_large', 'truncated', 'bad_magic', 'bad_version', 'bad_channel', 'unknown_record', 'bad_op',
  'bad_length', 'bad_reserved', 'bad_enum', 'out_of_range', 'limit_exceeded'];

// JSON tags of protocol_golden.cpp: {"$f": "NaN"}, {"$u64": "..."}, {"$hex": "..."}, {"$f32": [...]}, {"$u32": [...]}.
function revive(key, v) {
  if (v && typeof v === 'object' && !Array.isArray(v)) {
    const k = Object.keys(v);
    if (k.length === 1) {
      if (k[0] === '$f') return Number(v.$f);
      if (k[0] === '$u64') return BigInt(v.$u64);
      if (k[0] === '$hex') return new Uint8Array(Buffer.from(v.$hex, 'hex'));
      if (k[0] === '$f32') return new Float32Array(v.$f32);
      if (k[0] === '$u32') return new Uint32Array(v.$u32);
    }
  }
  return v;
}

// codecs/deflate.cpp's inflate_zlib_exact with node's zlib: exactly `size` bytes, nothing after
// the stream's end.
export function inflateExact(z, size) {
  let r;
  try {
    r = zlib.inflateSync(z, { info: true, maxOutputLength: size + 1 });
  } catch (e) {
    throw new Error(e.code === 'ERR_BUFFER_TOO_LARGE' ? `inflated size exceeds the declared ${size} bytes` : e.message);
  }
  if (r.buffer.length > size) throw new Error(`inflated size exceeds the declared ${size} bytes`);
  if (r.engine.bytesWritten !== z.length) throw new Error(`${z.length - r.engine.bytesWritten} bytes after the end of the stream`);
  return new Uint8Array(r.buffer.buffer, r.buffer.byteOffset, r.buffer.length);
}

const hex = (b) => Buffer.from(b).toString('hex');
const FLOATS = new Set(['f32', 'vec3', 'mat4']);

// The record and field that byte `at` of a message belongs to, by wire.toml's layout.
function where(bytes, at) {
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (at < MESSAGE_HEADER) return 'the message header';
  let p = MESSAGE_HEADER;
  for (let i = 0; p + RECORD_HEADER <= bytes.length; i++) {
    const type = bytes[p], len = dv.getUint32(p + 4, true);
    const name = Object.keys(RECORDS).find((k) => RECORDS[k].code === type) ?? `type ${type}`;
    if (at < p + RECORD_HEADER) return `record ${i} (${name}) header`;
    if (at < p + RECORD_HEADER + len) {
      const off = at - p - RECORD_HEADER;
      const fields = RECORDS[name]?.fields ?? [];
      const f = [...fields].reverse().find((x) => x.offset <= off);
      return `record ${i} (${name}) field ${f ? f.name : '?'} (body offset ${off})`;
    }
    p += RECORD_HEADER + len;
  }
  return 'past the last record';
}

function firstDifference(a, b) {
  const n = Math.min(a.length, b.length);
  for (let i = 0; i < n; i++) if (a[i] !== b[i]) return i;
  return a.length === b.length ? -1 : n;
}

// The field types of a record's JavaScript keys (vec3/mat4/f32 compare as floats).
function keyTypes(type) {
  const t = {};
  for (const f of RECORDS[type]?.fields ?? []) if (f.js) t[f.js.split('.')[0]] = f.js.includes('.') ? 'f32' : f.type;
  return t;
}

function same(a, b, float) {
  if (typeof a === 'number' && typeof b === 'number') return float ? Object.is(Math.fround(a), Math.fround(b)) : Object.is(a, b);
  if (typeof a === 'bigint' || typeof b === 'bigint') return typeof a === typeof b && a === b;
  if (ArrayBuffer.isView(a) || Array.isArray(a)) {
    if (!(ArrayBuffer.isView(b) || Array.isArray(b)) || a.length !== b.length) return false;
    for (let i = 0; i < a.length; i++) if (!same(a[i], b[i], float)) return false;
    return true;
  }
  if (a && typeof a === 'object') {
    if (!b || typeof b !== 'object') return false;
    return Object.keys(a).every((k) => same(a[k], b[k], float));
  }
  return a === b;
}

// The value of a field at its wire.toml offset, as Protocol.js represents it.
function readField(dv, at, f) {
  const p = at + f.offset;
  switch (f.type) {
    case 'u8': return dv.getUint8(p);
    case 'u16': return dv.getUint16(p, true);
    case 'u32': return dv.getUint32(p, true);
    case 'u64': { const v = dv.getBigUint64(p, true); return v <= BigInt(Number.MAX_SAFE_INTEGER) ? Number(v) : v; }
    case 'f32': return dv.getFloat32(p, true);
    case 'vec3': return [0, 1, 2].map((i) => dv.getFloat32(p + 4 * i, true));
    case 'mat4': return Float32Array.from({ length: 16 }, (_, i) => dv.getFloat32(p + 4 * i, true));
    case 'u8x3': return dv.getUint8(p) | dv.getUint8(p + 1) | dv.getUint8(p + 2);
    default: return undefined;
  }
}
const asJs = (f, v) => (f.enum ? ENUMS[f.enum][v] : f.flag ? v !== 0 : v);
const nonZero = (v) => (ArrayBuffer.isView(v) || Array.isArray(v) ? Array.prototype.some.call(v, nonZero) : v !== 0 && v !== 0n);

export function crosscheck(golden, codec) {
  const problems = [];
  const say = (s) => problems.push(s);
  if (JSON.stringify(golden.error_codes) !== JSON.stringify([...codec.ErrorCode]))
    say(`error code names differ: C++ ${golden.error_codes.join(',')} / JS ${codec.ErrorCode.join(',')}`);
  const keys = new Set([...Object.keys(golden.limits), ...Object.keys(codec.LIMITS)]);
  for (const k of keys) if (golden.limits[k] !== codec.LIMITS[k]) say(`limit ${k}: C++ ${golden.limits[k]}, JS ${codec.LIMITS[k]}`);

  const seenTypes = new Set(), nonZeroFields = new Set(), allFields = new Set();
  for (const [type, r] of Object.entries(RECORDS)) for (const f of r.fields) if (!f.reserved && f.type !== 'bytes' && f.type !== 'string') allFields.add(`${type}.${f.name}`);
  for (const v of golden.valid) {
    const client = v.channel === 'client';
    const enc = client ? codec.encodeClient : codec.encodeServer, dec = client ? codec.decodeClient : codec.decodeServer;
    const want = new Uint8Array(Buffer.from(v.hex, 'hex'));
    const tag = `valid "${v.name}"`;
    if (v.cpp !== 'ok') say(`${tag}: the C++ decoder refused it: ${v.cpp}`);
    if (v.cpp_roundtrip === false) say(`${tag}: the C++ decoder's records re-encode to other bytes`);
    let got;
    try { got = enc(v.records); } catch (e) { say(`${tag}: JS encoder threw ${e.message}`); continue; }
    const d = firstDifference(got, want);
    if (d >= 0) say(`${tag}: JS encodes other bytes than C++ from byte ${d}, ${where(want, d)}: JS ${hex(got.slice(d, d + 8))}, C++ ${hex(want.slice(d, d + 8))}`);
    let records;
    try { records = dec(want, { inflate: inflateExact }); } catch (e) { say(`${tag}: JS decoder refused C++'s bytes: ${e.code} ${e.message}`); continue; }
    const again = enc(records);
    const d2 = firstDifference(again, want);
    if (d2 >= 0) say(`${tag}: JS's decoded records re-encode to other bytes from byte ${d2}, ${where(want, d2)}`);
    if (records.length !== v.records.length) { say(`${tag}: JS decoded ${records.length} records, C++ encoded ${v.records.length}`); continue; }
    // Field by field against what was encoded, and against wire.toml's offsets in the bytes.
    const dv = new DataView(want.buffer, want.byteOffset, want.byteLength);
    let p = MESSAGE_HEADER;
    records.forEach((rec, i) => {
      const input = v.records[i];
      const types = keyTypes(input.type === 'remove' ? '' : input.type);
      if (!v.lossy)
        for (const k of Object.keys(input))
          if (!same(input[k], rec[k], FLOATS.has(types[k]) || k === 'timings'))
            say(`${tag}: record ${i} (${input.type}) ${k}: JS decodes ${String(rec[k])}, C++ encoded ${String(input[k])}`);
      const type = Object.keys(RECORDS).find((k) => RECORDS[k].code === want[p]);
      const op = want[p + 1], len = dv.getUint32(p + 4, true), body = p + RECORD_HEADER;
      if (op === Protocol.Op.remove) seenTypes.add(`remove ${type}`);
      else {
        seenTypes.add(type);
        const spec = RECORDS[type];
        if (spec.tail ? len < spec.fixed : len !== spec.fixed) say(`${tag}: record ${i} (${type}): body of ${len} bytes, wire.toml declares ${spec.fixed}${spec.tail ? ' and more' : ''}`);
        for (const f of spec.fields) {
          const raw = readField(dv, body, f);
          if (raw === undefined) continue;
          if (f.reserved) { if (raw !== 0) say(`${tag}: record ${i} (${type}) ${f.name}: reserved, holds ${raw}`); continue; }
          if (nonZero(raw)) nonZeroFields.add(`${type}.${f.name}`);
          if (!f.js) continue;
          const path = f.js.split('.');
          const value = path.reduce((o, k) => o?.[k], rec);
          if (value !== undefined && !same(asJs(f, raw), value, FLOATS.has(f.type)))
            say(`${tag}: record ${i} (${type}) ${f.name} at body offset ${f.offset}: wire.toml's layout reads ${String(asJs(f, raw))}, JS decodes ${String(value)}`);
        }
      }
      p = body + len;
    });
  }
  for (const [type, r] of Object.entries(RECORDS)) {
    if (!seenTypes.has(type)) say(`no valid message holds a ${type} record`);
    if (r.removable && !seenTypes.has(`remove ${type}`)) say(`no valid message removes a ${type}`);
  }
  for (const f of allFields) if (!nonZeroFields.has(f)) say(`field ${f} is 0 in every valid message`);

  const seenClasses = { client: new Set(), server: new Set() };
  for (const c of golden.invalid) {
    const tag = `malformed "${c.name}"`;
    if (c.code !== c.expect) say(`${tag}: made to be ${c.expect}, the C++ decoder says ${c.code}`);
    seenClasses[c.channel].add(c.code);
    const bytes = new Uint8Array(Buffer.from(c.hex, 'hex'));
    const dec = c.channel === 'client' ? codec.decodeClient : codec.decodeServer;
    try {
      dec(bytes, { limits: c.limits, inflate: inflateExact });
      say(`${tag}: JS accepts it, C++ refuses it with ${c.code}`);
    } catch (e) {
      if (!(e instanceof ProtocolError)) say(`${tag}: JS threw ${e.name}: ${e.message}`);
      else if (e.code !== c.code || e.record !== c.record)
        say(`${tag}: JS says ${e.code} (record ${e.record}), C++ ${c.code} (record ${c.record}): ${e.message}`);
    }
  }
  for (const k of DECODER_CLASSES) if (!seenClasses.client.has(k)) say(`no malformed client message of class ${k}`);
  for (const k of SERVER_CLASSES) if (!seenClasses.server.has(k)) say(`no malformed server message of class ${k}`);
  return problems;
}

// ---------------------------------------------------------------------------------------

const args = process.argv.slice(2);
const selfTest = args[0] === '--self-test';
const file = selfTest ? args[1] : args[0];
if (!file) {
  console.error('usage: crosscheck.js [--self-test] GOLDEN.json');
  process.exit(2);
}
const text = fs.readFileSync(file, 'utf8');
const load = () => JSON.parse(text, revive);
const golden = load();

if (!selfTest) {
  const problems = crosscheck(golden, Protocol);
  for (const p of problems.slice(0, 60)) console.log(`FAIL ${p}`);
  if (problems.length > 60) console.log(`... and ${problems.length - 60} more`);
  const records = golden.valid.reduce((n, v) => n + v.records.length, 0);
  const classes = new Set(golden.invalid.map((c) => c.code));
  console.log(`protocol_crosscheck: ${golden.valid.length} valid messages (${records} records), ${golden.invalid.length} malformed ` +
    `(${classes.size} error classes): ${problems.length ? `${problems.length} differences between C++ and JS` : 'C++ and JS agree'}`);
  process.exit(problems.length ? 1 : 0);
}

// Self-test: each change below must make the cross-check fail.
const tamper = {
  'a byte of a valid message': (g) => { const v = g.valid.find((x) => x.name === 'materials: every model and flag, ranges at both ends'); v.hex = v.hex.slice(0, 80) + (v.hex[80] === '0' ? '1' : '0') + v.hex.slice(81); },
  'the error class of a malformed message': (g) => { g.invalid.find((c) => c.code === 'out_of_range').code = 'limit_exceeded'; },
  'the record index of a malformed message': (g) => { g.invalid.find((c) => c.name === 'the third record fails').record = 0; },
  'a default limit': (g) => { g.limits.max_texture_size += 1; },
  'an error code name': (g) => { g.error_codes[18] = 'bad_meshes'; },
  'a field of an encoded record': (g) => { g.valid[0].records[0].jpegQuality += 1; },
  'a decoder that reads one field wrong': (g, codec) => {
    codec.decodeServer = (b, o) => Protocol.decodeServer(b, o).map((r) => (r.type === 'stats' ? { ...r, dropped: r.dropped + 1 } : r));
  },
  'a decoder that reports one class as another': (g, codec) => {
    codec.decodeClient = (b, o) => {
      try { return Protocol.decodeClient(b, o); } catch (e) {
        if (e.code === 'bad_components') e.code = 'out_of_range';
        throw e;
      }
    };
  },
  'a decoder that accepts what C++ refuses': (g, codec) => {
    codec.decodeServer = (b, o) => {
      try { return Protocol.decodeServer(b, o); } catch (e) { if (e.code === 'bad_reserved') return []; throw e; }
    };
  },
  'an encoder that writes one field differently': (g, codec) => {
    codec.encodeClient = (recs) => Protocol.encodeClient(recs.map((r) => (r.type === 'light' ? { ...r, softness: r.softness / 2 } : r)));
  },
  'a missing error class': (g) => { g.invalid = g.invalid.filter((c) => c.code !== 'bad_payload'); },
};
let failed = 0;
const clean = crosscheck(load(), Protocol);
if (clean.length) { console.log(`FAIL the unchanged golden file does not pass (${clean.length} problems): ${clean[0]}`); failed++; }
for (const [what, change] of Object.entries(tamper)) {
  const g = load(), codec = { ...Protocol };
  change(g, codec);
  const problems = crosscheck(g, codec);
  if (problems.length === 0) { console.log(`FAIL changing ${what} goes unnoticed`); failed++; }
  else console.log(`ok   changing ${what}: ${problems[0]}`);
}
console.log(`protocol_crosscheck self-test: ${failed ? `${failed} failures` : 'every change is caught'}`);
process.exit(failed ? 1 : 0);
