// Where server frames are shown (behind the transparent input canvas):
// JpegDisplay  - JPEG frames decoded by createImageBitmap (off the main thread in Chromium)
//                and shown on a 'bitmaprenderer' canvas;
// S3tcDisplay  - DXT1 frames uploaded as WEBGL_compressed_texture_s3tc and drawn as a quad;
// MjpegDisplay - an <img> on the node's MJPEG stream (http://host:port/mjpeg/<session>);
// VideoDisplay - H.264 access units decoded by WebCodecs' VideoDecoder onto a 2d canvas.

export class JpegDisplay {
  constructor(doc) {
    this.element = doc.createElement('canvas');
    this.element.className = 'tessera-display';
    this.ctx = this.element.getContext('bitmaprenderer');
    this.received = 0;
    this.shown = 0;
  }
  // Resolves true when the frame is on screen (false when a newer frame overtook it). Frames
  // are ordered by arrival: the refinements of a still share its frame number.
  async show(frame) {
    if (frame.encoding !== 'jpeg') throw new Error(`expected a JPEG frame, got ${frame.encoding}`);
    const order = ++this.received;
    const bitmap = await createImageBitmap(new Blob([frame.payload], { type: 'image/jpeg' }));
    if (order < this.shown) { bitmap.close(); return false; }
    this.shown = order;
    this.element.width = bitmap.width;
    this.element.height = bitmap.height;
    this.ctx.transferFromImageBitmap(bitmap);
    return true;
  }
  dispose() { this.element.remove(); }
}

export class S3tcDisplay {
  constructor(doc) {
    const c = this.element = doc.createElement('canvas');
    c.className = 'tessera-display';
    const gl = this.gl = c.getContext('webgl2', { alpha: false, antialias: false, preserveDrawingBuffer: true });
    this.ext = gl.getExtension('WEBGL_compressed_texture_s3tc');
    const sh = (type, src) => { const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s); return s; };
    const p = this.program = gl.createProgram();
    gl.attachShader(p, sh(gl.VERTEX_SHADER, `#version 300 es
      in vec2 pos; uniform vec2 scale; out vec2 uv;
      void main() { uv = vec2((pos.x * 0.5 + 0.5) * scale.x, (0.5 - pos.y * 0.5) * scale.y); gl_Position = vec4(pos, 0.0, 1.0); }`));
    gl.attachShader(p, sh(gl.FRAGMENT_SHADER, `#version 300 es
      precision mediump float; in vec2 uv; uniform sampler2D tex; out vec4 color;
      void main() { color = vec4(texture(tex, uv).rgb, 1.0); }`));
    gl.linkProgram(p);
    this.buffer = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, this.buffer);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 1, -1, -1, 1, 1, 1]), gl.STATIC_DRAW);
    this.texture = gl.createTexture();
    this.shown = 0;
  }
  async show(frame) {
    if (frame.encoding !== 'dxt1') throw new Error(`expected a DXT1 frame, got ${frame.encoding}`);
    if (frame.frame < this.shown) return false;
    this.shown = frame.frame;
    const gl = this.gl, w = frame.width, h = frame.height;
    const pw = Math.ceil(w / 4) * 4, ph = Math.ceil(h / 4) * 4;  // DXT1 level 0: whole 4x4 blocks
    if (this.element.width !== w || this.element.height !== h) { this.element.width = w; this.element.height = h; }
    gl.viewport(0, 0, w, h);
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    gl.compressedTexImage2D(gl.TEXTURE_2D, 0, this.ext.COMPRESSED_RGB_S3TC_DXT1_EXT, pw, ph, 0, frame.payload);
    gl.useProgram(this.program);
    gl.uniform2f(gl.getUniformLocation(this.program, 'scale'), w / pw, h / ph);
    const loc = gl.getAttribLocation(this.program, 'pos');
    gl.bindBuffer(gl.ARRAY_BUFFER, this.buffer);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 2, gl.FLOAT, false, 0, 0);
    gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
    return true;
  }
  dispose() { this.element.remove(); }
}

export class MjpegDisplay {
  constructor(doc, url) {
    this.element = doc.createElement('img');
    this.element.className = 'tessera-display';
    this.element.alt = '';
    this.url = url;
  }
  // Opened when the session is ready: the node sends each frame to the streams open at that
  // moment only, so a stream opened after the first frame would stay empty until the next one.
  start() { if (!this.element.src) this.element.src = this.url; }
  // True once the stream has delivered a picture.
  get showing() { return this.element.naturalWidth > 0; }
  // The image arrives on the HTTP stream; the WebSocket frame record only carries timings.
  async show() { this.start(); return true; }
  dispose() { this.element.src = ''; this.element.remove(); }
}

// H.264 (display 'h264'): each frame record carries one access unit in Annex B form (start
// codes), constrained baseline, so the decoder is configured without a `description`.

// The NAL unit types of an Annex B access unit, in order (5 IDR slice, 1 non-IDR slice, 7 SPS,
// 8 PPS, ...). A start code 00 00 01 (also the tail of 00 00 00 01) cannot occur inside a NAL
// unit (emulation prevention), so scanning for it is enough.
export function nalTypes(bytes) {
  const types = [];
  for (let i = 0; i + 3 < bytes.length; i++) {
    if (bytes[i] === 0 && bytes[i + 1] === 0 && bytes[i + 2] === 1) { types.push(bytes[i + 3] & 0x1f); i += 3; }
  }
  return types;
}

// A unit the decoder can start from: it holds an IDR slice (the node sends SPS and PPS with it).
export const isKeyframe = (bytes) => nalTypes(bytes).includes(5);

// Constrained baseline levels by their largest frame in macroblocks (H.264 table A-1, MaxFS),
// lowest first; level 3.1 covers 1280x720. A picture's sides may be at most sqrt(8 MaxFS)
// macroblocks each. The node encodes up to level 5.2.
const LEVELS = [[0x1f, 3600], [0x20, 5120], [0x28, 8192], [0x2a, 8704], [0x32, 22080], [0x33, 36864], [0x3c, 139264]];
export const H264_CODEC = 'avc1.42E01F';  // the probe's configuration (RemoteBackend, Features.js)

// The codec string for a width x height stream: constrained baseline (42 E0) at the lowest level
// from 3.1 up whose frame size fits.
export function h264Codec(width, height) {
  const mw = Math.ceil(width / 16), mh = Math.ceil(height / 16);
  const [level] = LEVELS.find(([, fs]) => mw * mh <= fs && Math.max(mw, mh) <= Math.sqrt(8 * fs)) || LEVELS.at(-1);
  return `avc1.42E0${level.toString(16).toUpperCase().padStart(2, '0')}`;
}

export class VideoDisplay {
  // onNeedKeyframe(error): called when the decoder cannot go on without a keyframe (after a
  // decoder error, with it; or a delta unit came first, with null), once per keyframe awaited;
  // RemoteBackend then asks the node for one (a video record).
  // VideoDecoder, EncodedVideoChunk: WebCodecs (replaced in unit tests).
  constructor(doc, { onNeedKeyframe = () => {}, VideoDecoder = globalThis.VideoDecoder,
    EncodedVideoChunk = globalThis.EncodedVideoChunk } = {}) {
    this.element = doc.createElement('canvas');
    this.element.className = 'tessera-display';
    this.ctx = this.element.getContext('2d', { alpha: false });
    Object.assign(this, { onNeedKeyframe, VideoDecoder, EncodedVideoChunk });
    this.pending = new Map();  // chunk timestamp -> {width, height, resolve}, in decode order
    this.chunks = 0;
    this.waitingForKey = true;  // a delta unit needs every unit since the last keyframe
    this.keyRequested = false;
    this.config = null;  // codec and size the decoder is configured for
    this.decoder = this.makeDecoder();
  }

  makeDecoder() {
    const dec = new this.VideoDecoder({ output: (f) => this.output(dec, f), error: (e) => this.failed(dec, e) });
    return dec;
  }

  // Resolves true when the frame is on screen, false when it is not shown (a delta unit before
  // the first keyframe, or the decoder failed on it or an earlier one).
  async show(frame) {
    if (frame.encoding !== 'h264') throw new Error(`expected an H.264 frame, got ${frame.encoding}`);
    if (!this.decoder) return false;  // disposed
    const key = isKeyframe(frame.payload);
    if (!key && this.waitingForKey) { this.needKeyframe(); return false; }
    if (key) {
      this.waitingForKey = false;
      this.keyRequested = false;
      // A keyframe may start a stream of another size (the node sends one after each size
      // change): the decoder is configured anew for it, at the level the size needs.
      const codec = h264Codec(frame.width, frame.height), config = `${codec} ${frame.width}x${frame.height}`;
      if (config !== this.config || this.decoder.state !== 'configured') {
        try { this.decoder.configure({ codec, optimizeForLatency: true }); } catch (e) { this.failed(this.decoder, e); return false; }
        this.config = config;
      }
    }
    const timestamp = this.chunks++;
    const shown = new Promise((resolve) => this.pending.set(timestamp, { width: frame.width, height: frame.height, resolve }));
    try {
      this.decoder.decode(new this.EncodedVideoChunk({ type: key ? 'key' : 'delta', timestamp, data: frame.payload }));
    } catch (e) {
      this.failed(this.decoder, e);
    }
    return shown;
  }

  // A decoded picture: drawn cropped to its frame's width x height (the node pads odd sizes by
  // one pixel), then closed (a VideoFrame holds decoder memory until then).
  output(dec, vf) {
    try {
      if (dec !== this.decoder) return;
      // One picture per unit, in decode order (no B-frames): units before this one that gave
      // none are not shown.
      for (const [t, p] of this.pending) {
        if (t >= vf.timestamp) break;
        this.pending.delete(t);
        p.resolve(false);
      }
      const p = this.pending.get(vf.timestamp);
      this.pending.delete(vf.timestamp);
      const w = Math.min(p ? p.width : vf.displayWidth, vf.displayWidth), h = Math.min(p ? p.height : vf.displayHeight, vf.displayHeight);
      if (this.element.width !== w || this.element.height !== h) { this.element.width = w; this.element.height = h; }
      this.ctx.drawImage(vf, 0, 0, w, h, 0, 0, w, h);
      if (p) p.resolve(true);
    } finally {
      vf.close();
    }
  }

  // The decoder failed (its error callback, or configure/decode threw): a fresh one waits for
  // the next keyframe, which is asked for once.
  failed(dec, e) {
    if (dec !== this.decoder) return;  // an earlier decoder's late error
    for (const p of this.pending.values()) p.resolve(false);
    this.pending.clear();
    try { if (dec.state !== 'closed') dec.close(); } catch { /* closed already */ }
    this.config = null;
    this.waitingForKey = true;
    this.decoder = this.makeDecoder();
    this.needKeyframe(e);
  }

  needKeyframe(error = null) {
    if (this.keyRequested) return;
    this.keyRequested = true;
    this.onNeedKeyframe(error);
  }

  dispose() {
    const dec = this.decoder;
    this.decoder = null;
    for (const p of this.pending.values()) p.resolve(false);
    this.pending.clear();
    try { if (dec && dec.state !== 'closed') dec.close(); } catch { /* closed already */ }
    this.element.remove();
  }
}
