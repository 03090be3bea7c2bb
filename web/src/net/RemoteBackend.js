// Server rendering backend: <xml3d server="[wss://]host:port" renderer="raytracer"
// display="jpeg|s3tc|mjpeg|h264|auto" nodes="N" sync-rate="60" jpeg-quality="85" video-kbps="8000"
// ao-samples="0" max-depth="4" refine-samples="64" frame-budget="33" token="..." references="off">
// (RenderSettings.js; the access token also from the page's #tessera-token=..., AccessToken.js;
// references="off": every buffer and texture is uploaded, none is left for the node to load
// from its URL).
// The scene goes to the node over the sync channel; frames come back on the same WebSocket and
// are shown in a display element behind a transparent input canvas (which takes the mouse).
// While the node refines a still, the status line says "refining k/N", then "converged N", and
// "interactive" after a requested frame.
import { SyncChannel } from './SyncChannel.js';
import { JpegDisplay, S3tcDisplay, MjpegDisplay, VideoDisplay } from './FrameDisplay.js';
import { hasS3TC, probeH264, warnOnce } from './Features.js';
import { LinkProbe } from './LinkProbe.js';
import { readRenderSettings, readVideoKbps, refineStatus } from './RenderSettings.js';
import { accessToken, withToken, redact } from './AccessToken.js';
import { pageBackground } from './PageBackground.js';

// The node's host:port and whether to use TLS (wss:// and https://) from the server attribute:
// "wss://h:p" or "https://h:p" ask for TLS, "ws://h:p" or "http://h:p" for none, a bare "h:p"
// follows the page (a page served over https can open only secure sockets).
export function nodeAddress(server, pageProtocol) {
  const m = /^(wss|ws|https|http):\/\//i.exec(server.trim());
  const host = server.trim().slice(m ? m[0].length : 0).replace(/[/?#].*$/, '');
  const secure = m ? /^(wss|https)$/i.test(m[1]) : pageProtocol === 'https:';
  return { host, secure };
}

// The sky's colour: what the page shows behind the element (PageBackground.js).
function cssColor(doc, el) {
  return pageBackground(el, (e) => doc.defaultView.getComputedStyle(e));
}

export const DISPLAYS = ['jpeg', 's3tc', 'mjpeg', 'h264', 'auto'];

// The display for display="h264" or "auto", once WebCodecs has been asked (probeH264, once per
// page): h264 when it decodes the node's stream, else jpeg. For "h264" that fallback is one
// console warning per page naming the reason; "auto" falls back silently (JPEG is one of its
// choices). For "auto", h264 means that H.264 may be used: the page starts with JPEG and
// switches to H.264 when it measures that the link, not the node, bounds the JPEG frames
// (LinkProbe.js, RemoteBackend.autoSwitch).
export async function chooseDisplay(display) {
  if (display !== 'h264' && display !== 'auto') return display;
  const { ok, reason } = await probeH264();
  if (ok) return 'h264';
  if (display === 'h264') warnOnce('h264', `${reason}: display="h264" falls back to JPEG frames`);
  return 'jpeg';
}

const int = (el, name, def) => {
  const v = parseInt(el.getAttribute(name) ?? '', 10);
  return Number.isFinite(v) ? v : def;
};

export class RemoteBackend {
  constructor(handler, server) {
    const doc = handler.container.ownerDocument, x = handler.xml3d;
    this.handler = handler;
    let display = (x.getAttribute('display') || 'jpeg').trim().toLowerCase();
    if (!DISPLAYS.includes(display)) {
      handler.setStatus('display', `⚠ display="${display}" unknown, jpeg used`, true);
      display = 'jpeg';
    }
    if (display === 's3tc' && !hasS3TC()) display = 'jpeg';
    this.display = display;  // h264 or auto: settled when the probe answers (start below)
    const { host, secure } = nodeAddress(server, doc.defaultView.location.protocol);
    const session = Math.random().toString(36).slice(2) + Date.now().toString(36);
    const token = accessToken(x, doc.defaultView);
    this.host = host;
    this.url = withToken(`${secure ? 'wss' : 'ws'}://${host}/ws?session=${session}`, token);
    this.mjpegUrl = withToken(`${secure ? 'https' : 'http'}://${host}/mjpeg/${session}`, token);
    this.frameView = null;  // made once the display is settled
    this.inputElement = doc.createElement('canvas');
    this.inputElement.className = '_xml3d tessera-input';  // transparent: never drawn
    handler.container.appendChild(this.inputElement);

    const renderer = x.getAttribute('renderer') || 'raytracer';
    const references = (x.getAttribute('references') || '').trim().toLowerCase() !== 'off';
    // With references the node loads glTF buffers itself, so the page's reader need not wait
    // for them (XML3DHandler.js): the scene goes out while the browser downloads them.
    this.defersBuffers = references;
    // Their downloads wait until the node has answered the references (or a few seconds, or the
    // session ended): the scene's way to the node comes first.
    let openGate;
    this.downloadGate = new Promise((r) => (openGate = r));
    this.openDownloads = openGate;
    this.gateTimer = setTimeout(openGate, 3000);
    const settings = this.readSettings();
    this.channel = new SyncChannel({
      url: this.url,
      handshake: { renderer: renderer === 'rasterizer' ? 'rasterizer' : 'raytracer', display,
        jpegQuality: Math.min(100, Math.max(1, int(x, 'jpeg-quality', 85))), maxNodes: Math.max(0, int(x, 'nodes', 0)),
        width: handler.width, height: handler.height },
      settings,
      videoKbps: this.videoKbps,
      rate: Math.min(120, Math.max(1, int(x, 'sync-rate', 60))),
      references,
      onReferencesAnswered: () => this.openDownloads(),
      onState: (state, detail) => this.state(state, detail),
      onFrame: (f) => this.frame(f),
      onServerError: (e) => handler.setStatus(`server:${e.codeName}:${e.message}`, `⚠ server: ${e.codeName}: ${e.message}`, true),
      onStats: (s) => { this.stats = s; },
      onRequest: (n) => { if (this.probe) this.probe.request(n, performance.now()); },
      // The node has answered everything and that frame is on screen: the page may have finished
      // loading since (a deferred buffer whose upload's frame came before the reader saw it
      // loaded), and no frame is coming to say so.
      onIdle: () => { if (this.shownFrame >= this.channel.frameNumber) handler.sceneShown(); },
      onProgress: (sent, queued) => handler.setStatus('upload', queued && sent < queued
        ? `uploading scene: ${Math.round(100 * sent / queued)}% of ${(queued / 1048576).toFixed(1)} MB` : null),
    });
    // The display (and the handshake, which names it) waits for the H.264 probe when it matters;
    // the others start at once, as before.
    if (display === 'h264') chooseDisplay(display).then((d) => this.start(d));
    else if (display === 'auto') {
      // JPEG first; H.264 once the link is measured to hold JPEG back (where it decodes).
      chooseDisplay(display).then((d) => {
        if (d === 'h264') this.probe = new LinkProbe({ rate: this.channel.rate });
        this.start('jpeg');
      });
    } else this.start(display);
  }

  // Shows frames of `display` and connects with it.
  start(display) {
    if (this.disposed) return;
    const doc = this.handler.container.ownerDocument;
    this.display = display;
    this.useView(display === 's3tc' ? new S3tcDisplay(doc)
      : display === 'mjpeg' ? new MjpegDisplay(doc, this.mjpegUrl)
        : display === 'h264' ? new VideoDisplay(doc, { onNeedKeyframe: (e) => this.needKeyframe(e) })
          : new JpegDisplay(doc));
    this.channel.handshake.display = display;
    this.channel.connect();
  }

  // The H.264 decoder cannot go on (an error, or a delta frame it has no keyframe for): the node
  // sends a keyframe with the next frame when asked. A decoder error is unusual (a corrupt
  // stream, a decoder that gave up): one warning per page says what it was.
  needKeyframe(error) {
    if (error) warnOnce('h264-decode', `the H.264 decoder failed (${error.message || error}); asking the node for a keyframe`);
    this.channel.requestKeyframe();
  }

  // The frame display, behind the input canvas.
  useView(view) {
    if (this.frameView) this.frameView.dispose();
    this.frameView = view;
    this.element = view.element;
    this.handler.container.insertBefore(this.element, this.inputElement);
  }

  // ao-samples / max-depth / refine-samples / frame-budget from the element; bad values are
  // warned about once and replaced by the default or clamped (also on the status line). Also
  // video-kbps (this.videoKbps, 0 when absent or bad).
  readSettings() {
    const { settings, problems } = readRenderSettings(this.handler.xml3d);
    const video = readVideoKbps(this.handler.xml3d);
    if (video.problem) problems.push(video.problem);
    this.videoKbps = video.kbps;
    const key = problems.join('\n');
    if (key !== this.settingsProblems) {
      this.settingsProblems = key;
      for (const p of problems) console.warn(`XML3D: ${p}`);
      this.handler.setStatus('settings', problems.length ? `⚠ ${problems.join('; ')}` : null, true);
    }
    return settings;
  }

  state(state, detail) {
    const h = this.handler;
    h.container.dataset.connection = state;
    const text = {
      connecting: `connecting to ${redact(this.url)}…`,
      handshake: 'connected, waiting for the node…',
      ready: null,
      disconnected: `⚠ connection to the Tessera node lost: ${detail}`,
      failed: `⚠ the Tessera node refused the session: ${detail}`,
    }[state];
    h.setStatus('connection', text, state === 'disconnected' || state === 'failed');
    // The end of this page's session: one console error that says why (the node's close reason).
    if (state === 'failed') console.error(`Tessera: the node ${this.host} refused the session: ${detail}`);
    if (state === 'failed' || state === 'disconnected') this.openDownloads();  // no answers are coming
    if (state === 'ready') {
      this.serverInfo = detail;
      if (this.frameView && this.frameView.start) this.frameView.start();
    }
  }

  // display="auto": the link holds the JPEG frames back (LinkProbe's figures): a new session
  // with H.264, which needs a fraction of JPEG's bytes and which the node fits to the link
  // (docs/protocol.md, "Bandwidth adaptation"). One console line says why; the page keeps
  // H.264 from then on.
  autoSwitch(v) {
    this.probe = null;
    console.info(`XML3D/Tessera: display="auto": JPEG frames came at ${v.fps.toFixed(1)}/s (${(v.kbps / 1000).toFixed(2)} Mbit/s) `
      + `where the node gives ${v.nodeFps.toFixed(1)}/s: the link bounds them, switching to H.264`);
    const doc = this.handler.container.ownerDocument;
    this.display = 'h264';
    this.useView(new VideoDisplay(doc, { onNeedKeyframe: (e) => this.needKeyframe(e) }));
    this.channel.handshake.display = 'h264';
    this.channel.restart();
  }

  async frame(f) {
    if (this.probe && f.encoding === 'jpeg' && !f.refined) {
      const verdict = this.probe.got(f, performance.now());
      if (verdict) { this.autoSwitch(verdict); return; }  // the next session's frames show
    }
    try {
      if (f.encoding === 'jpeg' && (this.display === 's3tc' || this.display === 'h264')) {
        // The node answered JPEG after all: switch displays.
        this.useView(new JpegDisplay(this.handler.container.ownerDocument));
        this.display = 'jpeg';
      }
      if (!(await this.frameView.show(f))) return;
      if (this.display === 'mjpeg') this.flushMjpeg(f);
      this.showRefinement(f);
      this.shownFrame = Math.max(this.shownFrame || 0, f.frame);
      this.handler.frameDrawn({ frame: f.frame, timeEnd: performance.now(), renderTimeInMilliseconds: f.timings.rendering,
        timings: f.timings, encoding: f.encoding, width: f.width, height: f.height, remote: true,
        refined: !!f.refined, converged: !!f.converged, samples: f.samples ?? 1 });
    } catch (e) {
      this.handler.setStatus('frame', `⚠ cannot show frame ${f.frame}: ${e.message}`, true);
    }
  }

  // Whether the node refines stills for this page: a target above 1 and the ray tracer.
  get refining() { return this.channel.settings?.refineSamples > 1 && this.channel.reply?.renderer === 'raytracer'; }
  // Whether the node may send frames unasked after a requested one: refinements, or (within a
  // frame budget) the full-resolution still after a scaled frame.
  get unasked() { return this.refining || this.channel.settings?.frameBudget > 0; }

  // The refinement status line ("interactive", "refining k/N", "converged N"), while refinement is on.
  showRefinement(f) {
    this.handler.setStatus('refine', this.refining ? refineStatus(f, this.channel.settings.refineSamples) : null);
  }

  // Chromium shows a part of a multipart/x-mixed-replace stream only when the next part
  // starts: the node closes each part with the boundary at once, but that alone does not
  // show it (tried), so the newest frame would stay hidden until another one comes. After
  // the last frame of a change the client therefore asks for one more (identical) frame,
  // which pushes the previous one out; and while the stream has shown nothing (it connected
  // after the first frames went out) it asks again, at most 20 times; if by then it shows a
  // picture (the frame before, pushed out by this one), this frame still needs its push, so it
  // is flushed as if it had come after the stream showed. A node that refines
  // stills (or follows a scaled frame with its full-resolution still) sends refined frames
  // after a requested one, which push it out: then the client asks only when none has come
  // within half a second, and never after a refined frame (a request would start the still
  // again), so the last refinement shows when the next frame comes.
  flushMjpeg(f) {
    const ch = this.channel;
    clearTimeout(this.flushTimer);
    if (f.refined) return;
    if (!this.frameView.showing && (this.mjpegRetries = (this.mjpegRetries || 0) + 1) <= 20) {
      this.flushTimer = setTimeout(() => (this.frameView.showing ? this.flushMjpeg(f) : ch.requestRender()), 150);
      return;
    }
    const flush = () => {
      if (f.frame === this.flushFrame || ch.outstanding > 0 || ch.renderWanted || ch.dirty || ch.queue.length || ch.waiting) return;
      ch.requestRender();
      this.flushFrame = ch.frameNumber;
    };
    if (this.unasked) this.flushTimer = setTimeout(flush, 500);
    else flush();
  }

  update(scene) {
    const h = this.handler;
    this.inputElement.width = h.width;
    this.inputElement.height = h.height;
    this.channel.setSettings(this.readSettings());
    this.channel.setVideoKbps(this.videoKbps);
    this.channel.setScene(scene, { width: h.width, height: h.height,
      background: cssColor(h.container.ownerDocument, h.container) });
  }

  draw() { return null; }  // frames arrive asynchronously

  dispose() {
    this.disposed = true;
    clearTimeout(this.gateTimer);
    this.openDownloads();
    clearTimeout(this.flushTimer);
    this.channel.close();
    if (this.frameView) this.frameView.dispose();
    this.inputElement.remove();
  }
}
