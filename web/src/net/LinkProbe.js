// display="auto": whether the link, not the node, bounds the JPEG frames' rate (docs/web-client.md,
// "H.264 display"). The page starts an auto session with JPEG where the browser decodes H.264 and
// feeds every answered JPEG frame here; when a window of frames shows the link holding them back,
// got() returns the figures once, and the page switches to H.264 (RemoteBackend).
//
// What is measured, per window of at least `windowMs` of waiting and `minFrames` frames:
//  - the frame rate the page gets while it waits: frames over the time it had a render request
//    outstanding (for each frame, from its request, or from the previous frame if that came
//    later, to its arrival), so a page that asks seldom is not mistaken for a slow link;
//  - the JPEG throughput: the frames' bytes over that time;
//  - the rate the node could give: 1000 / (rendering_ms + encode_ms), the frames' mean, and at
//    most the page's own request rate (sync-rate).
// The link bounds the frames when the page gets less than `ratio` (40%) of what the node could
// give. A long round trip also lowers the rate the page gets (it keeps at most two requests
// outstanding); the ratio leaves room for a round trip of about the node's frame time.
export class LinkProbe {
  constructor({ rate = 30, windowMs = 2000, minFrames = 6, ratio = 0.4 } = {}) {
    Object.assign(this, { rate, windowMs, minFrames, ratio });
    this.asked = new Map();  // frame number -> when its render request went (ms)
    this.last = -Infinity;   // when the previous answered frame arrived
    this.done = false;       // a verdict was given
    this.windows = 0;        // windows judged so far
    this.reset();
  }

  reset() {
    this.frames = 0;
    this.waitMs = 0;
    this.bytes = 0;
    this.nodeMs = 0;
  }

  // A render request for `frame` went at t (ms).
  request(frame, t) {
    if (this.done) return;
    this.asked.set(frame, t);
    if (this.asked.size > 64) this.asked.delete(this.asked.keys().next().value);  // never answered
  }

  // An answered JPEG frame ({frame, payload, timings: {rendering, encode}}) arrived at t (ms).
  // Returns null, or once, when the link bounds the frames: {fps, nodeFps, kbps}.
  got(f, t) {
    if (this.done) return null;
    const sent = this.asked.get(f.frame);
    const from = Math.max(this.last, sent ?? Infinity);
    this.last = t;
    if (sent === undefined || !(t > from)) return null;
    for (const k of this.asked.keys()) { if (k > f.frame) break; this.asked.delete(k); }
    this.frames++;
    this.waitMs += t - from;
    this.bytes += f.payload ? f.payload.length : 0;
    this.nodeMs += (f.timings?.rendering || 0) + (f.timings?.encode || 0);
    if (this.waitMs < this.windowMs || this.frames < this.minFrames) return null;
    const fps = (1000 * this.frames) / this.waitMs;
    const nodeFps = Math.min(this.rate, this.nodeMs > 0 ? (1000 * this.frames) / this.nodeMs : this.rate);
    const kbps = (8 * this.bytes) / this.waitMs;
    this.reset();
    this.windows++;
    if (fps >= this.ratio * nodeFps) return null;
    this.done = true;
    return { fps, nodeFps, kbps };
  }
}
