// The page's render settings for the node: <xml3d ao-samples="N" max-depth="D" refine-samples="R"
// frame-budget="MS">, sent as the protocol's settings record (protocol/protocol.h Settings),
// refine record (Refine) and budget record (Budget) after the handshake and whenever the
// attributes change. Bad values are reported (console warning, status line) and the default is
// used instead (a refine-samples or frame-budget beyond its range is clamped to it), so a typo
// never makes the node refuse the session. Also video-kbps, the H.264 display's bitrate (a
// video record; readVideoKbps below).

import { MIN_VIDEO_KBPS } from './Protocol.js';
import { RANGES } from './Wire.js';

// Same ranges as `tessera render --ao/--depth` and the node's default limits
// (protocol::Limits::max_ao_samples = 256, max_refine_samples = 4096, max_frame_budget_ms =
// 60000; a depth of 1 means primary rays only; 0 or 1 refine samples: no refinement; a frame
// budget of 0: interactive frames always at the client's resolution).
export const RENDER_SETTINGS = {
  aoSamples: { attribute: 'ao-samples', min: 0, max: 256, default: 0, what: 'ambient occlusion rays per hit' },
  maxDepth: { attribute: 'max-depth', min: 1, max: 64, default: 4, what: 'ray depth (1 = primary rays only)' },
  refineSamples: { attribute: 'refine-samples', min: 0, max: 4096, default: 64, clamp: true,
    what: 'samples per pixel a still image refines to; 0 or 1 = off' },
  frameBudget: { attribute: 'frame-budget', min: 0, max: 60000, default: 33, clamp: true,
    what: 'milliseconds an interactive frame should take, rendered at a lower resolution to fit; 0 = off' },
};

// Reads the settings from an <xml3d> element: {settings: {aoSamples, maxDepth, refineSamples,
// frameBudget}, problems: [text]}.
export function readRenderSettings(xml3d) {
  const settings = {}, problems = [];
  for (const [key, spec] of Object.entries(RENDER_SETTINGS)) {
    settings[key] = spec.default;
    if (!xml3d.hasAttribute(spec.attribute)) continue;
    const text = xml3d.getAttribute(spec.attribute);
    const v = (spec.clamp ? /^\s*[+-]?\d+\s*$/ : /^\s*\+?\d+\s*$/).test(text) ? Number(text) : NaN;
    const range = `${spec.min}..${spec.max}`;
    if (Number.isSafeInteger(v) && v >= spec.min && v <= spec.max) settings[key] = v;
    else if (spec.clamp && !Number.isNaN(v)) {
      settings[key] = Math.min(spec.max, Math.max(spec.min, v));
      problems.push(`<xml3d ${spec.attribute}="${text}">: not in ${range} (${spec.what}); using ${settings[key]}`);
    } else problems.push(`<xml3d ${spec.attribute}="${text}">: not a whole number in ${range} (${spec.what}); using ${spec.default}`);
  }
  return { settings, problems };
}

// <xml3d video-kbps="N">: the H.264 display's bitrate in kbit/s, sent as the protocol's video
// record (Video.bitrate_kbps). It has no default here: absent, or not a whole number in range
// (reported like the others), it is 0 and nothing is sent, so the node's own bitrate holds
// (`tessera.video-kbps`, 8000 unless configured).
export const VIDEO_KBPS = { attribute: 'video-kbps', min: MIN_VIDEO_KBPS, max: RANGES.video.bitrate_kbps.hi, what: 'H.264 bitrate in kbit/s' };

// {kbps (0: not set), problem (text or null)}.
export function readVideoKbps(xml3d) {
  const { attribute, min, max, what } = VIDEO_KBPS;
  if (!xml3d.hasAttribute(attribute)) return { kbps: 0, problem: null };
  const text = xml3d.getAttribute(attribute);
  const v = /^\s*\+?\d+\s*$/.test(text) ? Number(text) : NaN;
  if (Number.isSafeInteger(v) && v >= min && v <= max) return { kbps: v, problem: null };
  return { kbps: 0, problem: `<xml3d ${attribute}="${text}">: not a whole number in ${min}..${max} (${what}); ignored, the node's bitrate is used` };
}

export const sameSettings = (a, b) => !!a && !!b && a.aoSamples === b.aoSamples && a.maxDepth === b.maxDepth
  && a.refineSamples === b.refineSamples && a.frameBudget === b.frameBudget;

// The refinement status of a still after `frame` was shown, for a target of `target` samples per
// pixel: null when refinement is off (target 0 or 1), 'interactive' after a requested frame,
// 'refining k/N' while the node's unsolicited refinements come, 'converged k' at the still's
// last frame (at the target, or sooner where the node refines adaptively: k is then the mean
// samples per pixel).
export function refineStatus(frame, target) {
  if (!(target > 1)) return null;
  if (!frame.refined) return 'interactive';
  return frame.converged || frame.samples >= target ? `converged ${frame.samples}` : `refining ${frame.samples}/${target}`;
}
