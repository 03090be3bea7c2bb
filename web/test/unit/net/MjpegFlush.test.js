// When the MJPEG display asks the node for one more frame (RemoteBackend.flushMjpeg). Chromium
// shows a part of a multipart/x-mixed-replace stream only when the next part starts, so the
// last frame of a change stays hidden until the client asks for another. The channel and the
// <img> are stand-ins; the timers are real (150 ms retry, 500 ms with refinement).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { RemoteBackend } from '../../../src/net/RemoteBackend.js';

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// A backend with only what flushMjpeg reads: an idle channel that counts its requests (each
// request is the next frame number) and a stream that shows a picture once `showing` is set.
function backend({ refineSamples = 0 } = {}) {
  const b = Object.create(RemoteBackend.prototype);
  b.frameView = { showing: false };
  b.channel = {
    requests: 0, frameNumber: 2, outstanding: 0, renderWanted: false, dirty: false, queue: [], waiting: false,
    settings: { refineSamples, frameBudget: 0 }, reply: { renderer: 'raytracer' },
    requestRender() { this.requests++; this.frameNumber++; },
  };
  return b;
}

test('a stream that starts showing between two frames still gets the last frame pushed out', async () => {
  // Frame 1 (before the model loaded) and frame 2 (the scene) both arrive before the stream
  // shows anything; frame 2's part then pushes frame 1 onto the page. Frame 2 is the last of
  // the change: unless the client asks for frame 3, the page keeps showing frame 1.
  const b = backend();
  b.flushMjpeg({ frame: 1 });
  b.flushMjpeg({ frame: 2 });
  b.frameView.showing = true;
  await sleep(250);
  assert.equal(b.channel.requests, 1, 'one frame asked for to push frame 2 out');
  b.flushMjpeg({ frame: 3 });  // the pushing frame itself asks for nothing more
  await sleep(200);
  assert.equal(b.channel.requests, 1);
  clearTimeout(b.flushTimer);
});

test('while the stream shows nothing the client asks again after 150 ms, at most 20 times', async () => {
  // Each request brings the next frame (numbered as the channel counts them); the stream never
  // shows. 20 retries, then the ordinary flush asks once, and the frame that answers it is
  // not flushed again.
  const b = backend();
  let last = -1;
  while (b.channel.requests !== last) {
    last = b.channel.requests;
    b.flushMjpeg({ frame: b.channel.frameNumber });
    await sleep(170);
  }
  assert.equal(b.channel.requests, 21);
  clearTimeout(b.flushTimer);
});

test('a showing stream asks once after the last frame of a change, and not while the channel is busy', async () => {
  const b = backend();
  b.frameView.showing = true;
  b.channel.outstanding = 1;
  b.flushMjpeg({ frame: 2 });
  assert.equal(b.channel.requests, 0, 'a frame is on its way: it pushes frame 2 out');
  b.channel.outstanding = 0;
  b.flushMjpeg({ frame: 2 });
  assert.equal(b.channel.requests, 1);
  b.flushMjpeg({ frame: 3 });
  assert.equal(b.channel.requests, 1, 'the flush frame is not flushed again');
});

test('with refinement the client waits 500 ms for a refined frame, and never flushes after one', async () => {
  const b = backend({ refineSamples: 16 });
  b.frameView.showing = true;
  b.flushMjpeg({ frame: 2 });
  await sleep(100);
  b.flushMjpeg({ frame: 2, refined: true });  // a refinement came: it pushes frame 2 out
  await sleep(600);
  assert.equal(b.channel.requests, 0);
  b.flushMjpeg({ frame: 3 });
  await sleep(600);
  assert.equal(b.channel.requests, 1, 'no refinement within 500 ms: one frame asked for');
});
