// The colour a server-rendered frame is drawn on (issue 20 item 9). With WebGL, a transparent
// <xml3d> shows the page behind it; a JPEG frame has no alpha, so the node renders the sky in
// the colour the page would show there instead: the container's background composited over its
// ancestors' (each rgba over the one below it), over the browser's white canvas. Background
// images and content that overlaps the element are not seen this way; solid page colours are.
//
// getComputedStyle: (el) -> CSSStyleDeclaration-like with backgroundColor ("rgb(r, g, b)",
// "rgba(r, g, b, a)", "transparent"; the modern space-separated form too).
export function parseCssColor(text) {
  const c = String(text || '').trim();
  if (c === '' || c === 'transparent') return null;
  const m = /^rgba?\(([^)]*)\)$/.exec(c);
  if (!m) return null;
  const parts = m[1].split(/[\s,/]+/).filter((p) => p !== '');
  if (parts.length < 3) return null;
  const num = (p, scale) => (p.endsWith('%') ? (parseFloat(p) / 100) * scale : parseFloat(p));
  const [r, g, b] = parts.slice(0, 3).map((p) => num(p, 255) / 255);
  const a = parts.length > 3 ? num(parts[3], 1) : 1;
  if (![r, g, b, a].every(Number.isFinite)) return null;
  const clamp = (v) => Math.min(1, Math.max(0, v));
  return { rgb: [clamp(r), clamp(g), clamp(b)], a: clamp(a) };
}

export function pageBackground(el, getComputedStyle) {
  const layers = [];  // from el outwards
  for (let e = el; e && e.nodeType === 1; e = e.parentElement) {
    let c = null;
    try { c = parseCssColor(getComputedStyle(e).backgroundColor); } catch { /* not styled */ }
    if (c && c.a > 0) layers.push(c);
    if (c && c.a >= 1) break;  // opaque: nothing behind it shows
  }
  let bg = [1, 1, 1];  // the browser's canvas
  for (let i = layers.length - 1; i >= 0; i--) {
    const { rgb, a } = layers[i];
    bg = bg.map((v, k) => a * rgb[k] + (1 - a) * v);
  }
  return bg;
}
