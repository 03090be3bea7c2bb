// display="auto"'s measurement (src/net/LinkProbe.js): a link that holds JPEG frames back gives
// one verdict with its figures; a fast link, or a page that seldom asks, gives none.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { LinkProbe } from '../../../src/net/LinkProbe.js';

const frame = (n, bytes = 40000, rendering = 10, encode = 2) =>
  ({ frame: n, payload: new Uint8Array(bytes), timings: { rendering, encode } });

// The page keeps two requests outstanding; each frame takes `gapMs` to arrive after the one
// before it (the link's time for it, or the node's).
function run(probe, { frames = 200, gapMs, bytes = 40000, rendering = 10 }) {
  let t = 0, n = 0;
  const verdicts = [];
  probe.request(++n, t);
  probe.request(++n, t);
  for (let i = 1; i <= frames; i++) {
    t += gapMs;
    const v = probe.got(frame(i, bytes, rendering), t);
    if (v) verdicts.push({ ...v, at: t });
    probe.request(++n, t);
  }
  return verdicts;
}

test('a link that carries 5 of the 40 KB frames a second, where the node renders 80, is found once, with its figures', () => {
  const v = run(new LinkProbe({ rate: 30 }), { gapMs: 200 });
  assert.equal(v.length, 1);
  assert.ok(Math.abs(v[0].fps - 5) < 0.01, `${v[0].fps}`);
  assert.equal(v[0].nodeFps, 30);  // the page asks at most 30 a second
  assert.ok(Math.abs(v[0].kbps - 1600) < 1, `${v[0].kbps}`);  // 40 KB x 5/s
  assert.ok(v[0].at <= 2200, 'within the first window (2 s)');
});

test('a link that keeps up gives no verdict, nor does a slow node', () => {
  const fast = new LinkProbe({ rate: 30 });
  assert.deepEqual(run(fast, { gapMs: 34 }), []);  // 29 frames/s
  assert.ok(fast.windows >= 3);
  // The node renders 100 ms a frame and the frames come at that pace: the node bounds them.
  assert.deepEqual(run(new LinkProbe({ rate: 30 }), { gapMs: 105, rendering: 100 }), []);
});

test('a page that asks seldom is measured by its waits, not its requests', () => {
  const probe = new LinkProbe({ rate: 30 });
  // One request a second, each answered 20 ms later: 50 frames/s while it waits.
  let t = 0;
  for (let n = 1; n <= 30; n++) {
    probe.request(n, t);
    assert.equal(probe.got(frame(n), t + 20), null);
    t += 1000;
  }
});

test('unanswered requests are forgotten, and a frame of no known request is not counted', () => {
  const probe = new LinkProbe({ rate: 30 });
  for (let n = 1; n <= 100; n++) probe.request(n, n);
  assert.ok(probe.asked.size <= 64);
  assert.equal(probe.got(frame(500), 1000), null);
  assert.equal(probe.frames, 0);
});
