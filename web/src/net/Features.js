// Browser features the server path uses, probed once each (with one warning when missing).
import { H264_CODEC } from './FrameDisplay.js';

let s3tc, h264;
const warned = new Set();

export function warnOnce(key, message) {
  if (warned.has(key)) return;
  warned.add(key);
  console.warn(`XML3D/Tessera: ${message}`);
}

export function hasS3TC() {
  if (s3tc !== undefined) return s3tc;
  try {
    const c = document.createElement('canvas');
    const gl = c.getContext('webgl2') || c.getContext('webgl');
    s3tc = !!(gl && gl.getExtension('WEBGL_compressed_texture_s3tc'));
    const lose = gl && gl.getExtension('WEBGL_lose_context');
    if (lose) lose.loseContext();
  } catch { s3tc = false; }
  if (!s3tc) warnOnce('s3tc', 'WEBGL_compressed_texture_s3tc is not available: display="s3tc" falls back to JPEG frames');
  return s3tc;
}

export const hasCompressionStream = () => {
  const ok = typeof CompressionStream !== 'undefined';
  if (!ok) warnOnce('deflate', 'CompressionStream is not available: scene buffers are sent uncompressed');
  return ok;
};

export async function deflate(bytes) {
  const stream = new Blob([bytes]).stream().pipeThrough(new CompressionStream('deflate'));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}

// Whether WebCodecs can decode the node's H.264 stream (display="h264"/"auto"): a promise of
// {ok, reason}, asked once per page (isConfigSupported is asynchronous, and the answer does not
// change). The configuration is constrained baseline at level 3.1 (up to 1280x720), the level
// VideoDisplay uses for such sizes.
export function probeH264() {
  if (!h264) {
    h264 = (async () => {
      const { VideoDecoder, EncodedVideoChunk } = globalThis;
      if (typeof VideoDecoder !== 'function' || typeof EncodedVideoChunk !== 'function') {
        return { ok: false, reason: 'the browser has no VideoDecoder (WebCodecs)' };
      }
      try {
        const r = await VideoDecoder.isConfigSupported({ codec: H264_CODEC, optimizeForLatency: true });
        return r && r.supported ? { ok: true, reason: '' } : { ok: false, reason: `VideoDecoder does not support H.264 (${H264_CODEC})` };
      } catch (e) {
        return { ok: false, reason: `VideoDecoder.isConfigSupported(${H264_CODEC}) failed: ${e && e.message}` };
      }
    })();
  }
  return h264;
}

// Unit tests: forget every probe and warning, as a new page would.
export function resetFeatures() {
  s3tc = h264 = undefined;
  warned.clear();
}
