// Browser features the server path uses, probed once each (with one warning when missing).
let s3tc;
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
