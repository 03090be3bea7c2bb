import { test } from 'node:test';
import assert from 'node:assert/strict';
import { page } from '../dom.js';
import { readRenderSettings, refineStatus, sameSettings } from '../../../src/net/RenderSettings.js';
import { SyncChannel } from '../../../src/net/SyncChannel.js';
import { encodeClient } from '../../../src/net/Protocol.js';
import { MarkupReader } from '../../../src/reader/MarkupReader.js';
import { Resources } from '../../../src/reader/Resources.js';
import { FakeSocket } from './fake_socket.js';

const read = (attrs) => readRenderSettings(page(`<xml3d ${attrs}></xml3d>`).querySelector('xml3d'));

test('ao-samples, max-depth, refine-samples and frame-budget are read from <xml3d>, with the defaults when absent', () => {
  assert.deepEqual(read(''), { settings: { aoSamples: 0, maxDepth: 4, refineSamples: 64, frameBudget: 33 }, problems: [] });
  assert.deepEqual(read('ao-samples="8" max-depth="6"'), { settings: { aoSamples: 8, maxDepth: 6, refineSamples: 64, frameBudget: 33 }, problems: [] });
  assert.deepEqual(read('ao-samples=" 256 " max-depth="1" refine-samples="4096" frame-budget="60000"').settings,
    { aoSamples: 256, maxDepth: 1, refineSamples: 4096, frameBudget: 60000 });
  assert.deepEqual(read('ao-samples="0" max-depth="64" refine-samples="0" frame-budget="0"').settings,
    { aoSamples: 0, maxDepth: 64, refineSamples: 0, frameBudget: 0 });
  assert.deepEqual(read('refine-samples=" +1 " frame-budget=" +50 "'),
    { settings: { aoSamples: 0, maxDepth: 4, refineSamples: 1, frameBudget: 50 }, problems: [] });
});

test('frame-budget beyond 0..60000 is clamped with a warning; what is not a whole number gives the default (33)', () => {
  for (const [attrs, frameBudget, pattern] of [
    ['frame-budget="60001"', 60000, /<xml3d frame-budget="60001">: not in 0\.\.60000 .*using 60000/],
    ['frame-budget="99999999999999999999"', 60000, /using 60000/],
    ['frame-budget="-5"', 0, /<xml3d frame-budget="-5">: not in 0\.\.60000 .*using 0/],
    ['frame-budget="fast"', 33, /<xml3d frame-budget="fast">: not a whole number in 0\.\.60000 .*using 33/],
    ['frame-budget="16.7"', 33, /frame-budget="16\.7"/],
    ['frame-budget="1e3"', 33, /frame-budget="1e3"/],
    ['frame-budget=""', 33, /frame-budget=""/],
  ]) {
    const r = read(attrs);
    assert.equal(r.settings.frameBudget, frameBudget, attrs);
    assert.equal(r.problems.length, 1, attrs);
    assert.match(r.problems[0], pattern);
    assert.deepEqual({ ...r.settings, frameBudget: 0 }, { aoSamples: 0, maxDepth: 4, refineSamples: 64, frameBudget: 0 }, attrs);
  }
});

test('sameSettings compares the frame budget too', () => {
  const a = { aoSamples: 1, maxDepth: 4, refineSamples: 64, frameBudget: 33 };
  assert.equal(sameSettings(a, { ...a }), true);
  assert.equal(sameSettings(a, { ...a, frameBudget: 0 }), false);
  assert.equal(sameSettings(a, { ...a, refineSamples: 0 }), false);
});

test('refine-samples beyond 0..4096 is clamped with a warning; what is not a whole number gives the default', () => {
  for (const [attrs, refineSamples, pattern] of [
    ['refine-samples="5000"', 4096, /<xml3d refine-samples="5000">: not in 0\.\.4096 .*using 4096/],
    ['refine-samples="99999999999999999999"', 4096, /using 4096/],
    ['refine-samples="-3"', 0, /<xml3d refine-samples="-3">: not in 0\.\.4096 .*using 0/],
    ['refine-samples="many"', 64, /<xml3d refine-samples="many">: not a whole number in 0\.\.4096 .*using 64/],
    ['refine-samples="2.5"', 64, /refine-samples="2\.5"/],
    ['refine-samples=""', 64, /refine-samples=""/],
  ]) {
    const r = read(attrs);
    assert.equal(r.settings.refineSamples, refineSamples, attrs);
    assert.deepEqual(r.problems.length, 1, attrs);
    assert.match(r.problems[0], pattern);
  }
});

test('the refinement status: interactive after a requested frame, refining k/N, converged N; nothing when off', () => {
  assert.equal(refineStatus({ frame: 3, refined: false, samples: 1 }, 64), 'interactive');
  assert.equal(refineStatus({ frame: 3, refined: true, samples: 2 }, 64), 'refining 2/64');
  assert.equal(refineStatus({ frame: 3, refined: true, samples: 63 }, 64), 'refining 63/64');
  assert.equal(refineStatus({ frame: 3, refined: true, samples: 64 }, 64), 'converged 64');
  // Refined adaptively, a still converges before every pixel has the target: its last frame says so.
  assert.equal(refineStatus({ frame: 3, refined: true, converged: true, samples: 23 }, 64), 'converged 23');
  assert.equal(refineStatus({ frame: 3, refined: true, converged: false, samples: 23 }, 64), 'refining 23/64');
  for (const off of [0, 1, undefined]) assert.equal(refineStatus({ frame: 3, refined: true, samples: 2 }, off), null);
});

test('bad numbers give a clear problem each and the default is used', () => {
  for (const [attrs, withoutRefine, pattern] of [
    ['ao-samples="lots"', { aoSamples: 0, maxDepth: 4 }, /<xml3d ao-samples="lots">: not a whole number in 0\.\.256 .*using 0/],
    ['ao-samples="-1"', { aoSamples: 0, maxDepth: 4 }, /ao-samples="-1"/],
    ['ao-samples="257"', { aoSamples: 0, maxDepth: 4 }, /ao-samples="257"/],
    ['ao-samples="4.5"', { aoSamples: 0, maxDepth: 4 }, /ao-samples="4\.5"/],
    ['ao-samples=""', { aoSamples: 0, maxDepth: 4 }, /ao-samples=""/],
    ['max-depth="0"', { aoSamples: 0, maxDepth: 4 }, /<xml3d max-depth="0">: not a whole number in 1\.\.64 .*using 4/],
    ['max-depth="65" ao-samples="2"', { aoSamples: 2, maxDepth: 4 }, /max-depth="65"/],
    ['max-depth="1e2"', { aoSamples: 0, maxDepth: 4 }, /max-depth="1e2"/],
  ]) {
    const r = read(attrs), settings = { ...withoutRefine, refineSamples: 64, frameBudget: 33 };
    assert.deepEqual(r.settings, settings, attrs);
    assert.equal(r.problems.length, 1, attrs);
    assert.match(r.problems[0], pattern);
  }
  assert.equal(read('ao-samples="x" max-depth="y"').problems.length, 2);
});


const until = async (pred) => { for (let i = 0; i < 200 && !pred(); i++) await new Promise((r) => setTimeout(r, 5)); assert.ok(pred()); };

test('the channel sends the settings after the handshake, and again (with a render request) when they change', async () => {
  const saved = globalThis.WebSocket;
  globalThis.WebSocket = FakeSocket;
  let ch;
  try {
    ch = new SyncChannel({ url: 'ws://x/ws', rate: 100,
      handshake: { renderer: 'raytracer', display: 'jpeg', jpegQuality: 85, maxNodes: 0, width: 8, height: 8 },
      settings: { aoSamples: 8, maxDepth: 5 } });
    const doc = page('<xml3d><mesh><float3 name="position">0 0 -2 1 0 -2 0 1 -2</float3></mesh></xml3d>');
    ch.setScene(new MarkupReader().read(doc.querySelector('xml3d')), { width: 8, height: 8 });
    ch.connect();
    await until(() => FakeSocket.last && FakeSocket.last.sent.length === 1);
    const ws = FakeSocket.last;
    assert.deepEqual(ws.sent[0].map((r) => r.type), ['handshake']);
    ws.reply([{ type: 'handshake_reply', renderer: 'raytracer', display: 'jpeg', jpegQuality: 85, nodes: 1, width: 8, height: 8,
      maxMessageBytes: 1 << 20, maxBufferBytes: 1 << 28, serverVersion: 'test' }]);
    const all = () => ws.sent.flat();
    await until(() => all().some((r) => r.type === 'render'));
    const first = all();
    const settings = first.filter((r) => r.type === 'settings');
    assert.deepEqual(settings, [{ type: 'settings', aoSamples: 8, maxDepth: 5 }]);
    assert.ok(first.indexOf(settings[0]) < first.findIndex((r) => r.type === 'render'), 'settings before the render request');

    // The same settings again: nothing is sent.
    const n = all().length;
    ch.setSettings({ aoSamples: 8, maxDepth: 5 });
    await new Promise((r) => setTimeout(r, 50));
    assert.equal(all().length, n);
    // New settings: a settings record, then a render request (answer the outstanding frame first).
    ws.reply([{ type: 'frame', frame: 1, width: 8, height: 8, encoding: 'jpeg', timings: {}, payload: new Uint8Array(0) }]);
    ch.setSettings({ aoSamples: 0, maxDepth: 2 });
    await until(() => all().slice(n).some((r) => r.type === 'render'));
    assert.deepEqual(all().slice(n).map((r) => r.type), ['settings', 'render']);
    assert.deepEqual(all()[n], { type: 'settings', aoSamples: 0, maxDepth: 2 });
  } finally {
    if (ch) ch.close();
    globalThis.WebSocket = saved;
  }
});

test('an upload spread over several run-loop iterations by the send-buffer limit ends with a render request', async () => {
  const saved = globalThis.WebSocket;
  globalThis.WebSocket = FakeSocket;
  let ch;
  try {
    // highWater 1 byte: each iteration sends one message, then waits for the buffer to drain.
    ch = new SyncChannel({ url: 'ws://x/ws', rate: 200, highWater: 1, messageBytes: 400,
      handshake: { renderer: 'raytracer', display: 'jpeg', jpegQuality: 85, maxNodes: 0, width: 8, height: 8 } });
    const meshes = Array.from({ length: 20 }, (_, i) => `<mesh><float3 name="position">${i} 0 -2 1 0 -2 0 1 -2</float3></mesh>`).join('');
    ch.setScene(new MarkupReader().read(page(`<xml3d>${meshes}</xml3d>`).querySelector('xml3d')), { width: 8, height: 8 });
    ch.connect();
    await until(() => FakeSocket.last && FakeSocket.last.sent.length === 1);
    const ws = FakeSocket.last;
    const send = ws.send.bind(ws);
    ws.send = (bytes) => { send(bytes); ws.bufferedAmount = bytes.length; setTimeout(() => { ws.bufferedAmount = 0; }, 20); };
    ws.reply([{ type: 'handshake_reply', renderer: 'raytracer', display: 'jpeg', jpegQuality: 85, nodes: 1, width: 8, height: 8,
      maxMessageBytes: 1 << 20, maxBufferBytes: 1 << 28, serverVersion: 'test' }]);
    const isScene = (m) => m.some((r) => ['buffer', 'mesh', 'material', 'light'].includes(r.type));
    await until(() => ws.sent.filter(isScene).length >= 3 && !ch.queue.length);
    await new Promise((r) => setTimeout(r, 100));
    // Frames come back (so render requests are not held back by the outstanding limit).
    let answered = 0;
    const answer = () => { for (const r of ws.sent.flat().filter((x) => x.type === 'render' && x.frame > answered)) {
      answered = r.frame; ws.reply([{ type: 'frame', frame: r.frame, width: 8, height: 8, encoding: 'jpeg', timings: {}, payload: new Uint8Array(0) }]); } };
    answer();
    await new Promise((r) => setTimeout(r, 100));
    answer();
    const last = ws.sent.map(isScene).lastIndexOf(true);
    assert.ok(ws.sent.slice(last).flat().some((r) => r.type === 'render'), `a render request after the last upload message (${ws.sent.length} messages)`);
    assert.ok(ws.sent.filter(isScene).length >= 3, 'the upload took several messages');
  } finally {
    if (ch) ch.close();
    globalThis.WebSocket = saved;
  }
});

const HANDSHAKE = { renderer: 'raytracer', display: 'jpeg', jpegQuality: 85, maxNodes: 0, width: 8, height: 8 };
const REPLY = { type: 'handshake_reply', renderer: 'raytracer', display: 'jpeg', jpegQuality: 85, nodes: 1, width: 8, height: 8,
  maxMessageBytes: 1 << 20, maxBufferBytes: 1 << 28, serverVersion: 'test' };
const frameRecord = (frame, f = {}) => ({ type: 'frame', frame, width: 8, height: 8, encoding: 'jpeg', timings: {}, payload: new Uint8Array(0), ...f });
// A channel connected to a FakeSocket with a one-triangle scene, after the handshake reply.
async function connected(options) {
  const ch = new SyncChannel({ url: 'ws://x/ws', rate: 100, handshake: HANDSHAKE, ...options });
  const doc = page('<xml3d><mesh><float3 name="position">0 0 -2 1 0 -2 0 1 -2</float3></mesh></xml3d>');
  ch.setScene(new MarkupReader().read(doc.querySelector('xml3d')), { width: 8, height: 8 });
  ch.connect();
  await until(() => FakeSocket.last && FakeSocket.last.sent.length === 1);
  const ws = FakeSocket.last;
  ws.reply([REPLY]);
  await until(() => ws.sent.flat().some((r) => r.type === 'render'));
  return { ch, ws, all: () => ws.sent.flat() };
}
async function withFakeSocket(body) {
  const saved = globalThis.WebSocket;
  globalThis.WebSocket = FakeSocket;
  const opened = [];
  try { await body(opened); } finally {
    for (const ch of opened) ch.close();
    globalThis.WebSocket = saved;
  }
}

test('the refine record goes in the first message after the handshake reply, with the settings, and again when it changes', () => withFakeSocket(async (opened) => {
  const { ch, ws, all } = await connected({ settings: { aoSamples: 8, maxDepth: 5, refineSamples: 64 } });
  opened.push(ch);
  const first = ws.sent[1];
  assert.deepEqual(first.slice(0, 2), [{ type: 'settings', aoSamples: 8, maxDepth: 5 }, { type: 'refine', samples: 64 }]);
  assert.ok(first.some((r) => r.type === 'mesh'), 'with the first scene upload');
  assert.equal(all().filter((r) => r.type === 'refine').length, 1);

  // The same target again, or another AO setting: no refine record.
  ws.reply([frameRecord(1)]);
  let n = all().length;
  ch.setSettings({ aoSamples: 8, maxDepth: 5, refineSamples: 64 });
  await new Promise((r) => setTimeout(r, 50));
  assert.equal(all().length, n);
  ch.setSettings({ aoSamples: 2, maxDepth: 5, refineSamples: 64 });
  await until(() => all().slice(n).some((r) => r.type === 'render'));
  assert.deepEqual(all().slice(n).map((r) => r.type), ['settings', 'render']);

  // A new target: a refine record alone, then a render request (a new still refines to it).
  ws.reply([frameRecord(ch.frameNumber)]);
  n = all().length;
  ch.setSettings({ aoSamples: 2, maxDepth: 5, refineSamples: 0 });
  await until(() => all().slice(n).some((r) => r.type === 'render'));
  assert.deepEqual(all().slice(n).map((r) => r.type), ['refine', 'render']);
  assert.deepEqual(all()[n], { type: 'refine', samples: 0 });
}));

test('after a reconnect the refine record is sent again; without a target none is sent', () => withFakeSocket(async (opened) => {
  const a = await connected({ settings: { aoSamples: 0, maxDepth: 4, refineSamples: 16 } });
  opened.push(a.ch);
  a.ws.reply([REPLY]);  // a new session's handshake reply (as after a reconnect)
  await until(() => a.all().filter((r) => r.type === 'refine').length === 2);
  assert.deepEqual(a.all().filter((r) => r.type === 'refine'), [{ type: 'refine', samples: 16 }, { type: 'refine', samples: 16 }]);
  const b = await connected({ settings: { aoSamples: 0, maxDepth: 4 } });
  opened.push(b.ch);
  assert.equal(b.all().filter((r) => r.type === 'refine').length, 0);
}));

test('refined frames are shown, and answer the request of their frame number (the requested frame may have been replaced by them)', () => withFakeSocket(async (opened) => {
  const shown = [];
  const { ch, ws, all } = await connected({ settings: { aoSamples: 0, maxDepth: 4, refineSamples: 8 }, onFrame: (f) => shown.push(f) });
  opened.push(ch);
  assert.equal(ch.outstanding, 1);
  // Two more changes: the second request waits for a frame (two outstanding at most).
  ch.requestRender();
  ch.requestRender();
  assert.equal(ch.outstanding, 2);
  assert.equal(ch.renderWanted, true);
  const requests = () => all().filter((r) => r.type === 'render').length;
  const before = requests();
  ws.reply([frameRecord(1)]);  // the answer to request 1
  assert.equal(ch.outstanding, 2, 'the waiting request went out');
  assert.equal(ch.renderWanted, false);
  assert.equal(requests(), before + 1);
  // Frame 2 and its refinements: the refinements of a request already answered answer nothing more.
  ws.reply([frameRecord(2), frameRecord(2, { refined: true, samples: 2 }), frameRecord(2, { refined: true, samples: 3 })]);
  assert.equal(ch.outstanding, 1);
  assert.equal(requests(), before + 1, 'no request is sent for refined frames');
  // Frame 3 reached the client only as its refinement: the node's display replaced the
  // requested frame, which waited for the link, by the next sample. It answers request 3.
  ws.reply([frameRecord(3, { refined: true, samples: 2 })]);
  assert.equal(ch.outstanding, 0);
  assert.deepEqual(shown.map((f) => [f.frame, !!f.refined, f.samples]),
    [[1, false, 1], [2, false, 1], [2, true, 2], [2, true, 3], [3, true, 2]]);
}));

test('a frame answers every earlier request too: after requests merged by the node and frames replaced on the way, the last change is still rendered', () => withFakeSocket(async (opened) => {
  // The stuck state this guards against: each lost answer used to leave a request counted as
  // outstanding for good, and after two the channel held every later change back (the page
  // showed an earlier state of its animation for ever).
  const { ch, ws, all } = await connected({ settings: { aoSamples: 0, maxDepth: 4, refineSamples: 8 } });
  opened.push(ch);
  const requests = () => all().filter((r) => r.type === 'render').map((r) => r.frame);
  ws.reply([frameRecord(1)]);
  assert.equal(ch.outstanding, 0);
  for (let round = 0; round < 5; round++) {
    ch.requestRender();
    ch.requestRender();
    ch.requestRender();  // waits: two outstanding
    assert.equal(ch.renderWanted, true);
    const last = ch.frameNumber;
    // Only the newest request's refinement comes back: the earlier frame was replaced.
    ws.reply([frameRecord(last, { refined: true, samples: 2 })]);
    assert.equal(ch.renderWanted, false, `round ${round}: the waiting request went out`);
    assert.equal(ch.outstanding, 1);
    ws.reply([frameRecord(ch.frameNumber)]);
    assert.equal(ch.outstanding, 0, `round ${round}`);
  }
  // A frame number the client never asked for (a confused node) answers nothing it did not send.
  ws.reply([frameRecord(ch.frameNumber + 7)]);
  assert.equal(ch.outstanding, 0);
  ch.requestRender();
  assert.equal(ch.outstanding, 1);
  assert.equal(requests().at(-1), ch.frameNumber);
}));

test('the budget record goes in the first message after the handshake reply, with the settings and the refine record, and again when it changes', () => withFakeSocket(async (opened) => {
  const { ch, ws, all } = await connected({ settings: { aoSamples: 8, maxDepth: 5, refineSamples: 64, frameBudget: 33 } });
  opened.push(ch);
  const first = ws.sent[1];
  assert.deepEqual(first.slice(0, 3), [{ type: 'settings', aoSamples: 8, maxDepth: 5 }, { type: 'refine', samples: 64 },
    { type: 'budget', frameMs: 33 }]);
  assert.ok(first.some((r) => r.type === 'mesh'), 'with the first scene upload');
  assert.ok(all().findIndex((r) => r.type === 'budget') < all().findIndex((r) => r.type === 'render'), 'before the first render request');
  assert.equal(all().filter((r) => r.type === 'budget').length, 1);

  // The same budget again, or another refinement target: no budget record.
  ws.reply([frameRecord(1)]);
  let n = all().length;
  ch.setSettings({ aoSamples: 8, maxDepth: 5, refineSamples: 64, frameBudget: 33 });
  await new Promise((r) => setTimeout(r, 50));
  assert.equal(all().length, n);
  ch.setSettings({ aoSamples: 8, maxDepth: 5, refineSamples: 16, frameBudget: 33 });
  await until(() => all().slice(n).some((r) => r.type === 'render'));
  assert.deepEqual(all().slice(n).map((r) => r.type), ['refine', 'render']);

  // A new budget: a budget record alone, then a render request; 0 turns it off.
  for (const frameMs of [100, 0]) {
    ws.reply([frameRecord(ch.frameNumber)]);
    n = all().length;
    ch.setSettings({ aoSamples: 8, maxDepth: 5, refineSamples: 16, frameBudget: frameMs });
    await until(() => all().slice(n).some((r) => r.type === 'render'));
    assert.deepEqual(all().slice(n).map((r) => r.type), ['budget', 'render']);
    assert.deepEqual(all()[n], { type: 'budget', frameMs });
  }
}));

test('after a reconnect the budget record is sent again; without a budget in the settings none is sent', () => withFakeSocket(async (opened) => {
  const a = await connected({ settings: { aoSamples: 0, maxDepth: 4, refineSamples: 0, frameBudget: 0 } });
  opened.push(a.ch);
  a.ws.reply([REPLY]);  // a new session's handshake reply (as after a reconnect)
  await until(() => a.all().filter((r) => r.type === 'budget').length === 2);
  assert.deepEqual(a.all().filter((r) => r.type === 'budget'), [{ type: 'budget', frameMs: 0 }, { type: 'budget', frameMs: 0 }]);
  const b = await connected({ settings: { aoSamples: 0, maxDepth: 4, refineSamples: 64 } });
  opened.push(b.ch);
  assert.equal(b.all().filter((r) => r.type === 'budget').length, 0);
}));

test('a frame smaller than the client\'s resolution (within a budget) goes to the display like any other; the still that follows it unasked answers no request', () => withFakeSocket(async (opened) => {
  const shown = [];
  const { ch, ws } = await connected({ settings: { aoSamples: 0, maxDepth: 4, refineSamples: 0, frameBudget: 33 }, onFrame: (f) => shown.push(f) });
  opened.push(ch);
  assert.equal(ch.outstanding, 1);
  ws.reply([frameRecord(1, { width: 4, height: 3 }), frameRecord(1, { refined: true, samples: 1 })]);
  assert.equal(ch.outstanding, 0, 'the scaled frame answers the request, the full-resolution still answers none');
  assert.deepEqual(shown.map((f) => [f.frame, f.width, f.height, f.refined, f.samples]), [[1, 4, 3, false, 1], [1, 8, 8, true, 1]]);
}));

// References: a glTF model whose buffers and texture the node can load from their URLs (a
// buffer_ref each for the positions and the u16 indices, a texture_ref for the base colour),
// beside an XML3D mesh whose positions are always uploaded.
// deferBuffers: the Resources' glTF comes before its buffer (the page of a node that loads
// them itself); `download` then resolves the buffer's bytes.
async function referencedScene({ deferBuffers = false, download = null } = {}) {
  const bin = new ArrayBuffer(44), dv = new DataView(bin);
  [0, 0, -2, 1, 0, -2, 0, 1, -2].forEach((v, i) => dv.setFloat32(4 * i, v, true));
  [0, 1, 2].forEach((v, i) => dv.setUint16(36 + 2 * i, v, true));
  const gltf = {
    asset: { version: '2.0' }, scenes: [{ nodes: [0] }], nodes: [{ mesh: 0 }],
    meshes: [{ primitives: [{ attributes: { POSITION: 0 }, indices: 1, material: 0 }] }],
    materials: [{ pbrMetallicRoughness: { baseColorTexture: { index: 0 } } }], textures: [{ source: 0 }], images: [{ uri: 't.png' }],
    accessors: [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3' }, { bufferView: 1, componentType: 5123, count: 3, type: 'SCALAR' }],
    bufferViews: [{ buffer: 0, byteOffset: 0, byteLength: 36 }, { buffer: 0, byteOffset: 36, byteLength: 6 }],
    buffers: [{ uri: 'scene.bin', byteLength: 44 }],
  };
  const files = { 'http://localhost/m/scene.gltf': gltf, 'http://localhost/m/scene.bin': bin };
  const fetch = async (url) => ({ ok: true, status: 200, json: async () => files[url],
    arrayBuffer: async () => (download && url.endsWith('.bin') ? download.then(() => files[url]) : files[url]) });
  let loaded;
  const done = new Promise((r) => (loaded = r));
  const reader = new MarkupReader({ resources: new Resources({ fetch, deferBuffers, onLoad: () => loaded() }) });
  const doc = page('<xml3d><model src="m/scene.gltf"></model><mesh><float3 name="position">0 0 -2 1 0 -2 0 1 -2</float3></mesh></xml3d>');
  reader.read(doc.querySelector('xml3d'));
  await done;
  return reader.read(doc.querySelector('xml3d'));
}
// A channel to a FakeSocket with that scene, after the handshake reply (the references are on their way).
async function connectedTo(scene, options = {}, reply = REPLY) {
  const ch = new SyncChannel({ url: 'ws://x/ws', rate: 100, handshake: HANDSHAKE, ...options });
  ch.setScene(scene, { width: 8, height: 8 });
  ch.connect();
  await until(() => FakeSocket.last && FakeSocket.last.sent.length === 1);
  const ws = FakeSocket.last;
  ws.reply([reply]);
  await until(() => ws.sent.length >= 2);
  return { ch, ws };
}
const isRef = (r) => r.type === 'buffer_ref' || r.type === 'texture_ref';
// The node's answers to the references sent so far (in reverse order: they are matched by what and id).
function answerRefs(ws, refused = new Set()) {
  const refs = ws.sent.flat().filter(isRef);
  ws.reply(refs.reverse().map((r) => ({ type: 'reference', what: r.type === 'buffer_ref' ? 'buffer' : 'texture', ok: !refused.has(r.id),
    id: r.id, bytes: refused.has(r.id) ? 0 : 36, message: refused.has(r.id) ? `${r.url} is not in tessera.asset-origins` : '' })));
}
// loadTexture in Node: a 1x1 PNG (its header) behind fetch, createImageBitmap's size.
const PNG = new Uint8Array([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0, 0, 0, 13, 0x49, 0x48, 0x44, 0x52, 0, 0, 0, 1, 0, 0, 0, 1, 8, 6, 0, 0, 0]);
async function withTextures(body) {
  const saved = { fetch: globalThis.fetch, createImageBitmap: globalThis.createImageBitmap };
  globalThis.fetch = async () => new Response(PNG);
  globalThis.createImageBitmap = async () => ({ width: 1, height: 1, close() {} });
  try { await body(); } finally { Object.assign(globalThis, saved); }
}

test('references go first, in a message of their own; the rest follows without waiting for the answers; an answer ok means no upload', () => withFakeSocket(async (opened) => {
  const scene = await referencedScene();
  let answeredCalls = 0;  // the remote backend opens the deferred glTF downloads then
  const { ch, ws } = await connectedTo(scene, { onReferencesAnswered: () => answeredCalls++ });
  opened.push(ch);
  const [gltfMesh, markupMesh] = [...scene.meshes.values()];
  const texture = scene.materials.get(gltfMesh.material).diffuseTexture;
  assert.deepEqual(ws.sent[1], [
    { type: 'buffer_ref', id: gltfMesh.positions, bufferType: 'f32', components: 3, source: 'f32', values: 9, byteStride: 0, byteOffset: 0,
      url: 'http://localhost/m/scene.bin' },
    { type: 'buffer_ref', id: gltfMesh.indices, bufferType: 'u32', components: 1, source: 'u16', values: 3, byteStride: 0, byteOffset: 36,
      url: 'http://localhost/m/scene.bin' },
    { type: 'texture_ref', id: texture, wrapS: 'repeat', wrapT: 'repeat', filter: 'linear', srgb: true, url: 'http://localhost/m/t.png' },
  ]);
  // The node applies what follows after its answers, and holds a mesh whose buffers are missing.
  await until(() => ws.sent.flat().some((r) => r.type === 'render'));
  const early = ws.sent.slice(2).flat();
  assert.deepEqual(early.filter((r) => r.type === 'mesh').map((r) => r.id).sort(), [gltfMesh.id, markupMesh.id].sort(), 'meshes before the answers');
  assert.ok(early.some((r) => r.type === 'material'));
  assert.deepEqual(early.filter((r) => r.type === 'buffer').map((r) => r.id), [markupMesh.positions], 'only what has no source is uploaded');
  assert.equal(early.filter((r) => r.type === 'texture' || isRef(r)).length, 0);
  assert.equal(answeredCalls, 0);
  assert.equal(ch.unanswered.size, 3);
  const before = ws.sent.length;
  answerRefs(ws);
  await new Promise((r) => setTimeout(r, 60));
  assert.equal(answeredCalls, 1);
  assert.equal(ch.unanswered.size, 0);
  assert.equal(ws.sent.slice(before).flat().filter((r) => r.type === 'buffer' || r.type === 'texture').length, 0, 'nothing uploaded after ok answers');
}));

test('a refused reference is uploaded when its answer comes; one console warning sums the refusals up', () => withFakeSocket((opened) => withTextures(async () => {
  const scene = await referencedScene();
  const warnings = [];
  const warn = console.warn;
  console.warn = (...a) => warnings.push(a.join(' '));
  try {
    const { ch, ws } = await connectedTo(scene);
    opened.push(ch);
    const [gltfMesh] = [...scene.meshes.values()];
    const texture = scene.materials.get(gltfMesh.material).diffuseTexture;
    await until(() => ws.sent.flat().some((r) => r.type === 'render'));
    const before = ws.sent.length;
    answerRefs(ws, new Set([gltfMesh.positions, texture]));
    await until(() => ws.sent.slice(before).flat().some((r) => r.type === 'texture'));
    const after = ws.sent.slice(before).flat();
    const positions = after.filter((r) => r.type === 'buffer' && r.id === gltfMesh.positions);
    assert.equal(positions.length, 1, 'the refused buffer is uploaded');
    assert.deepEqual([...positions[0].data], [0, 0, -2, 1, 0, -2, 0, 1, -2]);
    assert.equal(ws.sent.flat().filter((r) => r.type === 'buffer' && r.id === gltfMesh.indices).length, 0, 'the loaded one is not');
    const tex = after.find((r) => r.type === 'texture');
    assert.deepEqual([tex.id, tex.format, tex.width, tex.height], [texture, 'png', 1, 1]);
    await until(() => ws.sent.slice(before).flat().some((r) => r.type === 'render'));  // the scene is complete now: a frame of it
    assert.equal(warnings.length, 1);
    assert.match(warnings[0], /refused 2 references.*is not in tessera\.asset-origins/);

    // A new session sends the references again; refusing them again warns no more.
    ws.reply([REPLY]);
    await until(() => ws.sent.flat().filter(isRef).length === 6);
    answerRefs(ws, new Set([gltfMesh.positions, texture]));
    await until(() => ws.sent.flat().filter((r) => r.type === 'buffer' && r.id === gltfMesh.positions).length === 2);
    assert.equal(warnings.length, 1, 'one warning per page load');
  } finally {
    console.warn = warn;
  }
})));

// A channel connected to a FakeSocket with the referenced scene, the console's warnings silenced.
async function quietlyReferenced(opened, body) {
  const warn = console.warn;
  console.warn = () => {};
  try {
    const scene = await referencedScene();
    const { ch, ws } = await connectedTo(scene);
    opened.push(ch);
    await body({ scene, ch, ws });
  } finally {
    console.warn = warn;
  }
}

test('an error record while reference answers are outstanding uploads the unanswered ones; a late answer changes nothing', () => withFakeSocket((opened) => withTextures(() => quietlyReferenced(opened, async ({ ch, ws }) => {
  const refs = ws.sent[1];
  ws.reply([{ type: 'error', code: 8, codeName: 'bad_length', fatal: false, record: 0, message: 'record 0 (buffer_ref): body length' }]);
  const uploaded = (r) => ws.sent.flat().filter((x) => x.type === (r.type === 'buffer_ref' ? 'buffer' : 'texture') && x.id === r.id).length;
  await until(() => refs.every((r) => uploaded(r) === 1));
  assert.equal(ch.unanswered.size, 0);
  answerRefs(ws, new Set([refs[0].id]));
  await new Promise((r) => setTimeout(r, 60));
  for (const r of refs) assert.equal(uploaded(r), 1, `${r.type} ${r.id} uploaded once`);
}))));

test('a refused reference is not uploaded when a newer record for its id went out before the answer', () => withFakeSocket((opened) => withTextures(() => quietlyReferenced(opened, async ({ scene, ch, ws }) => {
  const [gltfMesh] = [...scene.meshes.values()];
  await until(() => ws.sent.flat().some((r) => r.type === 'render'));
  // The page drops the glTF mesh and its positions before the node has answered.
  const without = { ...scene, meshes: new Map([...scene.meshes].filter(([id]) => id !== gltfMesh.id)),
    buffers: new Map([...scene.buffers].filter(([id]) => id !== gltfMesh.positions)) };
  ch.setScene(without, { width: 8, height: 8 });
  await until(() => ws.sent.flat().some((r) => r.type === 'remove' && r.what === 'buffer' && r.id === gltfMesh.positions));
  answerRefs(ws, new Set([gltfMesh.positions, gltfMesh.indices]));
  await until(() => ws.sent.flat().some((r) => r.type === 'buffer' && r.id === gltfMesh.indices));
  await new Promise((r) => setTimeout(r, 60));
  assert.equal(ws.sent.flat().filter((r) => r.type === 'buffer' && r.id === gltfMesh.positions).length, 0,
    'the removed buffer is not uploaded again');
  assert.equal(ws.sent.flat().filter((r) => r.type === 'buffer' && r.id === gltfMesh.indices).length, 1, 'the one still in the scene is');
}))));

test('one id referenced again before its first answer: the answers match in order, and only the latest reference may upload', () => withFakeSocket((opened) => withTextures(() => quietlyReferenced(opened, async ({ ch, ws }) => {
  await until(() => ws.sent.flat().some((r) => r.type === 'render'));
  answerRefs(ws);
  await until(() => ch.groups.length === 0);
  const ref = (k) => ({ type: 'buffer_ref', id: 77, bufferType: 'f32', components: 3, source: 'f32', values: 3, byteStride: 0,
    byteOffset: 12 * k, url: 'http://localhost/m/scene.bin', upload: { type: 'buffer', id: 77, bufferType: 'f32', components: 3, data: new Float32Array([k, k, k]) } });
  const uploads = () => ws.sent.flat().filter((r) => r.type === 'buffer' && r.id === 77).map((r) => r.data[0]);
  const answer = (...ok) => ws.reply(ok.map((o) => ({ type: 'reference', what: 'buffer', ok: o, id: 77, bytes: o ? 36 : 0, message: o ? '' : 'refused' })));
  // The older one refused, the newer one loaded: nothing to upload (the older is superseded).
  await ch.sendRefs({ refs: [ref(1)] }, ch.session);
  await ch.sendRefs({ refs: [ref(2)] }, ch.session);
  assert.equal(ch.groups.length, 2);
  answer(false);
  answer(true);
  await new Promise((r) => setTimeout(r, 30));
  assert.deepEqual(uploads(), []);
  assert.equal(ch.groups.length, 0, 'both messages answered: the room is given back');
  assert.equal(ch.unanswered.size, 0);
  // The older one loaded, the newer one refused: the newer one's values are uploaded.
  await ch.sendRefs({ refs: [ref(3)] }, ch.session);
  await ch.sendRefs({ refs: [ref(4)] }, ch.session);
  answer(true);
  answer(false);
  await until(() => uploads().length === 1);
  assert.deepEqual(uploads(), [4]);
  assert.equal(ch.groups.length, 0);
}))));

test('while answers are outstanding the channel sends at most half of what the node holds back, then the rest after the answers', () => withFakeSocket(async (opened) => {
  const scene = await referencedScene();
  // A node that holds 512 bytes of messages behind references it loads: 256 of them for the client.
  const { ch, ws } = await connectedTo(scene, {}, { ...REPLY, maxMessageBytes: 512 });
  opened.push(ch);
  await new Promise((r) => setTimeout(r, 60));
  const held = ws.sent.slice(2);
  const bytes = held.reduce((n, m) => n + encodeClient(m).byteLength, 0);
  assert.ok(bytes <= 256, `${bytes} bytes sent behind the references`);
  assert.ok(!held.flat().some((r) => r.type === 'render'), 'the scene change waits, and its render request with it');
  answerRefs(ws);
  await until(() => ws.sent.flat().filter((r) => r.type === 'mesh').length === 2 && ws.sent.flat().some((r) => r.type === 'render'));
  const all = ws.sent.slice(2).reduce((n, m) => n + encodeClient(m).byteLength, 0);
  assert.ok(all > 256, `the whole change (${all} bytes) is more than the node holds for the client`);
  assert.equal(ch.groups.length, 0);
}));

test('references: false uploads every buffer and texture, as before', () => withFakeSocket((opened) => withTextures(async () => {
  const scene = await referencedScene();
  const { ch, ws } = await connectedTo(scene, { references: false });
  opened.push(ch);
  await until(() => ws.sent.flat().some((r) => r.type === 'render'));
  const all = ws.sent.flat();
  assert.equal(all.filter(isRef).length, 0);
  assert.deepEqual(all.filter((r) => r.type === 'buffer').map((r) => r.id).sort(), [...scene.buffers.keys()].sort());
  assert.equal(all.filter((r) => r.type === 'texture').length, 1);
  assert.ok(all.findIndex((r) => r.type === 'texture') < all.findIndex((r) => r.type === 'material'));
})));

test('a connection lost while reference answers are outstanding does not hang the channel: the next session sends everything', () => withFakeSocket(async (opened) => {
  const scene = await referencedScene();
  const { ch, ws } = await connectedTo(scene);
  opened.push(ch);
  assert.equal(ch.unanswered.size, 3);
  ws.readyState = 3;
  ws.onclose({ code: 1006, reason: '' });
  assert.equal(ch.state, 'disconnected');
  assert.equal(ch.unanswered.size, 0);
  await until(() => !ch.flushing);
  const sent = ws.sent.length;
  await new Promise((r) => setTimeout(r, 60));
  assert.equal(ws.sent.length, sent, 'nothing more on the lost connection');
  await until(() => FakeSocket.last !== ws && FakeSocket.last.sent.length === 1);  // reconnected
  const ws2 = FakeSocket.last;
  ws2.reply([REPLY]);
  await until(() => ws2.sent.length >= 2);
  assert.equal(ws2.sent[1].filter(isRef).length, 3);
  answerRefs(ws2);
  await until(() => ws2.sent.flat().some((r) => r.type === 'render'));
  assert.equal(ws2.sent.flat().filter((r) => r.type === 'mesh').length, 2);
}));

test('references beyond one message are spread over several, each of references only', () => withFakeSocket(async (opened) => {
  const { ch, ws } = await connectedTo(await referencedScene(), { messageBytes: 100 });
  opened.push(ch);
  await until(() => ws.sent.length >= 4);
  await new Promise((r) => setTimeout(r, 30));
  assert.deepEqual(ws.sent.slice(1, 4).map((m) => m.map((r) => r.type)), [['buffer_ref'], ['buffer_ref'], ['texture_ref']]);
  assert.equal(ch.groups.length, 3, 'each message of references is answered on its own');
  answerRefs(ws);
  await until(() => ws.sent.flat().some((r) => r.type === 'render'));
  assert.equal(ws.sent.flat().filter((r) => r.type === 'mesh').length, 2);
}));

test('a refused reference of a deferred glTF is uploaded with its values once they are in, after the mesh that uses it', () => withFakeSocket((opened) => withTextures(async () => {
  let arrive;
  const download = new Promise((r) => (arrive = r));
  const scene = await referencedScene({ deferBuffers: true, download });
  const warn = console.warn;
  console.warn = () => {};
  try {
    const { ch, ws } = await connectedTo(scene);
    opened.push(ch);
    const [gltfMesh] = [...scene.meshes.values()];
    assert.deepEqual([...scene.buffers.get(gltfMesh.positions).data], [0, 0, 0, 0, 0, 0, 0, 0, 0], 'sent before the values are in');
    await until(() => ws.sent.flat().some((r) => r.type === 'mesh' && r.id === gltfMesh.id));  // held by the node until its buffers come
    answerRefs(ws, new Set([gltfMesh.positions]));
    await new Promise((r) => setTimeout(r, 60));
    assert.equal(ws.sent.flat().filter((r) => r.type === 'buffer' && r.id === gltfMesh.positions).length, 0, 'no upload of zeros');
    arrive();
    await until(() => ws.sent.flat().some((r) => r.type === 'buffer' && r.id === gltfMesh.positions));
    const positions = ws.sent.flat().filter((r) => r.type === 'buffer' && r.id === gltfMesh.positions);
    assert.equal(positions.length, 1);
    assert.deepEqual([...positions[0].data], [0, 0, -2, 1, 0, -2, 0, 1, -2], 'the file\'s values');
  } finally {
    console.warn = warn;
  }
})));

test('a change a period after the last one goes out at once, not at the next run-loop iteration; the next one within a period waits for it',
  () => withFakeSocket(async (opened) => {
    const { ch, ws, all } = await connected({ rate: 2 });  // a period of 500 ms
    opened.push(ch);
    ws.reply([frameRecord(1)]);
    const moved = (x) => {
      const doc = page(`<xml3d><mesh><float3 name="position">${x} 0 -2 1 0 -2 0 1 -2</float3></mesh></xml3d>`);
      ch.setScene(new MarkupReader().read(doc.querySelector('xml3d')), { width: 8, height: 8 });
    };
    await new Promise((r) => setTimeout(r, 600));  // no change for more than a period
    const n = all().length;
    moved(0.5);
    await new Promise((r) => setTimeout(r, 0));
    assert.ok(all().slice(n).some((r) => r.type === 'buffer'), 'sent at once');
    assert.ok(all().slice(n).some((r) => r.type === 'render'));
    const m = all().length;
    moved(0.25);  // within a period of the last change: the run loop sends it
    await new Promise((r) => setTimeout(r, 0));
    assert.equal(all().length, m);
    for (const t0 = Date.now(); Date.now() - t0 < 2000 && !all().slice(m).some((r) => r.type === 'buffer');) await new Promise((r) => setTimeout(r, 10));
    assert.ok(all().slice(m).some((r) => r.type === 'buffer'), 'sent by the run loop');
  }));
