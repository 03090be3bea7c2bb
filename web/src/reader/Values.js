// XML3D value elements (float, float2, float3, float4, float4x4, int, int4, bool, string,
// texture) and the data-compositing rules of <data>/<mesh>/<material>/<light>/<view>.

export const VALUE_TYPES = {
  float: { size: 1, array: Float32Array },
  float2: { size: 2, array: Float32Array },
  float3: { size: 3, array: Float32Array },
  float4: { size: 4, array: Float32Array },
  float4x4: { size: 16, array: Float32Array },
  int: { size: 1, array: Int32Array },
  int4: { size: 4, array: Int32Array },
  bool: { size: 1, array: Uint8Array },
  string: { size: 1, array: Array },
  texture: { size: 1, array: Array },
};

export const SCRIPT_PLACEHOLDER = '[value set by script]';
const NUMBER = /[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?/g;

// The numbers written in an attribute's text, in order (anything else between them ignored).
export const numbersIn = (s) => (String(s).match(NUMBER) || []).map(Number);

// Values given by setScriptValue, kept out of band (as xml3d.js does).
const scriptValues = new WeakMap();
// Parse cache: an unchanged element gives the same typed array (stable buffer identity).
const parseCache = new WeakMap();

export function setScriptValue(element, value) {
  scriptValues.set(element, value);
  // The attribute change is what MutationObservers see.
  element.textContent = SCRIPT_PLACEHOLDER;
  element.setAttribute('data-script-version', String(Number(element.getAttribute('data-script-version') || 0) + 1));
}

export function localName(el) {
  return (el.localName || el.tagName || '').toLowerCase();
}

export function isValueElement(el) {
  return Object.prototype.hasOwnProperty.call(VALUE_TYPES, localName(el));
}

// Parses a value element's text. Returns {type, value, error?}; bad tokens are reported,
// and the count is truncated to a whole number of tuples.
export function parseValueElement(el) {
  const type = localName(el);
  const info = VALUE_TYPES[type];
  if (scriptValues.has(el)) return { type, value: scriptValues.get(el) };
  const text = el.textContent || '';
  const cached = parseCache.get(el);
  if (cached && cached.text === text) return cached.result;
  let value, error;
  if (type === 'string') {
    value = text.split(',').map((s) => s.trim()).filter((s) => s.length);
  } else if (type === 'bool') {
    const toks = text.trim().split(/[\s,]+/).filter((s) => s.length);
    value = new Uint8Array(toks.length);
    toks.forEach((t, i) => {
      const l = t.toLowerCase();
      if (l === 'true' || l === '1') value[i] = 1;
      else if (l !== 'false' && l !== '0') error = `bool value "${t}" is not true/false/1/0`;
    });
  } else {
    const nums = text.match(NUMBER) || [];
    // The words that are not numbers, as the page has them, a space between each ("NaN NaN",
    // not "NaNNaN"), and how many there are beyond the first few.
    const junk = text.replace(NUMBER, ' ').split(/[\s,;]+/).filter((w) => w.length);
    if (junk.length) {
      const shown = junk.slice(0, 4).join(' ').slice(0, 60);
      error = `<${type} name="${el.getAttribute('name')}"> holds text that is not a number: "${shown}"` +
        (junk.length > 4 ? ` (and ${junk.length - 4} more)` : '');
    }
    let n = nums.length - (nums.length % info.size);
    if (n !== nums.length)
      error = (error ? error + '; ' : '') + `<${type} name="${el.getAttribute('name')}"> has ${nums.length} numbers, not a multiple of ${info.size}`;
    value = new info.array(n);
    for (let i = 0; i < n; i++) value[i] = info.array === Int32Array ? parseInt(nums[i], 10) : parseFloat(nums[i]);
  }
  const result = { type, value, error };
  parseCache.set(el, { text, result });
  return result;
}

export function first(entry, fallback) {
  if (!entry || !entry.value || entry.value.length === 0) return fallback;
  return entry.value[0];
}

export function vec3(entry, fallback) {
  if (!entry || !entry.value || entry.value.length < 3) return fallback;
  return [entry.value[0], entry.value[1], entry.value[2]];
}
