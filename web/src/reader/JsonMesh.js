// XML3D's JSON data format: {"format":"xml3d-json","version":"0.4.0","data":{name:{type,seq:[{value,key}]}}}
// ("material" instead of "data" when used as a material source). A value may be
// {url, byteOffset, byteLength} pointing at little-endian binary data.
import { VALUE_TYPES } from './Values.js';

const BINARY = {
  float: Float32Array, float2: Float32Array, float3: Float32Array, float4: Float32Array, float4x4: Float32Array,
  int: Int32Array, int4: Int32Array, bool: Uint8Array, byte: Int8Array, ubyte: Uint8Array,
};

export async function parseXml3dJson(json, url, fetchBinary) {
  if (!json || json.format !== 'xml3d-json') throw new Error('not an xml3d-json document (format must be "xml3d-json")');
  if (json.version !== '0.4.0') throw new Error(`xml3d-json version ${json.version} not supported (0.4.0)`);
  const data = json.data || json.material;
  if (!data || typeof data !== 'object') throw new Error('xml3d-json document has no "data"');
  const map = new Map();
  for (const [name, entry] of Object.entries(data)) {
    if (!entry || typeof entry !== 'object') throw new Error(`"${name}" is not an entry ({type, seq})`);
    const type = entry.type;
    const seq = Array.isArray(entry.seq) && entry.seq[0];
    if (!seq || typeof seq !== 'object') continue;
    let value = seq.value;
    const T = BINARY[type] || (VALUE_TYPES[type] && VALUE_TYPES[type].array) || Array;
    if (value && !Array.isArray(value) && typeof value === 'object' && typeof value.url === 'string') {
      const buf = await fetchBinary(new URL(value.url, url).href);
      const off = value.byteOffset ?? 0, len = value.byteLength ?? buf.byteLength - off;
      const size = T.BYTES_PER_ELEMENT || 1;
      if (!Number.isInteger(off) || !Number.isInteger(len) || off < 0 || len < 0 || off + len > buf.byteLength || len % size)
        throw new Error(`"${name}": byteOffset ${value.byteOffset} and byteLength ${value.byteLength} do not fit ${value.url} ` +
          `(${buf.byteLength} bytes) in whole ${type} values`);
      value = new T(buf.slice(off, off + len));
    } else if (value !== undefined && value !== null && !Array.isArray(value)) {
      // A number here would be a typed array's length: 1e9 would allocate gigabytes.
      throw new Error(`"${name}": value is neither an array nor a {url, byteOffset, byteLength} reference`);
    } else if (T !== Array) {
      value = new T(value || []);
    }
    const t = type === 'byte' || type === 'ubyte' ? 'int' : type;
    map.set(name, { type: t, value });
  }
  return map;
}
