// Where server frames are shown (behind the transparent input canvas):
// JpegDisplay  - JPEG frames decoded by createImageBitmap (off the main thread in Chromium)
//                and shown on a 'bitmaprenderer' canvas;
// S3tcDisplay  - DXT1 frames uploaded as WEBGL_compressed_texture_s3tc and drawn as a quad;
// MjpegDisplay - an <img> on the node's MJPEG stream (http://host:port/mjpeg/<session>).

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
