// Loads a texture for the server: PNG/JPEG bytes as they are when no flip is needed (glTF),
// otherwise decoded, flipped (XML3D textures have v = 0 at the bottom; the server's row 0 is
// v = 0) and sent as RGBA8.
export async function loadTexture(desc) {
  const res = await fetch(desc.url);
  if (!res.ok) throw new Error(`HTTP ${res.status}`);
  const blob = await res.blob();
  const head = new Uint8Array(await blob.slice(0, 4).arrayBuffer());
  const format = head[0] === 0x89 && head[1] === 0x50 ? 'png' : head[0] === 0xff && head[1] === 0xd8 ? 'jpeg' : null;
  const bitmap = await createImageBitmap(blob, { imageOrientation: desc.flipY ? 'flipY' : 'from-image',
    premultiplyAlpha: 'none', colorSpaceConversion: 'none' });
  const base = { wrapS: desc.wrapS, wrapT: desc.wrapT, filter: desc.filter, srgb: !!desc.srgb, width: bitmap.width, height: bitmap.height };
  if (format && !desc.flipY) {
    bitmap.close();
    return { ...base, format, bytes: new Uint8Array(await blob.arrayBuffer()) };
  }
  const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
  const ctx = canvas.getContext('2d');
  ctx.drawImage(bitmap, 0, 0);
  bitmap.close();
  const data = ctx.getImageData(0, 0, base.width, base.height).data;
  return { ...base, format: 'rgba8', bytes: new Uint8Array(data.buffer, data.byteOffset, data.byteLength) };
}
