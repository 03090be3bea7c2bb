import { test } from 'node:test';
import assert from 'node:assert/strict';
import { parseXml3dJson } from '../../../src/reader/JsonMesh.js';

const doc = (data) => ({ format: 'xml3d-json', version: '0.4.0', data });
const bin = new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0]).buffer;
const fetchBinary = async () => bin;

test('xml3d-json: inline arrays and {url, byteOffset, byteLength} references load', async () => {
  const m = await parseXml3dJson(doc({
    position: { type: 'float3', seq: [{ value: { url: 'tri.bin', byteOffset: 12, byteLength: 24 } }] },
    index: { type: 'int', seq: [{ value: [0, 1, 2] }] },
  }), 'http://localhost/m.json', fetchBinary);
  assert.deepEqual([...m.get('position').value], [1, 0, 0, 0, 1, 0]);
  assert.deepEqual([...m.get('index').value], [0, 1, 2]);
});

test('xml3d-json: values that are not arrays, and references that do not fit, are errors naming the entry', async () => {
  const cases = [
    [{ position: { type: 'float3', seq: [{ value: 1e9 }] } }, /"position": value is neither an array nor a \{url, byteOffset, byteLength\} reference/],
    [{ position: null }, /"position" is not an entry/],
    [{ position: { type: 'float3', seq: [{ value: { url: 'tri.bin', byteOffset: 40 } }] } }, /"position": byteOffset 40 and byteLength undefined do not fit tri\.bin \(36 bytes\)/],
    [{ position: { type: 'float3', seq: [{ value: { url: 'tri.bin', byteLength: 10 } }] } }, /do not fit tri\.bin \(36 bytes\) in whole float3 values/],
    [{ position: { type: 'float3', seq: [{ value: { url: 'tri.bin', byteOffset: -4, byteLength: 8 } }] } }, /byteOffset -4/],
  ];
  for (const [data, message] of cases) await assert.rejects(parseXml3dJson(doc(data), 'http://localhost/m.json', fetchBinary), message);
});
