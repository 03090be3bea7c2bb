// The page's render settings for the node: <xml3d ao-samples="N" max-depth="D">, sent as the
// protocol's settings record (protocol/protocol.h Settings) after the handshake and whenever the
// attributes change. Bad values are reported (console warning, status line) and the default
// is used instead, so a typo never makes the node refuse the session.

// Same ranges as `tessera render --ao/--depth` and the node's default limits
// (protocol::Limits::max_ao_samples = 256; a depth of 1 means primary rays only).
export const RENDER_SETTINGS = {
  aoSamples: { attribute: 'ao-samples', min: 0, max: 256, default: 0, what: 'ambient occlusion rays per hit' },
  maxDepth: { attribute: 'max-depth', min: 1, max: 64, default: 4, what: 'ray depth (1 = primary rays only)' },
};

// Reads the settings from an <xml3d> element: {settings: {aoSamples, maxDepth}, problems: [text]}.
export function readRenderSettings(xml3d) {
  const settings = {}, problems = [];
  for (const [key, spec] of Object.entries(RENDER_SETTINGS)) {
    settings[key] = spec.default;
    if (!xml3d.hasAttribute(spec.attribute)) continue;
    const text = xml3d.getAttribute(spec.attribute);
    const v = /^\s*\+?\d+\s*$/.test(text) ? Number(text) : NaN;
    if (Number.isSafeInteger(v) && v >= spec.min && v <= spec.max) settings[key] = v;
    else problems.push(`<xml3d ${spec.attribute}="${text}">: not a whole number in ${spec.min}..${spec.max} (${spec.what}); using ${spec.default}`);
  }
  return { settings, problems };
}

export const sameSettings = (a, b) => !!a && !!b && a.aoSamples === b.aoSamples && a.maxDepth === b.maxDepth;
