import { test } from 'node:test';
import assert from 'node:assert/strict';
import { encodeClient, decodeClient, encodeServer, decodeServer, clientRecordSize, ProtocolError, LIMITS, RECORDS } from '../../../src/net/Protocol.js';

// The JavaScript codec on its own: round trips, sizes and refusals. That it writes and reads the
// same bytes as protocol/protocol.cpp, and refuses the same messages with the same error
// classes, is CTest protocol_crosscheck's (web/test/wire/crosscheck.js, docs/testing.md).

const translate = new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 2, 3, 1]);
const scale = new Float32Array([2, 0, 0, 0, 0, 3, 0, 0, 0, 0, 4, 0, 0, 0, 0, 1]);
const CLIENT = [
  { type: 'settings', aoSamples: 16, maxDepth: 5 },
  { type: 'resolution', width: 640, height: 360 },
  { type: 'camera', toWorld: translate, fovY: 0.5 },
  { type: 'environment', ambient: [0.1, 0.2, 0.3], background: [0.5, 0.5, 0.5], exposure: 1, linear: false },
  { type: 'buffer', id: 7, bufferType: 'f32', components: 3, data: new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0]) },
  { type: 'buffer', id: 8, bufferType: 'u32', components: 1, data: new Uint32Array([0, 1, 2]) },
  { type: 'texture', id: 9, format: 'rgba8', wrapS: 'clamp', wrapT: 'repeat', filter: 'nearest', srgb: false, width: 1, height: 2,
    bytes: new Uint8Array([255, 0, 0, 255, 0, 255, 0, 128]) },
  { type: 'material', id: 10, model: 'phong', alphaMask: true, doubleSided: true, diffuseColor: [0.5, 0.25, 1], specularColor: [1, 1, 1],
    shininess: 0.2, emissiveColor: [0, 0.1, 0], ambientIntensity: 0.3, opacity: 0.75, diffuseTexture: 9, specularTexture: 0,
    emissiveTexture: 0, reflection: 0.1, refraction: 0.9, ior: 1.5, alphaCutoff: 0.5 },
  { type: 'mesh', id: 11, positions: 7, normals: 0, texcoords: 0, colors: 13, indices: 8, material: 10, transform: scale, visible: false },
  { type: 'light', id: 12, lightType: 'spot', on: true, castShadow: false, color: [1, 0.5, 0.25], intensity: 1, position: [1, 2, 3], direction: [0, -1, 0],
    attenuation: [1, 0, 0.1], cutoff: 0.4, softness: 0.5 },
  { type: 'remove', what: 'mesh', id: 5 },
  { type: 'render', frame: 42 },
  { type: 'refine', samples: 64 },
  { type: 'budget', frameMs: 33 },
];

// Each refusal carries the C++ decoder's error class and the offending record's index.
const refuses = (fn, code, record) => assert.throws(fn, (e) => e instanceof ProtocolError && e.code === code && e.record === record);

test('a handshake decodes back to what was encoded', () => {
  const h = { type: 'handshake', renderer: 'raytracer', display: 's3tc', jpegQuality: 80, maxNodes: 3, width: 320, height: 240 };
  assert.deepEqual(decodeClient(encodeClient([h])), [h]);
});

test('client records decode back to what was encoded', () => {
  const recs = decodeClient(encodeClient(CLIENT));
  assert.equal(recs.length, CLIENT.length);
  assert.deepEqual(recs.map((r) => r.type), CLIENT.map((r) => r.type));
  assert.deepEqual([...recs[4].data], [0, 0, 0, 1, 0, 0, 0, 1, 0]);
  assert.deepEqual([...recs[5].data], [0, 1, 2]);
  assert.equal(recs[7].model, 'phong');
  assert.equal(recs[7].alphaMask, true);
  assert.ok(Math.abs(recs[7].ior - 1.5) < 1e-6);
  assert.equal(recs[8].visible, false);
  assert.equal(recs[8].colors, 13);
  assert.equal(recs[8].indices, 8);
  assert.equal(recs[7].useVertexColor, false);
  assert.equal(recs[9].lightType, 'spot');
  assert.equal(recs[9].castShadow, false);
  assert.deepEqual(recs[10], { type: 'remove', what: 'mesh', id: 5 });
  assert.deepEqual(recs[11], { type: 'render', frame: 42 });
  assert.deepEqual(recs[12], { type: 'refine', samples: 64 });
  assert.deepEqual(recs[13], { type: 'budget', frameMs: 33 });
});

test('a refine record: code 0x06, a u32 body, up to max_refine_samples, no remove', () => {
  const m = encodeClient([{ type: 'refine', samples: 4096 }]);
  assert.deepEqual([...m.slice(8)], [0x06, 0, 0, 0, 4, 0, 0, 0, 0x00, 0x10, 0, 0]);
  assert.equal(LIMITS.max_refine_samples, 4096);
  for (const samples of [0, 1, 2, LIMITS.max_refine_samples])
    assert.deepEqual(decodeClient(encodeClient([{ type: 'refine', samples }])), [{ type: 'refine', samples }]);
  assert.deepEqual(decodeClient(encodeClient([{ type: 'refine' }])), [{ type: 'refine', samples: 0 }]);
  refuses(() => decodeClient(encodeClient([{ type: 'render', frame: 1 }, { type: 'refine', samples: LIMITS.max_refine_samples + 1 }])),
    'limit_exceeded', 1);
  refuses(() => decodeClient(encodeClient([{ type: 'refine', samples: 0xffffffff }])), 'limit_exceeded', 0);
  const lower = encodeClient([{ type: 'refine', samples: 17 }]);
  refuses(() => decodeClient(lower, { limits: { max_refine_samples: 16 } }), 'limit_exceeded', 0);
  const remove = m.slice(); remove[9] = 1;
  refuses(() => decodeClient(remove), 'bad_op', 0);
  const long = new Uint8Array(m.length + 1); long.set(m); long[12] = 5;
  refuses(() => decodeClient(long), 'bad_length', 0);
});

test('a budget record: code 0x07, a u32 body of milliseconds, up to max_frame_budget_ms, no remove', () => {
  const m = encodeClient([{ type: 'budget', frameMs: 60000 }]);
  assert.deepEqual([...m.slice(8)], [0x07, 0, 0, 0, 4, 0, 0, 0, 0x60, 0xea, 0, 0]);
  assert.equal(LIMITS.max_frame_budget_ms, 60000);
  assert.equal(RECORDS.budget.removable, false);
  for (const frameMs of [0, 1, 33, LIMITS.max_frame_budget_ms])
    assert.deepEqual(decodeClient(encodeClient([{ type: 'budget', frameMs }])), [{ type: 'budget', frameMs }]);
  assert.deepEqual(decodeClient(encodeClient([{ type: 'budget' }])), [{ type: 'budget', frameMs: 0 }]);
  refuses(() => decodeClient(encodeClient([{ type: 'render', frame: 1 }, { type: 'budget', frameMs: LIMITS.max_frame_budget_ms + 1 }])),
    'limit_exceeded', 1);
  refuses(() => decodeClient(encodeClient([{ type: 'budget', frameMs: 0xffffffff }])), 'limit_exceeded', 0);
  const lower = encodeClient([{ type: 'budget', frameMs: 101 }]);
  refuses(() => decodeClient(lower, { limits: { max_frame_budget_ms: 100 } }), 'limit_exceeded', 0);
  const remove = m.slice(); remove[9] = 1;
  refuses(() => decodeClient(remove), 'bad_op', 0);
  const long = new Uint8Array(m.length + 1); long.set(m); long[12] = 5;
  refuses(() => decodeClient(long), 'bad_length', 0);
  const short = m.slice(0, m.length - 1); short[12] = 3;
  refuses(() => decodeClient(short), 'bad_length', 0);
});

test('record sizes match the encoder', () => {
  for (const r of CLIENT) assert.equal(clientRecordSize(r), encodeClient([r]).length - 8, r.type);
});

test('server records round-trip', () => {
  const SERVER = [
    { type: 'handshake_reply', renderer: 'raytracer', display: 'jpeg', jpegQuality: 85, nodes: 2, width: 320, height: 240,
      maxMessageBytes: 1000000, maxBufferBytes: 5000000000, serverVersion: 'tessera 0.1.0' },
    { type: 'frame', frame: 42, width: 4, height: 4, encoding: 'dxt1', timings: { kernel: 1, rendering: 2, sat: 3, tiling: 4, pipeline: 5, encode: 6 },
      payload: new Uint8Array([1, 2, 3, 4, 5, 6, 7, 8]) },
    { type: 'frame', frame: 42, width: 4, height: 4, encoding: 'jpeg', refined: true, samples: 17, timings: {}, payload: new Uint8Array(0) },
    { type: 'error', code: 'bad_mesh', fatal: false, record: 3, message: 'mesh 11: bad' },
    { type: 'stats', frames: 10, dropped: 1, bytesSent: 12345, sceneBytes: 678, triangles: 1, nodes: 2, fps: 30, meanPipelineMs: 12.5 },
  ];
  const recs = decodeServer(encodeServer(SERVER));
  assert.equal(recs[0].serverVersion, 'tessera 0.1.0');
  assert.equal(recs[0].maxBufferBytes, 5000000000);
  assert.equal(recs[1].encoding, 'dxt1');
  assert.deepEqual([...recs[1].payload], [1, 2, 3, 4, 5, 6, 7, 8]);
  assert.equal(recs[1].timings.encode, 6);
  assert.equal(recs[1].refined, false, 'the answer to a render request');
  assert.equal(recs[1].samples, 1, 'one sample when the record names none');
  assert.equal(recs[2].refined, true);
  assert.equal(recs[2].samples, 17);
  assert.equal(recs[3].codeName, 'bad_mesh');
  assert.equal(recs[3].message, 'mesh 11: bad');
  assert.equal(recs[4].meanPipelineMs, 12.5);
});

test('a frame\'s refinement and samples sit where the reserved bytes were; samples are written as 1..65535', () => {
  const frame = (f) => encodeServer([{ type: 'frame', frame: 3, width: 1, height: 1, encoding: 'jpeg', timings: {}, payload: new Uint8Array(0), ...f }]);
  const body = 16;  // message header + record header
  const m = frame({ refined: true, samples: 300 });
  assert.equal(m.length, body + RECORDS.frame.fixed, 'the body size is unchanged');
  assert.deepEqual([...m.slice(body + 12, body + 16)], [0, 1, 300 & 0xff, 300 >> 8]);
  assert.equal(decodeServer(frame({ samples: 0 }))[0].samples, 1);
  assert.equal(decodeServer(frame({ samples: 70000 }))[0].samples, 65535);
  const zero = frame({}); zero[body + 14] = 0;
  assert.equal(decodeServer(zero)[0].samples, 0, 'a decoder takes 0 samples as they are');
  // Refinement: 0 requested, 1 refined, 2 the still's last (converged); nothing above.
  const last = frame({ refined: true, converged: true });
  assert.equal(last[body + 13], 2);
  const back = decodeServer(last)[0];
  assert.deepEqual([back.refined, back.converged, back.refinement], [true, true, 'converged']);
  const plain = decodeServer(frame({ refined: true }))[0];
  assert.deepEqual([plain.refined, plain.converged, plain.refinement], [true, false, 'refined']);
  const three = frame({}); three[body + 13] = 3;
  refuses(() => decodeServer(three), 'bad_enum', 0);
});

test('malformed messages are rejected with a reason', () => {
  const good = encodeServer([{ type: 'stats', frames: 10 }]);
  assert.throws(() => decodeServer(good.slice(0, 5)), ProtocolError);
  const bad = good.slice(); bad[0] = 0x58;
  assert.throws(() => decodeServer(bad), /magic/);
  assert.throws(() => decodeServer(encodeClient(CLIENT)), /channel/);
  assert.throws(() => decodeServer(good.slice(0, good.length - 1)), /truncated/);
  const v = good.slice(); v[2] = 9;
  assert.throws(() => decodeServer(v), /version/);
});

test('refusals name the error class and the record', () => {
  const ok = encodeClient([{ type: 'settings', aoSamples: 1, maxDepth: 2 }, { type: 'render', frame: 1 }]);
  refuses(() => decodeClient(ok.slice(0, 7)), 'truncated', 0xffffffff);
  refuses(() => decodeClient(encodeClient([{ type: 'settings', aoSamples: LIMITS.max_ao_samples + 1, maxDepth: 2 }])), 'limit_exceeded', 0);
  refuses(() => decodeClient(encodeClient([{ type: 'render', frame: 1 }, { type: 'resolution', width: 0, height: 5 }])), 'out_of_range', 1);
  refuses(() => decodeClient(encodeClient([{ type: 'remove', what: 'mesh', id: 0 }])), 'bad_id', 0);
  refuses(() => decodeClient(encodeClient([CLIENT[0], { type: 'handshake', width: 1, height: 1 }])), 'bad_handshake', 0xffffffff);
  const cam = encodeClient([{ type: 'camera', toWorld: new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]), fovY: Math.PI }]);
  refuses(() => decodeClient(cam), 'out_of_range', 0);
  const limited = encodeClient([{ type: 'resolution', width: 64, height: 64 }]);
  refuses(() => decodeClient(limited, { limits: { max_width: 63 } }), 'limit_exceeded', 0);
  refuses(() => decodeClient(limited, { limits: { max_message_bytes: limited.length - 1 } }), 'too_large', 0xffffffff);
});

test('ranges and sizes come from Wire.js (protocol/wire.toml)', () => {
  assert.equal(RECORDS.material.fixed, 84);
  const m = { ...CLIENT[7], opacity: Math.fround(1.0000001) };
  refuses(() => decodeClient(encodeClient([m])), 'out_of_range', 0);
  assert.equal(decodeClient(encodeClient([{ ...CLIENT[7], ior: RECORDS.material.fields.find((f) => f.name === 'ior').range.lo }]))[0].model, 'phong');
});

test('u64 fields beyond 2^53 decode exactly, as BigInt', () => {
  const [s] = decodeServer(encodeServer([{ type: 'stats', bytesSent: 2n ** 64n - 1n, sceneBytes: 5 }]));
  assert.equal(s.bytesSent, 2n ** 64n - 1n);
  assert.equal(s.sceneBytes, 5);
});

test('vertex colours: a mesh names its colour buffer (0: none), a material flag says use them', () => {
  const mesh = { ...CLIENT[8], colors: 0 };
  assert.equal(RECORDS.mesh.fixed, 96);
  const at = RECORDS.mesh.fields.find((f) => f.name === 'colors').offset;
  assert.equal(at, 16);
  assert.equal(decodeClient(encodeClient([mesh]))[0].colors, 0);
  const { colors, ...noColors } = mesh;  // a record without the field encodes as none
  assert.equal(decodeClient(encodeClient([noColors]))[0].colors, 0);
  const m = encodeClient([{ ...mesh, colors: 0x01020304 }]);
  assert.deepEqual([...m.slice(8 + 8 + at, 8 + 8 + at + 4)], [4, 3, 2, 1]);
  const mat = { ...CLIENT[7], alphaMask: false, doubleSided: false, useVertexColor: true };
  const bytes = encodeClient([mat]);
  assert.equal(bytes[8 + 8 + 5], 4, 'flag bit 2');
  const back = decodeClient(bytes)[0];
  assert.equal(back.useVertexColor, true);
  assert.equal(back.alphaMask, false);
  const unknown = bytes.slice(); unknown[8 + 8 + 5] = 8;
  refuses(() => decodeClient(unknown), 'bad_reserved', 0);
});

test('references: buffer_ref and texture_ref round-trip with their sizes, the node\'s reference answer too', () => {
  const refs = [
    { type: 'buffer_ref', id: 7, bufferType: 'f32', components: 3, source: 'f32', values: 9, byteStride: 24, byteOffset: 36,
      url: 'http://localhost/m/scene.bin' },
    { type: 'buffer_ref', id: 8, bufferType: 'u32', components: 1, source: 'u16', values: 3, byteStride: 0, byteOffset: 2n ** 64n - 1n,
      url: 'https://cdn.example/é.bin' },
    { type: 'texture_ref', id: 9, wrapS: 'clamp', wrapT: 'repeat', filter: 'nearest', srgb: true, url: 'https://cdn.example/t.png' },
  ];
  assert.deepEqual(decodeClient(encodeClient(refs)), refs);
  for (const r of refs) assert.equal(clientRecordSize(r), encodeClient([r]).length - 8, r.type);
  assert.equal(RECORDS.buffer_ref.removable, false);
  const answers = [
    { type: 'reference', what: 'buffer', ok: true, id: 7, bytes: 36, message: '' },
    { type: 'reference', what: 'texture', ok: false, id: 9, bytes: 2n ** 64n - 1n, message: 'texture 9 (https://cdn.example/t.png): not allowed' },
  ];
  assert.deepEqual(decodeServer(encodeServer(answers)), answers);
});

test('references are refused as protocol.cpp refuses them', () => {
  const ref = { type: 'buffer_ref', id: 7, bufferType: 'u32', components: 2, source: 'u16', values: 4, byteStride: 0, byteOffset: 0, url: 'http://h/a.bin' };
  refuses(() => decodeClient(encodeClient([{ type: 'render', frame: 1 }, { ...ref, source: 'f32' }])), 'bad_enum', 1);
  refuses(() => decodeClient(encodeClient([{ ...ref, bufferType: 'f32' }])), 'bad_enum', 0);
  refuses(() => decodeClient(encodeClient([{ ...ref, values: 3 }])), 'bad_components', 0);
  refuses(() => decodeClient(encodeClient([{ ...ref, byteStride: 2 }])), 'out_of_range', 0);  // shorter than an element
  refuses(() => decodeClient(encodeClient([{ ...ref, byteStride: 5 }])), 'out_of_range', 0);  // not a multiple of 2
  refuses(() => decodeClient(encodeClient([{ ...ref, byteStride: 254 }])), 'out_of_range', 0);
  refuses(() => decodeClient(encodeClient([{ ...ref, url: '' }])), 'bad_length', 0);
  assert.equal(decodeClient(encodeClient([{ ...ref, url: 'x'.repeat(5000) }]))[0].url.length, 4096, 'the encoder cuts a URL to 4096 bytes');
  refuses(() => decodeClient(encodeClient([{ type: 'texture_ref', id: 0, url: 'http://h/t.png' }])), 'bad_id', 0);
  const answer = encodeServer([{ type: 'reference', what: 'buffer', ok: false, id: 3, message: 'no' }]);
  const ok2 = answer.slice(); ok2[8 + 8 + 1] = 2;
  refuses(() => decodeServer(ok2), 'bad_enum', 0);
  const id0 = answer.slice(); id0[8 + 8 + 4] = 0;
  refuses(() => decodeServer(id0), 'bad_id', 0);
});
