// Parses a CSS transform value ("translate3d(1px,2px,3px) rotateY(30deg)", "matrix3d(...)",
// "none") into a column-major matrix. CSS px are scene units. Returns null for "none" or
// an empty value; throws an Error naming the function it cannot read.
import { identity, multiply, translation, scaling, axisAngle } from './Mat4.js';

function angle(tok) {
  const m = /^([+-]?[\d.]+(?:e[+-]?\d+)?)(deg|rad|grad|turn)?$/i.exec(tok.trim());
  if (!m) throw new Error(`bad angle "${tok}"`);
  const v = parseFloat(m[1]);
  switch ((m[2] || 'rad').toLowerCase()) {
    case 'deg': return v * Math.PI / 180;
    case 'grad': return v * Math.PI / 200;
    case 'turn': return v * 2 * Math.PI;
    default: return v;
  }
}

function length(tok) {
  const m = /^([+-]?[\d.]+(?:e[+-]?\d+)?)(px)?$/i.exec(tok.trim());
  if (!m) throw new Error(`bad length "${tok}" (only px or unitless)`);
  return parseFloat(m[1]);
}

export function parseCssTransform(text) {
  if (!text) return null;
  text = String(text).trim();
  if (!text || text === 'none') return null;
  let m = identity();
  const re = /([a-zA-Z0-9]+)\(([^)]*)\)/g;
  let match, consumed = '';
  while ((match = re.exec(text))) {
    consumed += match[0];
    const fn = match[1].toLowerCase();
    const args = match[2].split(/\s*,\s*|\s+/).filter((s) => s.length);
    let f;
    switch (fn) {
      case 'matrix': {
        const [a, b, c, d, e, g] = args.map(Number);
        f = identity();
        f[0] = a; f[1] = b; f[4] = c; f[5] = d; f[12] = e; f[13] = g;
        break;
      }
      case 'matrix3d': f = new Float32Array(args.map(Number)); break;
      case 'translate': f = translation(length(args[0]), args[1] ? length(args[1]) : 0, 0); break;
      case 'translate3d': f = translation(length(args[0]), length(args[1]), length(args[2])); break;
      case 'translatex': f = translation(length(args[0]), 0, 0); break;
      case 'translatey': f = translation(0, length(args[0]), 0); break;
      case 'translatez': f = translation(0, 0, length(args[0])); break;
      case 'scale': { const x = Number(args[0]); f = scaling(x, args[1] !== undefined ? Number(args[1]) : x, 1); break; }
      case 'scale3d': f = scaling(Number(args[0]), Number(args[1]), Number(args[2])); break;
      case 'scalex': f = scaling(Number(args[0]), 1, 1); break;
      case 'scaley': f = scaling(1, Number(args[0]), 1); break;
      case 'scalez': f = scaling(1, 1, Number(args[0])); break;
      case 'rotate': case 'rotatez': f = axisAngle(0, 0, 1, angle(args[0])); break;
      case 'rotatex': f = axisAngle(1, 0, 0, angle(args[0])); break;
      case 'rotatey': f = axisAngle(0, 1, 0, angle(args[0])); break;
      case 'rotate3d': f = axisAngle(Number(args[0]), Number(args[1]), Number(args[2]), angle(args[3])); break;
      default: throw new Error(`unsupported CSS transform function ${fn}()`);
    }
    if (f.length !== 16 || Array.from(f).some((v) => !Number.isFinite(v)))
      throw new Error(`bad arguments in ${match[0]}`);
    m = multiply(m, f);
  }
  if (!consumed) throw new Error(`cannot read CSS transform "${text}"`);
  return m;
}
